"""What a run's recording shows and how it opens: the plots (:data:`PLOTS`, each declared once:
path, view, series, style, what it reads from the tick log, its limit lines) and the
blueprint (the 3D scene, the plot tabs and the event log)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from pickplace.control.controllers import IK_STATUSES
from pickplace.errors import InvalidInputError, require_positive
from pickplace.sim.ticklog import TickLog
from pickplace.world.scene import Scene

# Default 3D camera: from the front right, above, looking down at both bins [m].
EYE_POSITION = (1.01, -1.1, 0.89)
EYE_TARGET = (0.25, -0.3, 0.25)


JOINT_COLORS = [
    (0.12, 0.47, 0.71),
    (1.00, 0.50, 0.05),
    (0.17, 0.63, 0.17),
    (0.84, 0.15, 0.16),
    (0.58, 0.40, 0.74),
    (0.55, 0.34, 0.29),
    (0.89, 0.47, 0.76),
]


_TLC = rrb.encodings.TextLogColumnKind
Color = tuple[float, ...]  # rgb or rgba in [0, 1]


RED: Color = (0.9, 0.1, 0.1)
IK_STATUS_NAMES = ", ".join(f"{i} {s}" for i, s in enumerate(IK_STATUSES))


def palette(n: int, alpha: float | None = None) -> list[Color]:
    """The joint palette over ``n`` lines (cycled), optionally with an alpha."""
    colors: list[Color] = [JOINT_COLORS[i % len(JOINT_COLORS)] for i in range(n)]
    return colors if alpha is None else [(*c, alpha) for c in colors]


def one_color(color: Color) -> Callable[[int], list[Color]]:
    """A colour rule: every one of the ``n`` lines in ``color``."""
    return lambda n: [color] * n


def _singular_value_names(sc: Scene) -> list[str]:
    return [f"σ{i}" for i in range(1, min(6, sc.robot.n_joints) + 1)]


def _joint_names(sc: Scene) -> list[str]:
    return list(sc.robot.arm_joint_names)


def _joint_limit_names(sc: Scene) -> list[str]:
    joints = sc.robot.arm_joint_names
    return [f"{j} lower" for j in joints] + [f"{j} upper" for j in joints]


@dataclass(frozen=True, kw_only=True)
class Series:
    """A ``Scalars`` entity and its static line style: one name, colour and width per value
    of a row.

    Attributes:
        path: Entity path.
        names: The series names, from the scene (a tuple when they do not depend on it).
        colors: The colours of the ``n`` lines, given ``n``.
        width: Line width [UI points].
    """

    path: str
    names: tuple[str, ...] | Callable[[Scene], Sequence[str]]
    colors: Callable[[int], Sequence[Color]] = palette
    width: float = 1.5

    def __post_init__(self) -> None:
        if not self.path.startswith("plots/"):
            raise InvalidInputError(f"a plot's entity path starts with 'plots/', got {self.path!r}")
        require_positive(f"line width of {self.path}", self.width)

    def series_names(self, scene: Scene) -> list[str]:
        """The names of the lines, one per value of a row, for ``scene``."""
        return list(self.names if isinstance(self.names, tuple) else self.names(scene))

    def style(self, scene: Scene) -> rr.SeriesLines:
        """The entity's static ``SeriesLines`` for ``scene``."""
        names = self.series_names(scene)
        return rr.SeriesLines(
            names=names, colors=list(self.colors(len(names))), widths=[self.width] * len(names)
        )


@dataclass(frozen=True, kw_only=True)
class LimitLines(Series):
    """Constant lines drawn in a plot's view, sent as one row at the first and one at the
    last tick.

    Attributes:
        values: The constant row, from the scene.
    """

    values: Callable[[Scene], Sequence[float] | np.ndarray]


@dataclass(frozen=True, kw_only=True)
class Plot(Series):
    """One recorded plot: what it reads from the tick log, its line style and its view.

    Attributes:
        tab: The blueprint tab that holds the view (tabs appear in the order of their first
            plot in :data:`PLOTS`).
        title: The view's title.
        values: ``values(log, rows)``: the plotted values of the tick log's ``rows`` (a slice
            of T ticks), (T,) or (T, N); ±inf is recorded as NaN (a gap).
        legend: Show the view's legend.
        y_range: Fixed range of the view's y axis, or None for automatic.
        limits: Constant lines shown in the same view, or None.
    """

    tab: str
    title: str
    values: Callable[[TickLog, slice], np.ndarray]
    legend: bool = True
    y_range: tuple[float, float] | None = None
    limits: LimitLines | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.y_range is not None and not self.y_range[0] < self.y_range[1]:
            raise InvalidInputError(
                f"y range of {self.path} must be (low, high) with low < high, got {self.y_range}"
            )


# Every recorded plot, in blueprint order: its entity, view, series names and style, and what it
# reads from the tick log. The entity table of docs/recordings.md describes each one for users.
PLOTS: tuple[Plot, ...] = (
    # σ1..σ6 of the 6×n tool Jacobian (n arm joints; min(6, n) values), and σt1..σt3 of its
    # 3×n translational rows.
    Plot(
        path="plots/kinematics/singular_values",
        tab="Kinematic health",
        title="Singular values σ of J [m/rad, -]",
        names=_singular_value_names,
        values=lambda log, sl: log.sigma[sl],
        legend=False,
    ),
    Plot(
        path="plots/kinematics/singular_values_translational",
        tab="Kinematic health",
        title="Translational σ [m/rad]",
        names=("σt1", "σt2", "σt3"),
        values=lambda log, sl: log.sigma_t[sl],
        legend=False,
    ),
    # Condition numbers (∞ at a singularity is recorded as NaN).
    Plot(
        path="plots/kinematics/condition",
        tab="Kinematic health",
        title="Condition number [-]",
        names=("full", "translational"),
        values=lambda log, sl: np.column_stack([log.condition[sl], log.condition_t[sl]]),
    ),
    # Manipulability measures w1..w4 of the full and of the translational Jacobian.
    Plot(
        path="plots/kinematics/manipulability",
        tab="Kinematic health",
        title="Manipulability",
        names=("w1", "w2", "w3", "w4"),
        values=lambda log, sl: log.manipulability[sl],
    ),
    Plot(
        path="plots/kinematics/manipulability_translational",
        tab="Kinematic health",
        title="Manipulability (transl.)",
        names=("w1", "w2", "w3", "w4"),
        values=lambda log, sl: log.manipulability_t[sl],
    ),
    # Actual vs planned tool: |p_actual − p_planned| [m] and the rotation angle [rad].
    Plot(
        path="plots/tracking/position_error",
        tab="Tracking / timing",
        title="Position error [m]",
        names=("position error [m]",),
        values=lambda log, sl: log.position_error[sl],
    ),
    Plot(
        path="plots/tracking/orientation_error",
        tab="Tracking / timing",
        title="Orientation error [rad]",
        names=("orientation error [rad]",),
        values=lambda log, sl: log.orientation_error[sl],
    ),
    # The plan's timing: the planned tool speed [m/s] and the plan segment being executed
    # (index of the keyframe it starts from; the event log names the keyframes reached).
    Plot(
        path="plots/plan/tool_speed",
        tab="Tracking / timing",
        title="Planned tool speed [m/s]",
        names=("planned tool speed [m/s]",),
        values=lambda log, sl: np.linalg.norm(log.V_WG_plan[sl, :3], axis=1),
    ),
    Plot(
        path="plots/plan/segment",
        tab="Tracking / timing",
        title="Plan segment [keyframe index]",
        names=("segment (index of its first keyframe)",),
        values=lambda log, sl: log.plan_segment[sl],
    ),
    # (q − lower) / (upper − lower) per joint, with lines at 0 and 1.
    Plot(
        path="plots/joints/position_normalized",
        tab="Joints",
        title="Joint position [0 lower … 1 upper limit]",
        names=_joint_names,
        values=lambda log, sl: (
            (log.q[sl] - log.scene.robot.q_min) / (log.scene.robot.q_max - log.scene.robot.q_min)
        ),
        legend=False,
        limits=LimitLines(
            path="plots/joints/position_normalized_limits",
            names=("lower limit", "upper limit"),
            values=lambda sc: [0.0, 1.0],
            colors=one_color(RED),
            width=2.0,
        ),
    ),
    # |q̇_cmd| / v_max per joint, with the line at 1 (the speed limit).
    Plot(
        path="plots/joints/speed_ratio",
        tab="Joints",
        title="Joint speed / its limit [-]",
        names=_joint_names,
        values=lambda log, sl: np.abs(log.qdot_cmd[sl]) / log.scene.robot.v_max,
        legend=False,
        limits=LimitLines(
            path="plots/joints/speed_ratio_limit",
            names=("limit",),
            values=lambda sc: [1.0],
            colors=one_color(RED),
            width=2.0,
        ),
    ),
    # Measured q per joint [rad], with the lower and upper limit of each.
    Plot(
        path="plots/joints/position",
        tab="Joints",
        title="Joint position [rad]",
        names=_joint_names,
        values=lambda log, sl: log.q[sl],
        legend=False,
        limits=LimitLines(
            path="plots/joints/position_limits",
            names=_joint_limit_names,
            values=lambda sc: np.concatenate([sc.robot.q_min, sc.robot.q_max]),
            colors=lambda n: palette(n // 2, alpha=0.45) * 2,
            width=1.0,
        ),
    ),
    # Commanded q̇ per joint [rad/s].
    Plot(
        path="plots/joints/speed",
        tab="Joints",
        title="Joint speed [rad/s]",
        names=_joint_names,
        values=lambda log, sl: log.qdot_cmd[sl],
    ),
    # Joint torques holding the brick's weight (Jᵀ statics) [N·m].
    Plot(
        path="plots/statics/holding_torque",
        tab="Joints",
        title="Holding torque [N·m]",
        names=_joint_names,
        values=lambda log, sl: log.holding_torque[sl],
    ),
    # Finger gap commanded and measured [m]; normal force on the brick per pad [N].
    Plot(
        path="plots/gripper/width",
        tab="Gripper / IK",
        title="Gripper width [m]",
        names=("commanded", "measured"),
        values=lambda log, sl: np.column_stack([log.gripper_cmd[sl], log.gripper_gap[sl]]),
    ),
    Plot(
        path="plots/gripper/pad_force",
        tab="Gripper / IK",
        title="Pad force [N]",
        names=("left", "right"),
        values=lambda log, sl: log.pad_force[sl],
    ),
    # Controller time per tick [µs] and IK status code (0 ok, 1 no-solution, 2 stuck, ...).
    Plot(
        path="plots/ik/tick_us",
        tab="Gripper / IK",
        title="IK time [µs]",
        names=("IK time [µs]",),
        values=lambda log, sl: log.ik_us[sl],
    ),
    Plot(
        path="plots/ik/status",
        tab="Gripper / IK",
        title="IK status [code]",
        names=(f"status ({IK_STATUS_NAMES})",),
        values=lambda log, sl: log.ik_status[sl],
        y_range=(-0.2, len(IK_STATUSES) - 0.8),
    ),
)


LIMIT_LINES: tuple[LimitLines, ...] = tuple(p.limits for p in PLOTS if p.limits is not None)


@dataclass(frozen=True)
class RunVerdict:
    """The answer a run's recording opens on: the outcome, its reason and when it happened.

    Attributes:
        success: Whether the run succeeded.
        reason: The failure reason (``missed-grasp``), or None for a success.
        text: What happened, one line: the failure's text, or the success's numbers.
        tick: The failure's tick, or the last tick of a success.
        t: Simulated time of ``tick`` [s].
        dt: Control period [s] (the width of the failure tick's time selection).
    """

    success: bool
    reason: str | None
    text: str
    tick: int
    t: float
    dt: float

    @property
    def headline(self) -> str:
        """``SUCCESS in 3.44 s`` or ``FAILED: missed-grasp at t = 1.25 s (tick 125)``."""
        if self.success:
            return f"SUCCESS in {self.t:.2f} s ({self.tick} ticks)"
        return f"FAILED: {self.reason} at t = {self.t:.2f} s (tick {self.tick})"

    def markdown(self) -> str:
        """The verdict panel's text: the headline, the reason, where the time cursor is."""
        where = (
            "The time cursor is at the end of the run."
            if self.success
            else "The time cursor is at the failure tick (highlighted in the time panel); "
            "press pause, then scrub or play to see before and after."
        )
        return f"**{self.headline}**  \n{self.text}  \n*{where}*"


# The plot tab that shows a failure best, by failure reason (the other tabs stay a click away).
FAILURE_TAB = {
    "missed-grasp": "Pad force [N]",
    "dropped": "Pad force [N]",
    "ik-failed": "Position error [m]",
    "limit-violated": "Joint speed / its limit [-]",
    "collision": "Position error [m]",
    "not-in-target-bin": "Gripper width [m]",
}
# Playback speed on opening a failure: the cursor runs from the start to the failure tick in a
# fraction of a second, then loops within that tick (the viewer loops a selection only once
# the cursor reaches it).
FAILURE_PLAYBACK_SPEED = 20.0
AXIS_PAD = 0.05  # automatic y ranges reach this fraction of the data's span past it


def y_range_of(values: np.ndarray, limits: Sequence[float] = ()) -> tuple[float, float] | None:
    """A y axis range that shows every finite value (and limit line) with a margin, from 0
    for data that never goes below it; None without finite data.

    Args:
        values: The plotted values (any shape).
        limits: Values of constant lines in the same view.
    """
    finite = np.asarray(values, dtype=np.float64).ravel()
    finite = np.concatenate([finite[np.isfinite(finite)], np.asarray(limits, dtype=np.float64)])
    if finite.size == 0:
        return None
    lo, hi = float(finite.min()), float(finite.max())
    lo = min(lo, 0.0)
    span = hi - lo if hi > lo else max(abs(hi), 1.0)
    pad = AXIS_PAD * span
    return (lo - pad if lo < 0.0 else 0.0, hi + pad)


def _time_series_view(plot: Plot, y_range: tuple[float, float] | None = None) -> rrb.TimeSeriesView:
    """The plot's view: its entity, and its limit lines if it has them; its y axis fixed to
    the plot's own range, else to ``y_range`` (from the recorded data), else automatic."""
    kw: dict[str, Any] = {}
    if not plot.legend:
        kw["plot_legend"] = rrb.PlotLegend(visible=False)
    y_range = plot.y_range or y_range
    if y_range is not None:
        kw["axis_y"] = rrb.ScalarAxis(range=y_range)
    if plot.limits is None:
        return rrb.TimeSeriesView(name=plot.title, origin=plot.path, **kw)
    contents = [plot.path, plot.limits.path]
    return rrb.TimeSeriesView(name=plot.title, origin="/", contents=contents, **kw)


def _time_panel(verdict: RunVerdict | None) -> rrb.TimePanel:
    """Where the time cursor is on opening: following the newest data while a run streams and
    at the end of a success; on a failure, held at its tick by playing fast into a looped
    selection under one tick wide (Rerun 0.41's blueprint has no field for the cursor)."""
    base: dict[str, Any] = {"state": "collapsed", "timeline": "sim_time"}
    if verdict is None or verdict.success:
        return rrb.TimePanel(play_state="following", **base)
    t0 = round(verdict.t * 1e9)
    return rrb.TimePanel(
        play_state="playing",
        loop_mode="selection",
        playback_speed=FAILURE_PLAYBACK_SPEED,
        # Ends before the next tick's row, so the cursor always shows the failure tick's.
        time_selection=rrb.components.AbsoluteTimeRange(t0, t0 + round(0.9 * verdict.dt * 1e9)),
        **base,
    )


def build_blueprint(
    verdict: RunVerdict | None = None,
    y_ranges: Mapping[str, tuple[float, float]] | None = None,
) -> rrb.Blueprint:
    """How a run's recording opens.

    Left (3/5 of the width): the verdict on top (outcome, reason, tick), the 3D scene, the
    event log below it (about eight rows). Right: the tabs of :data:`PLOTS`, one group per
    tab name; on a failure the tab that shows it best (:data:`FAILURE_TAB`) is the open one.
    The time panel is collapsed to its controls; see :func:`_time_panel` for the cursor.

    Args:
        verdict: The run's verdict, once it is known (None while it runs: "running").
        y_ranges: y axis range per plot path (:func:`y_range_of` of the recorded data).
    """
    ranges = y_ranges or {}
    tabs: dict[str, list[rrb.TimeSeriesView]] = {}
    for plot in PLOTS:
        tabs.setdefault(plot.tab, []).append(_time_series_view(plot, ranges.get(plot.path)))
    active = FAILURE_TAB.get(verdict.reason or "") if verdict is not None else None
    groups = []
    for name, views in tabs.items():
        titles = [v.name for v in views]
        index = titles.index(active) if active in titles else 0
        groups.append(rrb.Tabs(*views, name=name, active_tab=index))
    right = rrb.Vertical(*groups)
    events = rrb.TextLogView(
        name="Events",
        origin="events",
        columns=rrb.archetypes.TextLogColumns(
            text_log_columns=[
                rrb.encodings.TextLogColumn(kind, visible=kind != _TLC.EntityPath)
                for kind in (_TLC.LogLevel, _TLC.Body, _TLC.EntityPath)
            ]
        ),
    )
    scene = rrb.Spatial3DView(
        name="Scene",
        origin="world",
        eye_controls=rrb.EyeControls3D(
            position=EYE_POSITION, look_target=EYE_TARGET, eye_up=[0.0, 0.0, 1.0]
        ),
    )
    left = rrb.Vertical(
        rrb.TextDocumentView(name="Verdict", origin="verdict"),
        scene,
        rrb.Tabs(events, rrb.TextDocumentView(name="Summary (JSON)", origin="summary")),
        row_shares=[1.5, 5.5, 2.6],
    )
    return rrb.Blueprint(
        rrb.Horizontal(left, right, column_shares=[3.0, 2.0]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        _time_panel(verdict),
    )


# Keyframe labels (world/plan/keyframes) in the opening view: a pinhole at EYE_POSITION looking
# at EYE_TARGET with Rerun's default vertical field of view, the 3D view's size in the default
# 1600 x 900 window, and the size of a label's box.
VIEW_FOV_Y = np.deg2rad(55.0)  # [rad]
VIEW_HEIGHT_PX = 560.0
LABEL_HEIGHT_PX = 24.0  # one line and its margin
LABEL_CHAR_PX = 6.0  # per character, plus LABEL_PAD_PX
LABEL_PAD_PX = 10.0


def project_to_view(points_W: np.ndarray) -> np.ndarray:
    """Pixel offsets (right, up) of world points from the centre of the opening 3D view.

    Args:
        points_W: (N, 3) positions in world [m].
    """
    eye, target = np.asarray(EYE_POSITION), np.asarray(EYE_TARGET)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = np.asarray(points_W, dtype=np.float64) - eye
    depth = d @ forward
    scale = 0.5 * VIEW_HEIGHT_PX / np.tan(0.5 * VIEW_FOV_Y)
    return np.column_stack([d @ right / depth, d @ up / depth]) * scale


def label_groups(names: Sequence[str], points_W: np.ndarray) -> list[list[int]]:
    """Keyframes whose labels would overlap in the opening view, grouped under one label.

    Two keyframes' labels overlap when their boxes (:data:`LABEL_HEIGHT_PX` tall,
    :data:`LABEL_CHAR_PX` per character wide, centred on the projected keyframe) intersect;
    overlapping labels are grouped transitively, and a group shows one label, its names joined
    by " / ", at its first keyframe.

    Args:
        names: Keyframe names, in plan order.
        points_W: (N, 3) keyframe positions in world [m].

    Returns:
        Groups of keyframe indices, each in plan order, ordered by their first keyframe.
    """
    px = project_to_view(points_W)
    widths = [LABEL_CHAR_PX * len(n) + LABEL_PAD_PX for n in names]
    group = list(range(len(names)))

    def root(i: int) -> int:
        while group[i] != i:
            i = group[i]
        return i

    for i in range(len(names)):
        for j in range(i):
            dx, dy = np.abs(px[i] - px[j])
            if dy < LABEL_HEIGHT_PX and dx < 0.5 * (widths[i] + widths[j]):
                a, b = sorted((root(i), root(j)))
                group[b] = a
    out: dict[int, list[int]] = {}
    for i in range(len(names)):
        out.setdefault(root(i), []).append(i)
    return list(out.values())
