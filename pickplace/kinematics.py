"""Arm-only kinematics for differential IK: tool pose and Jacobian as functions of q.

The IK works on the scene's arm-only model (:attr:`~pickplace.scene.Scene.arm_model`), in which
every joint but the arm's is removed (fingers, the brick's free joint), so that nq = nv = 7 and
mink's tasks and limits see only the arm. Bodies, sites and geometry are unchanged, so the tool
site's forward kinematics are identical to the simulation's.
"""

from __future__ import annotations

import mink
import mujoco
import numpy as np
from mink.lie import SE3, SO3

from pickplace.scene import Scene


class ArmKinematics:
    """Tool-site forward kinematics and Jacobian of the arm.

    Args:
        scene: The loaded scene.
        model: Arm-only model; the scene's :attr:`Scene.arm_model` if omitted.
    """

    def __init__(self, scene: Scene, model: mujoco.MjModel | None = None) -> None:
        self.model = model if model is not None else scene.arm_model
        self.configuration = mink.Configuration(self.model, q=scene.q_home.copy())
        self.data = self.configuration.data
        self.tool_site = scene.names.tool_site
        self.tool_site_id = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, self.tool_site)
        self._jacp = np.zeros((3, self.model.nv))
        self._jacr = np.zeros((3, self.model.nv))

    @property
    def q(self) -> np.ndarray:
        """Joint positions currently loaded [rad]."""
        return self.configuration.q

    def update(self, q: np.ndarray) -> None:
        """Load joint positions ``q`` [rad] and run forward kinematics."""
        self.configuration.update(q)

    def X_WG(self) -> SE3:
        """Pose of the tool site G in world at the loaded q."""
        R = self.data.site_xmat[self.tool_site_id].reshape(3, 3)
        return SE3.from_rotation_and_translation(
            SO3.from_matrix(R), self.data.site_xpos[self.tool_site_id].copy()
        )

    def wxyz_xyz(self) -> np.ndarray:
        """Pose of the tool site as mink's parameter vector [qw, qx, qy, qz, x, y, z]."""
        out = np.empty(7)
        mujoco.mju_mat2Quat(out[:4], self.data.site_xmat[self.tool_site_id])
        out[4:] = self.data.site_xpos[self.tool_site_id]
        return out

    def p_WG(self) -> np.ndarray:
        """Position of the tool site in world [m] at the loaded q."""
        return self.data.site_xpos[self.tool_site_id].copy()

    def R_WG(self) -> np.ndarray:
        """Rotation matrix of the tool site in world at the loaded q."""
        return self.data.site_xmat[self.tool_site_id].reshape(3, 3).copy()

    def J_WG(self) -> np.ndarray:
        """Spatial Jacobian (6, 7) of the tool site at the loaded q.

        Rows are [v; ω]: the velocity of the tool-site origin [m/s] and the angular velocity
        [rad/s], both expressed in world, per unit joint velocity [rad/s].
        """
        mujoco.mj_jacSite(self.model, self.data, self._jacp, self._jacr, self.tool_site_id)
        return np.vstack([self._jacp, self._jacr])


def rotation_vector_W(quat_from: np.ndarray, quat_to: np.ndarray) -> np.ndarray:
    """World-frame rotation vector [rad] of the shortest rotation taking ``quat_from`` to
    ``quat_to`` (both wxyz): log(R_to R_fromᵀ)."""
    conj = np.empty(4)
    mujoco.mju_negQuat(conj, quat_from)
    q_err = np.empty(4)
    mujoco.mju_mulQuat(q_err, quat_to, conj)
    if q_err[0] < 0.0:  # q and -q are the same rotation: take the short way round
        q_err = -q_err
    w = np.empty(3)
    mujoco.mju_quat2Vel(w, q_err, 1.0)
    return w


def pose_error_W(x_WG: np.ndarray, x_WG_target: np.ndarray) -> np.ndarray:
    """Error (6,) between two poses given as wxyz_xyz vectors (see :meth:`SE3.wxyz_xyz`).

    Returns [p_target − p; log(R_target Rᵀ)]: the position error [m] and the world-frame
    rotation vector [rad] that takes R_WG onto R_WG_target.
    """
    out = np.empty(6)
    out[:3] = x_WG_target[4:] - x_WG[4:]
    out[3:] = rotation_vector_W(x_WG[:4], x_WG_target[:4])
    return out
