"""The record of a run, one row per control tick: what the loop stores, and what follows from it.

The loop writes the *raw* rows every tick: the plan, the IK's result and commands, and the
simulated state copied from MuJoCo. :meth:`TickLog.derive` then fills the *derived* rows of a
block of ticks in one vectorised pass: the Jacobian's health (singular values, condition
number, manipulability w1–w4, the translational velocity ellipsoid), the tracking errors, the
grip force, the speed and position limits. The grasp-dependent rows (``slip``,
``holding_torque``) are filled by the grasp monitor (:mod:`pickplace.sim.checks`), which knows the
grasp state.
"""

from __future__ import annotations

import mujoco
import numpy as np
from mink.lie import SE3, SO3

from pickplace.control.diagnostics import holding_torques, jacobian_health_rows
from pickplace.geometry import quaternion_angle, quaternion_step_W
from pickplace.world.scene import Scene

# Codes of TickLog.nonfinite: what first became non-finite at a tick.
FINITE, CONTROLLER_NONFINITE, STATE_NONFINITE = 0, 1, 2
# Length of a pose as mink's parameter vector wxyz_xyz.
POSE_SIZE = 7


class TickLog:
    """Preallocated per-tick arrays of one run.

    Args:
        scene: The scene the run simulates (sizes, addresses and limits).
        capacity: Rows to allocate (the most ticks the run can take).
        dt: Control period [s].
    """

    def __init__(self, scene: Scene, capacity: int, dt: float) -> None:
        n, model = capacity, scene.model
        nq = scene.robot.n_joints  # arm joints
        n_grip = len(scene.robot.gripper_actuator_ids)
        self.scene = scene
        self.dt = dt
        # ---- raw, written by the loop every tick
        self.q_cmd = np.zeros((n, nq))
        self.qdot_cmd = np.zeros((n, nq))
        self.x_WG_plan = np.zeros((n, POSE_SIZE))  # wxyz_xyz, at the tick's start
        self.V_WG_plan = np.zeros((n, 6))  # planned [v; ω] in world at the tick's start
        self.plan_segment = np.zeros(n, dtype=np.int16)  # index of the segment's first keyframe
        self.x_WG_cmd = np.zeros((n, POSE_SIZE))  # wxyz_xyz: FK of the q the IK used
        self.J_WG = np.zeros((n, 6, nq))  # tool Jacobian [v; ω] at that q
        self.gripper_cmd = np.zeros(n)  # commanded pad gap [m]
        self.ik_us = np.zeros(n)
        self.ik_status = np.zeros(n, dtype=np.int8)
        # 1 where the step met a row of the controller's collision limit (collision_held).
        self.collision_held = np.zeros(n, dtype=np.int8)
        # The robot's actuator commands, arm then gripper (one row is sent to MuJoCo per tick):
        # position targets q_cmd + (kv/kp) q̇_cmd, and the gripper command for gripper_cmd.
        self.ctrl = np.zeros((n, nq + n_grip))
        self.qpos = np.zeros((n, model.nq))
        self.p_WG = np.zeros((n, 3))
        self.R_WG = np.zeros((n, 3, 3))
        self.body_pos = np.zeros((n, model.nbody, 3))
        self.body_quat = np.zeros((n, model.nbody, 4))  # wxyz
        self.sensordata = np.zeros((n, model.nsensordata))
        # What became non-finite at the tick (FINITE, CONTROLLER_NONFINITE, STATE_NONFINITE).
        self.nonfinite = np.zeros(n, dtype=np.int8)
        # ---- derived, filled per block by derive()
        self.t = np.zeros(n)  # time at the end of the tick [s]
        self.q = np.zeros((n, nq))
        self.quat_WG = np.zeros((n, 4))  # wxyz
        self.gripper_gap = np.zeros(n)
        self.pad_force = np.zeros((n, 2))
        self.sigma = np.zeros((n, min(6, nq)))
        self.sigma_t = np.zeros((n, 3))
        self.U_t = np.zeros((n, 3, 3))  # axes of the translational velocity ellipsoid
        self.quat_t = np.zeros((n, 4))  # the same rotation (det U_t = +1) as a wxyz quaternion
        self.condition = np.zeros(n)
        self.condition_t = np.zeros(n)
        self.manipulability = np.zeros((n, 4))
        self.manipulability_t = np.zeros((n, 4))
        self.position_error = np.zeros(n)
        self.orientation_error = np.zeros(n)
        self.command_error = np.zeros(n)  # planned vs commanded tool position [m]
        self.robot_world_contacts = np.zeros(n, dtype=np.int32)  # robot-world contact count
        self.robot_world_force = np.zeros(n)  # largest robot-world normal force [N]
        self.speed_ratio = np.zeros(n)  # max over joints of |q̇_cmd| / q̇_max
        self.limit_violation = np.zeros(n)  # largest distance of q or q_cmd past a limit [rad]
        # ---- filled by the grasp checks
        self.holding_torque = np.zeros((n, nq))
        self.slip = np.full(n, np.nan)
        self._inv_v_max = 1.0 / scene.robot.v_max  # for derive()
        self._world_sensor_cols = scene.robot_world_sensor_adr[:, None] + np.arange(4)
        sides = scene.pad_sensor_side
        self._pad_sides = np.zeros((len(sides), 2))  # per pad sensor: 1 in its side's column
        self._pad_sides[np.arange(len(sides)), sides] = 1.0
        self.capacity = n
        self._make_views()

    def _make_views(self) -> None:
        """The views of the rows by part (made again when the log grows)."""
        nq = self.q_cmd.shape[1]
        self.arm_ctrl = self.ctrl[:, :nq]
        self.gripper_ctrl = self.ctrl[:, nq:]
        self.R_WG_flat = self.R_WG.reshape(self.capacity, 9)
        self.quat_WG_plan = self.x_WG_plan[:, :4]
        self.p_WG_plan = self.x_WG_plan[:, 4:]
        self.quat_WG_cmd = self.x_WG_cmd[:, :4]
        self.p_WG_cmd = self.x_WG_cmd[:, 4:]

    def grow(self, capacity: int) -> None:
        """Make room for ``capacity`` rows (a run whose plan was replaced by a longer one),
        keeping every row stored; new rows are as a new log's. Does nothing when the log is
        already that large.

        Args:
            capacity: Rows the log must hold.
        """
        if capacity <= self.capacity:
            return
        old = self.capacity
        for name, value in list(vars(self).items()):
            if not isinstance(value, np.ndarray) or value.base is not None or name[0] == "_":
                continue
            grown = np.zeros((capacity, *value.shape[1:]), dtype=value.dtype)
            if name == "slip":
                grown[:] = np.nan
            grown[:old] = value
            setattr(self, name, grown)
        self.capacity = capacity
        self._make_views()

    @staticmethod
    def bytes_per_tick(scene: Scene) -> int:
        """Memory one row of a log of ``scene`` takes [bytes] (it grows with the bodies and
        sensors of the model)."""
        row = TickLog(scene, 1, 1.0)
        return sum(
            v.nbytes for v in vars(row).values() if isinstance(v, np.ndarray) and v.base is None
        )

    def derive(self, k0: int, k1: int) -> tuple[int, int] | None:
        """Fill the derived rows ``[k0, k1)`` from the raw ones (idempotent).

        Returns:
            ``(tick, contacts)`` of the first tick at which a pad touched the brick in more
            points than its sensor reports (its grip force is then too low), else None.
        """
        if k1 <= k0:
            return None
        sc = self.scene
        sl = slice(k0, k1)
        qpos = self.qpos[sl]
        self.t[sl] = np.arange(k0, k1) * self.dt + self.dt
        self.q[sl] = qpos[:, sc.robot.arm_qpos_adr]
        y_W = self.R_WG[sl][..., :, 1]  # the tool's closing axis, from its logged rotation
        self.gripper_gap[sl] = sc.robot.gap_from_body_poses(
            self.body_pos[sl], self.body_quat[sl], y_W
        )
        pads = sc.pad_sensor_rows(self.sensordata[sl])  # (ticks, sensors, slots, 4)
        self.pad_force[sl] = pads[..., 1].sum(axis=-1) @ self._pad_sides
        found = pads[:, :, 0, 0].max(axis=1)  # contacts counted, slot 0 of each pad sensor
        for k in range(k0, k1):
            mujoco.mju_mat2Quat(self.quat_WG[k], self.R_WG_flat[k])

        # Jacobian health: singular values of J and of its translational rows.
        health = jacobian_health_rows(self.J_WG[sl])
        self.sigma[sl] = health.sigma
        self.sigma_t[sl] = health.sigma_t
        self.U_t[sl] = health.U_t
        self.quat_t[sl] = health.quat_t
        self.condition[sl] = health.condition
        self.manipulability[sl] = health.manipulability
        self.condition_t[sl] = health.condition_t
        self.manipulability_t[sl] = health.manipulability_t

        # The simulated tool is read at the tick's end, the plan sampled at its start: compare
        # both at the end, the plan carried one tick along its own velocity (to O(a dt²)).
        V = self.V_WG_plan[sl]
        p_plan_end = self.p_WG_plan[sl] + V[:, :3] * self.dt
        quat_plan_end = quaternion_step_W(self.quat_WG_plan[sl], V[:, 3:], self.dt)
        self.position_error[sl] = np.linalg.norm(self.p_WG[sl] - p_plan_end, axis=1)
        self.orientation_error[sl] = quaternion_angle(quat_plan_end, self.quat_WG[sl])
        self.command_error[sl] = np.linalg.norm(self.p_WG_plan[sl] - self.p_WG_cmd[sl], axis=1)
        self.speed_ratio[sl] = (np.abs(self.qdot_cmd[sl]) * self._inv_v_max).max(axis=1)
        if self._world_sensor_cols.size:
            world = self.sensordata[sl][:, self._world_sensor_cols]  # (n, bodies, 4)
            self.robot_world_contacts[sl] = world[..., 0].sum(axis=1)
            self.robot_world_force[sl] = world[..., 1].max(axis=1)
        q, q_cmd = self.q[sl], self.q_cmd[sl]
        self.limit_violation[sl] = np.maximum.reduce(
            [
                np.zeros(k1 - k0),
                (q - sc.robot.q_max).max(axis=1),
                (sc.robot.q_min - q).max(axis=1),
                (q_cmd - sc.robot.q_max).max(axis=1),
                (sc.robot.q_min - q_cmd).max(axis=1),
            ]
        )
        over = np.flatnonzero(found > sc.robot.pad_force_slots)
        return (k0 + int(over[0]), int(found[over[0]])) if over.size else None

    def set_holding(self, k0: int, k1: int, holding: np.ndarray, mass: float) -> None:
        """Fill ``holding_torque`` for rows ``[k0, k1)``: the Jᵀ statics of a load of ``mass``
        [kg] at the tool where ``holding`` (bool, k1 − k0) is set, zero elsewhere."""
        self.holding_torque[k0:k1] = 0.0
        if holding.any():
            J = self.J_WG[k0:k1][holding]
            self.holding_torque[k0:k1][holding] = holding_torques(J, mass)

    def restore(self, k: int, data: mujoco.MjData) -> mujoco.MjData:
        """Put the simulated configuration of tick ``k`` into ``data`` (joint positions and
        mocap bodies), with forward kinematics and collision detection run on it.

        Args:
            k: A tick whose raw rows are stored.
            data: MjData of the scene's model, overwritten.

        Returns:
            ``data``, whose contacts are those of the configuration at the end of tick ``k``.
        """
        model = self.scene.model
        data.qpos[:] = self.qpos[k]
        for b in np.flatnonzero(model.body_mocapid >= 0):
            m = model.body_mocapid[b]
            data.mocap_pos[m] = self.body_pos[k, b]
            data.mocap_quat[m] = self.body_quat[k, b]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_collision(model, data)
        return data

    def brick_pose(self, k: int) -> SE3:
        """The brick's pose X_WO at the end of tick ``k``."""
        b = self.scene.brick_body_id
        return SE3.from_rotation_and_translation(
            SO3(np.array(self.body_quat[k, b])), np.array(self.body_pos[k, b])
        )
