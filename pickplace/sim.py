"""The headless loop: trajectory → differential IK → position actuators → MuJoCo physics.

Each control tick (``SimConfig.control_rate_hz``, default 100 Hz):

1. read the planned tool pose X_WG(t), its spatial velocity V_WG(t) and the gripper width;
2. the controller turns them into joint velocities at the commanded configuration q_cmd;
3. q_cmd is integrated from those velocities and sent to the arm's position actuators;
4. MuJoCo steps the physics for one control period at the scene's timestep;
5. the commands, the IK's Jacobian and MuJoCo's state are copied into the tick log
   (:class:`~pickplace.ticklog.TickLog`).

The loop runs in blocks of :data:`ASSESS_PERIOD_S` of simulated time: steps 1–3 for the
block's ticks, then steps 4–5 tick by tick, then the block is assessed. Assessing derives
every diagnostic of every tick in one vectorised pass (the Jacobian's health, the tracking
errors, the grip force, the limits) and runs the checks in tick order, so failures keep their
exact tick. Doing this per block instead of per tick is what lets a run go tens of times
faster than real time; a block of one tick gives the identical run.

The brick is held by contact friction only: nothing here welds, attaches or moves it, except an
explicit fault injected by a scenario (:mod:`pickplace.faults`).

The verdict is judged from geometry stated in :class:`SuccessCriteria`, never assumed.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import mujoco
import numpy as np
from mink.lie import SE3, SO3

from pickplace.controllers import IK_STATUSES, DiffIKController, IKStatus
from pickplace.diagnostics import holding_torques
from pickplace.errors import InvalidInputError, require_positive
from pickplace.scene import Scene
from pickplace.ticklog import TickLog
from pickplace.trajectory import PoseTrajectory

FAILURE_REASONS: tuple[str, ...] = (
    "missed-grasp",
    "dropped",
    "ik-failed",
    "limit-violated",
    "not-in-target-bin",
    "nan",
    "interrupted",
)

# Joint-speed ratios are compared with 1 + this: the QP's bounds are exact up to solver tolerance.
SPEED_RATIO_TOLERANCE = 1e-6
# How far past a joint limit a joint may be before the run counts as a limit violation [rad].
POSITION_LIMIT_TOLERANCE = 1e-3


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


@dataclass(frozen=True)
class SimConfig:
    """Settings of the loop.

    Attributes:
        control_rate_hz: IK and actuator-command rate [Hz]; must divide into whole physics
            steps of the scene's timestep.
        velocity_feedforward: Send q_cmd + (kv/kp)·q̇_cmd to the position actuators, so that
            their damping term tracks the commanded joint velocity instead of braking it.
        criteria: Success and failure geometry.
    """

    control_rate_hz: float = 100.0
    velocity_feedforward: bool = True
    criteria: SuccessCriteria = field(default_factory=SuccessCriteria)

    def __post_init__(self) -> None:
        require_positive("control_rate_hz", self.control_rate_hz)


@dataclass(frozen=True)
class Event:
    """Something that happened at a tick: keyframe reached, grasp closed, drop, verdict."""

    tick: int
    t: float
    level: str  # "info", "warn" or "error"
    kind: str
    text: str


class Fault(Protocol):
    """A disturbance injected by a scenario (see :mod:`pickplace.faults`).

    A fault acts on the simulated world (``run.model``, ``run.data``), never on the
    controller: the commands of a block of ticks are computed before its physics.
    """

    name: str

    def apply(self, run: Simulation, tick: int) -> str | None:
        """Act on the simulation before tick ``tick``; return an event text when it acted."""


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


@dataclass
class RunResult:
    """Outcome of one run; :meth:`summary` is the JSON the CLI prints."""

    scenario: str
    controller: str
    seed: int
    goal: str
    success: bool
    failure: str | None
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
            "failure": self.failure,
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


@dataclass
class Task:
    """What one run must do: the plan, the brick's start and goal, and the faults.

    Attributes:
        scenario: Scenario name.
        seed: Seed the task was drawn with.
        goal: ``"place"`` (brick into the target bin) or ``"reach"`` (track the tool path
            within joint position and speed limits).
        trajectory: Planned tool trajectory.
        X_WO_start: Brick pose at the start.
        X_WO_goal: Brick pose the plan places it at (``"place"``), else None.
        faults: Disturbances injected during the run.
        grasp_keyframe: Name of the keyframe at which the grip must be closed.
        release_keyframe: Name of the keyframe at which the brick is released.
    """

    scenario: str
    seed: int
    goal: str
    trajectory: PoseTrajectory
    X_WO_start: SE3
    X_WO_goal: SE3 | None
    faults: Sequence[Fault] = ()
    grasp_keyframe: str = "grip-closed"
    release_keyframe: str = "release"


_STATUS_CODE = {status: IK_STATUSES.index(status.value) for status in IKStatus}
_NO_SOLUTION = _STATUS_CODE[IKStatus.NO_SOLUTION]
# The same, keyed by the members' ids: hashing an Enum member runs Python code.
_STATUS_CODE_BY_ID = {id(status): code for status, code in _STATUS_CODE.items()}

# Simulated time between two assessments of the log [s] (see :meth:`Simulation.assess`).
ASSESS_PERIOD_S = 0.5

# A failure found by a check: (tick, precedence within the tick, reason, text).
_Candidate = tuple[int, int, str, str]


class Simulation:
    """One run of a task with a controller; call :meth:`run`.

    The loop works in blocks of ticks (:data:`ASSESS_PERIOD_S` of simulated time, see
    :meth:`advance`): the block's commands (plan sample and IK), then its physics tick by tick
    with the raw state copied into :attr:`log`, then :meth:`assess`, which derives every
    diagnostic for all its ticks at once and runs the checks in tick order. A failure is
    reported at the exact tick it happened, and the run still stops ``failure_grace`` after
    it, because a block is never longer than the grace period.

    Args:
        scene: Loaded scene (its model may be modified by faults: load one per run).
        task: The task.
        controller: Differential-IK controller.
        config: Loop settings.
        observers: Receive blocks of ticks and events (e.g. the recorder).
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
        steps = self.config.control_rate_hz**-1 / self.model.opt.timestep
        self.substeps = round(steps)
        if self.substeps < 1 or abs(steps - self.substeps) > 1e-9:
            raise InvalidInputError(
                f"--control-rate {self.config.control_rate_hz:g} Hz is not a whole number of "
                f"physics steps of {self.model.opt.timestep:g} s; valid rates divide "
                f"{1.0 / self.model.opt.timestep:g} Hz"
            )
        self.dt = self.substeps * self.model.opt.timestep
        if abs(controller.dt - self.dt) > 1e-12:
            raise ValueError(f"controller dt {controller.dt} differs from control period {self.dt}")
        # Place the brick at the task's start pose (the plan's belief about the world).
        adr = scene.brick_qpos_adr
        self.data.qpos[adr : adr + 3] = task.X_WO_start.translation()
        self.data.qpos[adr + 3 : adr + 7] = task.X_WO_start.rotation().wxyz
        mujoco.mj_forward(self.model, self.data)
        self.q_cmd = self.data.qpos[scene.arm_qpos_adr].copy()
        act = scene.arm_actuator_ids
        kp = self.model.actuator_gainprm[act, 0]
        kv = -self.model.actuator_biasprm[act, 2]
        self._ff = kv / kp if self.config.velocity_feedforward else np.zeros(7)
        self._arm_ctrl = _as_slice(scene.arm_actuator_ids)
        self._gripper_ctrl = scene.gripper_actuator_id
        self._site = scene.tool_site_id
        self._views = _DataViews(self.data)
        autoreset_off = self.model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_AUTORESET
        self._check_qacc = bool(autoreset_off)
        self._sample = task.trajectory.sample
        self._command = controller.command

        horizon = task.trajectory.end_time + self.criteria.settle_time + self.criteria.failure_grace
        self.max_ticks = int(np.ceil(horizon / self.dt)) + 2
        self.log = TickLog(scene, self.max_ticks, self.dt)
        self.ticks = 0
        self.assessed = 0  # rows of the log that are complete
        grace_ticks = round(self.criteria.failure_grace / self.dt)
        self.block_ticks = max(1, min(round(ASSESS_PERIOD_S / self.dt), grace_ticks))
        self.events: list[Event] = []
        self.failure: str | None = None
        self.failure_tick: int | None = None
        self._stop_tick: int | None = None
        self._nan: tuple[int, str] | None = None
        self._keyframe_times = [(k.t, k.name) for k in task.trajectory.keyframes]
        self._next_keyframe = 0
        self._grasp_state = "open"  # open → holding → released
        self._p_GO_grasp: np.ndarray | None = None
        self._contact_lost_since: float | None = None
        self._slots_warned = False
        brick_size = scene.brick_half_extents
        # Box corners in the brick frame, for the footprint and resting checks.
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        self._corners_O = signs * brick_size
        self._brick_width = 2.0 * float(brick_size[1])
        self._time_expected = float(self.data.time)
        times = {kf.name: kf.t for kf in task.trajectory.keyframes}
        if task.goal == "place":
            names = [kf.name for kf in task.trajectory.keyframes]
            i_release = names.index(task.release_keyframe)
            self._grasp_times = (
                times[task.grasp_keyframe],
                task.trajectory.keyframes[i_release - 1].t,
                times[task.release_keyframe],
            )

    # ------------------------------------------------------------------ measurements

    def brick_pose(self) -> SE3:
        """Current pose X_WO of the brick."""
        b = self.scene.brick_body_id
        return SE3.from_rotation_and_translation(
            SO3(np.array(self.data.xquat[b])), np.array(self.data.xpos[b])
        )

    def gripper_gap(self) -> float:
        """Measured finger gap [m]."""
        return float(self.scene.finger_gap(self.data.qpos))

    def pad_forces(self) -> np.ndarray:
        """Normal force [N] of the brick on the left and right pads (from the pad sensors)."""
        return self.scene.pad_normal_forces(self.data.sensordata)

    def brick_touches_gripper(self) -> bool:
        """True if any geom of the gripper (or arm) touches the brick."""
        brick = self.scene.brick_geom_id
        for i in range(self.data.ncon):
            c = self.data.contact[i]
            g1, g2 = int(c.geom1), int(c.geom2)
            if brick in (g1, g2):
                other = g2 if g1 == brick else g1
                if self.model.geom_contype[other] & 2:  # arm and gripper geoms use bit 2
                    return True
        return False

    # ------------------------------------------------------------------ events

    def emit(self, kind: str, text: str, level: str = "info", tick: int | None = None) -> None:
        """Record an event at ``tick`` (default: the current tick)."""
        tick = self.ticks if tick is None else tick
        event = Event(tick=tick, t=tick * self.dt, level=level, kind=kind, text=text)
        self.events.append(event)
        for obs in self.observers:
            obs.on_event(self, event)

    def fail(self, reason: str, text: str, tick: int | None = None) -> None:
        """Record the first failure; the run stops ``failure_grace`` seconds after its tick."""
        if self.failure is not None:
            return
        tick = self.ticks if tick is None else tick
        self.failure = reason
        self.failure_tick = tick
        self._stop_tick = tick + round(self.criteria.failure_grace / self.dt)
        self.emit("failure", f"{reason}: {text}", level="error", tick=tick)

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
        try:
            self.advance(self.max_ticks)
        except KeyboardInterrupt:
            interrupted = True
            # Complete the rows already simulated (idempotent), without judging them.
            self._derive(self.assessed, self.ticks)
            self.assessed = self.ticks
        wall = time.perf_counter() - wall0
        if interrupted:
            self.failure = "interrupted"
            self.failure_tick = self.ticks
            self.emit("verdict", "interrupted by the user", level="warn")
        result = self._result(wall)
        if not interrupted:
            level = "info" if result.success else "error"
            verdict = "success" if result.success else f"failure: {result.failure}"
            self.emit("verdict", f"verdict: {verdict}", level=level)
            result.events = self._sorted_events()
        for obs in self.observers:
            obs.on_finish(self, result)
        return result

    def advance(self, ticks: int) -> None:
        """Simulate up to ``ticks`` more control ticks, fewer if the run ends, and assess them.

        Works block by block: the commands of a block's ticks (:meth:`_command_ticks`), then
        its physics tick by tick (:meth:`_physics_tick`), then :meth:`assess`. The IK never
        reads the simulated state (it integrates q_cmd open loop, like Drake's
        DifferentialInverseKinematicsIntegrator, and faults act on the world only), so this
        order gives exactly the run that interleaving IK and physics tick by tick gives,
        while each phase keeps its own code and data in the CPU's caches.

        Raises:
            InvalidInputError: ``ticks`` is negative.
        """
        if ticks < 0:
            raise InvalidInputError(f"ticks must be >= 0, got {ticks}")
        limit = min(self.max_ticks, self.ticks + ticks)
        end = self.task.trajectory.end_time
        settle_ticks = round(self.criteria.settle_time / self.dt)
        end_tick = int(np.ceil(end / self.dt - 1e-9))
        # MuJoCo's warnings become events instead of lines in ./MUJOCO_LOG.TXT.
        previous_handler = mujoco.get_mju_user_warning()
        mujoco.set_mju_user_warning(self._on_mujoco_warning)
        try:
            stopped = False
            while self.ticks < limit and not stopped:
                k0 = self.ticks
                k1 = self._command_ticks(k0, min(k0 + self.block_ticks, limit))
                for k in range(k0, k1):
                    failed_and_shown = self._stop_tick is not None and k >= self._stop_tick
                    settled = k > end_tick and (
                        self._brick_at_rest() or k >= end_tick + settle_ticks
                    )
                    if failed_and_shown or settled:
                        stopped = True
                        break
                    self._physics_tick(k)
                    self.ticks = k + 1
                    if self._nan is not None and self._nan[0] <= k:
                        stopped = True
                        break
                # Commands past the last simulated tick are dropped.
                if self.ticks > k0:
                    self.q_cmd = self.log.q_cmd[self.ticks - 1].copy()
                if self._nan is not None and self._nan[0] >= self.ticks:
                    self._nan = None
                self.assess()
        finally:
            mujoco.set_mju_user_warning(previous_handler)

    def _command_ticks(self, k0: int, k1: int) -> int:
        """Plan sample and IK for ticks ``[k0, k1)``, from ``q_cmd`` at ``k0``.

        Writes the commands into the log and returns the end of the ticks commanded: ``k1``,
        or one past a tick whose joint velocities were not finite (that tick commands no
        motion and is the last one simulated).
        """
        log, dt, ff = self.log, self.dt, self._ff
        sample, command = self._sample, self._command
        q_cmd = self.q_cmd
        for k in range(k0, k1):
            t = k * dt
            x_plan, V_plan, width = sample(t)
            t0 = time.perf_counter_ns()
            res = command(q_cmd, x_plan, V_plan)
            log.ik_us[k] = (time.perf_counter_ns() - t0) * 1e-3
            qdot = res.qdot
            finite = math.isfinite(qdot.sum())
            if not finite:
                self._nan = (k, f"controller returned non-finite joint velocities at t={t:.3f} s")
                qdot = np.zeros(7)
            q_cmd = q_cmd + qdot * dt
            log.x_WG_plan[k] = x_plan
            log.x_WG_cmd[k] = res.x_WG
            log.J_WG[k] = res.J_WG
            log.q_cmd[k] = q_cmd
            log.qdot_cmd[k] = qdot
            log.arm_ctrl[k] = q_cmd + ff * qdot
            log.gripper_cmd[k] = width
            log.ik_status[k] = _STATUS_CODE_BY_ID[id(res.status)]
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
                self.emit("fault", f"fault '{fault.name}': {text}", level="warn")
        v.ctrl[self._arm_ctrl] = log.arm_ctrl[k]
        v.ctrl[self._gripper_ctrl] = log.gripper_cmd[k]
        mujoco.mj_step(self.model, self.data, self.substeps)
        # MuJoCo checks qpos, qvel and qacc every step and resets the data (time back to 0)
        # on a non-finite value, so a clock that stopped advancing means a NaN; only with
        # autoreset disabled must qacc be checked here.
        self._time_expected += self.dt
        bad = abs(self.data.time - self._time_expected) > 1e-6 or (
            self._check_qacc and not math.isfinite(v.qacc.sum())
        )
        if bad and (self._nan is None or k < self._nan[0]):
            self._nan = (k, f"simulation state became non-finite at t={k * self.dt:.3f} s")
        log.qpos[k] = v.qpos
        log.p_WG[k] = v.site_xpos[self._site]
        log.R_WG_flat[k] = v.site_xmat[self._site]
        log.body_pos[k] = v.xpos
        log.body_quat[k] = v.xquat
        log.sensordata[k] = v.sensordata

    def _on_mujoco_warning(self, message: str) -> None:
        self.emit("mujoco-warning", f"MuJoCo: {message}", level="warn")

    # ------------------------------------------------------------------ assessment

    def assess(self) -> None:
        """Derive the diagnostics of the ticks stored since the last call and judge them.

        Checks run in tick order and, within a tick, in the order nan → ik-failed (no QP
        solution, then tracking) → limit-violated (speed, then position) → grasp checks; only
        the first failure of the run counts. Observers then receive the completed rows.
        """
        k0, k1 = self.assessed, self.ticks
        if k1 <= k0:
            return
        self._derive(k0, k1)
        self._keyframe_events(k0, k1)
        candidates = self._limit_checks(k0, k1)
        holding = np.zeros(k1 - k0, dtype=bool)
        if self.task.goal == "place":
            candidates += self._grasp_checks(k0, k1, holding)
        log = self.log
        log.holding_torque[k0:k1] = 0.0
        if holding.any():
            J = log.J_WG[k0:k1][holding]
            log.holding_torque[k0:k1][holding] = holding_torques(J, self.scene.brick_mass)
        if candidates:
            tick, _, reason, text = min(candidates, key=lambda c: (c[0], c[1]))
            self.fail(reason, text, tick=tick)
        self.assessed = k1
        for obs in self.observers:
            obs.on_ticks(self, k0, k1)

    def _derive(self, k0: int, k1: int) -> None:
        """Fill the derived rows ``[k0, k1)`` of the log; warn once if a pad sensor missed
        contacts (idempotent otherwise, so an interrupted run can complete its rows)."""
        overflow = self.log.derive(k0, k1)
        if overflow is not None and not self._slots_warned:
            self._slots_warned = True
            tick, found = overflow
            slots = self.scene.pad_force_slots
            self.emit(
                "sensor",
                f"a pad touched the brick in {found} points but its sensor reports {slots}: "
                "the grip force is underestimated",
                level="warn",
                tick=tick,
            )

    def _limit_checks(self, k0: int, k1: int) -> list[_Candidate]:
        """First tick of ``[k0, k1)`` at which each loop-level check fails."""
        log, sc, dt = self.log, self.scene, self.dt
        sl = slice(k0, k1)
        out: list[_Candidate] = []

        def first(mask: np.ndarray) -> int | None:
            idx = np.flatnonzero(mask)
            return k0 + int(idx[0]) if idx.size else None

        if self._nan is not None and k0 <= self._nan[0] < k1:
            out.append((self._nan[0], 0, "nan", self._nan[1]))
        k = first(log.ik_status[sl] == _NO_SOLUTION)
        if k is not None:
            out.append((k, 1, "ik-failed", f"the QP found no solution at t={k * dt:.3f} s"))
        limit = self.criteria.tracking_limit
        if self.task.goal == "place":
            k = first(log.command_error[sl] > limit)
            if k is not None:
                status = IK_STATUSES[int(log.ik_status[k])]
                text = (
                    f"commanded tool is {log.command_error[k] * 1000:.1f} mm from the plan at "
                    f"t={k * dt:.3f} s (limit {limit * 1000:.0f} mm; status {status})"
                )
                out.append((k, 2, "ik-failed", text))
        k = first(log.speed_ratio[sl] > 1.0 + SPEED_RATIO_TOLERANCE)
        if k is not None:
            qdot = log.qdot_cmd[k]
            j = int(np.argmax(np.abs(qdot) / sc.v_max))
            text = (
                f"joint{j + 1} commanded at {abs(qdot[j]):.2f} rad/s, limit {sc.v_max[j]:.2f} "
                f"rad/s ({log.speed_ratio[k]:.4f}x) at t={k * dt:.3f} s"
            )
            out.append((k, 3, "limit-violated", text))
        k = first(log.limit_violation[sl] > POSITION_LIMIT_TOLERANCE)
        if k is not None:
            text = f"a joint is {log.limit_violation[k]:.4f} rad past its limit at t={k * dt:.3f} s"
            out.append((k, 4, "limit-violated", text))
        return out

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
            self.emit(
                "keyframe",
                f"keyframe '{name}' reached (planned t={kt:.2f} s, "
                f"tool {err * 1000:.1f} mm from plan)",
                tick=k,
            )

    def _grasp_checks(self, k0: int, k1: int, holding: np.ndarray) -> list[_Candidate]:
        """Run the grasp state machine over ``[k0, k1)``; mark the ticks that start holding.

        open → holding when the grip closes with both pads pressing firmly on a brick of the
        right width (else missed-grasp); holding → released at the release keyframe, or
        dropped if before placing the brick slips ``drop_slip`` in the gripper frame or loses
        all pad contact for ``drop_contact_loss``.
        """
        cr, log = self.criteria, self.log
        t_grasp, t_place, t_release = self._grasp_times
        sl = slice(k0, k1)
        # Brick centre in the tool frame, p_GO = R_WGᵀ (p_WO − p_WG), for every tick.
        p_WO = log.body_pos[sl, self.scene.brick_body_id]
        p_GO_all = np.einsum("nji,nj->ni", log.R_WG[sl], p_WO - log.p_WG[sl])
        forces = log.pad_force[sl]
        touching: np.ndarray = np.any(forces > 0.0, axis=1)
        times: list[float] = log.t[sl].tolist()
        firm_force = cr.grasp_force_fraction * self.scene.gripper_force_limit
        out: list[_Candidate] = []
        slip: list[float] = []
        if self._grasp_state == "holding" and self._p_GO_grasp is not None:
            slip = np.linalg.norm(p_GO_all - self._p_GO_grasp, axis=1).tolist()
        for i, t in enumerate(times):
            k = k0 + i
            state = self._grasp_state
            if state == "released":
                break
            if state == "open":
                if t < t_grasp - 1e-9:
                    continue
                gap = float(log.gripper_gap[k])
                f = forces[i]
                self.emit(
                    "grasp",
                    f"grip closed: gap {gap * 1000:.1f} mm, pad forces {f[0]:.1f} / {f[1]:.1f} N",
                    tick=k,
                )
                if gap < cr.grasp_gap_fraction * self._brick_width or not (f > firm_force).all():
                    text = (
                        f"after closing the finger gap is {gap * 1000:.1f} mm (brick "
                        f"{self._brick_width * 1000:.0f} mm) and pad forces are {f[0]:.1f} / "
                        f"{f[1]:.1f} N (need > {firm_force:.0f} N each)"
                    )
                    out.append((k, 5, "missed-grasp", text))
                    self._grasp_state = "released"
                    break
                self._grasp_state = "holding"
                self._p_GO_grasp = p_GO_all[i].copy()
                slip = np.linalg.norm(p_GO_all - self._p_GO_grasp, axis=1).tolist()
                continue
            # holding
            holding[i] = True
            s = slip[i]
            if t <= t_place + 1e-9:
                log.slip[k] = s
            if touching[i]:
                self._contact_lost_since = None
            elif self._contact_lost_since is None:
                self._contact_lost_since = t
            lost = (
                self._contact_lost_since is not None
                and t - self._contact_lost_since >= cr.drop_contact_loss - 1e-9
            )
            if t < t_place - 1e-9 and (s > cr.drop_slip or lost):
                why = (
                    f"it moved {s * 1000:.0f} mm in the gripper frame"
                    if s > cr.drop_slip
                    else f"no pad contact for {cr.drop_contact_loss:.2f} s"
                )
                self.emit(
                    "drop", f"brick left the gripper at t={t:.3f} s: {why}", level="error", tick=k
                )
                out.append((k, 5, "dropped", f"brick left the gripper at t={t:.3f} s ({why})"))
                self._grasp_state = "released"
            elif t >= t_release - 1e-9:
                self._grasp_state = "released"
                gap = float(log.gripper_gap[k])
                self.emit("release", f"gripper opened: gap {gap * 1000:.1f} mm", tick=k)
        return out

    # ------------------------------------------------------------------ verdict

    def _brick_at_rest(self) -> bool:
        a = self.scene.brick_dof_adr
        v = self.data.qvel[a : a + 6]
        cr = self.criteria
        return bool(
            float(v[:3] @ v[:3]) < cr.rest_speed**2
            and float(v[3:] @ v[3:]) < cr.rest_angular_speed**2
        )

    def placement_problems(self) -> list[str]:
        """Reasons the brick is not verifiably resting in the target bin (empty if it is)."""
        cr, sc = self.criteria, self.scene
        X_WO = self.brick_pose()
        corners_W = np.asarray(X_WO.rotation().as_matrix() @ self._corners_O.T).T
        corners_W = corners_W + X_WO.translation()
        problems: list[str] = []
        bin_ = sc.target_bin
        if not bin_.contains_xy(corners_W):
            problems.append(f"footprint not inside {bin_.name}'s inner walls")
        lowest = float(corners_W[:, 2].min())
        if abs(lowest - bin_.floor_top_z) > cr.floor_tolerance:
            problems.append(
                f"lowest corner at z={lowest:.3f} m, {bin_.name} floor at "
                f"z={bin_.floor_top_z:.3f} m"
            )
        z_O = X_WO.rotation().as_matrix()[:, 2]
        tilt = float(np.arccos(np.clip(z_O[2], -1.0, 1.0)))
        if tilt > cr.max_tilt:
            problems.append(f"tilted {np.rad2deg(tilt):.0f} deg")
        if not self._brick_at_rest():
            problems.append("still moving")
        if self.brick_touches_gripper():
            problems.append("still touching the gripper")
        if self.gripper_gap() < self._brick_width:
            problems.append(f"gripper not open (gap {self.gripper_gap() * 1000:.0f} mm)")
        return problems

    def _sorted_events(self) -> list[Event]:
        return sorted(self.events, key=lambda e: e.tick)

    def _result(self, wall: float) -> RunResult:
        log = self.log
        X_WO = self.brick_pose()
        goal = self.task.X_WO_goal
        if self.failure is None and self.ticks > 0 and self.task.goal == "place":
            problems = self.placement_problems()
            if problems:
                self.fail("not-in-target-bin", "; ".join(problems))
        success = self.failure is None and self.ticks > 0
        if self.ticks == 0 and self.failure is None:
            self.failure = "interrupted"
        ticks = self.ticks
        sl = slice(0, ticks)
        counts = {s: 0 for s in IK_STATUSES}
        for code, c in zip(*np.unique(log.ik_status[sl], return_counts=True), strict=True):
            counts[IK_STATUSES[int(code)]] = int(c)
        slip = log.slip[sl]
        slip = slip[np.isfinite(slip)]
        finite = lambda x: float(x) if np.isfinite(x) else None  # noqa: E731
        metrics: dict[str, Any] = {
            "place_error_m": (
                float(np.linalg.norm(X_WO.translation() - goal.translation())) if goal else None
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
        return RunResult(
            scenario=self.task.scenario,
            controller=self.controller.name,
            seed=self.task.seed,
            goal=self.task.goal,
            success=success,
            failure=self.failure,
            failure_tick=self.failure_tick,
            failure_time_s=None if self.failure_tick is None else self.failure_tick * self.dt,
            ticks=ticks,
            sim_time_s=ticks * self.dt,
            wall_time_s=wall,
            brick_start_xyz=[float(x) for x in self.task.X_WO_start.translation()],
            brick_final_xyz=[float(x) for x in X_WO.translation()],
            target_xyz=[float(x) for x in goal.translation()] if goal else [],
            events=self._sorted_events(),
            metrics=metrics,
        )


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


def _as_slice(ids: np.ndarray) -> slice | np.ndarray:
    """A slice for consecutive ids (cheaper indexing every tick), else the ids."""
    if len(ids) and np.array_equal(ids, np.arange(ids[0], ids[0] + len(ids))):
        return slice(int(ids[0]), int(ids[0]) + len(ids))
    return ids
