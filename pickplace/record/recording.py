"""Rerun recording of a run: scene geometry, plan, per-tick state, health plots and events.

:class:`Recorder` is a :class:`~pickplace.sim.loop.TickObserver`. It writes to a ``.rrd`` file,
a viewer it spawns, a viewer at a gRPC URL, or several of them at once. Tick data is never
logged row by row: it is read from the run's preallocated :class:`~pickplace.sim.ticklog.TickLog`
and
sent with ``send_columns`` every ``flush_every`` ticks (or sooner, once ``flush_interval_s`` of
wall time has passed, so that a live viewer of a paced run stays current) and at the end, each
batch handed to the viewers at once. The file's bytes are encoded in memory and written in
``on_finish`` (also after Ctrl-C, SIGTERM or SIGHUP) to a temporary file, which is renamed onto
its path once it reads back complete, so the path holds either a complete recording (footer,
summary, verdict) or what was there before. See :class:`Recorder` for the file and the
viewers, and :mod:`pickplace.record.viewer` for the bounds on waiting for a viewer.

Timelines: ``sim_time`` (duration, the simulated time at the end of the tick) and ``tick``
(sequence, the control tick index k). Quaternions are stored xyzw. Lengths in m, angles in
rad, times in s unless stated.

=================================================  ==========================================
Entity path                                        Contents
=================================================  ==========================================
``world``                                          static: ``ViewCoordinates`` right-hand, z up
``world/static/<geom>``                            static: geoms of the world body (floor)
``world/bodies/<body>``                            body pose in world (``Transform3D``): one row
                                                   per tick for bodies that move (a joint in
                                                   their chain), static for the others (bins)
``world/bodies/<body>/<geom>``                     static: visual geom (box, sphere, capsule,
                                                   cylinder, ellipsoid, plane, mesh) at its
                                                   local pose in the body
``world/plan/path``                                static: planned tool path (``LineStrips3D``)
``world/plan/keyframes/<name>``                    static: keyframe pose with 5 cm axes and a
                                                   labelled point (keyframes at one position
                                                   show one label, "pick / settle / ...")
``world/plan/target_bin``                          static: target bin's free inner volume
                                                   (green box outline)
``world/tool/planned``                             per tick: planned tool pose, 12 cm axes
``world/tool/commanded``                           per tick: FK of the commanded q, 9 cm axes
``world/tool/actual``                              per tick: simulated tool pose, 6 cm axes
``world/tool/manipulability_ellipsoid``            per tick: translational velocity ellipsoid
                                                   at the actual tool (half sizes 0.1·σt [m])
``plots/...``                                      per tick: one ``Scalars`` entity per entry of
                                                   :data:`PLOTS`, which declares each plot once
                                                   (path, view, series, style, what it reads
                                                   from the tick log) with its constant limit
                                                   lines (a row at the first and the last tick)
``events``                                         ``TextLog`` of the run's events and verdict
``summary``                                        static: JSON summary (``TextDocument``)
=================================================  ==========================================

Names containing ``/`` (``gripper/left_pad``) are escaped as one path part (``gripper\\/left_pad``);
unnamed bodies and geoms are called ``body<i>`` and ``geom<i>``. The file embeds a blueprint:
the 3D scene on the left; on the right the plot tabs of :data:`PLOTS` (health, tracking,
joints, gripper and IK) and the event log.
"""

from __future__ import annotations

import contextlib
import json
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from pickplace.control.controllers import IK_STATUSES
from pickplace.errors import InvalidInputError, OutputError, RecordingError, require_positive
from pickplace.outfile import OutputFile
from pickplace.record.viewer import FINISH_TIMEOUT_S, ViewerRelay, parse_viewer_url, spawn_viewer
from pickplace.signals import deferred_interrupts
from pickplace.sim.events import EventKind

if TYPE_CHECKING:
    from pickplace.sim.events import Event
    from pickplace.sim.loop import Simulation
    from pickplace.sim.ticklog import TickLog
    from pickplace.sim.verdict import RunResult
    from pickplace.world.scene import Scene

APPLICATION_ID = "pickplace"
SPAWN_PORT = 9876
ELLIPSOID_SCALE = 0.1  # half sizes of the manipulability ellipsoid = this · σt [m per m/rad]
PLANE_EXTENT = 2.0  # half extent drawn for an infinite plane [m]
ENCODE_TIMEOUT_S = 30.0  # bound on encoding what was logged (normally milliseconds) [s]
VIEWER_FINISH_AFTER_INTERRUPT_S = 1.0  # time a viewer gets for the rest after Ctrl-C [s]
KEYFRAME_MERGE_DISTANCE = 0.01  # keyframes closer than this share one label [m]
# Default 3D camera: from the front right, above, looking down at both bins [m].
EYE_POSITION = (1.2, -1.3, 1.05)
EYE_TARGET = (0.25, -0.3, 0.25)

TOOL_AXES = {"planned": 0.12, "commanded": 0.09, "actual": 0.06}
JOINT_COLORS = [
    (0.12, 0.47, 0.71),
    (1.00, 0.50, 0.05),
    (0.17, 0.63, 0.17),
    (0.84, 0.15, 0.16),
    (0.58, 0.40, 0.74),
    (0.55, 0.34, 0.29),
    (0.89, 0.47, 0.76),
]
LEVELS = {
    "info": rr.TextLogLevel.INFO,
    "warn": rr.TextLogLevel.WARN,
    "error": rr.TextLogLevel.ERROR,
}

_GEOM = mujoco.mjtGeom
_TLC = rrb.encodings.TextLogColumnKind
_SOLID = rr.components.FillMode.Solid


def _xyzw(q_wxyz: np.ndarray) -> np.ndarray:
    """MuJoCo/mink wxyz quaternions (..., 4) → Rerun xyzw."""
    return np.asarray(q_wxyz)[..., [1, 2, 3, 0]]


def _quat(q_wxyz: np.ndarray) -> rr.Quaternion:
    """One MuJoCo/mink wxyz quaternion as a Rerun quaternion."""
    return rr.Quaternion(xyzw=_xyzw(q_wxyz))


def _ns(t: np.ndarray) -> np.ndarray:
    """Seconds → timedelta64[ns], rounded (k·dt sums such as 0.09 + 0.01 land 1 ns short)."""
    return np.round(np.asarray(t, dtype=np.float64) * 1e9).astype("timedelta64[ns]")


def _incomplete(path: Path) -> str | None:
    """None if the .rrd at ``path`` reads back with its footer and the summary, else what is
    wrong (reads the footer's manifest, not the data: milliseconds)."""
    from rerun.chunk import RrdReader

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "no footer" is reported below instead
            entities = RrdReader(path).store().schema().entity_paths()
    except (RuntimeError, OSError, ValueError) as exc:
        return f"the file does not read back ({' '.join(str(exc).split())[:200]})"
    if "/summary" not in entities:
        return "the file lacks the summary"
    return None


def _part(name: str) -> str:
    return str(rr.escape_entity_path_part(name))


def _finite_or_nan(a: np.ndarray) -> np.ndarray:
    """Copy of ``a`` with ±inf replaced by NaN (drawn as a gap in a plot)."""
    out = np.array(a, dtype=np.float64)
    out[~np.isfinite(out)] = np.nan
    return out


# Component descriptors of the per-tick columns, taken once from the archetypes: building
# ComponentColumns from them directly costs a fifth of ``Archetype.columns(...)``.
_DESCRIPTORS = {
    c.component_descriptor().component: c.component_descriptor()
    for c in [
        *rr.Transform3D.columns(translation=np.zeros((1, 3)), quaternion=np.eye(4)[3:]),
        *rr.Scalars.columns(scalars=np.zeros(1)),
    ]
}


def _transform_columns(p: np.ndarray, q_wxyz: np.ndarray) -> list[rr.ComponentColumn]:
    """Transform3D columns (translation, quaternion), one row per row of ``p`` (T, 3)."""
    offsets = np.arange(len(p) + 1, dtype=np.int32)
    return [
        rr.ComponentColumn(
            _DESCRIPTORS["Transform3D:translation"],
            rr.components.Translation3DBatch(p),
            offsets=offsets,
        ),
        rr.ComponentColumn(
            _DESCRIPTORS["Transform3D:quaternion"],
            rr.components.RotationQuatBatch(_xyzw(q_wxyz)),
            offsets=offsets,
        ),
    ]


def _scalar_columns(values: np.ndarray) -> list[rr.ComponentColumn]:
    """Scalars column of (T,) or (T, N) values (N lines); ±inf becomes NaN (a gap)."""
    v = _finite_or_nan(values)
    width = 1 if v.ndim == 1 else v.shape[1]
    offsets = np.arange(0, v.size + 1, width, dtype=np.int32)
    batch = rr.components.ScalarBatch(v.reshape(-1))
    return [rr.ComponentColumn(_DESCRIPTORS["Scalars:scalars"], batch, offsets=offsets)]


def _vertex_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted per-vertex normals of a triangle mesh."""
    normals = np.zeros_like(verts)
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    face_n = np.cross(b - a, c - a)
    for k in range(3):
        np.add.at(normals, faces[:, k], face_n)
    norm = np.linalg.norm(normals, axis=1, keepdims=True)
    return normals / np.where(norm > 0.0, norm, 1.0)


def geom_archetype(model: mujoco.MjModel, g: int, rgba: np.ndarray) -> Any | None:
    """Rerun shape of geom ``g`` in its own frame, or None for an unsupported type."""
    typ = int(model.geom_type[g])
    s = model.geom_size[g]
    color = [rgba]
    if typ == _GEOM.mjGEOM_BOX:
        return rr.Boxes3D(half_sizes=[s], colors=color, fill_mode=_SOLID)
    if typ == _GEOM.mjGEOM_SPHERE:
        return rr.Ellipsoids3D(half_sizes=[[s[0]] * 3], colors=color, fill_mode=_SOLID)
    if typ == _GEOM.mjGEOM_ELLIPSOID:
        return rr.Ellipsoids3D(half_sizes=[s], colors=color, fill_mode=_SOLID)
    if typ == _GEOM.mjGEOM_CAPSULE:
        # Rerun's capsule runs from its origin along +z; MuJoCo's is centred.
        return rr.Capsules3D(
            lengths=[2.0 * s[1]],
            radii=[s[0]],
            translations=[[0.0, 0.0, -s[1]]],
            colors=color,
            fill_mode=_SOLID,
        )
    if typ == _GEOM.mjGEOM_CYLINDER:
        return rr.Cylinders3D(lengths=[2.0 * s[1]], radii=[s[0]], colors=color, fill_mode=_SOLID)
    if typ == _GEOM.mjGEOM_PLANE:
        hx = s[0] if s[0] > 0 else PLANE_EXTENT
        hy = s[1] if s[1] > 0 else PLANE_EXTENT
        corners = [[-hx, -hy, 0.0], [hx, -hy, 0.0], [hx, hy, 0.0], [-hx, hy, 0.0]]
        return rr.Mesh3D(
            vertex_positions=corners,
            triangle_indices=[[0, 1, 2], [0, 2, 3]],
            vertex_normals=[[0.0, 0.0, 1.0]] * 4,
            albedo_factor=rgba,
        )
    if typ == _GEOM.mjGEOM_MESH and model.geom_dataid[g] >= 0:
        m = int(model.geom_dataid[g])
        va, vn = int(model.mesh_vertadr[m]), int(model.mesh_vertnum[m])
        fa, fn = int(model.mesh_faceadr[m]), int(model.mesh_facenum[m])
        verts = np.array(model.mesh_vert[va : va + vn], dtype=np.float64)
        faces = np.array(model.mesh_face[fa : fa + fn], dtype=np.int64)
        return rr.Mesh3D(
            vertex_positions=verts,
            triangle_indices=faces,
            vertex_normals=_vertex_normals(verts, faces),
            albedo_factor=rgba,
        )
    return None


def geom_rgba(model: mujoco.MjModel, g: int) -> np.ndarray:
    """Colour of geom ``g``: its material's when it has one, else ``geom_rgba``."""
    mat = int(model.geom_matid[g])
    return np.array(model.mat_rgba[mat] if mat >= 0 else model.geom_rgba[g], dtype=np.float64)


def _names(model: mujoco.MjModel, obj: mujoco.mjtObj, count: int, prefix: str) -> list[str]:
    return [mujoco.mj_id2name(model, obj, i) or f"{prefix}{i}" for i in range(count)]


# ---------------------------------------------------------------------------- the plots

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
# reads from the tick log. The README's entity table describes each one for users.
PLOTS: tuple[Plot, ...] = (
    # σ1..σ6 of the 6×n tool Jacobian (n arm joints; min(6, n) values), and σt1..σt3 of its
    # 3×n translational rows.
    Plot(
        path="plots/kinematics/singular_values",
        tab="Kinematic health",
        title="Singular values",
        names=_singular_value_names,
        values=lambda log, sl: log.sigma[sl],
        legend=False,
    ),
    Plot(
        path="plots/kinematics/singular_values_translational",
        tab="Kinematic health",
        title="Translational σ",
        names=("σt1", "σt2", "σt3"),
        values=lambda log, sl: log.sigma_t[sl],
        legend=False,
    ),
    # Condition numbers (∞ at a singularity is recorded as NaN).
    Plot(
        path="plots/kinematics/condition",
        tab="Kinematic health",
        title="Condition",
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
        tab="Tracking",
        title="Position error [m]",
        names=("position error [m]",),
        values=lambda log, sl: log.position_error[sl],
    ),
    Plot(
        path="plots/tracking/orientation_error",
        tab="Tracking",
        title="Orientation error [rad]",
        names=("orientation error [rad]",),
        values=lambda log, sl: log.orientation_error[sl],
    ),
    # (q − lower) / (upper − lower) per joint, with lines at 0 and 1.
    Plot(
        path="plots/joints/position_normalized",
        tab="Joints",
        title="Joint position (normalised)",
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
        title="Joint speed / limit",
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
    # The plan's timing: the planned tool speed [m/s] and the plan segment being executed
    # (index of the keyframe it starts from; the event log names the keyframes reached).
    Plot(
        path="plots/plan/tool_speed",
        tab="Timing",
        title="Planned tool speed [m/s]",
        names=("planned tool speed [m/s]",),
        values=lambda log, sl: np.linalg.norm(log.V_WG_plan[sl, :3], axis=1),
    ),
    Plot(
        path="plots/plan/segment",
        tab="Timing",
        title="Plan segment",
        names=("segment (index of its first keyframe)",),
        values=lambda log, sl: log.plan_segment[sl],
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
        title="IK status",
        names=(f"status ({IK_STATUS_NAMES})",),
        values=lambda log, sl: log.ik_status[sl],
        y_range=(-0.2, len(IK_STATUSES) - 0.8),
    ),
)
LIMIT_LINES: tuple[LimitLines, ...] = tuple(p.limits for p in PLOTS if p.limits is not None)


def _time_series_view(plot: Plot) -> rrb.TimeSeriesView:
    """The plot's view: its entity, and its limit lines if it has them."""
    kw: dict[str, Any] = {}
    if not plot.legend:
        kw["plot_legend"] = rrb.PlotLegend(visible=False)
    if plot.y_range is not None:
        kw["axis_y"] = rrb.ScalarAxis(range=plot.y_range)
    if plot.limits is None:
        return rrb.TimeSeriesView(name=plot.title, origin=plot.path, **kw)
    contents = [plot.path, plot.limits.path]
    return rrb.TimeSeriesView(name=plot.title, origin="/", contents=contents, **kw)


def build_blueprint() -> rrb.Blueprint:
    """3D scene left (3/5 of the width); the tabs of :data:`PLOTS` and the event log right."""
    tabs: dict[str, list[rrb.TimeSeriesView]] = {}
    for plot in PLOTS:
        tabs.setdefault(plot.tab, []).append(_time_series_view(plot))
    right = rrb.Vertical(
        *(rrb.Tabs(*views, name=name) for name, views in tabs.items()),
        rrb.Tabs(
            rrb.TextLogView(
                name="Events",
                origin="events",
                columns=rrb.archetypes.TextLogColumns(
                    text_log_columns=[
                        rrb.encodings.TextLogColumn(kind, visible=kind != _TLC.EntityPath)
                        for kind in (_TLC.LogLevel, _TLC.Body, _TLC.EntityPath)
                    ]
                ),
            ),
            rrb.TextDocumentView(name="Summary", origin="summary"),
            name="Events",
        ),
        row_shares=[1.0] * len(tabs) + [1.2],
    )
    scene = rrb.Spatial3DView(
        name="Scene",
        origin="world",
        eye_controls=rrb.EyeControls3D(
            position=EYE_POSITION, look_target=EYE_TARGET, eye_up=[0.0, 0.0, 1.0]
        ),
    )
    return rrb.Blueprint(
        rrb.Horizontal(scene, right, column_shares=[3.0, 2.0]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="expanded", timeline="sim_time"),
    )


class Recorder:
    """Record a :class:`~pickplace.sim.loop.Simulation` to Rerun (see the module docstring).

    One recorder records one run. The constructor only checks its arguments; :meth:`open`
    (called by the runner once every input is validated, or else by :meth:`on_start`) takes
    the output path and reaches the viewer. So a run refused for bad input never touches a file.

    The file: encoded in memory (a :class:`rerun.BinaryStream`; a run is a few MB), written
    to a temporary file beside ``path`` when the run has finished (success, failure or
    interruption) and renamed onto ``path`` once it reads back complete (footer and summary).
    A run that crashed or could not write the file (disk full, file size limit) deletes it
    and leaves an older file at ``path`` as it was; a killed run leaves the path as it was.
    One writer per path (a lock beside it, see :mod:`pickplace.outfile`). Nothing of Rerun's
    own file writer is used: its thread can deadlock after a write error.

    The viewers: fed through relay processes (:mod:`pickplace.record.viewer`), so a viewer that
    freezes, is stopped or goes away never blocks or ends the run: it is given up, an event
    says so and the file recording continues. Problems of either kind are listed in
    :attr:`file_error` and :attr:`warnings` after the run.

    Args:
        path: ``.rrd`` file to write, or None.
        recording_id: Recording id, e.g. ``pick-place/iiwa14-wsg50/qp/seed-0``.
        spawn: Also spawn a Rerun viewer (or use the one on port :data:`SPAWN_PORT`) and
            stream to it.
        connect: Also stream to a viewer at this gRPC URL
            (e.g. ``rerun+http://127.0.0.1:9876/proxy``).
        flush_every: Ticks per ``send_columns`` batch (each batch is flushed). Every batch
            costs the same ~35 calls whatever its length, so longer batches record faster.
        flush_interval_s: Also send what is complete once this much wall time [s] has passed
            since the last batch.

    Raises:
        RecordingError: No sink was given.
        InvalidInputError: ``flush_every`` is not a positive integer, ``flush_interval_s`` is
            not a positive number, or ``connect`` is not a viewer URL.
    """

    def __init__(
        self,
        path: Path | None,
        *,
        recording_id: str,
        spawn: bool = False,
        connect: str | None = None,
        flush_every: int = 200,
        flush_interval_s: float = 0.25,
    ) -> None:
        if isinstance(flush_every, bool) or not isinstance(flush_every, int) or flush_every < 1:
            raise InvalidInputError(f"flush_every must be an integer >= 1, got {flush_every!r}")
        if not (isinstance(flush_interval_s, int | float) and flush_interval_s > 0):
            raise InvalidInputError(
                f"flush_interval_s must be a number > 0 [s], got {flush_interval_s!r}"
            )
        if path is None and not spawn and connect is None:
            raise RecordingError("a recording needs a file path, spawn=True or a connect URL")
        self.path = Path(path) if path is not None else None
        self.recording_id = recording_id
        self.spawn = spawn
        self.connect = parse_viewer_url(connect) if connect is not None else None
        self.flush_every = flush_every
        self.flush_interval_s = float(flush_interval_s)
        self.file_error: str | None = None  # why the file could not be written
        self.warnings: list[str] = []  # viewer problems (the run went on)
        self.written: Path | None = None  # the file, once it is in place
        self._last_send = time.perf_counter()
        self.rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
        self.rec.set_log_time_enabled(False)
        self.rec.set_log_tick_enabled(False)
        self._output = OutputFile(self.path) if self.path is not None else None
        self._file_bytes: rr.BinaryStream | None = None  # the file, encoded in memory
        self._viewer_bytes: rr.BinaryStream | None = None  # what the viewer relays receive
        self._relays: list[ViewerRelay] = []
        self._opened = False
        self._closed = False
        self._finished = False
        self._started = False
        self._sent = 0  # ticks already sent
        self._verdict_logged = False
        self._early_events: list[Event] = []
        self._moving: list[tuple[int, str]] = []  # (body id, entity path)
        self._ik_status_names = ", ".join(f"{i} {s}" for i, s in enumerate(IK_STATUSES))

    # ------------------------------------------------------------------ lifecycle

    def open(self) -> None:
        """Take the output path, reach the viewers and open the sinks. Idempotent.

        Raises:
            OutputError: Another run writes the same path, the folder cannot be written, or a
                viewer does not answer; nothing is left behind.
            RecordingError: The recorder was closed.
        """
        if self._opened:
            return
        if self._closed:
            raise RecordingError("the recorder is closed; use one Recorder per run")
        sinks: list[Any] = []
        try:
            if self._output is not None:
                self._output.open()
                self._file_bytes = rr.binary_stream(recording=self.rec)
                sinks.append(self._file_bytes)
            addresses = []
            if self.spawn:
                addresses.append(spawn_viewer(SPAWN_PORT))
            if self.connect is not None:
                addresses.append(self.connect)
            for addr in addresses:
                self._relays.append(ViewerRelay(addr, self.recording_id))
            if self._relays:
                self._viewer_bytes = rr.binary_stream(recording=self.rec)
                sinks.append(self._viewer_bytes)
            self.rec.set_sinks(*sinks, default_blueprint=build_blueprint())
        except BaseException:
            self._discard()
            raise
        self._opened = True

    def __enter__(self) -> Recorder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        """True once the stream has been closed (the file is in place, or was not kept)."""
        return self._closed

    def close(self) -> None:
        """End without a finished run: nothing is put in place (an older file is kept), the
        viewers are let go. Idempotent; does nothing after :meth:`on_finish`."""
        if not self._closed:
            self._discard()

    def _discard(self) -> None:
        self._closed = True
        with contextlib.suppress(RuntimeError):
            self.rec.disconnect()
        for relay in self._relays:
            relay.kill()
        if self._output is not None:
            self._output.discard()

    def _flush(self, run: Simulation | None) -> None:
        """Hand the batch's bytes to the viewers (the file's stay in memory until the end)."""
        if self._viewer_bytes is not None:
            try:
                data = self._viewer_bytes.read(flush=True, flush_timeout_sec=ENCODE_TIMEOUT_S)
            except RuntimeError as exc:  # the viewers miss this batch; the file does not
                data = None
                self.warnings.append(f"a batch for the viewer could not be encoded: {exc}")
            for relay in self._relays:
                relay.send(data or b"")
        self._check_viewers(run)

    def _file_failed(self, reason: str) -> None:
        assert self.path is not None
        self.file_error = f"cannot write the recording '{self.path}': {reason}; " + (
            "an older file there is unchanged" if self.path.exists() else "no file was left"
        )

    def _write_file(self) -> None:
        """Write the encoded recording to the temporary file (fsync'd on commit)."""
        assert self._output is not None and self._file_bytes is not None
        temp = self._output.temp
        assert temp is not None
        try:
            data = self._file_bytes.read(flush=True, flush_timeout_sec=ENCODE_TIMEOUT_S)
        except RuntimeError as exc:
            self._file_failed(f"it could not be encoded within {ENCODE_TIMEOUT_S:g} s ({exc})")
            return
        try:
            with open(temp, "wb") as f:
                f.write(data or b"")
        except OSError as exc:
            self._file_failed(exc.strerror or str(exc))

    def _check_viewers(self, run: Simulation | None) -> None:
        for relay in self._relays:
            if relay.lost is not None and not any(relay.addr.url in w for w in self.warnings):
                when = f"; noticed at t={run.ticks * run.dt:.2f} s" if run is not None else ""
                text = (
                    f"the viewer at {relay.addr.url} {relay.lost}{when}; streaming to it "
                    "stopped" + (", the recording file goes on" if self._output is not None else "")
                )
                self.warnings.append(text)
                relay.kill()
                if run is not None:
                    run.emit(EventKind.VIEWER, text, level="warn")

    def _finish(self, run: Simulation, *, interrupted: bool) -> None:
        """Hand the rest to the viewers, write the file, close the stream, let the viewers
        take the rest (briefly after an interrupt: whoever stops a run wants it to end), check
        the file and put it in place."""
        self._flush(run)
        if self._output is not None:
            self._write_file()
        self._closed = True
        with contextlib.suppress(RuntimeError):
            self.rec.disconnect()
        timeout = VIEWER_FINISH_AFTER_INTERRUPT_S if interrupted else FINISH_TIMEOUT_S
        for relay in self._relays:
            problem = relay.finish(timeout)
            if problem is not None:
                self.warnings.append(problem)
        self._check_viewers(None)
        if self._output is None:
            return
        temp = self._output.temp
        if self.file_error is None and temp is not None:
            problem = _incomplete(temp)
            if problem is not None:
                self._file_failed(problem)
        if self.file_error is not None:
            self._output.discard()
            return
        try:
            self._output.commit()
        except OutputError as exc:
            self.file_error = str(exc)
            return
        self.written = self.path

    # ------------------------------------------------------------------ observer

    def on_start(self, run: Simulation) -> None:
        """Open (if not yet), then log the static scene, plan and plot styles."""
        self.open()
        self._started = True
        with deferred_interrupts():
            self._log_scene(run)
            self._log_plan(run)
            self._log_styles(run)
            for event in self._early_events:
                self._log_event(event.tick, event.t, event.level, event.text)
            self._early_events.clear()
            self._flush(run)

    def on_ticks(self, run: Simulation, start: int, end: int) -> None:
        """Send a batch once ``flush_every`` completed ticks are waiting, or once
        ``flush_interval_s`` has passed since the last batch."""
        if self._closed or end <= self._sent:
            return
        now = time.perf_counter()
        if end - self._sent >= self.flush_every or now - self._last_send >= self.flush_interval_s:
            with deferred_interrupts():
                self._send(run, end)
                self._flush(run)
            self._last_send = time.perf_counter()

    def on_event(self, run: Simulation, event: Event) -> None:
        """Log the event at its tick (events are rare: plain ``log``)."""
        if self._closed:
            return
        if not self._started:
            self._early_events.append(event)  # e.g. scene warnings emitted before the run
            return
        self._log_event(event.tick, event.t, event.level, event.text)
        if event.kind is EventKind.VERDICT:
            self._verdict_logged = True

    def on_finish(self, run: Simulation, result: RunResult) -> None:
        """Send the rest of the log, the summary and the verdict, close the stream and put the
        file in place."""
        if self._closed:
            return
        try:
            if self._started:
                last = min(int(run.ticks), len(run.log.t))
                self._send(run, last)
                if last > 1:
                    self._send_limit_rows(run.log, last - 1)
            summary = result.summary()
            if summary.get("recording") is None and self.path is not None:
                summary["recording"] = str(self.path)
            text = json.dumps(summary, indent=2, default=str)
            self.rec.log(
                "summary",
                rr.TextDocument(f"```json\n{text}\n```", media_type=rr.MediaType.MARKDOWN),
                static=True,
            )
            if not self._verdict_logged:
                verdict = "success" if result.success else f"failure: {result.failure}"
                level = "info" if result.success else "error"
                self._log_event(result.ticks, result.sim_time_s, level, f"verdict: {verdict}")
                self._verdict_logged = True
            self._finish(run, interrupted=str(result.failure) == "interrupted")
            self._finished = True
        finally:
            if not self._finished:
                self._discard()

    # ------------------------------------------------------------------ static content

    def _log_scene(self, run: Simulation) -> None:
        model, data, rec = run.model, run.data, self.rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        bodies = _names(model, mujoco.mjtObj.mjOBJ_BODY, model.nbody, "body")
        geoms = _names(model, mujoco.mjtObj.mjOBJ_GEOM, model.ngeom, "geom")
        body_paths = ["world/static"] + [f"world/bodies/{_part(n)}" for n in bodies[1:]]
        used: set[int] = set()
        for g in range(model.ngeom):
            rgba = geom_rgba(model, g)
            if model.geom_group[g] > 2 or rgba[3] <= 0.0:
                continue
            shape = geom_archetype(model, g, rgba)
            if shape is None:
                continue
            b = int(model.geom_bodyid[g])
            used.add(b)
            path = f"{body_paths[b]}/{_part(geoms[g])}"
            pose = rr.Transform3D(
                translation=model.geom_pos[g], quaternion=_quat(model.geom_quat[g])
            )
            rec.log(path, pose, shape, static=True)
        self._moving = []
        for b in range(1, model.nbody):
            if model.body_weldid[b] != 0 or model.body_mocapid[b] >= 0:
                self._moving.append((b, body_paths[b]))
            elif b in used:
                pose = rr.Transform3D(translation=data.xpos[b], quaternion=_quat(data.xquat[b]))
                rec.log(body_paths[b], pose, static=True)
        for name, length in TOOL_AXES.items():
            rec.log(f"world/tool/{name}", rr.TransformAxes3D(length), static=True)
        rec.log(
            "world/tool/manipulability_ellipsoid",
            rr.Ellipsoids3D.from_fields(
                colors=[[0.2, 0.6, 1.0, 0.25]], fill_mode=_SOLID, line_radii=[0.0005]
            ),
            static=True,
        )

    def _log_plan(self, run: Simulation) -> None:
        rec, traj = self.rec, run.task.trajectory
        path = traj.sample_path(400)
        rec.log(
            "world/plan/path",
            rr.LineStrips3D([path], colors=[[0.1, 0.75, 0.95]], radii=[0.003]),
            static=True,
        )
        # Keyframes at one position (pick, settle, grip-closed) would print their labels on top
        # of each other: the first of such a group shows all the names, the others none.
        names: list[str] = []
        for i, kf in enumerate(traj.keyframes):
            names.append(kf.name if kf.name not in names else f"{kf.name}-{i}")
        poses = [np.asarray(kf.X_WG.wxyz_xyz) for kf in traj.keyframes]
        leader = list(range(len(poses)))
        for i in range(len(poses)):
            for j in range(i):
                if np.linalg.norm(poses[i][4:] - poses[j][4:]) < KEYFRAME_MERGE_DISTANCE:
                    leader[i] = leader[j]
                    break
        for i, (name, wxyz_xyz) in enumerate(zip(names, poses, strict=True)):
            group = [names[j] for j in range(len(names)) if leader[j] == i]
            rec.log(
                f"world/plan/keyframes/{_part(name)}",
                rr.Transform3D(translation=wxyz_xyz[4:], quaternion=_quat(wxyz_xyz[:4])),
                rr.TransformAxes3D(0.05),
                rr.Points3D(
                    [[0.0, 0.0, 0.0]],
                    radii=[0.008],
                    colors=[[1.0, 0.85, 0.1]],
                    labels=[" / ".join(group) if group else name],
                    show_labels=bool(group),
                ),
                static=True,
            )
        bin_ = run.scene.target_bin
        height = bin_.wall_top_z - bin_.floor_top_z
        center = bin_.center_W + np.array([0.0, 0.0, 0.5 * height])
        half = [bin_.inner_half_extents[0], bin_.inner_half_extents[1], 0.5 * height]
        rec.log(
            "world/plan/target_bin",
            rr.Boxes3D(
                half_sizes=[half],
                centers=[center],
                quaternions=[_xyzw(bin_.X_WB.rotation().wxyz)],
                colors=[[0.1, 0.85, 0.2]],
                radii=[0.003],
                labels=[f"target: {bin_.name}"],
                show_labels=False,  # the keyframe labels above it say enough
            ),
            static=True,
        )
        self._log_rejected(run)

    def _log_rejected(self, run: Simulation) -> None:
        """Each candidate plan the planner rejected: its path, thin and grey, and a red marker
        where its first problem happened (contact point, limited joint or tool), labelled."""
        planning = run.task.planning
        if planning is None:
            return
        for i, c in enumerate(planning.candidates):
            problem = c.preflight.problem
            if problem is None:
                continue
            base = f"world/plan/rejected/{i}"
            self.rec.log(
                f"{base}/path",
                rr.LineStrips3D(
                    [c.plan.trajectory.sample_path(200)],
                    colors=[[0.55, 0.55, 0.6]],
                    radii=[0.0015],
                ),
                static=True,
            )
            self.rec.log(
                f"{base}/problem",
                rr.Points3D(
                    [problem.point_W],
                    radii=[0.012],
                    colors=[[0.95, 0.15, 0.15]],
                    labels=[f"{c.label}: {problem.kind} at t={problem.t:.2f} s"],
                ),
                static=True,
            )

    def _log_styles(self, run: Simulation) -> None:
        """Log the static line style of every plot of :data:`PLOTS` and of its limit lines."""
        for series in (*PLOTS, *LIMIT_LINES):
            self.rec.log(series.path, series.style(run.scene), static=True)

    # ------------------------------------------------------------------ tick data

    def _log_event(self, tick: int, t: float, level: str, text: str) -> None:
        self.rec.set_time("sim_time", duration=_ns(np.array([t]))[0])
        self.rec.set_time("tick", sequence=int(tick))
        self.rec.log("events", rr.TextLog(text, level=LEVELS.get(level, rr.TextLogLevel.INFO)))

    def _send(self, run: Simulation, end: int) -> None:
        """Send rows ``[self._sent, end)`` of ``run.log`` as columns."""
        start = self._sent
        if end <= start:
            return
        self._sent = end
        log: TickLog = run.log
        sl = slice(start, end)
        times = [
            rr.TimeColumn("sim_time", duration=_ns(log.t[sl])),
            rr.TimeColumn("tick", sequence=np.arange(start, end, dtype=np.int64)),
        ]
        send = self.rec.send_columns

        for b, path in self._moving:
            send(path, times, _transform_columns(log.body_pos[sl, b], log.body_quat[sl, b]))
        send(
            "world/tool/planned", times, _transform_columns(log.p_WG_plan[sl], log.quat_WG_plan[sl])
        )
        send(
            "world/tool/commanded", times, _transform_columns(log.p_WG_cmd[sl], log.quat_WG_cmd[sl])
        )
        send("world/tool/actual", times, _transform_columns(log.p_WG[sl], log.quat_WG[sl]))

        half = ELLIPSOID_SCALE * log.sigma_t[sl]
        half[~np.isfinite(half)] = 0.0
        send(
            "world/tool/manipulability_ellipsoid",
            times,
            rr.Ellipsoids3D.columns(
                half_sizes=half, centers=log.p_WG[sl], quaternions=_xyzw(log.quat_t[sl])
            ),
        )

        for plot in PLOTS:
            send(plot.path, times, _scalar_columns(plot.values(log, sl)))

        if start == 0:
            self._send_limit_rows(log, 0)

    def _send_limit_rows(self, log: TickLog, tick: int) -> None:
        """The constant limit lines get a row at the first and at the last tick only."""
        times = [
            rr.TimeColumn("sim_time", duration=_ns(log.t[tick : tick + 1])),
            rr.TimeColumn("tick", sequence=np.array([tick], dtype=np.int64)),
        ]
        for lines in LIMIT_LINES:
            row = np.asarray(lines.values(log.scene), dtype=np.float64)
            self.rec.send_columns(lines.path, times, _scalar_columns(row[None, :]))
