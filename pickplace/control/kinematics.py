"""Arm-only kinematics for differential IK: tool pose and Jacobian as functions of q.

The IK works on the scene's arm-only model (:attr:`~pickplace.world.scene.Scene.arm_model`), in
which
every joint but the arm's is removed (the gripper's, the brick's free joint), so that nq = nv =
n, the robot's number of arm joints, and mink's tasks and limits see only the arm. Bodies, sites
and geometry are unchanged, so the tool site's forward kinematics are identical to the
simulation's.
"""

from __future__ import annotations

import mink
import mujoco
import numpy as np
from mink.lie import SE3, SO3

from pickplace.world.scene import Scene


class ArmKinematics:
    """Tool-site forward kinematics and Jacobian of the arm.

    Args:
        scene: The loaded scene.
        model: Arm-only model; the scene's :attr:`Scene.arm_model` if omitted.
    """

    def __init__(self, scene: Scene, model: mujoco.MjModel | None = None) -> None:
        self.model = model if model is not None else scene.arm_model
        self.configuration = mink.Configuration(self.model, q=scene.robot.q_home.copy())
        self.data = self.configuration.data
        self.tool_site = scene.robot.tool_site_name
        self.tool_site_id = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, self.tool_site)
        self.nv = int(self.model.nv)
        # Live views into MjData (its buffers never move): no attribute look-ups per tick.
        self._qpos = self.data.qpos
        self._p_WG = self.data.site_xpos[self.tool_site_id]
        self._R_WG_flat = self.data.site_xmat[self.tool_site_id]
        self._has_equality = self.model.neq > 0
        self._quat_WG = np.empty(4)

    @property
    def q(self) -> np.ndarray:
        """Joint positions currently loaded [rad]."""
        return self.configuration.q

    def update(self, q: np.ndarray) -> None:
        """Load joint positions ``q`` [rad] and run forward kinematics.

        Does what :meth:`mink.Configuration.update` does (the configuration shares this
        MjData), minus its per-call look-ups.
        """
        self._qpos[:] = q
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_comPos(self.model, self.data)  # cdof, for Jacobians
        if self._has_equality:
            mujoco.mj_makeConstraint(self.model, self.data)

    def X_WG(self) -> SE3:
        """Pose of the tool site G in world at the loaded q."""
        return SE3.from_rotation_and_translation(
            SO3.from_matrix(self._R_WG_flat.reshape(3, 3)), self._p_WG.copy()
        )

    def wxyz_xyz(self) -> np.ndarray:
        """Pose of the tool site as mink's parameter vector [qw, qx, qy, qz, x, y, z]
        ([-], [m]); a new array."""
        out = np.empty(4 + 3)  # quaternion, position
        mujoco.mju_mat2Quat(out[:4], self._R_WG_flat)
        out[4:] = self._p_WG
        return out

    def wxyz_xyz_list(self) -> list[float]:
        """:meth:`wxyz_xyz` as a list of Python floats ([-], [m]), for plain float math."""
        mujoco.mju_mat2Quat(self._quat_WG, self._R_WG_flat)
        return self._quat_WG.tolist() + self._p_WG.tolist()

    def p_WG(self) -> np.ndarray:
        """Position of the tool site in world [m] at the loaded q."""
        return self._p_WG.copy()

    def R_WG(self) -> np.ndarray:
        """Rotation matrix of the tool site in world at the loaded q."""
        return self._R_WG_flat.reshape(3, 3).copy()

    def J_WG(self) -> np.ndarray:
        """Spatial Jacobian (6, n) of the tool site at the loaded q; a new array.

        Rows are [v; ω]: the velocity of the tool-site origin [m/s] and the angular velocity
        [rad/s], both expressed in world, per unit joint velocity [rad/s].
        """
        J = np.empty((6, self.nv))
        mujoco.mj_jacSite(self.model, self.data, J[:3], J[3:], self.tool_site_id)
        return J
