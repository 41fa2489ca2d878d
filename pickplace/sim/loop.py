"""The headless loop: trajectory → differential IK → position actuators → MuJoCo physics.

Each control tick (``SimConfig.control_rate_hz``, default 100 Hz):

1. read the planned tool pose X_WG(t), its spatial velocity V_WG(t) and the gripper width;
2. the controller turns them into joint velocities at the commanded configuration q_cmd;
3. q_cmd is integrated from those velocities and sent to the arm's position actuators (the
   controller sees the world's mocap poses and the fingers' commanded gap: its collision
   limit keeps the robot clear of the world);
4. MuJoCo steps the physics for one control period at the scene's timestep;
5. the commands, the IK's Jacobian and MuJoCo's state are copied into the tick log
   (:class:`~pickplace.sim.ticklog.TickLog`).

The loop runs in blocks of :data:`ASSESS_PERIOD_S` of simulated time: steps 1–3 for the
block's ticks, then steps 4–5 tick by tick, then the block is assessed. Assessing derives
every diagnostic of every tick in one vectorised pass (the Jacobian's health, the tracking
errors, the grip force, the limits) and runs the checks in tick order, so failures keep their
exact tick. Doing this per block instead of per tick is what lets a run go tens of times
faster than real time; a block of one tick gives the identical run.

The brick is held by contact friction only: nothing here welds, attaches or moves it, except an
explicit fault injected by a scenario (:mod:`pickplace.sim.faults`).

The loop knows nothing of grasps or bins: the task's goal (:mod:`pickplace.sim.goals`) supplies the
checks that judge each block (:mod:`pickplace.sim.checks`) and the verdict on the end state, from
geometry stated in :class:`~pickplace.sim.checks.SuccessCriteria`.

Nor does it know when to try again: a task with a recovery (:class:`~pickplace.sim.task.Recovery`,
e.g. :mod:`pickplace.sim.recovery`) is asked about the failures of each block before they count,
and after each block; it may replace the plan being executed (:meth:`Simulation.replace_plan`),
which is all the loop itself can do about it: from the next tick on it samples the new plan at
``t - t_start``, with a new set of the goal's checks.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol

import mujoco
import numpy as np

from pickplace.control.controllers import IK_STATUSES, DiffIKController, IKStatus
from pickplace.errors import ControllerError, InvalidInputError, require_positive
from pickplace.planning.plan import Plan, grasp_width
from pickplace.planning.planner import PlanningReport
from pickplace.sim.checks import Check, CheckContext, Failure, FailureReason, SuccessCriteria
from pickplace.sim.events import Event, EventKind
from pickplace.sim.task import Task
from pickplace.sim.ticklog import CONTROLLER_NONFINITE, FINITE, STATE_NONFINITE, TickLog
from pickplace.sim.verdict import RunResult, brick_pose, run_metrics
from pickplace.world.scene import Scene


@dataclass(frozen=True)
class SimConfig:
    """Settings of the loop.

    Attributes:
        control_rate_hz: IK and actuator-command rate [Hz]; must divide into whole physics
            steps of the scene's timestep.
        velocity_feedforward: Send q_cmd + (kv/kp)·q̇_cmd to the position actuators, so that
            their damping term tracks the commanded joint velocity instead of braking it.
        dynamics_feedforward: Also add τ/kp, the torque of the commanded motion (inertia,
            Coriolis and centrifugal forces, joint damping and armature: inverse dynamics)
            per actuator gain, so that the actuators drive the arm along instead of lagging by
            τ/kp — 16 mm at the tool for the iiwa at full speed and acceleration. q̈_cmd is
            the change of q̇_cmd over a tick.
        criteria: Success and failure geometry.
    """

    control_rate_hz: float = 100.0
    velocity_feedforward: bool = True
    dynamics_feedforward: bool = True
    criteria: SuccessCriteria = field(default_factory=SuccessCriteria)

    def __post_init__(self) -> None:
        require_positive("control rate [Hz]", self.control_rate_hz)


class TickObserver(Protocol):
    """Receives the run as it goes (the Rerun recorder is one)."""

    def on_start(self, run: Simulation) -> None:
        """The run is set up; nothing has been stepped."""

    def on_ticks(self, run: Simulation, start: int, end: int) -> None:
        """Rows ``[start, end)`` of ``run.log`` are complete, derived quantities included."""

    def on_event(self, run: Simulation, event: Event) -> None:
        """An event happened."""

    def on_finish(self, run: Simulation, result: RunResult) -> None:
        """The run is over (also after an interruption or an error)."""


_STATUS_CODE = {status: IK_STATUSES.index(status.value) for status in IKStatus}
# The same, keyed by the members' ids: hashing an Enum member runs Python code.
_STATUS_CODE_BY_ID = {id(status): code for status, code in _STATUS_CODE.items()}

# Simulated time between two assessments of the log [s] (see :meth:`Simulation.assess`).
ASSESS_PERIOD_S = 0.5


def control_substeps(control_rate_hz: float, timestep: float) -> int:
    """Physics steps per control tick.

    Raises:
        InvalidInputError: The control period is not a whole number (≥ 1) of timesteps; the
            message lists the valid rates, computed from ``timestep`` (field ``control_rate_hz``).
    """
    steps = 1.0 / (control_rate_hz * timestep)
    substeps = round(steps)
    if substeps < 1 or abs(steps - substeps) > 1e-9:
        valid = ", ".join(f"{1.0 / (n * timestep):g}" for n in range(1, 5))
        raise InvalidInputError(
            f"control rate {control_rate_hz:g} Hz is not a whole number of physics steps of "
            f"{timestep:g} s; valid rates are 1 / (n · {timestep:g} s): {valid}, ... Hz",
            field="control_rate_hz",
        )
    return substeps


# The most memory a run's tick log may take [bytes]: about an hour of simulated time at
# 100 Hz for the bundled robots (3 kB a tick), six minutes at 1000 Hz.
MAX_LOG_BYTES = 2**30


def _check_log_size(scene: Scene, ticks: int, dt: float) -> None:
    """Refuse a run whose tick log (:class:`TickLog`, preallocated) would pass
    :data:`MAX_LOG_BYTES`.

    Raises:
        InvalidInputError: It would; the message gives the longest plan at this rate.
    """
    per_tick = TickLog.bytes_per_tick(scene)
    if ticks * per_tick <= MAX_LOG_BYTES:
        return
    longest = MAX_LOG_BYTES / per_tick * dt
    raise InvalidInputError(
        f"the run would take {ticks} control ticks ({ticks * dt:.4g} s at {1 / dt:.6g} Hz) and "
        f"its tick log {ticks * per_tick / 2**30:.3g} GiB at {per_tick / 1000:.1f} kB a tick; "
        f"valid: at most {MAX_LOG_BYTES / 2**30:g} GiB, a plan of at most {longest:.0f} s at "
        "this rate: raise the speed override (--speed), lower the control rate, or give the "
        "robot faster speed_limits and accel_limits"
    )


class Simulation:
    """One run of a task with a controller; call :meth:`run`.

    The loop works in blocks of ticks (:data:`ASSESS_PERIOD_S` of simulated time, see
    :meth:`advance`): the block's commands (plan sample and IK), then its physics tick by tick
    with the raw state copied into :attr:`log`, then :meth:`assess`, which derives every
    diagnostic for all its ticks at once and runs the goal's checks. A failure is reported at
    the exact tick it happened, and the run still stops ``failure_grace`` after it, because a
    block is never longer than the grace period.

    Args:
        scene: Loaded scene (its model may be modified by faults: load one per run).
        task: The task.
        controller: Differential-IK controller.
        config: Loop settings.
        observers: Receive blocks of ticks and events (e.g. the recorder).

    Raises:
        InvalidInputError: The control rate does not divide into physics steps.
        ControllerError: The controller's period differs from the control period.
    """

    def __init__(
        self,
        scene: Scene,
        task: Task,
        controller: DiffIKController,
        config: SimConfig | None = None,
        observers: Sequence[TickObserver] = (),
    ) -> None:
        self.scene = scene
        self.task = task
        self.controller = controller
        self.config = config or SimConfig()
        self.observers = list(observers)
        self.model = scene.model
        self.data = scene.make_data()
        self.criteria = self.config.criteria
        self.substeps = control_substeps(self.config.control_rate_hz, self.model.opt.timestep)
        self.dt = self.substeps * self.model.opt.timestep
        if abs(controller.dt - self.dt) > 1e-12:
            raise ControllerError(
                f"controller period {controller.dt} s differs from the control period {self.dt} s"
            )
        scene.set_brick_pose(self.data, task.X_WO_start)
        mujoco.mj_forward(self.model, self.data)
        self.q_cmd = self.data.qpos[scene.robot.arm_qpos_adr].copy()
        act = scene.robot.arm_actuator_ids
        kp = self.model.actuator_gainprm[act, 0]
        kv = -self.model.actuator_biasprm[act, 2]
        self._ff = kv / kp if self.config.velocity_feedforward else np.zeros(len(act))
        self._dynamics = _DynamicsFeedforward(scene.arm_model, kp, self.dt)
        self._use_dynamics = self.config.dynamics_feedforward
        self._zero_qdot = np.zeros(len(act))
        # The robot's actuators, arm then gripper: one row of the log's ctrl per tick.
        self._robot_ctrl = _as_slice(np.concatenate([act, scene.robot.gripper_actuator_ids]))
        self._ctrl_for_widths = scene.robot.ctrl_for_widths
        self._site = scene.robot.tool_site_id
        self._views = _DataViews(self.data)
        autoreset_off = self.model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_AUTORESET
        self._check_qacc = bool(autoreset_off)
        self._plan = task.plan
        self.plan_start = 0.0  # run time at which the plan's clock reads 0 [s]
        self._plan_replaced = False  # in the block being assessed
        self._sample = task.plan.trajectory.sample
        self._command = controller.command
        self._following = False  # the controller follows a C-space motion's joint path
        self._set_width = controller.set_gripper_width
        # The IK sees the fingers at the commanded gap, never narrower than the grasped brick
        # (closed on it they stop there), as the pre-flight does.
        self._width_held = grasp_width(task.plan, scene)
        # The world's moving bodies as the IK last saw them (see _world_moved).
        self._seen_mocap_pos = self.data.mocap_pos.copy()
        self._seen_mocap_quat = self.data.mocap_quat.copy()
        self._has_mocap = self.model.nmocap > 0

        self.max_ticks = self._horizon_ticks(task.plan, 0.0)
        _check_log_size(scene, self.max_ticks, self.dt)
        self.log = TickLog(scene, self.max_ticks, self.dt)
        self.ticks = 0
        self.assessed = 0  # rows of the log that are complete
        grace_ticks = round(self.criteria.failure_grace / self.dt)
        self.block_ticks = max(1, min(round(ASSESS_PERIOD_S / self.dt), grace_ticks))
        self.events: list[Event] = []
        self.failure: FailureReason | None = None
        self.failure_tick: int | None = None
        self._stop_tick: int | None = None
        self._keyframe_times = [(k.t, k.name) for k in task.trajectory.keyframes]
        self._next_keyframe = 0
        self._slots_warned = False
        self._time_expected = float(self.data.time)
        self.context = CheckContext(scene, task.plan, self.criteria, self.dt, self.emit)
        self.checks: list[Check] = task.goal.checks(self.context)

    @property
    def plan(self) -> Plan:
        """The plan being executed (the task's, until a recovery replaced it)."""
        return self._plan

    def _horizon_ticks(self, plan: Plan, t_start: float) -> int:
        """The most ticks the run can take with ``plan`` started at run time ``t_start`` [s]:
        to its end, the settling and the grace after a failure."""
        cr = self.criteria
        horizon = t_start + plan.trajectory.end_time + cr.settle_time + cr.failure_grace
        return int(np.ceil(horizon / self.dt)) + 2

    def replace_plan(self, plan: Plan, t_start: float, text: str) -> None:
        """Execute ``plan`` from the next tick to be commanded on, sampled at run time minus
        ``t_start``; the goal's checks start anew on it (a new set, whose context has the plan
        and ``t_start``), its keyframes get their events, the log grows to its horizon, and a
        ``replan`` event at the next tick says ``text``.

        A recovery calls this between blocks (:class:`~pickplace.sim.task.Recovery`). For the
        commanded motion to continue without a step, the new plan should start where the old
        one is at ``t_start`` — e.g. ``t_start`` the last commanded tick's time and the plan's
        first pose and velocity that tick's planned ones.

        Args:
            plan: The plan to execute.
            t_start: Run time at which the plan's clock reads 0 [s]: at most the next tick's
                time, k·dt.
            text: What the event says (why the plan was replaced).

        Raises:
            InvalidInputError: ``t_start`` is not finite or lies after the next tick, or the
                run's tick log would pass :data:`MAX_LOG_BYTES` (nothing is replaced then).
        """
        now = self.ticks * self.dt
        if not (math.isfinite(t_start) and t_start <= now + 1e-9):
            raise InvalidInputError(
                f"a plan may start at most at the next tick's time {now:.4f} s, got {t_start!r}"
            )
        max_ticks = self._horizon_ticks(plan, t_start)
        _check_log_size(self.scene, max_ticks, self.dt)
        self.log.grow(max_ticks)
        self.max_ticks = max_ticks
        self._plan = plan
        self.plan_start = float(t_start)
        self._sample = plan.trajectory.sample
        self._keyframe_times = [(t_start + k.t, k.name) for k in plan.trajectory.keyframes]
        self._next_keyframe = 0
        self.context = replace(self.context, plan=plan, t_start=self.plan_start)
        self.checks = self.task.goal.checks(self.context)
        self._plan_replaced = True
        self.emit(EventKind.REPLAN, f"plan replaced at t={now:.2f} s: {text}", level="warn")

    def pad_forces(self) -> np.ndarray:
        """Normal force [N] of the brick on the left and right pads (from the pad sensors)."""
        return self.scene.robot.pad_normal_forces(self.data.sensordata)

    # ------------------------------------------------------------------ events

    def emit(
        self, kind: EventKind, text: str, level: str = "info", tick: int | None = None
    ) -> None:
        """Record an event at ``tick`` (default: the current tick).

        An event of a simulated tick is stamped with the time the tick ends, (tick + 1)·dt,
        when its state was observed (as the tick log's rows are); one before the tick is
        simulated (a fault acting, the plan, the verdict after the last tick) with tick·dt.
        """
        tick = self.ticks if tick is None else tick
        t = (tick + 1) * self.dt if tick < self.ticks else tick * self.dt
        event = Event(tick=tick, t=t, level=level, kind=kind, text=text)
        self.events.append(event)
        for obs in self.observers:
            obs.on_event(self, event)

    def fail(self, reason: FailureReason, text: str, tick: int | None = None) -> None:
        """Record the first failure; the run stops ``failure_grace`` seconds after its tick."""
        if self.failure is not None:
            return
        tick = self.ticks if tick is None else tick
        self.failure = reason
        self.failure_tick = tick
        self._stop_tick = tick + round(self.criteria.failure_grace / self.dt)
        self.emit(EventKind.FAILURE, f"{reason.value}: {text}", level="error", tick=tick)

    # ------------------------------------------------------------------ loop

    def run(self) -> RunResult:
        """Simulate to the end (or failure) and judge the outcome.

        A KeyboardInterrupt ends the run with failure ``interrupted``; observers still get
        :meth:`TickObserver.on_finish`, so a recording is flushed and readable.
        """
        for obs in self.observers:
            obs.on_start(self)
        wall0 = time.perf_counter()
        interrupted = False
        planning = self.task.planning
        try:
            if planning is not None:
                self._planning_events(planning)
            if planning is None or planning.feasible:
                self.advance()
        except KeyboardInterrupt:
            interrupted = True
            # Complete the rows already simulated (idempotent), without judging them.
            self._derive(self.assessed, self.ticks)
            self.assessed = self.ticks
        wall = time.perf_counter() - wall0
        if interrupted:
            self.failure = FailureReason.INTERRUPTED
            self.failure_tick = self.ticks
            self.emit(EventKind.VERDICT, "interrupted by the user", level="warn")
        result = self._result(wall)
        if not interrupted:
            level = "info" if result.success else "error"
            verdict = "success" if result.success else f"failure: {result.failure}"
            self.emit(EventKind.VERDICT, f"verdict: {verdict}", level=level)
            result.events = self._sorted_events()
        for obs in self.observers:
            obs.on_finish(self, result)
        return result

    def _planning_events(self, planning: PlanningReport) -> None:
        """Events at tick 0 for each candidate the planner rejected and for the one chosen;
        if none is feasible, the failure ``no-feasible-plan`` (the run then takes no step)."""
        for c in planning.candidates:
            if c.preflight.problem is not None:
                p = c.preflight.problem
                self.emit(
                    EventKind.PLAN,
                    f"plan candidate '{c.label}' rejected: at t={p.t:.2f} s {p.text}",
                    level="warn",
                    tick=0,
                )
        if planning.chosen is None:
            self.fail(
                FailureReason.NO_FEASIBLE_PLAN,
                f"none of the {len(planning.candidates)} candidate plans is feasible; "
                f"{planning.refusal()}",
                tick=0,
            )
            return
        chosen = planning.candidates[planning.chosen]
        if chosen.warning is not None:
            self.emit(EventKind.PLAN, chosen.warning, level="warn", tick=0)
        m = chosen.preflight
        self.emit(
            EventKind.PLAN,
            f"plan '{chosen.label}' chosen (candidate {planning.chosen + 1} of "
            f"{len(planning.candidates)}): min clearance {m.min_clearance * 1000:.1f} mm, "
            f"min joint margin {m.min_joint_margin:.3f} rad, peak speed ratio "
            f"{m.peak_speed_ratio:.2f}, σmin {m.min_singular_value:.3f}",
            tick=0,
        )

    def advance(self, ticks: int | None = None) -> None:
        """Simulate up to ``ticks`` more control ticks (None: to the end of the run), fewer if
        the run ends, and assess them.

        Works block by block: the commands of a block's ticks (:meth:`_command_ticks`), then
        its physics tick by tick (:meth:`_physics_tick`), then :meth:`assess`. The IK never
        reads the robot's simulated state (it integrates q_cmd open loop, like Drake's
        DifferentialInverseKinematicsIntegrator, and faults act on the world only); of the
        world it sees the mocap poses, handed over at a block's start, and a tick whose
        faults move one ends its block. So this order gives exactly the run that
        interleaving IK and physics tick by tick gives, while each phase keeps its own code
        and data in the CPU's caches.

        Raises:
            InvalidInputError: ``ticks`` is negative.
        """
        if ticks is not None and ticks < 0:
            raise InvalidInputError(f"ticks must be >= 0, got {ticks}")
        target = None if ticks is None else self.ticks + ticks
        settle_ticks = round(self.criteria.settle_time / self.dt)
        goal, scene, data, criteria = self.task.goal, self.scene, self.data, self.criteria
        # MuJoCo's warnings become events instead of lines in ./MUJOCO_LOG.TXT.
        previous_handler = mujoco.get_mju_user_warning()
        mujoco.set_mju_user_warning(self._on_mujoco_warning)
        try:
            stopped = False
            while not stopped:
                # The plan (and with it the run's end) may have been replaced after a block.
                limit = self.max_ticks if target is None else min(self.max_ticks, target)
                if self.ticks >= limit:
                    break
                end = self.plan_start + self._plan.trajectory.end_time
                end_tick = int(np.ceil(end / self.dt - 1e-9))
                nonfinite = self.log.nonfinite  # the log may have grown with a new plan
                k0 = self.ticks
                k1 = self._command_ticks(k0, self._block_end(k0, limit))
                for k in range(k0, k1):
                    failed_and_shown = self._stop_tick is not None and k >= self._stop_tick
                    settled = k > end_tick and (
                        goal.settled(scene, data, criteria) or k >= end_tick + settle_ticks
                    )
                    if failed_and_shown or settled:
                        stopped = True
                        break
                    self._physics_tick(k)
                    self.ticks = k + 1
                    if nonfinite[k] != FINITE:
                        stopped = True
                        break
                    if self._has_mocap and self._world_moved():
                        break  # the next ticks' commands must see the moved world
                # Commands past the last simulated tick are dropped.
                if self.ticks > k0:
                    self.q_cmd = self.log.q_cmd[self.ticks - 1].copy()
                self.assess()
                if self._plan_replaced and self.failure is None:
                    stopped = False  # a new plan goes on from here
                self._plan_replaced = False
        finally:
            mujoco.set_mju_user_warning(previous_handler)

    def _block_end(self, k0: int, limit: int) -> int:
        """End of the block starting at ``k0``: :attr:`block_ticks` later, at most ``limit``,
        and ended early at the tick whose end reaches the next decision time of the task's
        recovery (:meth:`~pickplace.sim.task.Recovery.next_decision_time`), so that it can act
        right after that tick. Blocks of any length give the same run."""
        end = min(k0 + self.block_ticks, limit)
        recovery = self.task.recovery
        if recovery is not None and self.failure is None:
            t = recovery.next_decision_time(self)
            if t is not None:
                k = math.ceil(t / self.dt - 1e-9)  # tick k - 1 ends at k·dt >= t
                if k0 < k < end:
                    end = k
        return end

    def _command_ticks(self, k0: int, k1: int) -> int:
        """Plan sample and IK for ticks ``[k0, k1)``, from ``q_cmd`` at ``k0``.

        Writes the commands into the log and returns the end of the ticks commanded: ``k1``,
        or one past a tick whose joint velocities were not finite (that tick commands no
        motion and is the last one simulated). The gripper's commands for the planned widths
        are computed for the whole block at once.
        """
        v = self._views
        self._seen_mocap_pos[:] = v.mocap_pos
        self._seen_mocap_quat[:] = v.mocap_quat
        self.controller.observe_world(v.mocap_pos, v.mocap_quat)
        end = self._arm_commands(k0, k1)
        log = self.log
        log.gripper_ctrl[k0:end] = self._ctrl_for_widths(log.gripper_cmd[k0:end])
        return end

    def _arm_commands(self, k0: int, k1: int) -> int:
        """The per-tick part of :meth:`_command_ticks`: plan samples and IK."""
        log, dt, ff = self.log, self.dt, self._ff
        sample, command = self._sample, self._command
        controller = self.controller
        segment_index = self._plan.trajectory.segment_index
        t_start = self.plan_start
        dynamics = self._dynamics if self._use_dynamics else None
        set_width, width_held = self._set_width, self._width_held
        q_cmd = self.q_cmd
        qdot_prev = log.qdot_cmd[k0 - 1] if k0 > 0 else self._zero_qdot
        trajectory = self._plan.trajectory
        # A C-space motion's joint path steers the controller's null space (posture).
        joints = trajectory.joint_sample if trajectory.has_joint_segments else None
        for k in range(k0, k1):
            t = k * dt - t_start  # the plan's clock
            x_plan, V_plan, width = sample(t)
            if joints is not None:
                js = joints(t)
                if js is not None or self._following:
                    self.controller.follow_joints(*(js if js is not None else (None, None)))
                self._following = js is not None
            t0 = time.perf_counter_ns()
            set_width(width if width > width_held else width_held)
            res = command(q_cmd, x_plan, V_plan)
            log.ik_us[k] = (time.perf_counter_ns() - t0) * 1e-3
            qdot = res.qdot
            finite = math.isfinite(qdot.sum())
            if not finite:
                log.nonfinite[k] = CONTROLLER_NONFINITE
                qdot = self._zero_qdot
            else:
                log.nonfinite[k] = FINITE
            q_cmd = q_cmd + qdot * dt
            log.x_WG_plan[k] = x_plan
            log.V_WG_plan[k] = V_plan
            log.plan_segment[k] = segment_index(t)
            log.x_WG_cmd[k] = res.x_WG
            log.J_WG[k] = res.J_WG
            log.q_cmd[k] = q_cmd
            log.qdot_cmd[k] = qdot
            if dynamics is None:
                log.arm_ctrl[k] = q_cmd + ff * qdot
            else:
                log.arm_ctrl[k] = q_cmd + ff * qdot + dynamics(q_cmd, qdot, qdot - qdot_prev)
            qdot_prev = qdot
            log.gripper_cmd[k] = width
            log.ik_status[k] = _STATUS_CODE_BY_ID[id(res.status)]
            log.collision_held[k] = controller.collision_held
            if not finite:
                return k + 1
        return k1

    def _physics_tick(self, k: int) -> None:
        """Physics of tick ``k``: faults, the tick's actuator commands, MuJoCo's steps, and
        the simulated state copied into the log (see :meth:`assess` for what is derived)."""
        log, v = self.log, self._views
        for fault in self.task.faults:
            text = fault.apply(self, k)
            if text:
                self.emit(EventKind.FAULT, f"fault '{fault.name}': {text}", level="warn")
        v.ctrl[self._robot_ctrl] = log.ctrl[k]
        mujoco.mj_step(self.model, self.data, self.substeps)
        # MuJoCo checks qpos, qvel and qacc every step and resets the data (time back to 0)
        # on a non-finite value, so a clock that stopped advancing means a NaN; only with
        # autoreset disabled must qacc be checked here.
        self._time_expected += self.dt
        bad = abs(self.data.time - self._time_expected) > 1e-6 or (
            self._check_qacc and not math.isfinite(v.qacc.sum())
        )
        if bad and log.nonfinite[k] == FINITE:
            log.nonfinite[k] = STATE_NONFINITE
        log.qpos[k] = v.qpos
        log.p_WG[k] = v.site_xpos[self._site]
        log.R_WG_flat[k] = v.site_xmat[self._site]
        log.body_pos[k] = v.xpos
        log.body_quat[k] = v.xquat
        log.sensordata[k] = v.sensordata

    def _world_moved(self) -> bool:
        """True if a mocap body (an obstacle a fault moves) is not where the IK last saw it.

        The block's commands were computed before its physics, so they saw the world as it
        was at the block's start; a tick that moves it ends the block, and the next block's
        commands see the world after that tick, as tick-by-tick IK and physics would
        (a mocap body moves only by a fault, and the moved world is handed to the controller
        by :meth:`_command_ticks`).
        """
        v = self._views
        return bool(
            (v.mocap_pos != self._seen_mocap_pos).any()
            or (v.mocap_quat != self._seen_mocap_quat).any()
        )

    def _on_mujoco_warning(self, message: str) -> None:
        self.emit(EventKind.MUJOCO_WARNING, f"MuJoCo: {message}", level="warn")

    # ------------------------------------------------------------------ assessment

    def assess(self) -> None:
        """Derive the diagnostics of the ticks stored since the last call and judge them.

        Keyframe events first, then the goal's checks on the block; the earliest failure wins,
        and of failures at one tick the check listed first (the goal's order is the
        precedence); only the first failure of the run counts. A task's recovery is asked
        first whether it takes the block's failures up (the run then goes on, on a plan it
        puts in place), and after the block whether the run must end. Observers then receive
        the completed rows.
        """
        k0, k1 = self.assessed, self.ticks
        if k1 <= k0:
            return
        self._derive(k0, k1)
        self._keyframe_events(k0, k1)
        found: list[Failure] = []
        for check in self.checks:
            failure = check.first_failure(self.log, k0, k1)
            if failure is not None:
                found.append(failure)
        found.sort(key=lambda f: f.tick)  # stable: of one tick, the check listed first
        recovery = self.task.recovery
        if found and (
            recovery is None or self.failure is not None or not recovery.take_up(self, found)
        ):
            self.fail(found[0].reason, found[0].text, tick=found[0].tick)
        self.assessed = k1
        if recovery is not None and self.failure is None:
            final = recovery.after_block(self)
            if final is not None:
                self.fail(final.reason, final.text, tick=final.tick)
        for obs in self.observers:
            obs.on_ticks(self, k0, k1)

    def _derive(self, k0: int, k1: int) -> None:
        """Fill the derived rows ``[k0, k1)`` of the log; warn once if a pad sensor missed
        contacts (idempotent otherwise, so an interrupted run can complete its rows)."""
        overflow = self.log.derive(k0, k1)
        if overflow is not None and not self._slots_warned:
            self._slots_warned = True
            tick, found = overflow
            slots = self.scene.robot.pad_force_slots
            self.emit(
                EventKind.SENSOR,
                f"a pad touched the brick in {found} points but its sensor reports {slots}: "
                "the grip force is underestimated",
                level="warn",
                tick=tick,
            )

    def _keyframe_events(self, k0: int, k1: int) -> None:
        """Emit 'keyframe reached' at the first tick whose end time passes each keyframe."""
        times = self.log.t[k0:k1]
        while self._next_keyframe < len(self._keyframe_times):
            kt, name = self._keyframe_times[self._next_keyframe]
            i = int(np.searchsorted(times, kt - 1e-9))
            if i >= len(times):
                return
            k = k0 + i
            self._next_keyframe += 1
            err = self.log.position_error[k]
            t0 = self.plan_start
            of_plan = "" if t0 == 0.0 else f" of the plan started at t={t0:.2f} s"
            self.emit(
                EventKind.KEYFRAME,
                f"keyframe '{name}' reached (planned t={kt - self.plan_start:.2f} s{of_plan}, "
                f"tool {err * 1000:.1f} mm from plan)",
                tick=k,
            )

    # ------------------------------------------------------------------ verdict

    def _sorted_events(self) -> list[Event]:
        return sorted(self.events, key=lambda e: e.tick)

    def _result(self, wall: float) -> RunResult:
        goal = self.task.goal
        if self.failure is None and self.ticks > 0:
            final = goal.final_failure(self.context, self.data, self.ticks)
            if final is not None:
                self.fail(final.reason, final.text, tick=final.tick)
        success = self.failure is None and self.ticks > 0
        if self.ticks == 0 and self.failure is None:
            self.failure = FailureReason.INTERRUPTED
        # After a non-finite state MuJoCo has reset the data: judge the rows before it.
        bad = np.flatnonzero(self.log.nonfinite[: self.ticks] != FINITE)
        valid = int(bad[0]) if bad.size else self.ticks
        if valid < self.ticks:
            X_WO = self.task.X_WO_start if valid == 0 else self.log.brick_pose(valid - 1)
        else:
            X_WO = brick_pose(self.scene, self.data)
        X_WO_goal = goal.X_WO_goal
        end = self.plan_start + self._plan.trajectory.end_time
        recovery = self.task.recovery
        return RunResult(
            scenario=self.task.scenario,
            controller=self.controller.name,
            seed=self.task.seed,
            goal=goal.name,
            success=success,
            failure=self.failure,
            failure_tick=self.failure_tick,
            failure_time_s=(
                None
                if self.failure_tick is None
                else min(self.failure_tick + 1, self.ticks) * self.dt
            ),
            ticks=self.ticks,
            sim_time_s=self.ticks * self.dt,
            wall_time_s=wall,
            brick_start_xyz=[float(x) for x in self.task.X_WO_start.translation()],
            brick_final_xyz=[float(x) for x in X_WO.translation()],
            target_xyz=[float(x) for x in X_WO_goal.translation()] if X_WO_goal else [],
            events=self._sorted_events(),
            metrics={
                **run_metrics(self.log, valid, X_WO, X_WO_goal),
                "cycle_time_s": end if self.ticks * self.dt >= end - 1e-9 else None,
            },
            planning=self.task.planning,
            robot=self.scene.robot.name,
            parameters=self.task.parameters,
            attempts=None if recovery is None else recovery.attempts(),
        )


class _DynamicsFeedforward:
    """τ / kp: the actuator setpoint offset that makes a position actuator of gain kp supply
    the joint torque τ = M(q) q̈ + c(q, q̇) + D q̇ + A q̈ of a commanded motion — inertia,
    Coriolis and centrifugal forces (MuJoCo's recursive Newton-Euler on the arm-only model,
    gravity off: the arm's bodies have gravity compensation), joint damping D and armature A.

    The arm-only model keeps the gripper as a rigid body and has no brick.
    """

    def __init__(self, model: mujoco.MjModel, kp: np.ndarray, dt: float) -> None:
        self.model = copy.deepcopy(model)
        self.model.opt.gravity[:] = 0.0
        self.data = mujoco.MjData(self.model)
        self.inv_kp = 1.0 / np.asarray(kp, dtype=np.float64)
        self.inv_dt = 1.0 / dt
        self.damping = self.model.dof_damping.copy()
        self.armature = self.model.dof_armature.copy()
        self.out = np.zeros(self.model.nv)

    def __call__(self, q: np.ndarray, qdot: np.ndarray, dqdot: np.ndarray) -> np.ndarray:
        """The offset for joints at ``q`` moving at ``qdot`` whose velocity changed by
        ``dqdot`` over the last tick."""
        m, d = self.model, self.data
        qacc = dqdot * self.inv_dt
        d.qpos[:] = q
        d.qvel[:] = qdot
        d.qacc[:] = qacc
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_comVel(m, d)
        mujoco.mj_rne(m, d, 1, self.out)
        return (self.out + self.damping * qdot + self.armature * qacc) * self.inv_kp


class _DataViews:
    """NumPy views of the MjData arrays the loop touches every tick.

    Each attribute access on MjData builds a new array object; these are built once (MjData
    never reallocates its buffers, so the views stay valid for its lifetime).
    """

    def __init__(self, data: mujoco.MjData) -> None:
        self.ctrl = data.ctrl
        self.qpos = data.qpos
        self.qacc = data.qacc
        self.xpos = data.xpos
        self.xquat = data.xquat
        self.site_xpos = data.site_xpos
        self.site_xmat = data.site_xmat
        self.sensordata = data.sensordata
        self.mocap_pos = data.mocap_pos
        self.mocap_quat = data.mocap_quat


def _as_slice(ids: np.ndarray) -> slice | np.ndarray:
    """A slice for consecutive ids (cheaper indexing every tick), else the ids."""
    if len(ids) and np.array_equal(ids, np.arange(ids[0], ids[0] + len(ids))):
        return slice(int(ids[0]), int(ids[0]) + len(ids))
    return ids
