"""A sweep as one Rerun recording that opens ready to review.

Input: the per-trial summaries (the JSON keys of ``pickplace run --json``; at least ``seed``,
``success``, ``failure`` and ``brick_start_xyz``), the varied parameters and each trial's draw
(:mod:`pickplace.vary`), and the sweep's report dict. Everything is static (no timeline): a
sweep has no time axis of its own. Lengths in m.

=========================================  ====================================================
Entity path                                Contents
=========================================  ====================================================
``world``                                  ``ViewCoordinates`` right-hand, z up
``world/source_bin/floor``                 the source bin's free floor (between the inner
                                           walls), from :class:`~pickplace.scene.BinGeometry`
``world/source_bin/walls``                 outline of the inner walls, floor to rim
``world/source_bin/arm_side``              label on the wall that faces the arm's base
``world/trials/<outcome>``                 one point per trial at its ``brick_start_xyz``,
                                           coloured by outcome (``success`` or the failure
                                           reason), labelled ``reason · seed N`` (labels shown
                                           up to ``MAX_SHOWN_LABELS`` failures, else on hover)
``world/trials/pose_offsets``              when ``pose_noise`` is varied: an arrow per trial
                                           from the planned brick position to where it was
                                           moved after planning, coloured by outcome
``world/legend``                           one labelled point per outcome, "dropped (25)",
                                           beside the bin
``plots/success_by/<parameter>/...``       a bar chart per varied parameter (a 2D view, so
                                           that it can carry whiskers): ``bars`` (``Boxes2D``,
                                           success rate per bin, hover text with counts and
                                           interval), ``intervals`` (95 % Wilson whiskers),
                                           ``counts`` ("3/10" above each bar), ``axes``,
                                           ``grid``, ``x_ticks`` (bin edges, or grid values),
                                           ``y_ticks`` (0–100 %), ``x_title`` (name [unit]).
                                           Chart units: x in [0, ``CHART_WIDTH``] across the
                                           bins, y = −rate[%] · ``CHART_HEIGHT`` / 100
``report``                                 the report (``TextDocument``, markdown): rate with
                                           its Wilson interval, failures by reason with seeds
                                           and the command that re-runs one, p50/p95/worst of
                                           the metrics, per-bin tables, then the report dict
=========================================  ====================================================

The embedded blueprint shows the bin from above (camera placed from the bin's geometry) over
the charts on the left, the report on the right.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from pickplace.errors import InvalidInputError, RecordingError
from pickplace.scene import BinGeometry, Scene, load_scene
from pickplace.stats import RateInterval, percentiles, success_rate
from pickplace.vary import BinStat, ParameterDraw, VaryPlan, VarySpec, success_by_parameter

APPLICATION_ID = "pickplace"
POINT_RADIUS = 0.005  # trial markers [m]
SUCCESS_COLOR = (0.17, 0.63, 0.17)
FAILURE_COLORS = {
    "missed-grasp": (1.00, 0.50, 0.05),
    "dropped": (0.84, 0.15, 0.16),
    "ik-failed": (0.58, 0.40, 0.74),
    "limit-violated": (0.55, 0.34, 0.29),
    "not-in-target-bin": (0.12, 0.47, 0.71),
    "nan": (0.50, 0.50, 0.50),
    "interrupted": (0.10, 0.10, 0.10),
}
# Further reasons take these in order of first appearance.
EXTRA_COLORS = [(0.89, 0.47, 0.76), (0.74, 0.74, 0.13), (0.09, 0.75, 0.81)]
BIN_FLOOR_COLOR = (0.55, 0.42, 0.30, 0.35)
BIN_WALL_COLOR = (0.35, 0.27, 0.20)
RATE_COLOR = (0.17, 0.63, 0.17)
# Trial labels are shown when at most this many failed trials are drawn (else on hover only).
MAX_SHOWN_LABELS = 15


@dataclass(frozen=True)
class Metric:
    """A per-trial summary value shown as p50 / p95 / worst in the report.

    Attributes:
        key: Summary key.
        label: Name shown.
        unit: Unit shown ("" for none).
        scale: Factor from the summary's SI value to ``unit``.
        successes_only: Only successful trials count (a failed run's place error is its
            distance to the target, its cycle time where it stopped).
        low_is_worse: The bad tail is the low one (σmin): show p5 and the minimum instead.
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
    Metric("sim_time_s", "cycle time (simulated)", "s", successes_only=True),
    Metric("min_singular_value", "smallest σ of the Jacobian", "", low_is_worse=True),
    Metric("max_joint_speed_ratio", "joint speed / limit", ""),
    Metric("max_position_error_m", "tool position error", "mm", 1000.0),
)


def outcome_of(trial: Mapping[str, Any]) -> str:
    """``success`` or the trial's failure reason."""
    return "success" if trial["success"] else str(trial.get("failure") or "failed")


def outcome_colors(outcomes: Sequence[str]) -> dict[str, tuple[float, float, float]]:
    """Colour of each outcome: green for success, a fixed colour per known failure reason."""
    colors: dict[str, tuple[float, float, float]] = {}
    extra = iter(EXTRA_COLORS * (1 + len(outcomes) // len(EXTRA_COLORS)))
    for o in outcomes:
        if o in colors:
            continue
        if o == "success":
            colors[o] = SUCCESS_COLOR
        else:
            colors[o] = FAILURE_COLORS.get(o) or next(extra)
    return colors


def bin_outline_W(bin_: BinGeometry) -> tuple[np.ndarray, np.ndarray]:
    """Corners (4, 3) of a bin's free floor at floor height and at rim height, in world [m]."""
    hx, hy = bin_.inner_half_extents
    corners_B = np.array([[-hx, -hy, 0.0], [hx, -hy, 0.0], [hx, hy, 0.0], [-hx, hy, 0.0]])
    R_WB = bin_.X_WB.rotation().as_matrix()
    corners_W = corners_B @ R_WB.T + bin_.X_WB.translation()
    floor = corners_W.copy()
    floor[:, 2] = bin_.floor_top_z
    rim = corners_W.copy()
    rim[:, 2] = bin_.wall_top_z
    return floor, rim


def _log_bin(rec: rr.RecordingStream, bin_: BinGeometry, p_W_base: np.ndarray) -> None:
    """The bin's floor, wall outline and a label on the wall that faces the arm's base."""
    floor, rim = bin_outline_W(bin_)
    mids = 0.5 * (rim + np.roll(rim, -1, axis=0))
    near = int(np.argmin(np.linalg.norm(mids[:, :2] - np.asarray(p_W_base)[:2], axis=1)))
    rec.log(
        "world/source_bin/arm_side",
        rr.Points3D(
            mids[near : near + 1],
            radii=[0.001],
            colors=[BIN_WALL_COLOR],
            labels=[f"{bin_.name}: this wall faces the arm"],
            show_labels=True,
        ),
        static=True,
    )
    rec.log(
        "world/source_bin/floor",
        rr.Mesh3D(
            vertex_positions=floor,
            triangle_indices=[[0, 1, 2], [0, 2, 3]],
            vertex_normals=[[0.0, 0.0, 1.0]] * 4,
            albedo_factor=BIN_FLOOR_COLOR,
        ),
        static=True,
    )
    loops = [np.vstack([floor, floor[:1]]), np.vstack([rim, rim[:1]])]
    posts = [np.vstack([floor[i], rim[i]]) for i in range(4)]
    rec.log(
        "world/source_bin/walls",
        rr.LineStrips3D([*loops, *posts], colors=[BIN_WALL_COLOR], radii=[0.0015]),
        static=True,
    )


def _log_trials(
    rec: rr.RecordingStream,
    trials: Sequence[Mapping[str, Any]],
    draws: Mapping[int, ParameterDraw],
    colors: Mapping[str, tuple[float, float, float]],
) -> None:
    by_outcome: dict[str, list[Mapping[str, Any]]] = {}
    for t in trials:
        if t.get("brick_start_xyz") is not None:
            by_outcome.setdefault(outcome_of(t), []).append(t)
    failed = sum(len(g) for o, g in by_outcome.items() if o != "success")
    for outcome, group in by_outcome.items():
        labels = [
            f"seed {t['seed']}" if outcome == "success" else f"{outcome} · seed {t['seed']}"
            for t in group
        ]
        rec.log(
            f"world/trials/{rr.escape_entity_path_part(outcome)}",
            rr.Points3D(
                np.array([t["brick_start_xyz"] for t in group], dtype=np.float64),
                radii=[POINT_RADIUS],
                colors=[colors[outcome]],
                labels=labels,
                show_labels=outcome != "success" and failed <= MAX_SHOWN_LABELS,
            ),
            static=True,
        )
    origins, vectors, arrow_colors = [], [], []
    for t in trials:
        d = draws.get(int(t["seed"]))
        offset = d.pose_offset_W if d is not None else None
        if offset is not None and t.get("brick_start_xyz") is not None:
            origins.append(t["brick_start_xyz"])
            vectors.append(offset)
            arrow_colors.append(colors[outcome_of(t)])
    if origins:
        rec.log(
            "world/trials/pose_offsets",
            rr.Arrows3D(origins=origins, vectors=vectors, colors=arrow_colors, radii=[0.001]),
            static=True,
        )


def _log_legend(
    rec: rr.RecordingStream, bin_: BinGeometry, counts: Mapping[str, int], colors: Mapping[str, Any]
) -> None:
    """One labelled point per outcome in a column beside the bin (outside its +x wall)."""
    hx, hy = bin_.inner_half_extents
    n = len(counts)
    step = 2.0 * hy / max(n, 1)
    p_B = np.array([[hx + 0.05, hy - (k + 0.5) * step, 0.0] for k in range(n)])
    R_WB = bin_.X_WB.rotation().as_matrix()
    p_W = p_B @ R_WB.T + bin_.X_WB.translation()
    p_W[:, 2] = bin_.floor_top_z
    rec.log(
        "world/legend",
        rr.Points3D(
            p_W,
            radii=[1.5 * POINT_RADIUS],
            colors=[colors[o] for o in counts],
            labels=[f"{o} ({c})" for o, c in counts.items()],
            show_labels=True,
        ),
        static=True,
    )


# Chart coordinates (2D view, y down): bins span x in [0, CHART_WIDTH], 100 % is at
# y = -CHART_HEIGHT.
CHART_WIDTH = 100.0
CHART_HEIGHT = 60.0
CHART_BOUNDS = ((-13.0, 104.0), (-CHART_HEIGHT - 10.0, 15.0))
AXIS_COLOR = (0.75, 0.75, 0.75)
GRID_COLOR = (0.25, 0.25, 0.25)
WHISKER_COLOR = (0.95, 0.95, 0.95)
EMPTY_COLOR = (0.5, 0.5, 0.5)


def _chart_slots(stats: Sequence[BinStat]) -> list[tuple[float, float]]:
    """(left, width) of each bin on the chart's x axis: proportional to the parameter's value
    for equal-width bins, equal slots for grid values (categories)."""
    if all(s.low == s.high for s in stats):
        w = CHART_WIDTH / len(stats)
        return [(k * w, w) for k in range(len(stats))]
    lo, hi = stats[0].low, stats[-1].high
    scale = CHART_WIDTH / (hi - lo)
    return [((s.low - lo) * scale, (s.high - s.low) * scale) for s in stats]


def _filled_boxes(
    left: Sequence[float], width: Sequence[float], height: Sequence[float]
) -> tuple[list[list[float]], list[list[float]], list[float]]:
    """Boxes2D mins, sizes and radii that draw filled bars from y = 0 up to -height.

    Boxes2D draws outlines only: an outline whose stroke half-width is a quarter of the bar's
    smaller side, on a box shrunk by that much, covers the whole bar.
    """
    mins, sizes, radii = [], [], []
    for x, w, h in zip(left, width, height, strict=True):
        t = 0.25 * min(w, h)
        mins.append([x + t, -h + t])
        sizes.append([w - 2.0 * t, h - 2.0 * t])
        radii.append(t)
    return mins, sizes, radii


def _log_bins(rec: rr.RecordingStream, spec: VarySpec, stats: Sequence[BinStat]) -> None:
    """A bar chart of the success rate per bin with 95 % Wilson whiskers and n per bar."""
    base = f"plots/success_by/{spec.name}"
    unit = spec.parameter.unit
    slots = _chart_slots(stats)
    y = CHART_HEIGHT / 100.0  # chart units per percent
    rec.log(
        f"{base}/axes",
        rr.LineStrips2D(
            [[[0.0, 0.0], [CHART_WIDTH, 0.0]], [[0.0, 0.0], [0.0, -CHART_HEIGHT]]],
            radii=[0.25],
            colors=[AXIS_COLOR],
            draw_order=3.0,
        ),
        static=True,
    )
    levels = [25.0, 50.0, 75.0, 100.0]
    rec.log(
        f"{base}/grid",
        rr.LineStrips2D(
            [[[0.0, -v * y], [CHART_WIDTH, -v * y]] for v in levels],
            radii=[0.12],
            colors=[GRID_COLOR],
            draw_order=0.0,
        ),
        static=True,
    )
    rec.log(
        f"{base}/y_ticks",
        rr.Points2D(
            [[-8.0, -v * y - 1.0] for v in [0.0, *levels]],
            radii=[0.01],
            colors=[AXIS_COLOR],
            labels=[f"{v:.0f} %" for v in [0.0, *levels]],
            show_labels=True,
        ),
        static=True,
    )
    grid = all(s.low == s.high for s in stats)
    if grid:
        tick_x = [x + 0.5 * w for x, w in slots]
        tick_text = [f"{s.low:g}" for s in stats]
    else:
        tick_x = [x for x, _ in slots] + [slots[-1][0] + slots[-1][1]]
        edges = [s.low for s in stats] + [stats[-1].high]
        d = _decimals(stats[0].high - stats[0].low)
        tick_text = [f"{v:.{d}f}" for v in edges]
    rec.log(
        f"{base}/x_ticks",
        rr.Points2D(
            [[x, 2.0] for x in tick_x],
            radii=[0.01],
            colors=[AXIS_COLOR],
            labels=tick_text,
            show_labels=True,
        ),
        static=True,
    )
    title = f"{spec.name} [{unit}]" if unit != "-" else spec.name
    rec.log(
        f"{base}/x_title",
        rr.Points2D(
            [[0.5 * CHART_WIDTH, 7.0]],
            radii=[0.01],
            colors=[AXIS_COLOR],
            labels=[title],
            show_labels=True,
        ),
        static=True,
    )
    filled = [(s, s.rate, slot) for s, slot in zip(stats, slots, strict=True) if s.rate is not None]
    if filled:
        left = [x + 0.12 * w for _, _, (x, w) in filled]
        width = [0.76 * w for _, _, (_, w) in filled]
        height = [max(100.0 * r.rate * y, 0.3) for _, r, _ in filled]
        mins, sizes, radii = _filled_boxes(left, width, height)
        rec.log(
            f"{base}/bars",
            rr.Boxes2D(
                mins=mins,
                sizes=sizes,
                radii=radii,
                colors=[RATE_COLOR],
                labels=[_bin_text(s, r, unit) for s, r, _ in filled],
                show_labels=False,
                draw_order=1.0,
            ),
            static=True,
        )
        whiskers = []
        for _, r, (x, w) in filled:
            xc, cap = x + 0.5 * w, 0.12 * w
            lo, hi = -100.0 * r.low * y, -100.0 * r.high * y
            whiskers += [[[xc, lo], [xc, hi]], [[xc - cap, lo], [xc + cap, lo]]]
            whiskers.append([[xc - cap, hi], [xc + cap, hi]])
        rec.log(
            f"{base}/intervals",
            rr.LineStrips2D(whiskers, radii=[0.3], colors=[WHISKER_COLOR], draw_order=2.0),
            static=True,
        )
    rec.log(
        f"{base}/counts",
        rr.Points2D(
            [
                [x + 0.5 * w, -100.0 * (s.rate.high if s.rate else 0.0) * y - 6.5]
                for s, (x, w) in zip(stats, slots, strict=True)
            ],
            radii=[0.01],
            colors=[AXIS_COLOR if s.rate else EMPTY_COLOR for s in stats],
            labels=[f"{s.successes}/{s.trials}" if s.trials else "none" for s in stats],
            show_labels=True,
            draw_order=4.0,
        ),
        static=True,
    )


def _decimals(width: float) -> int:
    """Decimals that tell apart bin edges ``width`` apart (at least one below 10)."""
    d = max(0, math.ceil(-math.log10(width)))
    return 1 if d == 0 and width < 10.0 else d


def _bin_text(s: BinStat, r: RateInterval, unit: str) -> str:
    """Hover text of one bar (``r``: the bin's rate)."""
    u = "" if unit == "-" else f" {unit}"
    fails = ", ".join(f"{k} {v}" for k, v in s.failures.items())
    return (
        f"{s.parameter} {s.label}{u}: {s.successes} of {s.trials} succeeded "
        f"({100 * r.rate:.0f} %, 95 % CI {100 * r.low:.0f}–{100 * r.high:.0f} %)"
        + (f"; {fails}" if fails else "")
    )


def _fmt(value: float | None, scale: float) -> str:
    if value is None:
        return "–"
    v = value * scale
    return f"{v:.3g}" if math.isfinite(v) else str(v)


def report_markdown(
    trials: Sequence[Mapping[str, Any]],
    report: Mapping[str, Any],
    plan: VaryPlan | None = None,
    by_parameter: Mapping[str, Sequence[BinStat]] | None = None,
) -> str:
    """The report as markdown: headline, failures with seeds, metrics, bins, then the dict."""
    rate = success_rate([bool(t["success"]) for t in trials])
    scenario = report.get("scenario", trials[0].get("scenario", "?"))
    controller = report.get("controller", trials[0].get("controller", "?"))
    lines = [
        f"# {scenario} / {controller}: {rate.successes} of {rate.trials} succeeded",
        "",
        f"**Success rate {100 * rate.rate:.1f} %** (95 % Wilson interval "
        f"{100 * rate.low:.1f}–{100 * rate.high:.1f} %).",
        "",
        f"Varied: {plan.describe() if plan is not None else 'nothing varied but the seed'}.",
        "",
    ]
    failed: dict[str, list[int]] = {}
    for t in trials:
        if not t["success"]:
            failed.setdefault(outcome_of(t), []).append(int(t["seed"]))
    if failed:
        lines += ["## Failures", "", "| reason | trials | seeds |", "|---|---:|---|"]
        for reason, seeds in sorted(failed.items(), key=lambda kv: -len(kv[1])):
            shown = " ".join(map(str, sorted(seeds)[:20])) + (" …" if len(seeds) > 20 else "")
            lines.append(f"| {reason} | {len(seeds)} | {shown} |")
        first = min(min(s) for s in failed.values())
        vary = "" if plan is None else " " + " ".join(f"--vary {s.flag()}" for s in plan.specs)
        lines += [
            "",
            f"Re-run one alone: `pickplace run --scenario {scenario} --controller {controller} "
            f"--seed {first}{vary}`",
            "",
        ]
    lines += [
        "## Metrics",
        "",
        "| metric | trials | p50 | p95 ¹ | worst ¹ |",
        "|---|---:|---:|---:|---:|",
    ]
    for m in METRICS:
        if not any(m.key in t for t in trials):
            continue
        used = [t for t in trials if t["success"]] if m.successes_only else list(trials)
        sign = -1.0 if m.low_is_worse else 1.0
        values = [t.get(m.key) for t in used]
        p = percentiles(None if v is None else sign * v for v in values)
        scale = sign * m.scale
        name = f"{m.label} [{m.unit}]" if m.unit else m.label
        note = " (successes)" if m.successes_only else ""
        lines.append(
            f"| {name}{note} | {p.count} | {_fmt(p.p50, scale)} | {_fmt(p.p95, scale)} | "
            f"{_fmt(p.max, scale)} |"
        )
    lines += ["", "¹ p95 and max; p5 and min where low is worse (σ).", ""]
    for name, stats in (by_parameter or {}).items():
        unit = plan.spec(name).parameter.unit if plan is not None else ""
        lines += [
            f"## Success rate by {name}" + (f" [{unit}]" if unit and unit != "-" else ""),
            "",
            "| bin | trials | succeeded | rate | 95 % Wilson | failures |",
            "|---|---:|---:|---:|---|---|",
        ]
        for s in stats:
            if s.rate is None:
                lines.append(f"| {s.label} | 0 | 0 | – | – | |")
                continue
            fails = ", ".join(f"{k} {v}" for k, v in s.failures.items())
            lines.append(
                f"| {s.label} | {s.trials} | {s.successes} | {100 * s.rate.rate:.0f} % | "
                f"{100 * s.rate.low:.0f}–{100 * s.rate.high:.0f} % | {fails} |"
            )
        lines.append("")
    lines += ["## Report", "", "```json", json.dumps(report, indent=2, default=str), "```", ""]
    return "\n".join(lines)


def eye_above(bin_: BinGeometry) -> tuple[np.ndarray, np.ndarray]:
    """Camera position and target [m] looking down at a bin's floor, from outside its -y side
    (in the bin frame) at about 70° below the horizon, far enough to see the whole bin."""
    R_WB = bin_.X_WB.rotation().as_matrix()
    target = bin_.center_W
    reach = 2.4 * float(np.max(bin_.inner_half_extents))
    tilt = math.radians(70.0)
    offset_B = np.array([0.0, -math.cos(tilt), math.sin(tilt)]) * reach
    return target + R_WB @ offset_B, target


def build_sweep_blueprint(
    plan: VaryPlan | None = None, scene: Scene | None = None
) -> rrb.Blueprint:
    """Bin 1 from above over one chart per varied parameter (left), the report (right).

    Args:
        plan: Varied parameters (one chart each).
        scene: Scene whose source bin the camera looks at; default
            :func:`~pickplace.scene.load_scene`.
    """
    scene = scene or load_scene()
    eye, target = eye_above(scene.source_bin)
    bin_view = rrb.Spatial3DView(
        name=f"Brick start per trial in {scene.source_bin.name}, coloured by outcome",
        origin="world",
        eye_controls=rrb.EyeControls3D(position=eye, look_target=target, eye_up=[0.0, 0.0, 1.0]),
    )
    (x_lo, x_hi), (y_lo, y_hi) = CHART_BOUNDS
    charts = [
        rrb.Spatial2DView(
            name=f"Success rate by {spec.name} (whiskers: 95 % Wilson interval)",
            origin=f"plots/success_by/{spec.name}",
            visual_bounds=rrb.VisualBounds2D(x_range=(x_lo, x_hi), y_range=(y_lo, y_hi)),
        )
        for spec in (plan.specs if plan is not None else ())
    ]
    left: Any = bin_view
    if charts:
        lower = charts[0] if len(charts) == 1 else rrb.Grid(*charts)
        left = rrb.Vertical(bin_view, lower, row_shares=[3.0, 2.0 + 1.0 * (len(charts) > 2)])
    return rrb.Blueprint(
        rrb.Horizontal(
            left, rrb.TextDocumentView(name="Report", origin="report"), column_shares=[3.0, 2.0]
        ),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed"),
    )


def log_sweep(
    rec: rr.RecordingStream,
    trials: Sequence[Mapping[str, Any]],
    report: Mapping[str, Any],
    plan: VaryPlan | None = None,
    draws: Sequence[ParameterDraw] = (),
    scene: Scene | None = None,
    bins: int | None = None,
) -> dict[str, list[BinStat]]:
    """Log a sweep into an open recording stream (see the module docstring).

    Args:
        rec: The stream.
        trials: Per-trial summaries (keys ``seed``, ``success``, ``failure``,
            ``brick_start_xyz`` and any of :data:`METRICS`).
        report: The sweep report (shown as JSON at the end of the text).
        plan: The varied parameters, if any.
        draws: One draw per trial (matched by seed); needed when ``plan`` varies something.
        scene: Scene whose source bin is drawn; default :func:`~pickplace.scene.load_scene`.
        bins: Bins per uniform parameter (default: see :func:`pickplace.vary.success_by_bin`).

    Returns:
        The success rate per bin of each varied parameter, as plotted.

    Raises:
        InvalidInputError: No trials, or a trial without a draw when parameters vary.
    """
    if not trials:
        raise InvalidInputError("a sweep recording needs at least one trial, got none")
    scene = scene or load_scene()
    by_seed = {d.seed: d for d in draws}
    by_parameter = (
        success_by_parameter(plan, draws, trials, bins) if plan is not None and plan.specs else {}
    )
    colors = outcome_colors([outcome_of(t) for t in trials])
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    _log_bin(rec, scene.source_bin, scene.p_W_base)
    _log_trials(rec, trials, by_seed, colors)
    counts: dict[str, int] = {}
    for t in trials:
        counts[outcome_of(t)] = counts.get(outcome_of(t), 0) + 1
    ordered = dict(sorted(counts.items(), key=lambda kv: (kv[0] != "success", -kv[1], kv[0])))
    _log_legend(rec, scene.source_bin, ordered, colors)
    for spec in plan.specs if plan is not None else ():
        _log_bins(rec, spec, by_parameter[spec.name])
    text = report_markdown(trials, report, plan, by_parameter)
    rec.log("report", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN), static=True)
    return by_parameter


def write_sweep_recording(
    path: str | Path,
    trials: Sequence[Mapping[str, Any]],
    report: Mapping[str, Any],
    plan: VaryPlan | None = None,
    draws: Sequence[ParameterDraw] = (),
    scene: Scene | None = None,
    bins: int | None = None,
    recording_id: str | None = None,
) -> Path:
    """Write a sweep to an ``.rrd`` file with its blueprint (see :func:`log_sweep`).

    Args:
        path: The ``.rrd`` file.
        trials: Per-trial summaries.
        report: The sweep report.
        plan: The varied parameters, if any.
        draws: One draw per trial.
        scene: Scene whose source bin is drawn.
        bins: Bins per uniform parameter.
        recording_id: Default ``sweep/SCENARIO/CONTROLLER/seeds-FIRST-LAST``.

    Raises:
        RecordingError: The file cannot be written.
        InvalidInputError: See :func:`log_sweep`.
    """
    path = Path(path)
    if not trials:
        raise InvalidInputError("a sweep recording needs at least one trial, got none")
    scene = scene or load_scene()
    if recording_id is None:
        seeds = [int(t["seed"]) for t in trials]
        scenario = report.get("scenario", trials[0].get("scenario", "sweep"))
        controller = report.get("controller", trials[0].get("controller", ""))
        recording_id = f"sweep/{scenario}/{controller}/seeds-{min(seeds)}-{max(seeds)}"
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    try:
        rec.set_sinks(rr.FileSink(str(path)), default_blueprint=build_sweep_blueprint(plan, scene))
    except (RuntimeError, OSError, ValueError) as exc:
        raise RecordingError(f"cannot open the recording sink (file '{path}'): {exc}") from exc
    try:
        log_sweep(rec, trials, report, plan, draws, scene, bins)
    finally:
        rec.flush()
        rec.disconnect()
    return path


__all__ = [
    "METRICS",
    "Metric",
    "bin_outline_W",
    "build_sweep_blueprint",
    "log_sweep",
    "outcome_colors",
    "outcome_of",
    "report_markdown",
    "write_sweep_recording",
]
