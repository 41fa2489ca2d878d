"""A sweep as one Rerun recording that opens ready to review.

Input: the per-trial summaries (the JSON keys of ``pickplace run --json``; at least ``seed``,
``success``, ``failure`` and ``brick_start_xyz``), the varied parameters and each trial's draw
(:mod:`pickplace.sim.vary`), and the sweep's report dict. Everything is static (no timeline): a
sweep has no time axis of its own. Lengths in m.

=========================================  ====================================================
Entity path                                Contents
=========================================  ====================================================
``world``                                  ``ViewCoordinates`` right-hand, z up
``world/source_bin/floor``                 the source bin's free floor (between the inner
                                           walls), from :class:`~pickplace.world.scene.BinGeometry`
``world/source_bin/walls``                 outline of the inner walls, floor to rim
``world/source_bin/arm_side``              label on the wall that faces the arm's base
``world/trials/<outcome>``                 one point per trial at its ``brick_start_xyz``,
                                           coloured by outcome (``success`` or the failure
                                           reason), labelled ``reason · seed N`` (on hover);
                                           refusals per cause (the trial's ``refusal``) under
                                           ``world/trials/no-feasible-plan/<cause>``, each a
                                           colour, labelled ``no-feasible-plan (footprint) ·
                                           seed N`` (:func:`map_outcome`)
``world/callouts/labels``, ``.../leaders`` up to ``MAX_SHOWN_LABELS`` failed trials: their labels
                                           in a column outside the bin's -x wall, one row each
                                           (never overlapping), a leader line to each point
``world/trials/pose_offsets``              when ``pose_noise`` is varied: an arrow per trial
                                           from the planned brick position to where it was
                                           moved after planning (the offset the run applied,
                                           kept inside the bin), coloured by outcome
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

In a comparison (``--compare``: trials carry an ``arm``, e.g. ``controller=qp``) each arm's
points are under ``world/trials/<arm>/<outcome>`` and its charts under
``plots/<arm>/success_by/<parameter>`` (``=`` written ``-``: ``controller-qp``); the legend
names the arm; the report adds the paired comparison.

The embedded blueprint shows the bin from above (camera placed from the bin's geometry) over
the charts on the left, the report on the right. The file is encoded in memory, written beside
its path and renamed onto it once it reads back complete (:class:`~pickplace.outfile.OutputFile`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from pickplace.errors import OutputError, RecordingError
from pickplace.outfile import OutputFile
from pickplace.record.rrd_file import commit_bytes
from pickplace.sim.loader import load_scene
from pickplace.sim.vary import ParameterDraw, VaryPlan, VarySpec
from pickplace.sweep.bins import BinStat, success_by_parameter
from pickplace.sweep.report import METRICS, Metric, outcome_of, sweep_title
from pickplace.sweep.stats import RateInterval
from pickplace.world.scene import BinGeometry, Scene

if TYPE_CHECKING:
    from pickplace.sweep.sweep import SweepRequest

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
    "no-feasible-plan": (0.62, 0.62, 0.85),
    "collision": (0.95, 0.85, 0.10),
    "worker-died": (0.30, 0.30, 0.30),
    "worker-error": (0.40, 0.20, 0.40),
}
# Further reasons take these in order of first appearance.
EXTRA_COLORS = [(0.89, 0.47, 0.76), (0.74, 0.74, 0.13), (0.09, 0.75, 0.81)]
BIN_FLOOR_COLOR = (0.55, 0.42, 0.30, 0.35)
BIN_WALL_COLOR = (0.35, 0.27, 0.20)
RATE_COLOR = (0.17, 0.63, 0.17)  # a bar at 100 %
RATE_MID_COLOR = (0.93, 0.67, 0.10)  # at 50 %
RATE_LOW_COLOR = (0.84, 0.15, 0.16)  # at 0 %
ENCODE_TIMEOUT_S = 30.0  # bound on encoding what was logged (normally milliseconds) [s]
# Failed trials get a callout (label in a column, leader line to the point) when at most this
# many are drawn, else their labels show on hover only: the column beside the bin's 0.30 m side
# then spaces labels 20 mm apart, about a label's height in the sweep's view.
MAX_SHOWN_LABELS = 15
# The callout column stands this far outside the bin's -x wall [m]: labels are centred on their
# anchor, and "missed-grasp · seed 14" spans about 0.16 m in the sweep's view.
CALLOUT_OFFSET = 0.13
CALLOUT_LINE_COLOR = (0.6, 0.6, 0.6)


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
    base: str = "world/trials",
) -> None:
    by_outcome: dict[str, list[Mapping[str, Any]]] = {}
    for t in trials:
        if t.get("brick_start_xyz") is not None:
            by_outcome.setdefault(map_outcome(t), []).append(t)
    for outcome, group in by_outcome.items():
        parts = [outcome_of(group[0])]  # a refusal's cause below its reason: .../<reason>/<cause>
        if outcome != parts[0]:
            parts.append(str(group[0]["refusal"]))
        rec.log(
            "/".join([base, *(rr.escape_entity_path_part(part) for part in parts)]),
            rr.Points3D(
                np.array([t["brick_start_xyz"] for t in group], dtype=np.float64),
                radii=[POINT_RADIUS],
                colors=[colors[outcome]],
                labels=[trial_label(t) for t in group],
                show_labels=False,  # on hover; the few failures get callouts (_log_callouts)
            ),
            static=True,
        )
    origins, vectors, arrow_colors = [], [], []
    for t in trials:
        offset = _pose_offset(t, draws.get(int(t["seed"])))
        if offset is not None and t.get("brick_start_xyz") is not None:
            origins.append(t["brick_start_xyz"])
            vectors.append(offset)
            arrow_colors.append(colors[map_outcome(t)])
    if origins:
        rec.log(
            f"{base}/pose_offsets",
            rr.Arrows3D(origins=origins, vectors=vectors, colors=arrow_colors, radii=[0.001]),
            static=True,
        )


def map_outcome(trial: Mapping[str, Any]) -> str:
    """A trial's outcome as the bin's picture shows it: ``success`` or its failure reason
    (:func:`~pickplace.sweep.report.outcome_of`), a refusal with its cause,
    ``no-feasible-plan (footprint)`` (the trial's ``refusal``), so that the picture shows where
    in the bin each cause refuses."""
    outcome = outcome_of(trial)
    cause = trial.get("refusal")
    return f"{outcome} ({cause})" if cause and not trial["success"] else outcome


def trial_label(trial: Mapping[str, Any], arm: str = "") -> str:
    """A trial's label: ``seed 9`` for a success, ``missed-grasp · seed 14`` for a failure,
    ``no-feasible-plan (footprint) · seed 3`` for a refusal (prefixed by its arm in a
    comparison, ``controller=pinv: …``)."""
    outcome = map_outcome(trial)
    text = f"seed {trial['seed']}" if outcome == "success" else f"{outcome} · seed {trial['seed']}"
    return f"{arm}: {text}" if arm else text


def callout_anchors_W(bin_: BinGeometry, p_W: np.ndarray) -> np.ndarray:
    """Where the callouts of points ``p_W`` (n, 3) [m] are anchored: a column outside the bin's
    -x wall at floor height, evenly spaced over the bin's y extent, in the order of the
    points' y in the bin frame (top to bottom), so leader lines do not cross needlessly and no
    two labels share a row."""
    hx, hy = bin_.inner_half_extents
    R_WB = bin_.X_WB.rotation().as_matrix()
    p_WB = bin_.X_WB.translation()
    y_B = (p_W - p_WB) @ R_WB[:, 1]
    n = len(p_W)
    step = 2.0 * hy / max(n, 1)
    anchors_B = np.zeros((n, 3))
    for row, i in enumerate(np.argsort(-y_B, kind="stable")):
        anchors_B[i] = (-hx - CALLOUT_OFFSET, hy - (row + 0.5) * step, 0.0)
    anchors_W = anchors_B @ R_WB.T + p_WB
    anchors_W[:, 2] = bin_.floor_top_z
    return anchors_W


def _log_callouts(
    rec: rr.RecordingStream,
    bin_: BinGeometry,
    failed: Sequence[tuple[np.ndarray, str, tuple[float, float, float]]],
) -> None:
    """Labels of the failed trials in a column beside the bin, each joined to its point by a
    leader line, when there are at most :data:`MAX_SHOWN_LABELS` (labels drawn at the points
    themselves overlap wherever two failures lie close)."""
    if not failed or len(failed) > MAX_SHOWN_LABELS:
        return
    p_W = np.array([p for p, _, _ in failed], dtype=np.float64)
    anchors_W = callout_anchors_W(bin_, p_W)
    colors = [c for _, _, c in failed]
    rec.log(
        "world/callouts/labels",
        rr.Points3D(
            anchors_W,
            radii=[0.5 * POINT_RADIUS],
            colors=colors,
            labels=[label for _, label, _ in failed],
            show_labels=True,
        ),
        static=True,
    )
    rec.log(
        "world/callouts/leaders",
        rr.LineStrips3D(
            [np.vstack([a, p]) for a, p in zip(anchors_W, p_W, strict=True)],
            colors=[CALLOUT_LINE_COLOR],
            radii=[0.0006],
        ),
        static=True,
    )


def _pose_offset(trial: Mapping[str, Any], draw: ParameterDraw | None) -> np.ndarray | None:
    """Where the brick was moved after planning: the offset the run applied (kept inside the
    bin) when the trial records it, else the drawn one; None without pose noise."""
    applied = (trial.get("parameters") or {}).get("pose_offset_applied_xy_m")
    if applied is not None:
        return np.array([applied[0], applied[1], 0.0])
    return draw.pose_offset_W if draw is not None else None


def _log_legend(
    rec: rr.RecordingStream,
    bin_: BinGeometry,
    entries: Sequence[tuple[str, tuple[float, float, float]]],
) -> None:
    """One labelled point per (label, colour) in a column beside the bin (outside its +x
    wall)."""
    if not entries:  # no trial ended (a sweep stopped at its start)
        return
    hx, hy = bin_.inner_half_extents
    n = len(entries)
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
            colors=[c for _, c in entries],
            labels=[label for label, _ in entries],
            show_labels=True,
        ),
        static=True,
    )


# Chart coordinates (2D view, y down): bins span x in [0, CHART_WIDTH], 100 % is at
# y = -CHART_HEIGHT.
CHART_WIDTH = 100.0
CHART_HEIGHT = 60.0
CHART_BOUNDS = ((-13.0, 104.0), (-CHART_HEIGHT - 17.0, 15.0))  # room for two rows of counts
AXIS_COLOR = (0.75, 0.75, 0.75)
GRID_COLOR = (0.25, 0.25, 0.25)
WHISKER_COLOR = (0.95, 0.95, 0.95)
EMPTY_COLOR = (0.5, 0.5, 0.5)


def rate_color(rate: float) -> tuple[float, float, float]:
    """A bar's colour by its success rate in [0, 1]: red at 0, amber at 0.5, green at 1."""
    r = min(max(float(rate), 0.0), 1.0)
    a, b, u = (
        (RATE_LOW_COLOR, RATE_MID_COLOR, 2 * r)
        if r < 0.5
        else (RATE_MID_COLOR, RATE_COLOR, 2 * r - 1)
    )
    return (a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1]), a[2] + u * (b[2] - a[2]))


# With more bins than this, the count labels above the bars take two rows, alternately, so
# that neighbours never collide.
ONE_ROW_OF_COUNTS = 6


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


def _log_bins(rec: rr.RecordingStream, spec: VarySpec, stats: Sequence[BinStat], base: str) -> None:
    """A bar chart of the success rate per bin with 95 % Wilson whiskers and n per bar, at
    entity path ``base``."""
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
                colors=[rate_color(r.rate) for _, r, _ in filled],
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
                [
                    x + 0.5 * w,
                    -100.0 * (s.rate.high if s.rate else 0.0) * y
                    - 6.5
                    - 7.0 * (k % 2 if len(stats) > ONE_ROW_OF_COUNTS else 0),
                ]
                for k, (s, (x, w)) in enumerate(zip(stats, slots, strict=True))
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


def _outcome_markdown(
    r: Mapping[str, Any], title: str, units: Mapping[str, str], level: str = "#"
) -> list[str]:
    """Headline, failures with seeds and re-run commands, metrics, bins of one outcome dict of
    the report (the whole sweep's, or one arm's: :func:`pickplace.sweep.report.outcome_report`),
    as markdown lines: the same numbers the text report prints."""
    lines = [f"{level} {title}: {r['successes']} of {r['completed']} succeeded", ""]
    interval = r["success_interval"]
    if interval is not None:
        lines += [
            f"**Success rate {100 * interval['rate']:.1f} %** (95 % Wilson interval "
            f"{100 * interval['low']:.1f}–{100 * interval['high']:.1f} %).",
            "",
        ]
    sub = level + "#"
    failures = sorted(r["failures"].items(), key=lambda kv: -kv[1]["count"])
    if failures:
        lines += [f"{sub} Failures", "", "| reason | trials | seeds |", "|---|---:|---|"]
        for reason, f in failures:
            seeds = f["seeds"]
            shown = " ".join(map(str, seeds[:20])) + (" …" if len(seeds) > 20 else "")
            lines.append(f"| {reason} | {f['count']} | {shown} |")
            for cause, n in (f.get("by_cause") or {}).items():
                lines.append(f"| … {cause} | {n} | |")
        lines.append("")
        for reason, f in failures:
            text = f.get("example")
            lines.append(
                f"- **{reason}**, seed {f['example_seed']}" + (f": {text}" if text else "")
            )
            if f.get("rerun"):
                lines.append(f"  re-run it alone: `{f['rerun']}`")
        lines.append("")
    lines += [
        f"{sub} Metrics",
        "",
        "| metric | trials | p50 | p95 ¹ | worst ¹ |",
        "|---|---:|---:|---:|---:|",
    ]
    for m in METRICS:
        p = r["metrics"].get(m.key)
        if not p or not p["count"]:
            continue
        tail, worst = ("p5", "min") if m.low_is_worse else ("p95", "max")
        name = f"{m.label} [{m.unit}]" if m.unit else m.label
        note = " (successes)" if m.successes_only else ""
        lines.append(
            f"| {name}{note} | {p['count']} | {_fmt(p['p50'], m.scale)} | "
            f"{_fmt(p[tail], m.scale)} | {_fmt(p[worst], m.scale)} |"
        )
    lines += [
        "",
        "Over the trials that moved (not refused before any physics). ¹ p95 and max; p5 and "
        "min where low is worse (σ).",
        "",
    ]
    for name, stats in r["by_parameter"].items():
        unit = units.get(name, "")
        lines += [
            f"{sub} Success rate by {name}" + (f" [{unit}]" if unit and unit != "-" else ""),
            "",
            "| bin | trials | succeeded | rate | 95 % Wilson | failures |",
            "|---|---:|---:|---:|---|---|",
        ]
        for st in map(BinStat.from_dict, stats):
            if st.rate is None:
                lines.append(f"| {st.label} | 0 | 0 | – | – | |")
                continue
            fails = ", ".join(f"{k} {v}" for k, v in st.failures.items())
            lines.append(
                f"| {st.label} | {st.trials} | {st.successes} | {100 * st.rate.rate:.0f} % | "
                f"{100 * st.rate.low:.0f}–{100 * st.rate.high:.0f} % | {fails} |"
            )
        lines.append("")
    return lines


def report_markdown(report: Mapping[str, Any]) -> str:
    """The report (:func:`pickplace.sweep.sweep.sweep_report`) as markdown: headline,
    failures with seeds and the command that re-runs each, metrics, bins (per arm and the
    paired comparison with ``--compare``), then the report dict (without its per-trial
    list). Rendered from the report's numbers, as the text report is
    (:func:`pickplace.sweep.report.report_text`)."""
    units = {p["name"]: p["unit"] for p in report["vary"]["parameters"]}
    varied = report.get("vary_text") or "nothing varied but the seed"
    compare = report.get("compare")
    title = sweep_title(report)
    if compare is None:
        lines = _outcome_markdown(report, title, units)
        lines[2:2] = [f"Varied: {varied}.", ""]
    else:
        lines = [f"# {title}", "", f"Varied: {varied}.", ""]
        for p in compare.get("paired", []):
            lines += [
                f"**{p['a']} − {p['b']}: {100 * p['difference']:+.1f} points** on "
                f"{p['pairs']} paired seeds (95 % interval {100 * p['low']:+.1f} to "
                f"{100 * p['high']:+.1f}; {p['interval_method']}); only {p['a']} succeeded on "
                f"{p['a_only']}, only {p['b']} on {p['b_only']}; McNemar exact p = "
                f"{p['mcnemar_p']:.3g}.",
                "",
            ]
        for label, arm in compare["arms"].items():
            if arm["completed"]:
                lines += _outcome_markdown(arm, label, units, level="##")
    shown = {k: v for k, v in report.items() if k != "trial_results"}
    lines += ["## Report", "", "```json", json.dumps(shown, indent=2, default=str), "```", ""]
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


def _arm_part(arm: str) -> str:
    """An arm's label as an entity path part: ``controller=qp`` → ``controller-qp``."""
    return str(rr.escape_entity_path_part(arm.replace("=", "-")))


def chart_path(name: str, arm: str = "") -> str:
    """Entity path of the chart of parameter ``name`` (of one arm in a comparison, e.g.
    ``plots/controller-qp/success_by/brick_mass``)."""
    return f"plots/{_arm_part(arm)}/success_by/{name}" if arm else f"plots/success_by/{name}"


def build_sweep_blueprint(
    plan: VaryPlan | None = None, scene: Scene | None = None, arms: Sequence[str] = ()
) -> rrb.Blueprint:
    """Bin 1 from above over one chart per varied parameter (left), the report (right).

    Args:
        plan: Varied parameters (one chart each).
        scene: Scene whose source bin the camera looks at; default
            :func:`~pickplace.sim.loader.load_scene`.
        arms: The arms of a comparison (one chart per arm and parameter).
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
            name=(f"{arm}: " if arm else "")
            + f"Success rate by {spec.name} (whiskers: 95 % Wilson interval)",
            origin=chart_path(spec.name, arm),
            visual_bounds=rrb.VisualBounds2D(x_range=(x_lo, x_hi), y_range=(y_lo, y_hi)),
        )
        for arm in (arms or ("",))
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


def _arms_of(trials: Sequence[Mapping[str, Any]]) -> list[str]:
    """The arms of a comparison in order of first appearance ([] without one)."""
    arms: list[str] = []
    for t in trials:
        arm = t.get("arm")
        if arm and arm not in arms:
            arms.append(str(arm))
    return arms


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

    In a comparison (trials with an ``arm``) each arm's trials are drawn under
    ``world/trials/<arm>/`` and its charts at ``plots/<arm>/success_by/<parameter>``.

    Args:
        rec: The stream.
        trials: Per-trial summaries (keys ``seed``, ``success``, ``failure``,
            ``brick_start_xyz`` and any of :data:`METRICS`).
        report: The sweep report (shown as JSON at the end of the text).
        plan: The varied parameters, if any.
        draws: One draw per seed (matched by seed); needed when ``plan`` varies something.
        scene: Scene whose source bin is drawn; default :func:`~pickplace.sim.loader.load_scene`.
        bins: Bins per uniform parameter; default: the report's
        (:func:`~pickplace.sweep.bins.success_by_bin`).

    Returns:
        The success rate per bin of each varied parameter, as plotted (over every trial).

    Raises:
        InvalidInputError: A trial without a draw when parameters vary. (No trials at all, a
            sweep stopped before any ended, is the bin, the empty charts and the report.)
    """
    scene = scene or load_scene()
    by_seed = {d.seed: d for d in draws}
    varied = plan is not None and bool(plan.specs)

    def bins_of(outcome: Mapping[str, Any] | None, group: Sequence[Mapping[str, Any]]) -> Any:
        """The report's bins of an outcome (the sweep's or an arm's); counted here from the
        draws only when another bin count is asked for, or the report has no bins."""
        if bins is None and outcome is not None and outcome.get("by_parameter"):
            return {
                k: [BinStat.from_dict(b) for b in v] for k, v in outcome["by_parameter"].items()
            }
        assert plan is not None
        return success_by_parameter(plan, draws, group, bins)

    by_parameter = bins_of(report, trials) if varied else {}
    arm_outcomes = (report.get("compare") or {}).get("arms", {})
    colors = outcome_colors([map_outcome(t) for t in trials])
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    _log_bin(rec, scene.source_bin, scene.robot.p_W_base)
    arms = _arms_of(trials)
    legend: list[tuple[str, tuple[float, float, float]]] = []
    failed: list[tuple[np.ndarray, str, tuple[float, float, float]]] = []
    for arm in arms or [""]:
        group = [t for t in trials if t.get("arm", "") == arm] if arm else list(trials)
        base = f"world/trials/{_arm_part(arm)}" if arm else "world/trials"
        _log_trials(rec, group, by_seed, colors, base)
        failed += [
            (np.asarray(t["brick_start_xyz"], dtype=np.float64), trial_label(t, arm), colors[o])
            for t in group
            if (o := map_outcome(t)) != "success" and t.get("brick_start_xyz") is not None
        ]
        counts: dict[str, int] = {}
        for t in group:
            counts[map_outcome(t)] = counts.get(map_outcome(t), 0) + 1
        ordered = sorted(counts.items(), key=lambda kv: (kv[0] != "success", -kv[1], kv[0]))
        legend += [(f"{arm}: " * bool(arm) + f"{o} ({c})", colors[o]) for o, c in ordered]
        if plan is not None and varied:
            stats = by_parameter if not arm else bins_of(arm_outcomes.get(arm), group)
            for spec in plan.specs:
                _log_bins(rec, spec, stats[spec.name], chart_path(spec.name, arm))
    _log_legend(rec, scene.source_bin, legend)
    _log_callouts(rec, scene.source_bin, failed)
    text = report_markdown(report)
    rec.log("report", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN), static=True)
    return by_parameter


def _default_recording_id(trials: Sequence[Mapping[str, Any]], report: Mapping[str, Any]) -> str:
    seeds = [int(t["seed"]) for t in trials]
    if not seeds:  # stopped before any trial ended: the seeds asked for
        first = int(report.get("first_seed", 0))
        seeds = [first, first + max(0, int(report.get("trials", 1)) - 1)]
    first_trial = trials[0] if trials else {}
    scenario = report.get("scenario", first_trial.get("scenario", "sweep"))
    what = report.get("compare_flag") or report.get("controller") or first_trial.get("controller")
    return f"sweep/{scenario}/{what or ''}/seeds-{min(seeds)}-{max(seeds)}"


def encode_sweep(
    trials: Sequence[Mapping[str, Any]],
    report: Mapping[str, Any],
    plan: VaryPlan | None = None,
    draws: Sequence[ParameterDraw] = (),
    scene: Scene | None = None,
    bins: int | None = None,
    recording_id: str | None = None,
) -> bytes:
    """The sweep's ``.rrd`` bytes with its blueprint (see :func:`log_sweep`), encoded in
    memory (a sweep recording is small: points, charts and text).

    Raises:
        RecordingError: The recording could not be encoded.
        InvalidInputError: See :func:`log_sweep`.
    """
    scene = scene or load_scene()
    rid = recording_id or _default_recording_id(trials, report)
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=rid)
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    stream = rr.binary_stream(recording=rec)
    arms = _arms_of(trials)
    rec.set_sinks(stream, default_blueprint=build_sweep_blueprint(plan, scene, arms))
    try:
        log_sweep(rec, trials, report, plan, draws, scene, bins)
        data = stream.read(flush=True, flush_timeout_sec=ENCODE_TIMEOUT_S)
    except RuntimeError as exc:
        raise RecordingError(f"the sweep recording could not be encoded: {exc}") from exc
    finally:
        rec.disconnect()
    return bytes(data or b"")


def commit_recording(output: OutputFile, data: bytes) -> Path:
    """Write the encoded sweep recording ``data`` to ``output`` once it reads back with its
    report (:func:`~pickplace.record.rrd_file.commit_bytes`).

    Raises:
        OutputError: The file could not be written or is incomplete (an older file at the
            path is unchanged).
    """
    return commit_bytes(output, data, "report", "the sweep recording")


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
    """Write a sweep to an ``.rrd`` file with its blueprint (see :func:`log_sweep`): encoded
    in memory, written beside ``path`` and renamed onto it once it reads back complete
    (:class:`~pickplace.outfile.OutputFile`: one writer per path).

    Args:
        path: The ``.rrd`` file.
        trials: Per-trial summaries.
        report: The sweep report.
        plan: The varied parameters, if any.
        draws: One draw per seed.
        scene: Scene whose source bin is drawn.
        bins: Bins per uniform parameter.
        recording_id: Default ``sweep/SCENARIO/CONTROLLER/seeds-FIRST-LAST`` (the
            ``--compare`` flag in place of the controller in a comparison).

    Raises:
        RecordingError: The recording could not be encoded or its folder does not exist.
        OutputError: The file could not be written (another run writes it, disk full, ...).
        InvalidInputError: See :func:`log_sweep`.
    """
    path = Path(path)
    if not path.parent.is_dir():
        raise RecordingError(f"cannot open the recording sink (file '{path}'): no such folder")
    data = encode_sweep(trials, report, plan, draws, scene, bins, recording_id)
    return commit_recording(OutputFile(path), data)


def record_sweep(output: OutputFile, req: SweepRequest, report: Mapping[str, Any]) -> Path:
    """Write the recording of a finished sweep ``req`` to ``output`` (opened by the caller
    before the sweep, so that a second writer of the path is refused at once).

    Raises:
        OutputError: The file could not be written or encoded.
    """
    trials = report["trial_results"]
    scene = load_scene(robot=req.specs()[0].robot)  # composed by the sweep: a cache hit
    try:
        data = encode_sweep(trials, report, req.vary, scene=scene)
    except RecordingError as exc:
        output.discard()
        raise OutputError(str(exc)) from None
    return commit_recording(output, data)


__all__ = [
    "METRICS",
    "Metric",
    "bin_outline_W",
    "build_sweep_blueprint",
    "chart_path",
    "commit_recording",
    "encode_sweep",
    "log_sweep",
    "map_outcome",
    "outcome_colors",
    "outcome_of",
    "record_sweep",
    "report_markdown",
    "write_sweep_recording",
]
