"""Checks: objects that judge a block of ticks of the log and report the first failure.

Every check has one interface, :meth:`Check.first_failure`: given the tick log and a block of
ticks ``[k0, k1)`` whose rows are complete (raw and derived), return the first failure in it
(reason, tick, text) or None. A goal (:mod:`pickplace.sim.goals`) owns a list of checks; the order
of the list is the precedence of failures that happen at the same tick. The loop calls each
check once per block, in tick order, and keeps the run's first failure.

A check may keep state from block to block (the grasp monitor does), may emit events, and may
fill the log's grasp-dependent rows; it never acts on the simulation.

To add a check: subclass :class:`Check` in this module, with its reason in
:class:`FailureReason` if it is a new one, add it to :data:`PLACE_CHECKS` (or
:data:`REACH_CHECKS`) at the precedence it should have, give it a test that makes it fail and
one that does not, and add the reason to the failure list of docs/failures.md.
"""

from __future__ import annotations

import enum
from abc import ABC, abstractmethod
from dataclasses import dataclass

import mujoco
import numpy as np

from pickplace.control.controllers import IK_STATUSES, IKStatus
from pickplace.planning.plan import Plan, grasp_width
from pickplace.sim.events import Emit, EventKind
from pickplace.sim.ticklog import CONTROLLER_NONFINITE, FINITE, TickLog
from pickplace.world.scene import Scene

_NO_SOLUTION = IK_STATUSES.index(IKStatus.NO_SOLUTION.value)


class FailureReason(enum.Enum):
    """Why a run failed; the values are the strings of the JSON summary."""

    MISSED_GRASP = "missed-grasp"
    DROPPED = "dropped"
    COLLISION = "collision"
    IK_FAILED = "ik-failed"
    LIMIT_VIOLATED = "limit-violated"
    NOT_IN_TARGET_BIN = "not-in-target-bin"
    NAN = "nan"
    INTERRUPTED = "interrupted"
    NO_FEASIBLE_PLAN = "no-feasible-plan"

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
        grasp_force_fraction: A side's pads push on the brick "firmly" above this fraction of
            the gripper's squeeze force, measured in calibration (:attr:`Scene.squeeze_force
            <pickplace.world.scene.Scene.squeeze_force>`; the iiwa's WSG-like gripper: 0.25 · 40 N =
            10 N, and a held brick sees the full 40 N).
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
        max_tilt: Largest angle between world z and the brick's nearest face normal for lying
            flat [rad].
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


@dataclass(frozen=True)
class CheckContext:
    """What checks may read besides the log: the scene, the plan, the criteria, the clock,
    and where to report events.

    Attributes:
        scene: The scene being simulated (ids, limits, brick and gripper geometry).
        plan: The plan being executed (its phases say when to judge what).
        criteria: Thresholds of the verdict.
        dt: Control period [s].
        emit: Records an event (``emit(kind, text, level, tick)``).
        t_start: Run time at which the plan's clock reads 0 [s]: 0 for the run's first plan,
            later for a plan that replaced another (the log's times are run times; a plan's
            phases are on its own clock).
    """

    scene: Scene
    plan: Plan
    criteria: SuccessCriteria
    dt: float
    emit: Emit
    t_start: float = 0.0


def first_tick(mask: np.ndarray, k0: int) -> int | None:
    """Index ``k0 + i`` of the first true entry of ``mask``, or None."""
    idx = np.flatnonzero(mask)
    return k0 + int(idx[0]) if idx.size else None


class Check(ABC):
    """Judges blocks of ticks; see the module docstring.

    Args:
        ctx: What the check may read besides the log.
    """

    @abstractmethod
    def __init__(self, ctx: CheckContext) -> None:
        """Take what the check needs from ``ctx``."""

    @abstractmethod
    def first_failure(self, log: TickLog, k0: int, k1: int) -> Failure | None:
        """The first failure among ticks ``[k0, k1)`` of ``log``, or None."""


class NonFiniteCheck(Check):
    """The controller's joint velocities or the simulated state became NaN or infinite."""

    def __init__(self, ctx: CheckContext) -> None:
        self.dt = ctx.dt

    def first_failure(self, log: TickLog, k0: int, k1: int) -> Failure | None:
        k = first_tick(log.nonfinite[k0:k1] != FINITE, k0)
        if k is None:
            return None
        what = (
            "controller returned non-finite joint velocities"
            if log.nonfinite[k] == CONTROLLER_NONFINITE
            else "simulation state became non-finite"
        )
        return Failure(k, FailureReason.NAN, f"{what} at t={log.t[k]:.3f} s")


class QPSolutionCheck(Check):
    """The IK found no solution (the commanded joints then stand still)."""

    def __init__(self, ctx: CheckContext) -> None:
        self.dt = ctx.dt

    def first_failure(self, log: TickLog, k0: int, k1: int) -> Failure | None:
        k = first_tick(log.ik_status[k0:k1] == _NO_SOLUTION, k0)
        if k is None:
            return None
        return Failure(
            k, FailureReason.IK_FAILED, f"the QP found no solution at t={log.t[k]:.3f} s"
        )


class TrackingCheck(Check):
    """The commanded tool fell more than ``criteria.tracking_limit`` behind the plan."""

    def __init__(self, ctx: CheckContext) -> None:
        self.dt = ctx.dt
        self.limit = ctx.criteria.tracking_limit

    def first_failure(self, log: TickLog, k0: int, k1: int) -> Failure | None:
        k = first_tick(log.command_error[k0:k1] > self.limit, k0)
        if k is None:
            return None
        status = IK_STATUSES[int(log.ik_status[k])]
        text = (
            f"commanded tool is {log.command_error[k] * 1000:.1f} mm from the plan at "
            f"t={log.t[k]:.3f} s (limit {self.limit * 1000:.0f} mm; status {status})"
        )
        return Failure(k, FailureReason.IK_FAILED, text)


class SpeedLimitCheck(Check):
    """A commanded joint speed exceeded its limit (beyond the QP's solver tolerance)."""

    def __init__(self, ctx: CheckContext) -> None:
        self.dt = ctx.dt
        self.v_max = ctx.scene.robot.v_max
        self.names = ctx.scene.robot.arm_joint_names
        self.threshold = 1.0 + ctx.criteria.speed_ratio_tolerance

    def first_failure(self, log: TickLog, k0: int, k1: int) -> Failure | None:
        k = first_tick(log.speed_ratio[k0:k1] > self.threshold, k0)
        if k is None:
            return None
        qdot = log.qdot_cmd[k]
        j = int(np.argmax(np.abs(qdot) / self.v_max))
        text = (
            f"{self.names[j]} commanded at {abs(qdot[j]):.2f} rad/s, limit {self.v_max[j]:.2f} "
            f"rad/s ({log.speed_ratio[k]:.4f}x) at t={log.t[k]:.3f} s"
        )
        return Failure(k, FailureReason.LIMIT_VIOLATED, text)


class PositionLimitCheck(Check):
    """A joint (measured or commanded) went past its range by more than the tolerance."""

    def __init__(self, ctx: CheckContext) -> None:
        self.dt = ctx.dt
        self.tolerance = ctx.criteria.position_limit_tolerance

    def first_failure(self, log: TickLog, k0: int, k1: int) -> Failure | None:
        k = first_tick(log.limit_violation[k0:k1] > self.tolerance, k0)
        if k is None:
            return None
        text = (
            f"a joint is {log.limit_violation[k]:.4f} rad past its range at t={log.t[k]:.3f} s "
            f"(tolerance {self.tolerance:.4f} rad)"
        )
        return Failure(k, FailureReason.LIMIT_VIOLATED, text)


class CollisionCheck(Check):
    """A robot geom (arm link, palm, finger) touched the world (a bin, the floor, an obstacle).

    The pads on the brick are the only contacts a plan intends, and the brick is not part of
    the world: any robot-world contact counts, at the tick it starts, named by its two geoms
    (the deepest pair, found again from the logged state) and its force.
    """

    def __init__(self, ctx: CheckContext) -> None:
        self.ctx = ctx
        self.data = mujoco.MjData(ctx.scene.model)

    def first_failure(self, log: TickLog, k0: int, k1: int) -> Failure | None:
        k = first_tick(log.robot_world_contacts[k0:k1] > 0, k0)
        if k is None:
            return None
        scene = self.ctx.scene
        pair = "a robot geom touched the world"
        for contact in scene.robot_world_contacts(scene.model, log.restore(k, self.data)):
            pair = f"{scene.geom_name(contact.geom)} touched {scene.geom_name(contact.other)}"
            break
        text = (
            f"{pair} with {log.robot_world_force[k]:.1f} N at t={log.t[k]:.3f} s (no "
            "robot–world contact is allowed)"
        )
        return Failure(k, FailureReason.COLLISION, text)


def _newtons(value: float, limit: float) -> str:
    """A force with the digits its limit needs: 0.3 N is not rounded to 0."""
    digits = 1 if limit >= 1.0 else 2
    return f"{value:.{digits}f}"


def missed_grasp_text(
    gap: float, min_gap: float, brick_width: float, forces: np.ndarray, firm_force: float
) -> str:
    """What a closed grip measured against what a grasp needs, naming what fell short.

    Args:
        gap: Finger gap after closing [m].
        min_gap: Smallest gap of a grasp (a fraction of the brick's width) [m].
        brick_width: The brick's width across the fingers [m].
        forces: Normal force of each pad side on the brick [N].
        firm_force: Force each side must exceed [N].
    """
    short = []
    if gap < min_gap:
        short.append("the fingers closed past the brick")
    if not (forces > firm_force).all():
        short.append("a pad does not press firmly")
    f = " / ".join(_newtons(float(v), firm_force) for v in forces)
    return (
        f"{' and '.join(short) or 'the grip did not close on the brick'}: finger gap "
        f"{gap * 1000:.1f} mm (need >= {min_gap * 1000:.1f} mm, "
        f"{100 * min_gap / brick_width:.0f} % of the {brick_width * 1000:.0f} mm brick), pad "
        f"forces {f} N (need > "
        f"{_newtons(firm_force, firm_force)} N each)"
    )


class GraspState(enum.Enum):
    """Where the brick is with respect to the gripper."""

    OPEN = "open"  # not grasped yet
    HOLDING = "holding"  # gripped since the grip closed
    RELEASED = "released"  # let go (placed, dropped or never grasped)


class GraspMonitor(Check):
    """The grasp state machine over the plan's phases: missed grasps and drops.

    OPEN → HOLDING when the grip closes (``phases.grip_closed``) with both pads pressing firmly
    on a brick of the right width (else missed-grasp); HOLDING → RELEASED at
    ``phases.release``, or dropped if, before ``phases.place_reached``, the brick slips
    ``drop_slip`` in the gripper frame or loses all pad contact for ``drop_contact_loss``.
    While holding it fills the log's ``slip`` (up to the place) and ``holding_torque``.

    The phases are on the plan's clock, which starts at ``ctx.t_start`` of the run. A plan
    without phases carries nothing (e.g. the stop between two attempts of a run, see
    :mod:`pickplace.sim.recovery`): the monitor then starts released and judges nothing.
    """

    def __init__(self, ctx: CheckContext) -> None:
        self.ctx = ctx
        self.phases = ctx.plan.phases
        self.state = GraspState.OPEN if self.phases is not None else GraspState.RELEASED
        self.p_GO_grasp: np.ndarray | None = None
        self.contact_lost_since: float | None = None
        self.brick_width = grasp_width(ctx.plan, ctx.scene)
        self.firm_force = ctx.criteria.grasp_force_fraction * ctx.scene.robot.squeeze_force

    def first_failure(self, log: TickLog, k0: int, k1: int) -> Failure | None:
        holding = np.zeros(k1 - k0, dtype=bool)
        failure = self._run(log, k0, k1, holding) if self.phases is not None else None
        log.set_holding(k0, k1, holding, self.ctx.scene.brick_mass)
        return failure

    def _run(self, log: TickLog, k0: int, k1: int, holding: np.ndarray) -> Failure | None:
        cr, emit = self.ctx.criteria, self.ctx.emit
        assert self.phases is not None
        t0 = self.ctx.t_start  # the phases in run time, as the log's times
        t_grasp, t_place = t0 + self.phases.grip_closed, t0 + self.phases.place_reached
        t_release = t0 + self.phases.release
        sl = slice(k0, k1)
        # Brick centre in the tool frame, p_GO = R_WGᵀ (p_WO − p_WG), for every tick.
        p_WO = log.body_pos[sl, self.ctx.scene.brick_body_id]
        p_GO_all = np.einsum("nji,nj->ni", log.R_WG[sl], p_WO - log.p_WG[sl])
        forces = log.pad_force[sl]
        touching: np.ndarray = np.any(forces > 0.0, axis=1)
        times: list[float] = log.t[sl].tolist()
        failure: Failure | None = None
        slip: list[float] = []
        if self.state is GraspState.HOLDING and self.p_GO_grasp is not None:
            slip = np.linalg.norm(p_GO_all - self.p_GO_grasp, axis=1).tolist()
        for i, t in enumerate(times):
            k = k0 + i
            if self.state is GraspState.RELEASED:
                break
            if self.state is GraspState.OPEN:
                if t < t_grasp - 1e-9:
                    continue
                gap = float(log.gripper_gap[k])
                f = forces[i]
                emit(
                    EventKind.GRASP,
                    f"grip closed: gap {gap * 1000:.1f} mm, pad forces {f[0]:.1f} / {f[1]:.1f} N",
                    tick=k,
                )
                if (
                    gap < cr.grasp_gap_fraction * self.brick_width
                    or not (f > self.firm_force).all()
                ):
                    text = missed_grasp_text(
                        gap,
                        cr.grasp_gap_fraction * self.brick_width,
                        self.brick_width,
                        f,
                        self.firm_force,
                    )
                    failure = Failure(k, FailureReason.MISSED_GRASP, text)
                    self.state = GraspState.RELEASED
                    break
                self.state = GraspState.HOLDING
                self.p_GO_grasp = p_GO_all[i].copy()
                slip = np.linalg.norm(p_GO_all - self.p_GO_grasp, axis=1).tolist()
                continue
            # HOLDING
            holding[i] = True
            s = slip[i]
            if t <= t_place + 1e-9:
                log.slip[k] = s
            if touching[i]:
                self.contact_lost_since = None
            elif self.contact_lost_since is None:
                self.contact_lost_since = t
            lost = (
                self.contact_lost_since is not None
                and t - self.contact_lost_since >= cr.drop_contact_loss - 1e-9
            )
            if t < t_place - 1e-9 and (s > cr.drop_slip or lost):
                why = (
                    f"it moved {s * 1000:.0f} mm in the gripper frame since the grasp "
                    f"(limit {cr.drop_slip * 1000:.0f} mm)"
                    if s > cr.drop_slip
                    else f"no pad touched it for {cr.drop_contact_loss:.2f} s (the limit)"
                )
                emit(
                    EventKind.DROP,
                    f"brick left the gripper at t={t:.3f} s: {why}",
                    level="error",
                    tick=k,
                )
                if failure is None:
                    failure = Failure(
                        k, FailureReason.DROPPED, f"brick left the gripper at t={t:.3f} s: {why}"
                    )
                self.state = GraspState.RELEASED
            elif t >= t_release - 1e-9:
                self.state = GraspState.RELEASED
                gap = float(log.gripper_gap[k])
                emit(EventKind.RELEASE, f"gripper opened: gap {gap * 1000:.1f} mm", tick=k)
        return failure


# The checks of each goal, in order of precedence within a tick (see pickplace.sim.goals).
PLACE_CHECKS: tuple[type[Check], ...] = (
    NonFiniteCheck,
    QPSolutionCheck,
    TrackingCheck,
    SpeedLimitCheck,
    PositionLimitCheck,
    CollisionCheck,
    GraspMonitor,
)
REACH_CHECKS: tuple[type[Check], ...] = (
    NonFiniteCheck,
    QPSolutionCheck,
    SpeedLimitCheck,
    PositionLimitCheck,
    CollisionCheck,
)
