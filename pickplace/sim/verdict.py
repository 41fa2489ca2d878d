"""The verdict of a run: failure reasons, the geometry that decides them, metrics, the summary.

Everything here is judged from stated geometry (:class:`~pickplace.sim.checks.SuccessCriteria`, the
scene's bins and brick) and from the tick log, never assumed. The checks that run during a run,
and the failure reasons, are in :mod:`pickplace.sim.checks`; the goals in
:mod:`pickplace.sim.goals`.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from mink.lie import SE3, SO3

from pickplace.control.controllers import IK_STATUSES
from pickplace.geometry import box_corners, box_tilt, transform_points
from pickplace.planning.planner import PlanningReport
from pickplace.sim.checks import FailureReason, SuccessCriteria
from pickplace.sim.events import Event, EventKind
from pickplace.sim.ticklog import TickLog
from pickplace.world.placements import footprint_inside
from pickplace.world.scene import BinGeometry, Scene

# ------------------------------------------------------------------------ the brick


def brick_pose(scene: Scene, data: mujoco.MjData) -> SE3:
    """Current pose X_WO of the brick."""
    b = scene.brick_body_id
    return SE3.from_rotation_and_translation(SO3(np.array(data.xquat[b])), np.array(data.xpos[b]))


def brick_at_rest(scene: Scene, data: mujoco.MjData, criteria: SuccessCriteria) -> bool:
    """True if the brick's linear and angular speeds are below the rest thresholds."""
    a = scene.brick_dof_adr
    v = data.qvel[a : a + 6]
    return bool(
        float(v[:3] @ v[:3]) < criteria.rest_speed**2
        and float(v[3:] @ v[3:]) < criteria.rest_angular_speed**2
    )


def brick_touches_robot(scene: Scene, data: mujoco.MjData) -> bool:
    """True if any geom of the robot (arm or gripper) touches the brick."""
    held = set(scene.object.geom_ids.tolist())
    for i in range(data.ncon):
        c = data.contact[i]
        g1, g2 = int(c.geom1), int(c.geom2)
        if g1 in held or g2 in held:
            other = g2 if g1 in held else g1
            if scene.is_robot_geom(other):
                return True
    return False


def lying_tilt(scene: Scene, X_WO: SE3) -> float:
    """How far the object is from lying flat [rad]: a box (the brick) from resting on any of
    its faces (world z from the nearest face normal), a ball never, another object from
    standing on its base (its z axis from world z)."""
    if scene.object.box_half_extents is not None:
        return box_tilt(X_WO.rotation())
    if scene.object.is_round:
        return 0.0
    z_O = X_WO.rotation().as_matrix()[:, 2]
    return float(np.arccos(np.clip(z_O[2], -1.0, 1.0)))


def placement_problems(
    scene: Scene,
    data: mujoco.MjData,
    bin_: BinGeometry,
    criteria: SuccessCriteria,
    grasp_width: float,
) -> list[str]:
    """Reasons the brick is not verifiably resting in ``bin_`` (empty if it is).

    The object (the brick's box corners; another object's support along the walls' normals)
    must lie over the bin's floor inside its inner walls, its lowest point on the floor's top
    face within ``floor_tolerance``, lying flat (a box on any of its faces: world z within
    ``max_tilt`` of that face's normal; another object with its z axis within ``max_tilt`` of
    vertical; a ball any way up); it must be at rest, free of the gripper, and the gripper
    open wider than the brick was between its fingers (``grasp_width`` [m]).
    """
    X_WO = brick_pose(scene, data)
    box = scene.object.box_half_extents
    if box is not None:
        corners_W = transform_points(X_WO, box_corners(box))
        lowest = float(corners_W[:, 2].min())
        inside = bin_.contains_xy(corners_W)
    else:  # another object: its support along the walls' normals and straight down
        lowest = -float(scene.object.extent_W(X_WO, np.array([[0.0, 0.0, -1.0]]))[0])
        inside = footprint_inside(scene, X_WO, bin_)
    problems: list[str] = []
    if not inside:
        c = X_WO.translation()
        problems.append(
            f"the brick's footprint (centre at x={c[0]:.3f}, y={c[1]:.3f} m) is not inside "
            f"{bin_.name}'s inner walls"
        )
    if abs(lowest - bin_.floor_top_z) > criteria.floor_tolerance:
        problems.append(
            f"the brick's lowest corner is at z={lowest:.3f} m, {bin_.name}'s floor at "
            f"z={bin_.floor_top_z:.3f} m (tolerance {criteria.floor_tolerance * 1000:.0f} mm)"
        )
    tilt = lying_tilt(scene, X_WO)
    if tilt > criteria.max_tilt:
        measured = (
            "world z from its nearest face normal" if box is not None else "its z axis from world z"
        )
        problems.append(
            f"the brick is tilted {np.rad2deg(tilt):.0f} deg from lying flat ({measured}; "
            f"limit {np.rad2deg(criteria.max_tilt):.0f} deg)"
        )
    if not brick_at_rest(scene, data, criteria):
        a = scene.brick_dof_adr
        v = data.qvel[a : a + 6]
        problems.append(
            f"the brick still moves at {np.linalg.norm(v[:3]):.3f} m/s, "
            f"{np.linalg.norm(v[3:]):.2f} rad/s (at rest below {criteria.rest_speed:g} m/s, "
            f"{criteria.rest_angular_speed:g} rad/s)"
        )
    if brick_touches_robot(scene, data):
        problems.append("the brick still touches the gripper")
    gap = scene.robot.gap(data)
    if gap < grasp_width:
        problems.append(
            f"the gripper is not open: gap {gap * 1000:.1f} mm (need >= {grasp_width * 1000:.1f}"
            " mm, the brick's width between the fingers)"
        )
    return problems


# -------------------------------------------------------------------------- metrics


def run_metrics(log: TickLog, ticks: int, X_WO_final: SE3, X_WO_goal: SE3 | None) -> dict[str, Any]:
    """The summary's metrics over the first ``ticks`` rows of the log (see docs/cli.md)."""
    sl = slice(0, ticks)
    counts = {s: 0 for s in IK_STATUSES}
    for code, c in zip(*np.unique(log.ik_status[sl], return_counts=True), strict=True):
        counts[IK_STATUSES[int(code)]] = int(c)
    slip = log.slip[sl]
    slip = slip[np.isfinite(slip)]

    def finite(x: float) -> float | None:
        return float(x) if np.isfinite(x) else None

    return {
        "place_error_m": (
            float(np.linalg.norm(X_WO_final.translation() - X_WO_goal.translation()))
            if X_WO_goal
            else None
        ),
        "min_singular_value": float(log.sigma[sl, -1].min()) if ticks else float("nan"),
        "max_condition_number": finite(log.condition[sl].max()) if ticks else None,
        "min_manipulability_w1": float(log.manipulability[sl, 0].min()) if ticks else None,
        "max_joint_speed_ratio": float(log.speed_ratio[sl].max()) if ticks else 0.0,
        "max_joint_limit_violation_rad": float(log.limit_violation[sl].max()) if ticks else 0.0,
        "max_position_error_m": float(log.position_error[sl].max()) if ticks else 0.0,
        "max_orientation_error_rad": float(log.orientation_error[sl].max()) if ticks else 0.0,
        "max_slip_m": float(slip.max()) if slip.size else None,
        "max_robot_world_contact_force_n": float(log.robot_world_force[sl].max()) if ticks else 0.0,
        "ik_status_counts": counts,
        "ik_tick_us_median": float(np.median(log.ik_us[sl])) if ticks else None,
    }


# -------------------------------------------------------------------------- summary


@dataclass(frozen=True)
class Attempt:
    """One attempt of a run: a plan executed from where the run stood, and how it ended.

    Attributes:
        number: 1 for the run's first plan, then 2, 3, ...
        start_tick: Control tick at which its plan started (0 for the first).
        start_time_s: Run time at which its plan's clock read 0 [s].
        candidate: Label of the plan's candidate (None: a plan made without the planner).
        failure: Why it failed, when a recovery took that failure up and the run went on
            (None for the run's last attempt, whose outcome is the run's).
        failure_tick: Tick of that failure.
        failure_time_s: Run time at the end of that tick [s].
        failure_text: Its text, as a failure event would say it (``"dropped: ..."``).
        stop_tick: Tick from which the arm was brought to a stop after the failure.
        pushes: Pushes of the object its plan made before the pick (where no grasp fit,
            :mod:`pickplace.planning.push`), each counted once the tool had backed away.
    """

    number: int
    start_tick: int
    start_time_s: float
    candidate: str | None
    failure: FailureReason | None = None
    failure_tick: int | None = None
    failure_time_s: float | None = None
    failure_text: str | None = None
    stop_tick: int | None = None
    pushes: int = 0


def attempt_rows(
    attempts: list[Attempt], result: RunResult
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The summary's ``attempts`` and ``replans`` (see docs/cli.md): each attempt with its
    outcome (the last one's is the run's), and each replan with the failure it followed and
    the new plan's candidate."""
    rows = []
    for i, a in enumerate(attempts):
        last = i == len(attempts) - 1
        failure = result.failure if last else a.failure
        tick = result.failure_tick if last else a.failure_tick
        t = result.failure_time_s if last else a.failure_time_s
        rows.append(
            {
                "attempt": a.number,
                "start_tick": a.start_tick,
                "start_time_s": a.start_time_s,
                "candidate": a.candidate,
                "success": bool(last and result.success),
                "failure": None if failure is None else failure.value,
                "failure_tick": tick,
                "failure_time_s": t,
                "failure_text": result.failure_text if last else a.failure_text,
                "stop_tick": a.stop_tick,
                "pushes": a.pushes,
            }
        )
    replans = [
        {
            "attempt": b.number,
            "tick": b.start_tick,
            "t": b.start_time_s,
            "after": None if a.failure is None else a.failure.value,
            "failure_text": a.failure_text,
            "candidate": b.candidate,
        }
        for a, b in itertools.pairwise(attempts)
    ]
    return rows, replans


@dataclass
class RunResult:
    """Outcome of one run, read by attribute (a sweep's trial, the CLI); :meth:`summary` is
    the JSON the CLI prints, derived from it here and nowhere else."""

    scenario: str
    controller: str
    seed: int
    goal: str
    success: bool
    failure: FailureReason | None
    failure_tick: int | None
    failure_time_s: float | None
    ticks: int
    sim_time_s: float
    wall_time_s: float
    brick_start_xyz: list[float]
    brick_final_xyz: list[float]
    target_xyz: list[float]
    events: list[Event]
    metrics: dict[str, Any]
    planning: PlanningReport | None = None
    recording: str | None = None
    robot: str | None = None
    parameters: dict[str, Any] | None = None
    attempts: list[Attempt] | None = None

    @property
    def failure_text(self) -> str | None:
        """The failure event's text (``"dropped: ..."``), and for ``no-feasible-plan`` the
        first candidate's first problem; None for a success."""
        text = next((e.text for e in self.events if e.kind is EventKind.FAILURE), None)
        if self.failure is FailureReason.NO_FEASIBLE_PLAN and self.planning is not None:
            problems = [c.preflight.problem for c in self.planning.candidates]
            first = next((p for p in problems if p is not None), None)
            if first is not None:
                text = f"{text}; first candidate: {first.kind}: {first.text}"
        return text

    def _chosen_label(self) -> str | None:
        planning = self.planning
        if planning is None or planning.chosen is None:
            return None
        return planning.candidates[planning.chosen].label

    def summary(self) -> dict[str, Any]:
        """JSON-serialisable summary (the keys are an interface: see docs/cli.md)."""
        rtf = self.sim_time_s / self.wall_time_s if self.wall_time_s > 0 else float("inf")
        out: dict[str, Any] = {
            "scenario": self.scenario,
            "robot": self.robot,
            "controller": self.controller,
            "seed": self.seed,
            "goal": self.goal,
            "success": self.success,
            "failure": None if self.failure is None else self.failure.value,
            "failure_tick": self.failure_tick,
            "failure_time_s": self.failure_time_s,
            "brick_start_xyz": self.brick_start_xyz,
            "brick_final_xyz": self.brick_final_xyz,
            "target_xyz": self.target_xyz,
            "sim_time_s": self.sim_time_s,
            "wall_time_s": self.wall_time_s,
            "realtime_factor": rtf,
            "ticks": self.ticks,
        }
        out.update(self.metrics)
        planning = self.planning
        out["planning_time_s"] = None if planning is None else planning.planning_time_s
        out["plan"] = None if planning is None else planning.as_dict()
        if planning is not None and planning.used_cspace:  # only when C-space was planned
            out["planner_time_s"] = dict(planning.planner_time_s)
        if self.failure is FailureReason.NO_FEASIBLE_PLAN and planning is not None:
            out["refusal"] = planning.refusal_cause  # only when refused: a REFUSAL_CAUSES key
        out["events"] = [
            {"tick": e.tick, "t": e.t, "level": e.level, "kind": e.kind.value, "text": e.text}
            for e in self.events
        ]
        out["recording"] = self.recording
        attempts = self.attempts or [
            Attempt(1, 0, 0.0, None if self.planning is None else self._chosen_label())
        ]
        out["attempts"], out["replans"] = attempt_rows(attempts, self)
        if self.parameters is not None:  # only when something was varied
            out["parameters"] = self.parameters
        return out


# Fields that differ between two runs of the same inputs (wall-clock measurements).
WALL_TIME_FIELDS: tuple[str, ...] = (
    "wall_time_s",
    "realtime_factor",
    "ik_tick_us_median",
    "planning_time_s",
    "planner_time_s",
)
