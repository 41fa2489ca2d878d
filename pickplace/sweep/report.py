"""The report of a sweep: what a set of trials says, as a JSON-ready dict and as text.

From the trials' compact summaries (:func:`pickplace.sweep.sweep.compact_summary`):

- the success rate with its 95 % Wilson interval (:func:`pickplace.sweep.stats.wilson_interval`);
- failures by reason, with their seeds, the failure text of the first one and the command
  that re-runs it alone; ``no-feasible-plan`` also counted by its refusal cause (why the
  planner refused: :data:`pickplace.planning.planner.REFUSAL_CAUSES`);
- p50 / p95 / max of the metrics in :data:`METRICS` (and p5 / min where low is worse);
- the success rate per bin of each varied parameter (:func:`pickplace.sim.vary.success_by_bin`);
- with ``--compare``: the same per arm, and for each pair of arms the paired comparison on
  the seeds both completed (:func:`pickplace.sweep.stats.compare_paired`: Newcombe's interval of the
  difference, McNemar's exact test);
- every trial's record (seed, outcome, metrics and drawn parameters) under ``trial_results``.

The keys are an interface (see docs/sweeps.md); :data:`SWEEP_WALL_TIME_FIELDS` are the ones that
measure the wall clock.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from pickplace.sim.vary import VaryPlan
from pickplace.sweep.bins import success_by_parameter
from pickplace.sweep.stats import PAIRED_METHOD, compare_paired, percentiles, wilson_interval

SWEEP_WALL_TIME_FIELDS = (
    "wall_time_s",
    "backend_start_s",
    "trials_per_second",
    "trials_per_second_per_worker",
)
# Seeds listed per failure reason in the text report (the JSON lists them all).
SHOWN_SEEDS = 20


@dataclass(frozen=True)
class Metric:
    """A per-trial summary value shown as p50 / p95 / worst in the report.

    Attributes:
        key: Summary key.
        label: Name shown.
        unit: Unit shown ("" for none).
        scale: Factor from the summary's SI value to ``unit``.
        successes_only: Only successful trials count (a failed run's place error is its
            distance to the target).
        low_is_worse: The bad tail is the low one (σmin): the text shows p5 and the minimum.
    """

    key: str
    label: str
    unit: str
    scale: float = 1.0
    successes_only: bool = False
    low_is_worse: bool = False


METRICS: tuple[Metric, ...] = (
    Metric("place_error_m", "place error", "mm", 1000.0, successes_only=True),
    Metric("max_slip_m", "slip in the gripper", "mm", 1000.0),
    Metric("cycle_time_s", "cycle time", "s"),
    Metric("min_singular_value", "smallest σ of the Jacobian", "", low_is_worse=True),
    Metric("max_joint_speed_ratio", "joint speed / limit", ""),
    Metric("max_robot_world_contact_force_n", "robot–world contact force", "N"),
    Metric("max_position_error_m", "tool position error", "mm", 1000.0),
)


class Arm(Protocol):
    """What the report needs of a trial spec (:class:`pickplace.sweep.sweep.TrialSpec`)."""

    @property
    def arm(self) -> str:
        """The arm's label ("" without a comparison)."""

    def rerun_command(self, seed: int) -> str:
        """The command that re-runs the trial with ``seed`` alone."""


def outcome_of(trial: Mapping[str, Any]) -> str:
    """``success`` or the trial's failure reason."""
    return "success" if trial["success"] else str(trial.get("failure") or "failed")


def metric_summary(trials: Sequence[Mapping[str, Any]], metric: Metric) -> dict[str, Any]:
    """count, p50, p95 and max of ``metric`` over the trials that moved (took a simulated
    step: not lost, not refused before any physics), successes only where the metric says so;
    plus p5 and min. None and NaN values are skipped. SI units."""
    used = [t for t in trials if not t.get("lost") and (t.get("sim_time_s") or 0.0) > 0.0]
    if metric.successes_only:
        used = [t for t in used if t["success"]]
    values = [t.get(metric.key) for t in used]
    high = percentiles(values)
    low = percentiles(None if v is None else -v for v in values)
    return {
        "count": high.count,
        "min": None if low.max is None else -low.max,
        "p5": None if low.p95 is None else -low.p95,
        "p50": high.p50,
        "p95": high.p95,
        "max": high.max,
    }


def _failures(
    trials: Sequence[Mapping[str, Any]], arms: Mapping[str, Arm]
) -> tuple[dict[str, list[int]], dict[str, dict[str, Any]]]:
    """Seeds per failure reason, and per reason its count, seeds, first failure's text and
    the command that re-runs it (the trial of the smallest seed, first arm first); for
    ``no-feasible-plan`` also its count per refusal cause (the trials' ``refusal``, most
    frequent first)."""
    seeds: dict[str, list[int]] = {}
    first: dict[str, Mapping[str, Any]] = {}
    causes: dict[str, Counter[str]] = {}
    for t in trials:
        if t["success"]:
            continue
        reason = outcome_of(t)
        seeds.setdefault(reason, []).append(int(t["seed"]))
        first.setdefault(reason, t)
        if t.get("refusal"):
            causes.setdefault(reason, Counter())[str(t["refusal"])] += 1
    details = {}
    for reason in sorted(seeds):
        t = first[reason]
        arm = arms.get(str(t.get("arm", "")))
        details[reason] = {
            "count": len(seeds[reason]),
            "seeds": seeds[reason],
            "example_seed": int(t["seed"]),
            "example": t.get("failure_text") or t.get("detail"),
            "rerun": None if arm is None else arm.rerun_command(int(t["seed"])),
        }
        if reason in causes:
            details[reason]["by_cause"] = dict(
                sorted(causes[reason].items(), key=lambda kv: (-kv[1], kv[0]))
            )
        if t.get("arm"):
            details[reason]["example_arm"] = t["arm"]
    return dict(sorted(seeds.items())), details


def outcome_report(
    trials: Sequence[Mapping[str, Any]], arms: Mapping[str, Arm], plan: VaryPlan
) -> dict[str, Any]:
    """The outcome part of a report over ``trials`` (sorted by seed, then arm)."""
    ok = [t for t in trials if t["success"]]
    full = [t for t in trials if not t.get("lost")]
    seeds, failures = _failures(trials, arms)
    interval = wilson_interval(len(ok), len(trials)).as_dict() if trials else None
    by_parameter: dict[str, list[dict[str, Any]]] = {}
    if plan.specs and trials:
        draws = [plan.draw(int(s)) for s in sorted({int(t["seed"]) for t in trials})]
        bins = success_by_parameter(plan, draws, trials)
        by_parameter = {name: [b.as_dict() for b in stats] for name, stats in bins.items()}
    errors = [t["place_error_m"] for t in ok if t.get("place_error_m") is not None]
    place = percentiles(errors)
    slips = [t["max_slip_m"] for t in full if t.get("max_slip_m") is not None]
    replanned = [t for t in full if (t.get("attempts") or 1) > 1]
    pushed = [t for t in full if t.get("pushes")]
    return {
        "completed": len(trials),
        "successes": len(ok),
        "success_rate": len(ok) / len(trials) if trials else 0.0,
        "success_interval": interval,
        "failures_by_reason": {k: len(v) for k, v in seeds.items()},
        "failed_seeds": seeds,
        "failures": failures,
        "metrics": {m.key: metric_summary(trials, m) for m in METRICS},
        "by_parameter": by_parameter,
        "place_error_p50_m": place.p50,
        "place_error_p95_m": place.p95,
        "min_singular_value": min(_present(full, "min_singular_value"), default=None),
        "max_joint_speed_ratio": max(_present(full, "max_joint_speed_ratio"), default=None),
        "max_slip_m": max(slips, default=None) if full else None,
        "replanned": {
            "trials": len(replanned),
            "successes": sum(1 for t in replanned if t["success"]),
        },
        "pushed": {
            "trials": len(pushed),
            "successes": sum(1 for t in pushed if t["success"]),
        },
    }


def _present(trials: Sequence[Mapping[str, Any]], key: str) -> list[float]:
    """The trials' finite values of ``key``."""
    out = []
    for t in trials:
        v = t.get(key)
        if v is not None and math.isfinite(v):
            out.append(float(v))
    return out


def paired_comparison(trials: Sequence[Mapping[str, Any]], a: str, b: str) -> dict[str, Any] | None:
    """Arm ``a`` against arm ``b`` on the seeds both completed (None if there is none)."""
    by_arm: dict[str, dict[int, bool]] = {a: {}, b: {}}
    for t in trials:
        arm = str(t.get("arm", ""))
        if arm in by_arm:
            by_arm[arm][int(t["seed"])] = bool(t["success"])
    seeds = sorted(set(by_arm[a]) & set(by_arm[b]))
    if not seeds:
        return None
    result = compare_paired([by_arm[a][s] for s in seeds], [by_arm[b][s] for s in seeds])
    return {"a": a, "b": b, **result.as_dict()}


def build_report(
    header: Mapping[str, Any],
    specs: Sequence[Arm],
    trials: Sequence[dict[str, Any]],
    plan: VaryPlan,
    wall_s: float,
    compare: Mapping[str, Any] | None = None,
    start_s: float = 0.0,
) -> dict[str, Any]:
    """The whole report: ``header`` (what was asked), the outcome over every run, the
    comparison's arms and pairs, the timing and every trial's record.

    Args:
        header: Fields describing the request (scenario, seeds, backend, ...).
        specs: The trial specs, one per arm.
        trials: Every finished trial (compact summaries and lost-trial entries).
        plan: The varied parameters.
        wall_s: Wall time of the sweep [s].
        compare: ``{"key": ..., "values": [...]}`` of a comparison, or None.
        start_s: The part of ``wall_s`` spent starting the backend (a Ray cluster) [s]:
            ``trials_per_second`` counts all of the wall time, ``trials_per_second_per_worker``
            the time after it.
    """
    trials = sorted(trials, key=lambda t: (int(t["seed"]), str(t.get("arm", ""))))
    arms = {s.arm: s for s in specs}
    out: dict[str, Any] = dict(header)
    out.update(outcome_report(trials, arms, plan))
    out["sim_time_s"] = float(sum(t["sim_time_s"] for t in trials if not t.get("lost")))
    if compare is not None:
        labels = [s.arm for s in specs]
        out["compare"] = {
            **compare,
            "arms": {
                label: outcome_report([t for t in trials if t.get("arm") == label], arms, plan)
                for label in labels
            },
            "paired": [
                p
                for a, b in itertools.combinations(labels, 2)
                if (p := paired_comparison(trials, a, b)) is not None
            ],
            "paired_method": PAIRED_METHOD,
        }
    workers = out.get("workers") or 0
    rate = len(trials) / wall_s if wall_s > 0 and trials else None
    running = wall_s - start_s
    out["wall_time_s"] = wall_s
    out["backend_start_s"] = start_s
    out["trials_per_second"] = rate
    out["trials_per_second_per_worker"] = (
        len(trials) / running / workers if trials and workers and running > 0 else None
    )
    out["trial_results"] = trials
    return out


# ---------------------------------------------------------------------- text


def _pct(x: float) -> str:
    return f"{100.0 * x:.1f} %"


def _interval(r: Mapping[str, Any] | None) -> str:
    if r is None:
        return "no trial"
    return f"{_pct(r['rate'])} (95 % Wilson {_pct(r['low'])}–{_pct(r['high'])})"


def _value(v: float | None, scale: float) -> str:
    if v is None:
        return "–"
    x = v * scale
    return f"{x:.3g}" if math.isfinite(x) else str(x)


def _outcome_lines(r: Mapping[str, Any], plan_units: Mapping[str, str], indent: str) -> list[str]:
    lines = []
    replanned = r.get("replanned") or {}
    if replanned.get("trials"):
        lines.append(
            f"{indent}replanned: {replanned['trials']} trials took more than one attempt "
            f"(--attempts), {replanned['successes']} of them succeeded"
        )
    pushed = r.get("pushed") or {}
    if pushed.get("trials"):
        lines.append(
            f"{indent}pushed: {pushed['trials']} trials pushed the object from a wall before "
            f"the pick, {pushed['successes']} of them succeeded"
        )
    for reason, f in r["failures"].items():
        seeds = f["seeds"]
        shown = " ".join(map(str, seeds[:SHOWN_SEEDS])) + (" …" if len(seeds) > SHOWN_SEEDS else "")
        lines.append(f"{indent}{reason}: {f['count']} (seeds {shown})")
        if f.get("by_cause"):
            by = ", ".join(f"{cause} {n}" for cause, n in f["by_cause"].items())
            lines.append(f"{indent}  by cause: {by}")
        if f.get("example"):
            lines.append(f"{indent}  seed {f['example_seed']}: {f['example']}")
        if f.get("rerun"):
            lines.append(f"{indent}  re-run: {f['rerun']}")
    rows = []
    for m in METRICS:
        s = r["metrics"].get(m.key)
        if not s or not s["count"]:
            continue
        name = f"{m.label} [{m.unit}]" if m.unit else m.label
        if m.successes_only:
            name += " (successes)"
        if m.low_is_worse:
            tail = f"p5 {_value(s['p5'], m.scale)}, min {_value(s['min'], m.scale)}"
        else:
            tail = f"p95 {_value(s['p95'], m.scale)}, max {_value(s['max'], m.scale)}"
        rows.append(f"{indent}  {name}: p50 {_value(s['p50'], m.scale)}, {tail} (n={s['count']})")
    if rows:
        lines.append(f"{indent}metrics:")
        lines += rows
    for name, bins in r["by_parameter"].items():
        unit = plan_units.get(name, "")
        lines.append(f"{indent}success by {name}" + (f" [{unit}]" if unit and unit != "-" else ""))
        for b in bins:
            label = f"{b['low']:g}" if b["low"] == b["high"] else f"{b['low']:.3g}–{b['high']:.3g}"
            if not b["trials"]:
                lines.append(f"{indent}  {label:>13}: no trial")
                continue
            fails = ", ".join(f"{k} {v}" for k, v in b["failures"].items())
            lines.append(
                f"{indent}  {label:>13}: {b['successes']:>4}/{b['trials']:<4} "
                f"{100 * b['rate']:5.1f} % ({100 * b['rate_low']:.0f}–{100 * b['rate_high']:.0f} %)"
                + (f"  {fails}" if fails else "")
            )
    return lines


def sweep_title(report: Mapping[str, Any]) -> str:
    """``scenario / robot / controller`` as a run's title names them; a compared key gives
    its ``--compare`` flag in its place."""
    compared = report.get("compare")
    parts = [str(report["scenario"])]
    for key in ("robot", "controller"):
        if report.get(key) is not None:
            parts.append(str(report[key]))
        elif compared is not None and compared.get("key") == key:
            parts.append(str(report["compare_flag"]))
    return " / ".join(parts)


def report_text(report: Mapping[str, Any]) -> str:
    """The report for a person, in lines of plain text."""
    rate = report["trials_per_second"]
    compare = report.get("compare")
    if compare is None:
        head = (
            f"{sweep_title(report)}: {report['successes']}/{report['completed']} "
            f"succeeded, {_interval(report['success_interval'])}"
        )
        if report["completed"] < report["runs"]:
            head += f" of {report['runs']} requested"
    else:  # each seed ran once per arm: count seeds, and give each arm its own rate below
        arms = len(compare["arms"])
        head = f"{sweep_title(report)}: {report['trials']} seeds × {arms} arms ({compare['key']})"
        if report["completed"] < report["runs"]:
            head += f", {report['completed']} of {report['runs']} runs finished"
    head += f"; {report['backend']} backend, {report['workers']} worker(s)"
    if rate is not None:
        head += f", {rate:.2f} trials/s"
    lines = [head]
    if report["interrupted"]:
        lines.append("  interrupted: the trials not finished are left out")
    units = {p["name"]: p["unit"] for p in report["vary"]["parameters"]}
    lines.append(f"  varied: {report['vary_text']}")
    recording = [f"  recording: {report['recording']}"] if report.get("recording") else []
    if compare is None:
        lines += _outcome_lines(report, units, "  ")
        return "\n".join(lines + recording)
    for label, arm in compare["arms"].items():
        rate = _interval(arm["success_interval"])
        lines.append(f"  {label}: {arm['successes']}/{arm['completed']} seeds succeeded, {rate}")
        lines += _outcome_lines(arm, units, "    ")
    for p in compare["paired"]:
        lines.append(
            f"  {p['a']} − {p['b']} on {p['pairs']} paired seeds: {100 * p['difference']:+.1f} "
            f"points (95 % CI {100 * p['low']:+.1f} to {100 * p['high']:+.1f}); "
            f"{p['a_only']} seeds only {p['a']} succeeded, {p['b_only']} only {p['b']}; "
            f"McNemar exact p = {p['mcnemar_p']:.3g}"
        )
    if compare["paired"]:
        lines.append(f"  interval: {compare['paired_method']}")
    return "\n".join(lines + recording)


__all__ = [
    "METRICS",
    "SWEEP_WALL_TIME_FIELDS",
    "Arm",
    "Metric",
    "build_report",
    "metric_summary",
    "outcome_of",
    "outcome_report",
    "paired_comparison",
    "report_text",
]
