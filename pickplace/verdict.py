"""The verdict of a run: failure reasons, the geometry that decides them, metrics, the summary.

Everything here is judged from stated geometry (:class:`SuccessCriteria`, the scene's bins and
brick) and from the tick log, never assumed. The checks that run during a run are in
:mod:`pickplace.checks`; the goals that choose them in :mod:`pickplace.goals`.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from mink.lie import SE3, SO3

from pickplace.controllers import IK_STATUSES
from pickplace.events import Event
from pickplace.geometry import box_corners, transform_points
from pickplace.scene import BinGeometry, Scene
from pickplace.ticklog import TickLog


class FailureReason(enum.Enum):
    """Why a run failed; the values are the strings of the JSON summary."""

    MISSED_GRASP = "missed-grasp"
    DROPPED = "dropped"
    IK_FAILED = "ik-failed"
    LIMIT_VIOLATED = "limit-violated"
    NOT_IN_TARGET_BIN = "not-in-target-bin"
    NAN = "nan"
    INTERRUPTED = "interrupted"

    def __str__(self) -> str:
        return self.value


FAILURE_REASONS: tuple[str, ...] = tuple(r.value for r in FailureReason)


@dataclass(frozen=True)
class Failure:
    """A failure found by a check: its reason, the tick it happened at and a text."""

    tick: int
    reason: FailureReason
    text: str


@dataclass(frozen=True)
class SuccessCriteria:
    """Geometry that decides grasp, drop and placement verdicts.

    Attributes:
        grasp_force_fraction: A pad touches the brick "firmly" above this fraction of the
            gripper's force limit (0.25 · 40 N = 10 N; a held brick sees the full 40 N).
        grasp_gap_fraction: After closing, the finger gap must be at least this fraction of the
            brick's width across the fingers (0.5 · 0.05 m); an empty gripper closes to 0.
        drop_slip: Brick displacement in the gripper frame since the grasp [m] that counts as
            dropped: 0.02 m exceeds the pads' 0.015 m half-height, so the brick is no longer
            between the pads where it was gripped.
        drop_contact_loss: Seconds without any pad-brick contact that count as dropped [s].
        rest_speed: Brick linear speed below which it is at rest [m/s].
        rest_angular_speed: Brick angular speed below which it is at rest [rad/s].
        floor_tolerance: Largest gap between the brick's lowest corner and the bin floor's top
            face for the brick to be resting on it [m] (contacts penetrate < 1 mm).
        max_tilt: Largest angle between the brick's z axis and world z for lying flat [rad].
        settle_time: Longest time simulated after the plan ends for the brick to come to
            rest [s].
        failure_grace: Time still simulated after a failure, so that its consequence can be
            seen in the recording [s].
        tracking_limit: Planned-vs-commanded tool position error beyond which the IK has lost
            the plan (ik-failed) [m]: larger than any lag of a tracking IK (< 1 mm).
        speed_ratio_tolerance: Joint-speed ratios are compared with 1 + this: the QP's bounds
            are exact up to solver tolerance [-].
        position_limit_tolerance: How far past a joint limit a joint may be before the run
            counts as a limit violation [rad].
    """

    grasp_force_fraction: float = 0.25
    grasp_gap_fraction: float = 0.5
    drop_slip: float = 0.02
    drop_contact_loss: float = 0.1
    rest_speed: float = 0.005
    rest_angular_speed: float = 0.05
    floor_tolerance: float = 0.003
    max_tilt: float = np.deg2rad(5.0)
    settle_time: float = 1.5
    failure_grace: float = 0.5
    tracking_limit: float = 0.02
    speed_ratio_tolerance: float = 1e-6
    position_limit_tolerance: float = 1e-3


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
    brick = scene.brick_geom_id
    for i in range(data.ncon):
        c = data.contact[i]
        g1, g2 = int(c.geom1), int(c.geom2)
        if brick in (g1, g2):
            other = g2 if g1 == brick else g1
            if scene.is_robot_geom(other):
                return True
    return False


def placement_problems(
    scene: Scene,
    data: mujoco.MjData,
    bin_: BinGeometry,
    criteria: SuccessCriteria,
) -> list[str]:
    """Reasons the brick is not verifiably resting in ``bin_`` (empty if it is).

    The brick's box corners must lie over the bin's floor inside its inner walls, its lowest
    corner on the floor's top face within ``floor_tolerance``, its z axis within ``max_tilt``
    of vertical; it must be at rest, free of the gripper, and the gripper open wider than it.
    """
    X_WO = brick_pose(scene, data)
    corners_W = transform_points(X_WO, box_corners(scene.brick_half_extents))
    problems: list[str] = []
    if not bin_.contains_xy(corners_W):
        problems.append(f"footprint not inside {bin_.name}'s inner walls")
    lowest = float(corners_W[:, 2].min())
    if abs(lowest - bin_.floor_top_z) > criteria.floor_tolerance:
        problems.append(
            f"lowest corner at z={lowest:.3f} m, {bin_.name} floor at z={bin_.floor_top_z:.3f} m"
        )
    z_O = X_WO.rotation().as_matrix()[:, 2]
    tilt = float(np.arccos(np.clip(z_O[2], -1.0, 1.0)))
    if tilt > criteria.max_tilt:
        problems.append(f"tilted {np.rad2deg(tilt):.0f} deg")
    if not brick_at_rest(scene, data, criteria):
        problems.append("still moving")
    if brick_touches_robot(scene, data):
        problems.append("still touching the gripper")
    gap = float(scene.finger_gap(data.qpos))
    if gap < scene.brick_width:
        problems.append(f"gripper not open (gap {gap * 1000:.0f} mm)")
    return problems


# -------------------------------------------------------------------------- metrics


def run_metrics(log: TickLog, ticks: int, X_WO_final: SE3, X_WO_goal: SE3 | None) -> dict[str, Any]:
    """The summary's metrics over the first ``ticks`` rows of the log (see the README)."""
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
        "ik_status_counts": counts,
        "ik_tick_us_median": float(np.median(log.ik_us[sl])) if ticks else None,
    }


# -------------------------------------------------------------------------- summary


@dataclass
class RunResult:
    """Outcome of one run; :meth:`summary` is the JSON the CLI prints."""

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
    recording: str | None = None

    def summary(self) -> dict[str, Any]:
        """JSON-serialisable summary (the keys are an interface: see the README)."""
        rtf = self.sim_time_s / self.wall_time_s if self.wall_time_s > 0 else float("inf")
        out: dict[str, Any] = {
            "scenario": self.scenario,
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
        out["events"] = [
            {"tick": e.tick, "t": e.t, "level": e.level, "kind": e.kind, "text": e.text}
            for e in self.events
        ]
        out["recording"] = self.recording
        return out


# Fields that differ between two runs of the same inputs (wall-clock measurements).
WALL_TIME_FIELDS: tuple[str, ...] = ("wall_time_s", "realtime_factor", "ik_tick_us_median")
