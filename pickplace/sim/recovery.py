"""Trying again after a missed grasp or a drop: stop the arm, wait for the brick, plan anew.

:class:`Reattempt` is a task's :class:`~pickplace.sim.task.Recovery`. The loop asks it about the
failures of every assessed block; it takes up those in :data:`RECOVERABLE` while attempts are
left, and then:

1. **stops the arm** without a velocity step: from the last commanded tick on, the plan being
   executed is replaced by a :class:`StopTrajectory`, the same plan slowed down along its own
   (pre-flighted) path, its speed falling smoothly to zero (``1 - 3u² + 2u³`` of the planned
   speed over the stop time, u = t / T), while the gripper opens as wide as the plan ever
   does (so that a brick caught between the fingers falls free);
2. **backs off** straight up (:attr:`RecoveryConfig.rise`, at rest at both ends) and **waits
   for the brick** to be at rest and free of the robot (checked after every block of the
   loop, at most :attr:`RecoveryConfig.max_wait` after the arm has come to rest);
3. **plans again** with the task's planner from the brick's pose as the simulation has it and
   from where the arm stopped (its commanded configuration and the stop's tool pose), and puts
   the new plan in place from the next tick: the next attempt, judged by a new set of the
   goal's checks.

A failure it does not take up ends the run as it would without it, with the same reason and
text; so does a failure after the last attempt. When the brick does not come to rest in time,
or it rests tilted, not flat on a face, or no plan is feasible from where it lies, the run
ends with the
failure that was taken up, at its tick, its text saying why it could not be recovered.
A box resting upside down, or on a side as tall as its height, is the same box with its frame
turned (:func:`~pickplace.geometry.box_resting_frame`), planned for that frame; one standing
on a face of another size (a brick on its end) is planned as the box lying with a turned
frame's z up (:func:`~pickplace.geometry.upright_turn`, the planner's ``turn``) and placed
standing so (:func:`standing_goal`).

Which failures are recoverable (:data:`RECOVERABLE`): ``missed-grasp`` and ``dropped``, where
the brick lies somewhere in the world the arm left intact; and an ``ik-failed`` that the
controller's collision limit caused (:func:`limit_held`: the tool fell behind the plan at a
tick whose step met a row of the limit, as the controller reports per tick into the log's
``collision_held``), where the plan runs into a world that changed after planning. Not
``collision`` (the robot hit the world: a real cell stops), any other ``ik-failed`` and
``limit-violated`` (the controller cannot follow plans from here: a new plan from the same
state would fail again), ``nan`` (the state is lost), ``not-in-target-bin`` (the end-state
verdict, judged when the run is over) nor ``interrupted``.

A limit-held ``ik-failed`` is taken up differently: the arm stops along its own commanded
joint motion (:class:`CommandedDrift`, over :attr:`RecoveryConfig.held_stop_time`), not the
plan's path, with the gripper as it is and no rise; every replan first hands the planner the
simulation's mocap poses (the obstacle where it is now); and while the brick is still in the
hand the next attempt carries it on from there
(:meth:`~pickplace.planning.planner.PickPlacePlanner.plan_held`: to the pre-place, in
C-space around what blocks, then the place), instead of waiting for it to rest.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from mink.lie import SE3, SO3

from pickplace.control.kinematics import ArmKinematics
from pickplace.errors import InvalidInputError, ObjectError, PlanError, require_positive
from pickplace.geometry import FloatArray, box_resting_frame, turned_half_extents, upright_turn
from pickplace.planning.plan import Plan
from pickplace.planning.planner import PickPlacePlanner, PlanningReport, Start
from pickplace.planning.push import PushTrajectory
from pickplace.planning.trajectory import Keyframe, PoseTrajectory, profile_by_name
from pickplace.sim.checks import Failure, FailureReason
from pickplace.sim.task import RunControl
from pickplace.sim.verdict import (
    Attempt,
    brick_at_rest,
    brick_pose,
    brick_touches_robot,
    lying_tilt,
)
from pickplace.world.placements import footprint_inside


def standing_goal(X_WO_goal: SE3, half_extents: FloatArray, turn: FloatArray) -> SE3:
    """The goal of a box resting on another face: where ``X_WO_goal`` (the box lying with its
    frame's z up, on a floor) puts the turned frame ``O' = O · turn``, raised or lowered so
    that the box, sizes ``|turn|ᵀ h`` along O''s axes, rests on the same floor; in O.

    Args:
        X_WO_goal: The goal of the box lying, z up.
        half_extents: Its half sizes h along O's axes [m].
        turn: The turn of O that the box rests with the z of ``O · turn`` up (3, 3).
    """
    R = np.asarray(turn, dtype=np.float64)
    rise = float(turned_half_extents(half_extents, R)[2] - half_extents[2])
    X_WOp = SE3.from_rotation_and_translation(
        X_WO_goal.rotation(), X_WO_goal.translation() + np.array([0.0, 0.0, rise])
    )
    return X_WOp @ SE3.from_rotation(SO3.from_matrix(R).inverse())


RECOVERABLE: frozenset[FailureReason] = frozenset(
    {FailureReason.MISSED_GRASP, FailureReason.DROPPED}
)
"""The failures a run may try again after (see the module docstring)."""

_SINE = profile_by_name("sine")

PLACE_SHIFTS: tuple[float, ...] = (0.02, 0.04, 0.06, 0.08)
"""How far a held replan may move the brick's goal away from what blocks its place [m], in
the order tried (:meth:`Reattempt._held_elsewhere`)."""

MAX_PUSHES = 2
"""The most pushes one attempt makes before its pick (:meth:`Reattempt._after_push`): a
second where the first left the object where no grasp fits after all."""

MAX_ATTEMPTS = 10
"""The most attempts a run may take (``--attempts``)."""


@dataclass(frozen=True)
class RecoveryConfig:
    """How a run stops and waits between attempts.

    Attributes:
        accel_fraction: Fraction of each joint's acceleration limit the stop's own
            deceleration may take [-]: the stop lasts ``1.5 |q̇ᵢ| / (fraction · q̈ᵢ,max)`` for
            the fastest-braking joint i (1.5 is the peak of the speed profile's slope), and
            the rest is left to the plan's own acceleration, which the slow-down scales by the
            square of the falling speed.
        held_stop_time: Duration of a stop where the collision limit holds the arm against
            the world [s]: the commanded arm brakes along its own joint motion
            (:class:`CommandedDrift`), which the limit may block, the commanded tool then
            falling behind the stop; over the acceleration limits' stop time (0.3–0.6 s for
            the bundled robots in ``fault-obstacle``) the menagerie iiwa's fell 20 mm behind,
            so this stop brakes over a fixed short time (peak deceleration 1.5 q̇ / this,
            beyond ``accel_limits`` for a fast arm).
        min_stop_time: Shortest stop [s] (the gripper opens over it).
        rise: Height the tool backs off straight up after stopping [m], at most (never above
            the planner's transfer clearance height).
        rise_speed: Peak speed of that rise [m/s].
        rise_accel: Peak acceleration of that rise [m/s²].
        max_wait: Longest wait after the arm has stopped for the brick to come to rest and be
            free of the robot [s].
        rest_window: The brick must have moved less than ``rest_speed`` times this over the
            last this many seconds, besides being at rest at the end (a bounce's top is
            momentarily at rest) [s].
        default_accel_time: For a robot without ``accel_limits``: the time in which a joint
            reaches its speed limit, as the planner's timing assumes [s].
    """

    accel_fraction: float = 0.5
    held_stop_time: float = 0.15
    min_stop_time: float = 0.15
    rise: float = 0.10
    rise_speed: float = 0.25
    rise_accel: float = 0.5
    max_wait: float = 3.0
    rest_window: float = 0.1
    default_accel_time: float = 0.25

    def __post_init__(self) -> None:
        """Validate every field (finite and > 0; ``accel_fraction`` at most 1)."""
        for name in (
            "accel_fraction",
            "held_stop_time",
            "min_stop_time",
            "rise",
            "rise_speed",
            "rise_accel",
            "max_wait",
            "rest_window",
            "default_accel_time",
        ):
            require_positive(f"recovery {name}", getattr(self, name))
        if self.accel_fraction > 1.0:
            raise InvalidInputError(
                f"recovery accel_fraction must be in (0, 1], got {self.accel_fraction!r}"
            )


def check_attempts(attempts: object) -> int:
    """``attempts`` as the number of attempts a run may take.

    Raises:
        InvalidInputError: Not an integer in [1, :data:`MAX_ATTEMPTS`] (field ``attempts``).
    """
    if (
        isinstance(attempts, bool)
        or not isinstance(attempts, int)
        or not 1 <= attempts <= MAX_ATTEMPTS
    ):
        raise InvalidInputError(
            f"attempts must be an integer in [1, {MAX_ATTEMPTS}], got {attempts!r}",
            field="attempts",
        )
    return attempts


class StopTrajectory(PoseTrajectory):
    """A plan's trajectory from time ``t0`` on, slowed down to rest along its own path, then
    backed off straight up with the gripper open, then held.

    With u = t / T over the stop time T, the tool is where the plan is at ``t0 + s(t)``,
    s = T (u − u³ + u⁴ / 2), and moves at the plan's velocity there times
    ṡ = 1 − 3u² + 2u³: the full planned velocity at t = 0 (no step), zero at T, the slow-down
    smooth (s̈ = 0 at both ends, at most 1.5 / T). The gripper's command ramps linearly from
    ``width0`` to ``width_open`` over the stop. Then the tool rises ``rise`` along world z
    under a sine profile (at rest at both ends; straight up is how the plan leaves the pick),
    so that the fingers leave a brick that leans on them, and holds there.

    Its keyframes (``stop`` at 0, ``stopped`` at T, ``backed-off`` after the rise, ``hold``
    ``hold`` later) are the poses at those times; between the first two the path is the
    plan's, not a straight line, so it is a trajectory to execute, not one to time again.

    Args:
        path: The plan's trajectory.
        t0: Plan time of the stop's start [s].
        stop_time: T [s].
        rise: Height the tool backs off after stopping [m] (≥ 0).
        rise_time: Duration of the rise [s].
        hold: How long the backed-off pose is held [s].
        width0: Gripper command at the start [m].
        width_open: Gripper command from T on [m].
    """

    def __init__(
        self,
        path: PoseTrajectory,
        t0: float,
        stop_time: float,
        rise: float,
        rise_time: float,
        hold: float,
        width0: float,
        width_open: float,
    ) -> None:
        require_positive("stop time [s]", stop_time)
        require_positive("rise time [s]", rise_time)
        require_positive("hold [s]", hold)
        self.path = path
        self.t0 = float(t0)
        self.stop_time = float(stop_time)
        self.rise = float(rise)
        self.rise_time = float(rise_time)
        self.width0 = float(width0)
        self.width_open = float(width_open)
        x_start = path.sample(self.t0)[0]
        self.x_stopped = path.sample(self.t0 + 0.5 * self.stop_time)[0]
        self.x_backed_off = self.x_stopped.copy()
        self.x_backed_off[6] += self.rise
        T = self.stop_time
        self.rest_time = T + self.rise_time  # from here on the tool is at rest
        X_stopped, X_rest = SE3(wxyz_xyz=self.x_stopped), SE3(wxyz_xyz=self.x_backed_off)
        w = self.width_open
        super().__init__(
            [
                Keyframe("stop", 0.0, SE3(wxyz_xyz=x_start), self.width0),
                Keyframe("stopped", T, X_stopped, w),
                Keyframe("backed-off", self.rest_time, X_rest, w),
                Keyframe("hold", self.rest_time + hold, X_rest, w),
            ],
            "linear",
        )

    @property
    def X_WG_rest(self) -> SE3:
        """The tool pose the arm comes to rest at (backed off)."""
        return SE3(wxyz_xyz=self.x_backed_off.copy())

    def sample(self, t: float) -> tuple[FloatArray, FloatArray, float]:
        """Pose, spatial velocity [m/s, rad/s] and gripper width [m] at stop time ``t`` [s]
        (see the class docstring)."""
        T = self.stop_time
        if t >= self.rest_time:
            return self.x_backed_off.copy(), np.zeros(6), self.width_open
        if t >= T:
            tau = (t - T) / self.rise_time
            x = self.x_stopped.copy()
            x[6] += self.rise * _SINE.s(tau)
            V = np.zeros(6)
            V[2] = self.rise * _SINE.ds(tau) / self.rise_time
            return x, V, self.width_open
        u = max(t, 0.0) / T
        s = T * (u - u**3 + 0.5 * u**4)
        s_dot = 1.0 - 3.0 * u * u + 2.0 * u**3
        x, V, _ = self.path.sample(self.t0 + s)
        return x, V * s_dot, self.width0 + u * (self.width_open - self.width0)


def limit_held(run: RunControl, failure: Failure) -> bool:
    """Whether ``failure`` is an ``ik-failed`` that the controller's collision limit caused:
    the tool fell behind the plan (not a QP without solution) at a tick whose step met a row
    of the limit (:attr:`~pickplace.control.controllers.DiffIKController.collision_held`,
    logged per tick), i.e. the limit, not the arm's reach or its speed limits, held the tool
    back from a plan that runs into the world."""
    return (
        failure.reason is FailureReason.IK_FAILED
        and 0 <= failure.tick < run.ticks
        and bool(run.log.collision_held[failure.tick])
        and float(run.log.command_error[failure.tick]) > run.criteria.tracking_limit
    )


class CommandedDrift(PoseTrajectory):
    """The commanded arm's motion continued from one tick: its joints moving on at that tick's
    commanded joint velocities, the tool where the forward kinematics puts it, the gripper at
    one width. A :class:`StopTrajectory` along it slows the commanded arm down from where the
    IK had it, not from where the plan was (a plan the collision limit held the tool back
    from runs into the world). Continued in joint space, the motion keeps a distance the limit
    held constant (its gradient times q̇ was zero) constant to first order; a twist continued
    in Cartesian space would turn the links into the world.

    Args:
        kinematics: Arm kinematics (changed by :meth:`sample`).
        q: The commanded joint positions at the tick [rad].
        qdot: The tick's commanded joint velocities [rad/s].
        width: Gripper command [m].
    """

    def __init__(
        self, kinematics: ArmKinematics, q: FloatArray, qdot: FloatArray, width: float
    ) -> None:
        self.kinematics = kinematics
        self.q0 = np.asarray(q, dtype=np.float64).copy()
        self.qdot0 = np.asarray(qdot, dtype=np.float64).copy()
        self.width = float(width)
        kinematics.update(self.q0)
        X0 = kinematics.X_WG()
        super().__init__(
            [Keyframe("commanded", 0.0, X0, self.width), Keyframe("on", 1.0, X0, self.width)],
            "linear",
        )

    def sample(self, t: float) -> tuple[FloatArray, FloatArray, float]:
        """Tool pose (wxyz_xyz) at ``q + q̇ t`` (``t`` [s]), its spatial velocity ``J q̇``
        [m/s, rad/s] there, and the width [m]."""
        kin = self.kinematics
        kin.update(self.q0 + self.qdot0 * t)
        x = np.array(kin.wxyz_xyz_list())
        return x, kin.J_WG().dot(self.qdot0), self.width


def stop_time(run: RunControl, config: RecoveryConfig) -> float:
    """How long the arm takes to stop from its last commanded joint speeds [s] (see
    :attr:`RecoveryConfig.accel_fraction`)."""
    robot = run.scene.robot
    a_max = robot.a_max if robot.a_max is not None else robot.v_max / config.default_accel_time
    qdot = np.abs(run.log.qdot_cmd[run.ticks - 1])
    needed = 1.5 * float(np.max(qdot / (config.accel_fraction * np.asarray(a_max))))
    return max(config.min_stop_time, needed)


class Reattempt:
    """The recovery of a pick-and-place task: up to ``attempts`` attempts (module docstring).

    Args:
        planner: The task's planner (it made the first plan).
        X_WO_goal: Goal pose of the brick in world.
        attempts: Most attempts the run may take (1: every failure ends the run, as without a
            recovery).
        first_candidate: Label of the first plan's candidate (None: made without the planner).
        config: How the arm stops and how long the brick is waited for.

    Raises:
        InvalidInputError: ``attempts`` is not an integer in [1, :data:`MAX_ATTEMPTS`].
    """

    def __init__(
        self,
        planner: PickPlacePlanner,
        X_WO_goal: SE3,
        attempts: int,
        first_candidate: str | None,
        config: RecoveryConfig | None = None,
    ) -> None:
        self.planner = planner
        self.X_WO_goal = X_WO_goal
        self.max_attempts = check_attempts(attempts)
        self.config = config or RecoveryConfig()
        self._attempts: list[Attempt] = [Attempt(1, 0, 0.0, first_candidate)]
        self._pushes = 0  # pushes finished in the current attempt
        self._stop: StopTrajectory | None = None  # while stopping and waiting
        self._taken: Failure | None = None  # the failure taken up, while stopping

    def attempts(self) -> list[Attempt]:
        """The attempts so far (the last one is running, or ended the run)."""
        return list(self._attempts)

    def take_up(self, run: RunControl, failures: Sequence[Failure]) -> bool:
        """Take the block's failures up if all are recoverable, the arm is executing an
        attempt (not stopping after one) and attempts are left: stop the arm (module
        docstring) and return True."""
        if (
            self._stop is not None
            or isinstance(run.plan.trajectory, PushTrajectory)  # nothing to try again from
            or len(self._attempts) >= self.max_attempts
            or not failures
            or run.ticks < 1
            or not all(f.reason in RECOVERABLE or limit_held(run, f) for f in failures)
        ):
            return False
        failure = failures[0]
        k = run.ticks - 1  # the last commanded tick: the stop starts from its plan sample
        dt = run.dt
        t_stop = stop_time(run, self.config)
        plan = run.plan
        width0 = float(run.log.gripper_cmd[k])
        t0 = k * dt - run.plan_start
        cfg = self.config
        if failure.reason in RECOVERABLE:
            width_open = max(width0, *(kf.gripper_width for kf in plan.trajectory.keyframes))
            path: PoseTrajectory = plan.trajectory
            z_stopped = float(path.sample(t0 + 0.5 * t_stop)[0][6])
            rise = min(cfg.rise, max(0.0, self.planner.clearance_z - z_stopped))
            how = (
                f"the arm stops along its path over {t_stop:.2f} s, the gripper opening, backs "
                f"off {rise * 1000:.0f} mm up and waits for the brick to rest"
            )
        else:  # held back by the collision limit: stop where the IK has the tool, holding on
            # From the configuration the tick's command started at (its tool pose is the
            # tick's commanded one), on at its joint velocities.
            q_k = run.log.q_cmd[k] - run.log.qdot_cmd[k] * dt
            drift = CommandedDrift(ArmKinematics(run.scene), q_k, run.log.qdot_cmd[k], width0)
            t_stop = cfg.held_stop_time
            path, t0, width_open, rise = drift, 0.0, width0, 0.0
            how = (
                f"the arm stops where the collision limit holds it over {t_stop:.2f} s, the "
                "gripper as it is, and plans around the world as it is now"
            )
        rise_time = max(cfg.min_stop_time, _SINE.min_duration(rise, cfg.rise_speed, cfg.rise_accel))
        stop = StopTrajectory(path, t0, t_stop, rise, rise_time, cfg.max_wait, width0, width_open)
        current = self._attempts[-1]
        text = f"{failure.reason.value}: {failure.text}"
        try:
            run.replace_plan(
                Plan(stop),
                k * dt,
                f"attempt {current.number} of {self.max_attempts} failed at t="
                f"{(failure.tick + 1) * dt:.2f} s ({text}); {how}",
            )
        except InvalidInputError:  # the run's log would pass its memory bound
            return False
        self._attempts[-1] = replace(
            current,
            failure=failure.reason,
            failure_tick=failure.tick,
            failure_time_s=(failure.tick + 1) * dt,
            failure_text=text,
            stop_tick=run.ticks,
        )
        self._stop, self._taken = stop, failure
        return True

    def next_decision_time(self, run: RunControl) -> float | None:
        """While attempts are left: the run time at which the attempt's grasp is judged (the
        plan's ``grip_closed``), if it lies ahead; the stop then starts while the arm still
        rests at the pick, before the lift drags a brick the fingers caught by an edge."""
        phases = run.plan.phases
        if self._stop is not None or len(self._attempts) >= self.max_attempts or phases is None:
            return None
        t = run.plan_start + phases.grip_closed
        return t if t > run.ticks * run.dt else None

    def after_block(self, run: RunControl) -> Failure | None:
        """While stopped: once the arm has stopped and the brick rests free of the robot,
        plan the next attempt from there and put it in place; give up (the failure taken up,
        with why) when the brick does not rest in time or no plan is feasible."""
        stop, taken = self._stop, self._taken
        if stop is None and isinstance(run.plan.trajectory, PushTrajectory):
            return self._after_push(run, run.plan.trajectory)
        if stop is None or taken is None:
            return None
        t_plan = run.ticks * run.dt - run.plan_start
        if t_plan < stop.rest_time:
            return None
        # The planner sees the world as the simulation has it (an obstacle that moved).
        self.planner.observe_world(run.data.mocap_pos, run.data.mocap_quat)
        if taken.reason not in RECOVERABLE and brick_touches_robot(run.scene, run.data):
            return self._replan_held(run, stop, taken)
        ready, why = self._brick_ready(run)
        if not ready:
            if t_plan >= stop.rest_time + self.config.max_wait:
                return self._give_up(
                    taken, f"{why} {self.config.max_wait:g} s after the arm stopped"
                )
            return None
        start = Start(run.q_cmd.copy(), stop.X_WG_rest)
        planned = self._plan_where_it_rests(run, start)
        if isinstance(planned, str):
            return self._give_up(taken, planned)
        report, X_WO, standing = planned
        p = X_WO.translation()
        if not report.feasible:
            return self._give_up(
                taken,
                f"no new plan picks it where it lies at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) "
                f"m: {report.refusal()}",
            )
        assert report.chosen is not None
        return self._put_in_place(
            run,
            report,
            taken,
            f"plan '{{label}}' (candidate {report.chosen + 1} of {len(report.candidates)}) "
            f"picks the brick where it rests, at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m"
            f"{standing}",
        )

    def _plan_where_it_rests(
        self, run: RunControl, start: Start, push: bool | None = None
    ) -> tuple[PlanningReport, SE3, str] | str:
        """Plan the pick of the brick resting where the simulation has it, from ``start``
        (``push``: the planner's, see :meth:`PickPlacePlanner.plan`): the report, the pose
        planned and, for a brick standing on its end, words saying so; or why it cannot be
        planned (it rests tilted, or standing where no grasp fits), words that end a
        sentence."""
        X_WO_lying = brick_pose(run.scene, run.data)
        tilt = lying_tilt(run.scene, X_WO_lying)
        if tilt > run.criteria.max_tilt:
            return (
                f"the brick came to rest tilted {math.degrees(tilt):.0f} deg from lying flat "
                f"(at most {math.degrees(run.criteria.max_tilt):.0f} deg)"
            )
        # Upside down or on a side of the same size, the brick is the same box with its frame
        # turned: the planner plans for that frame. On a face of another size (on its end) it
        # is planned as the box lying with a turned frame's z up, and placed standing so.
        box = run.scene.object.box_half_extents
        X_WO = X_WO_lying if box is None else box_resting_frame(X_WO_lying, box)
        turn, X_WO_goal, standing = None, self.X_WO_goal, ""
        if X_WO is None:
            assert box is not None  # only a box has no resting frame
            X_WO = X_WO_lying
            turn = upright_turn(X_WO.rotation())
            X_WO_goal = standing_goal(self.X_WO_goal, box, turn)
            tall = 2000.0 * float(np.abs(X_WO.rotation().as_matrix()[2, :]) @ box)
            standing = f", standing {tall:.0f} mm tall (placed so)"
        try:
            report = self.planner.plan(X_WO, X_WO_goal, start=start, turn=turn, push=push)
        except (ObjectError, PlanError) as exc:  # the box standing: no grasp of it fits
            return f"it rests standing: {exc}"
        return report, X_WO, standing

    def _after_push(self, run: RunControl, push: PushTrajectory) -> Failure | None:
        """After a push (:mod:`pickplace.planning.push`): once the tool has backed away and
        the object rests free of the robot, plan its pick from where it lies (or, while the
        attempt has made fewer than :data:`MAX_PUSHES`, another push where no grasp is
        feasible) and put that plan in place, the same attempt going on, as
        :meth:`after_block` plans after a miss (a box on its end planned standing);
        ``no-feasible-plan``, saying why, when the object does not come to rest in time, rests
        tilted, or no grasp of it is feasible where it came to rest."""
        t_plan = run.ticks * run.dt - run.plan_start
        if t_plan < push.push_end_time:
            return None
        label = push.push.label
        tick = run.ticks - 1
        ready, why = self._brick_ready(run)
        if not ready:
            # Within the push's own hold (half of it: the loop ends a plan whose brick rests).
            wait = min(self.config.max_wait, 0.5 * (push.end_time - push.push_end_time))
            if t_plan >= push.push_end_time + wait:
                return Failure(
                    tick,
                    FailureReason.NO_FEASIBLE_PLAN,
                    f"after the push ({label}) {why} {wait:g} s after the arm backed away",
                )
            return None
        start = Start(run.q_cmd.copy(), push.keyframes[-1].X_WG)
        self._pushes += 1
        self._attempts[-1] = replace(self._attempts[-1], pushes=self._pushes)
        planned = self._plan_where_it_rests(run, start, push=self._pushes < MAX_PUSHES)
        if isinstance(planned, str):
            return Failure(
                tick, FailureReason.NO_FEASIBLE_PLAN, f"after the push ({label}) {planned}"
            )
        report, X_WO, standing = planned
        p = X_WO.translation()
        where = f"({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m{standing}"
        if not report.feasible:
            return Failure(
                tick,
                FailureReason.NO_FEASIBLE_PLAN,
                f"after the push ({label}) no plan picks the object where it came to rest, at "
                f"{where}: {report.refusal()}",
            )
        assert report.chosen is not None
        chosen = report.candidates[report.chosen]
        current = self._attempts[-1]
        what = (
            "pushes it on from where it came to rest"
            if isinstance(report.plan.trajectory, PushTrajectory)
            else "picks the object where it came to rest"
        )
        try:
            run.replace_plan(
                report.plan,
                run.ticks * run.dt,
                f"after the push ({label}) plan '{chosen.label}' (candidate "
                f"{report.chosen + 1} of {len(report.candidates)}) {what}, at {where}",
            )
        except InvalidInputError as exc:  # the run's log would pass its memory bound
            return Failure(tick, FailureReason.NO_FEASIBLE_PLAN, str(exc))
        self._attempts[-1] = replace(current, candidate=f"{current.candidate}, then {chosen.label}")
        return None

    def _put_in_place(
        self, run: RunControl, report: PlanningReport, taken: Failure, what: str
    ) -> Failure | None:
        """Replace the run's plan by ``report``'s chosen one from the next tick, as the next
        attempt (its event text: ``what``, with ``{label}`` the candidate's label); give up
        when the run's log would pass its memory bound."""
        assert report.chosen is not None
        chosen = report.candidates[report.chosen]
        number = len(self._attempts) + 1
        try:
            run.replace_plan(
                report.plan,
                run.ticks * run.dt,
                f"attempt {number} of {self.max_attempts}: " + what.format(label=chosen.label),
            )
        except InvalidInputError as exc:  # the run's log would pass its memory bound
            return self._give_up(taken, str(exc))
        self._attempts.append(Attempt(number, run.ticks, run.ticks * run.dt, chosen.label))
        self._stop = self._taken = None
        self._pushes = 0
        return None

    def _replan_held(self, run: RunControl, stop: StopTrajectory, taken: Failure) -> Failure | None:
        """Plan the rest of the task with the brick in the hand, from where the arm stopped
        (:meth:`~pickplace.planning.planner.PickPlacePlanner.plan_held`), and put it in place;
        give up when no plan is feasible."""
        X_WO = brick_pose(run.scene, run.data)
        k = run.ticks - 1
        X_WG_sim = SE3.from_rotation_and_translation(
            SO3.from_matrix(run.log.R_WG[k]), run.log.p_WG[k].copy()
        )
        X_OG = X_WO.inverse() @ X_WG_sim  # the grasp as the hand holds the brick now
        start = Start(run.q_cmd.copy(), stop.X_WG_rest)
        report = self.planner.plan_held(start, X_WO, self.X_WO_goal, X_OG)
        moved = ""
        if not report.feasible:
            shifted = self._held_elsewhere(run, start, X_WO, X_OG, report)
            if shifted is not None:
                report, shift = shifted
                moved = f", its goal moved {shift * 1000:.0f} mm away from what blocks its place"
        if not report.feasible:
            return self._give_up(
                taken,
                f"no new plan carries the brick on from where the arm stopped: {report.refusal()}",
            )
        how = "around the world as it is now in C-space" if report.used_cspace else "straight on"
        return self._put_in_place(
            run,
            report,
            taken,
            "plan '{label}' carries the brick on from where the arm stopped to the pre-place "
            f"({how}) and places it{moved}",
        )

    def _held_elsewhere(
        self, run: RunControl, start: Start, X_WO: SE3, X_OG: SE3, report: PlanningReport
    ) -> tuple[PlanningReport, float] | None:
        """When the held plan collides after its transfer (placing: the world that changed
        stands beside the goal), the first feasible held plan with the goal moved horizontally
        straight away from the collision's point by one of :data:`PLACE_SHIFTS`, the brick's
        footprint kept inside the target bin's inner walls by the pre-flight's clearance
        (the placement verdict wants it in the bin, not at the goal); with the shift [m]."""
        candidate = report.candidates[0]
        problem, phases = candidate.preflight.problem, candidate.plan.phases
        if (
            problem is None
            or problem.kind != "collision"
            or problem.point_W is None
            or phases is None
            or problem.t <= phases.transport[1]
        ):
            return None
        goal = self.X_WO_goal.translation()
        away = goal - np.asarray(problem.point_W, dtype=np.float64)
        away[2] = 0.0
        norm = float(np.linalg.norm(away))
        if norm < 1e-9:
            return None
        away /= norm
        scene, margin = run.scene, self.planner.preflight.config.clearance
        for shift in PLACE_SHIFTS:
            X_goal = SE3.from_rotation_and_translation(
                self.X_WO_goal.rotation(), goal + shift * away
            )
            if not footprint_inside(scene, X_goal, scene.target_bin, margin):
                return None
            moved = self.planner.plan_held(start, X_WO, X_goal, X_OG)
            if moved.feasible:
                return moved, shift
        return None

    def _brick_ready(self, run: RunControl) -> tuple[bool, str]:
        """Whether the brick rests free of the robot, or why not (its words end a sentence
        that a time completes)."""
        scene, data, cr = run.scene, run.data, run.criteria
        window = max(1, round(self.config.rest_window / run.dt))
        b = scene.brick_body_id
        log = run.log
        first = max(0, run.ticks - 1 - window)
        moved = float(np.linalg.norm(log.body_pos[run.ticks - 1, b] - log.body_pos[first, b]))
        if not brick_at_rest(scene, data, cr) or moved > cr.rest_speed * self.config.rest_window:
            return False, "the brick was still moving"
        if brick_touches_robot(scene, data):
            return False, "the brick still touched the robot"
        return True, ""

    def _give_up(self, taken: Failure, why: str) -> Failure:
        """The failure taken up, ending the run at its tick, its text saying why it was not
        recovered; the attempt it ended is the run's last."""
        self._stop = self._taken = None
        self._attempts[-1] = replace(
            self._attempts[-1],
            failure=None,
            failure_tick=None,
            failure_time_s=None,
            failure_text=None,
            stop_tick=None,
        )
        return Failure(taken.tick, taken.reason, f"{taken.text}; not recovered: {why}")


__all__ = [
    "MAX_ATTEMPTS",
    "MAX_PUSHES",
    "PLACE_SHIFTS",
    "RECOVERABLE",
    "CommandedDrift",
    "Reattempt",
    "RecoveryConfig",
    "StopTrajectory",
    "check_attempts",
    "limit_held",
]
