"""The headless loop: trajectory → differential IK → position actuators → MuJoCo physics.

Each control tick (``SimConfig.control_rate_hz``, default 100 Hz):

1. read the planned tool pose X_WG(t), its spatial velocity V_WG(t) and the gripper width;
2. the controller turns them into joint velocities at the commanded configuration q_cmd;
3. q_cmd is integrated from those velocities and sent to the arm's position actuators;
4. MuJoCo steps the physics for one control period at the scene's timestep;
5. the Jacobian's health, the tracking errors, the grasp and the brick are measured and stored.

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
from pickplace.diagnostics import holding_torques, manipulability_measures
from pickplace.errors import InvalidInputError, require_positive
from pickplace.kinematics import rotation_vector_W
from pickplace.scene import Scene
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
    """A disturbance injected by a scenario (see :mod:`pickplace.faults`)."""

    name: str

    def apply(self, run: Simulation, tick: int) -> str | None:
        """Act on the simulation before tick ``tick``; return an event text when it acted."""


class TickObserver(Protocol):
    """Receives the run as it goes (the Rerun recorder is one)."""

    def on_start(self, run: Simulation) -> None:
        """The run is set up; nothing has been stepped."""

    def on_tick(self, run: Simulation, tick: int) -> None:
        """Tick ``tick`` has been stored in ``run.log``."""

    def on_event(self, run: Simulation, event: Event) -> None:
        """An event happened."""

    def on_finish(self, run: Simulation, result: RunResult) -> None:
        """The run is over (also after an interruption or an error)."""


class TickLog:
    """Preallocated per-tick arrays (one row per control tick)."""

    def __init__(self, capacity: int, nbody: int) -> None:
        n = capacity
        self.t = np.zeros(n)
        self.q_cmd = np.zeros((n, 7))
        self.q = np.zeros((n, 7))
        self.qdot_cmd = np.zeros((n, 7))
        self.p_WG_plan = np.zeros((n, 3))
        self.quat_WG_plan = np.zeros((n, 4))  # wxyz
        self.p_WG_cmd = np.zeros((n, 3))
        self.quat_WG_cmd = np.zeros((n, 4))
        self.p_WG = np.zeros((n, 3))
        self.quat_WG = np.zeros((n, 4))
        self.sigma = np.zeros((n, 6))
        self.sigma_t = np.zeros((n, 3))
        self.U_t = np.zeros((n, 3, 3))  # axes of the translational velocity ellipsoid
        self.quat_t = np.zeros((n, 4))  # the same rotation (det U_t = +1) as a wxyz quaternion
        self.condition = np.zeros(n)
        self.condition_t = np.zeros(n)
        self.manipulability = np.zeros((n, 4))
        self.manipulability_t = np.zeros((n, 4))
        self.position_error = np.zeros(n)
        self.orientation_error = np.zeros(n)
        self.gripper_cmd = np.zeros(n)
        self.gripper_gap = np.zeros(n)
        self.pad_force = np.zeros((n, 2))
        self.holding_torque = np.zeros((n, 7))
        self.ik_us = np.zeros(n)
        self.ik_status = np.zeros(n, dtype=np.int8)
        self.body_pos = np.zeros((n, nbody, 3))
        self.body_quat = np.zeros((n, nbody, 4))  # wxyz
        self.slip = np.full(n, np.nan)


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


class Simulation:
    """One run of a task with a controller; call :meth:`run`.

    Args:
        scene: Loaded scene (its model may be modified by faults: load one per run).
        task: The task.
        controller: Differential-IK controller.
        config: Loop settings.
        observers: Receive ticks and events (e.g. the recorder).
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
                f"{1.0 / self.model.opt.timestep:g} Hz (e.g. 100, 125, 250, 500)"
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

        horizon = task.trajectory.end_time + self.criteria.settle_time + self.criteria.failure_grace
        self.max_ticks = int(np.ceil(horizon / self.dt)) + 2
        self.log = TickLog(self.max_ticks, self.model.nbody)
        self.ticks = 0
        self.events: list[Event] = []
        self.failure: str | None = None
        self.failure_tick: int | None = None
        self._stop_tick: int | None = None
        self._keyframe_times = [(k.t, k.name) for k in task.trajectory.keyframes]
        self._next_keyframe = 0
        self._grasp_state = "open"  # open → holding → released
        self._p_GO_grasp: np.ndarray | None = None
        self._contact_lost_since: float | None = None
        self._f6 = np.zeros(6)
        brick_size = scene.brick_half_extents
        # Box corners in the brick frame, for the footprint and resting checks.
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        self._corners_O = signs * brick_size
        self._brick_width = 2.0 * float(brick_size[1])
        self._pad_pairs = [(pad, scene.brick_geom_id) for pad in scene.pad_geom_ids]
        self._time_expected = float(self.data.time)
        self._eig, self._eigvec = np.empty(3), np.empty(9)
        self._inv_v_max = 1.0 / scene.v_max
        self._finger_adr = (int(scene.finger_qpos_adr[0]), int(scene.finger_qpos_adr[1]))
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
        qpos = self.data.qpos
        return float(qpos[self._finger_adr[0]] + qpos[self._finger_adr[1]])

    def pad_forces(self) -> np.ndarray:
        """Normal force [N] of the brick on the left and right pads."""
        forces = np.zeros(2)
        d = self.data
        if d.ncon == 0:
            return forces
        geoms = d.contact.geom[: d.ncon]
        for i, pair in enumerate(self._pad_pairs):
            rows = np.flatnonzero(
                ((geoms[:, 0] == pair[0]) & (geoms[:, 1] == pair[1]))
                | ((geoms[:, 0] == pair[1]) & (geoms[:, 1] == pair[0]))
            )
            for row in rows:
                mujoco.mj_contactForce(self.model, d, int(row), self._f6)
                forces[i] += self._f6[0]
        return forces

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

    def _p_GO(self) -> np.ndarray:
        """Brick centre in the tool frame G [m]."""
        d, site = self.data, self.scene.tool_site_id
        R_WG = d.site_xmat[site].reshape(3, 3)
        return R_WG.T @ (d.xpos[self.scene.brick_body_id] - d.site_xpos[site])

    # ------------------------------------------------------------------ events

    def emit(self, kind: str, text: str, level: str = "info") -> None:
        """Record an event at the current tick."""
        tick = self.ticks
        event = Event(tick=tick, t=tick * self.dt, level=level, kind=kind, text=text)
        self.events.append(event)
        for obs in self.observers:
            obs.on_event(self, event)

    def fail(self, reason: str, text: str) -> None:
        """Record the first failure; the run stops ``failure_grace`` seconds later."""
        if self.failure is not None:
            return
        self.failure = reason
        self.failure_tick = self.ticks
        self._stop_tick = self.ticks + round(self.criteria.failure_grace / self.dt)
        self.emit("failure", f"{reason}: {text}", level="error")

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
        # MuJoCo's warnings become events instead of lines in ./MUJOCO_LOG.TXT.
        previous_handler = mujoco.get_mju_user_warning()
        mujoco.set_mju_user_warning(self._on_mujoco_warning)
        try:
            self._loop()
        except KeyboardInterrupt:
            interrupted = True
        finally:
            mujoco.set_mju_user_warning(previous_handler)
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
            result.events = list(self.events)
        for obs in self.observers:
            obs.on_finish(self, result)
        return result

    def _loop(self) -> None:
        traj = self.task.trajectory
        end = traj.end_time
        settle_ticks = round(self.criteria.settle_time / self.dt)
        end_tick = int(np.ceil(end / self.dt - 1e-9))
        while self.ticks < self.max_ticks:
            k = self.ticks
            if self._stop_tick is not None and k >= self._stop_tick:
                break
            if k > end_tick and (self._brick_at_rest() or k >= end_tick + settle_ticks):
                break
            self._tick(k, k * self.dt)
            if self.failure == "nan":
                self.ticks += 1
                break
            self.ticks += 1

    def _tick(self, k: int, t: float) -> None:
        sc, d, log = self.scene, self.data, self.log
        traj = self.task.trajectory
        for fault in self.task.faults:
            text = fault.apply(self, k)
            if text:
                self.emit("fault", f"fault '{fault.name}': {text}", level="warn")

        x_plan = traj.pose_wxyz_xyz(t)
        V_plan = traj.spatial_velocity(t)
        t0 = time.perf_counter_ns()
        res = self.controller.command(self.q_cmd, x_plan, V_plan)
        ik_ns = time.perf_counter_ns() - t0
        qdot = res.qdot
        if not math.isfinite(float(qdot.sum())):
            self.fail("nan", f"controller returned non-finite joint velocities at t={t:.3f} s")
            qdot = np.zeros(7)
        # The kinematics still hold the FK of the q_cmd the IK just used: the commanded frame.
        log.p_WG_cmd[k] = self.controller.kinematics.p_WG()
        mujoco.mju_mat2Quat(log.quat_WG_cmd[k], self.controller.kinematics.R_WG().ravel())
        self.q_cmd = self.q_cmd + qdot * self.dt

        # Jacobian health (seed notes 003): singular values of J and of its translational rows.
        J = res.J_WG
        sigma = np.linalg.svd(J, compute_uv=False)
        # Translational ellipsoid: eigen-decomposition of J_v J_vᵀ = U Σ² Uᵀ. mju_eig3 returns
        # eigenvalues in decreasing order and U as a proper rotation (columns = axes).
        Jv = J[:3]
        mujoco.mju_eig3(self._eig, self._eigvec, log.quat_t[k], (Jv @ Jv.T).ravel())
        sigma_t = np.sqrt(np.maximum(self._eig, 0.0))
        log.sigma[k] = sigma
        log.sigma_t[k] = sigma_t
        log.U_t[k] = self._eigvec.reshape(3, 3)
        c, *w = manipulability_measures(sigma)
        log.condition[k] = c
        log.manipulability[k] = w
        c, *w = manipulability_measures(sigma_t)
        log.condition_t[k] = c
        log.manipulability_t[k] = w

        ctrl_gripper = traj.gripper_width(t)
        d.ctrl[sc.arm_actuator_ids] = self.q_cmd + self._ff * qdot
        d.ctrl[sc.gripper_actuator_id] = ctrl_gripper
        for _ in range(self.substeps):
            mujoco.mj_step(self.model, d)
        # MuJoCo resets the data (time back to 0) after a NaN and counts a warning, so a state
        # that stopped advancing in time is as bad as a non-finite one.
        self._time_expected += self.substeps * self.model.opt.timestep
        if abs(d.time - self._time_expected) > 1e-6 or not math.isfinite(float(d.qacc.sum())):
            self.fail("nan", f"simulation state became non-finite at t={t:.3f} s")

        # ---- store
        site = sc.tool_site_id
        p_WG = d.site_xpos[site]
        quat_WG = log.quat_WG[k]
        mujoco.mju_mat2Quat(quat_WG, d.site_xmat[site])
        log.t[k] = t + self.dt
        log.q_cmd[k] = self.q_cmd
        log.q[k] = d.qpos[sc.arm_qpos_adr]
        log.qdot_cmd[k] = qdot
        log.p_WG_plan[k] = x_plan[4:]
        log.quat_WG_plan[k] = x_plan[:4]
        log.p_WG[k] = p_WG
        dp = p_WG - x_plan[4:]
        log.position_error[k] = math.sqrt(float(dp @ dp))
        dw = rotation_vector_W(x_plan[:4], quat_WG)
        log.orientation_error[k] = math.sqrt(float(dw @ dw))
        log.gripper_cmd[k] = ctrl_gripper
        log.gripper_gap[k] = self.gripper_gap()
        forces = self.pad_forces()
        log.pad_force[k] = forces
        holding = self._grasp_state == "holding"
        log.holding_torque[k] = holding_torques(J, sc.brick_mass) if holding else 0.0
        log.ik_us[k] = ik_ns * 1e-3
        log.ik_status[k] = _STATUS_CODE[res.status]
        log.body_pos[k] = d.xpos
        log.body_quat[k] = d.xquat

        # ---- checks
        if res.status is IKStatus.NO_SOLUTION:
            self.fail("ik-failed", f"the QP found no solution at t={t:.3f} s")
        e = res.error
        cmd_error = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
        if self.task.goal == "place" and cmd_error > self.criteria.tracking_limit:
            self.fail(
                "ik-failed",
                f"commanded tool is {cmd_error * 1000:.1f} mm from the plan at t={t:.3f} s "
                f"(limit {self.criteria.tracking_limit * 1000:.0f} mm; status {res.status.value})",
            )
        ratio = float((np.abs(qdot) * self._inv_v_max).max())
        if ratio > 1.0 + SPEED_RATIO_TOLERANCE:
            j = int(np.argmax(np.abs(qdot) / sc.v_max))
            self.fail(
                "limit-violated",
                f"joint{j + 1} commanded at {abs(qdot[j]):.2f} rad/s, limit {sc.v_max[j]:.2f} "
                f"rad/s ({ratio:.4f}x) at t={t:.3f} s",
            )
        over = self._limit_violation(log.q[k], log.q_cmd[k])
        if over > POSITION_LIMIT_TOLERANCE:
            self.fail("limit-violated", f"a joint is {over:.4f} rad past its limit at t={t:.3f} s")
        self._keyframe_events(t + self.dt, k)
        if self.task.goal == "place":
            self._grasp_checks(t + self.dt, k, forces)
        for obs in self.observers:
            obs.on_tick(self, k)

    def _on_mujoco_warning(self, message: str) -> None:
        self.emit("mujoco-warning", f"MuJoCo: {message}", level="warn")

    def _limit_violation(self, q: np.ndarray, q_cmd: np.ndarray) -> float:
        """Largest distance [rad] of ``q`` or ``q_cmd`` past a joint limit (0 inside)."""
        sc = self.scene
        return max(
            0.0,
            float((q - sc.q_max).max()),
            float((sc.q_min - q).max()),
            float((q_cmd - sc.q_max).max()),
            float((sc.q_min - q_cmd).max()),
        )

    def _keyframe_events(self, t: float, k: int) -> None:
        while (
            self._next_keyframe < len(self._keyframe_times)
            and self._keyframe_times[self._next_keyframe][0] <= t + 1e-9
        ):
            kt, name = self._keyframe_times[self._next_keyframe]
            self._next_keyframe += 1
            err = self.log.position_error[k]
            self.emit(
                "keyframe",
                f"keyframe '{name}' reached (planned t={kt:.2f} s, "
                f"tool {err * 1000:.1f} mm from plan)",
            )

    def _grasp_checks(self, t: float, k: int, forces: np.ndarray) -> None:
        cr = self.criteria
        t_grasp, t_place, t_release = self._grasp_times
        if self._grasp_state == "open" and t >= t_grasp - 1e-9:
            gap = self.gripper_gap()
            firm = forces > cr.grasp_force_fraction * self.scene.gripper_force_limit
            self.emit(
                "grasp",
                f"grip closed: gap {gap * 1000:.1f} mm, pad forces {forces[0]:.1f} / "
                f"{forces[1]:.1f} N",
            )
            if gap < cr.grasp_gap_fraction * self._brick_width or not np.all(firm):
                self.fail(
                    "missed-grasp",
                    f"after closing the finger gap is {gap * 1000:.1f} mm (brick "
                    f"{self._brick_width * 1000:.0f} mm) and pad forces are {forces[0]:.1f} / "
                    f"{forces[1]:.1f} N (need > "
                    f"{cr.grasp_force_fraction * self.scene.gripper_force_limit:.0f} N each)",
                )
                self._grasp_state = "released"
                return
            self._grasp_state = "holding"
            self._p_GO_grasp = self._p_GO()
        elif self._grasp_state == "holding":
            if self._p_GO_grasp is None:  # holding always starts with a grasp pose
                return
            p_GO = self._p_GO()
            slip = float(np.linalg.norm(p_GO - self._p_GO_grasp))
            if t <= t_place + 1e-9:
                self.log.slip[k] = slip
            touching = bool(np.any(forces > 0.0))
            if touching:
                self._contact_lost_since = None
            elif self._contact_lost_since is None:
                self._contact_lost_since = t
            lost = (
                self._contact_lost_since is not None
                and t - self._contact_lost_since >= cr.drop_contact_loss - 1e-9
            )
            if t < t_place - 1e-9 and (slip > cr.drop_slip or lost):
                why = (
                    f"it moved {slip * 1000:.0f} mm in the gripper frame"
                    if slip > cr.drop_slip
                    else f"no pad contact for {cr.drop_contact_loss:.2f} s"
                )
                self.emit("drop", f"brick left the gripper at t={t:.3f} s: {why}", level="error")
                self.fail("dropped", f"brick left the gripper at t={t:.3f} s ({why})")
                self._grasp_state = "released"
            elif t >= t_release - 1e-9:
                self._grasp_state = "released"
                self.emit("release", f"gripper opened: gap {self.gripper_gap() * 1000:.1f} mm")

    # ------------------------------------------------------------------ verdict

    def _brick_at_rest(self) -> bool:
        v = self.data.qvel[self.scene.brick_dof_adr : self.scene.brick_dof_adr + 6]
        return bool(
            np.linalg.norm(v[:3]) < self.criteria.rest_speed
            and np.linalg.norm(v[3:]) < self.criteria.rest_angular_speed
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

    def _result(self, wall: float) -> RunResult:
        sc, log = self.scene, self.log
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
        ratio = np.abs(log.qdot_cmd[sl]) / sc.v_max if ticks else np.zeros((1, 7))
        viol = 0.0
        for k in range(ticks):
            viol = max(viol, self._limit_violation(log.q[k], log.q_cmd[k]))
        counts = {s: 0 for s in IK_STATUSES}
        for code, c in zip(*np.unique(log.ik_status[sl], return_counts=True), strict=True):
            counts[IK_STATUSES[int(code)]] = int(c)
        slip = log.slip[sl]
        slip = slip[np.isfinite(slip)]
        finite = lambda x: float(x) if np.isfinite(x) else None  # noqa: E731
        sigma_min = float(log.sigma[sl, -1].min()) if ticks else float("nan")
        metrics: dict[str, Any] = {
            "place_error_m": (
                float(np.linalg.norm(X_WO.translation() - goal.translation())) if goal else None
            ),
            "min_singular_value": sigma_min,
            "max_condition_number": finite(log.condition[sl].max()) if ticks else None,
            "min_manipulability_w1": float(log.manipulability[sl, 0].min()) if ticks else None,
            "max_joint_speed_ratio": float(ratio.max()),
            "max_joint_limit_violation_rad": viol,
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
            events=list(self.events),
            metrics=metrics,
        )
