"""Arm-only kinematics for differential IK: tool pose and Jacobian as functions of q.

The IK works on the scene's arm-only model (:attr:`~pickplace.scene.Scene.arm_model`), in which
every joint but the arm's is removed (fingers, the brick's free joint), so that nq = nv = 7 and
mink's tasks and limits see only the arm. Bodies, sites and geometry are unchanged, so the tool
site's forward kinematics are identical to the simulation's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

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
        out = np.empty(7)
        mujoco.mju_mat2Quat(out[:4], self._R_WG_flat)
        out[4:] = self._p_WG
        return out

    def wxyz_xyz_list(self) -> list[float]:
        """:meth:`wxyz_xyz` as a list of 7 Python floats ([-], [m]), for plain float math."""
        mujoco.mju_mat2Quat(self._quat_WG, self._R_WG_flat)
        return self._quat_WG.tolist() + self._p_WG.tolist()

    def p_WG(self) -> np.ndarray:
        """Position of the tool site in world [m] at the loaded q."""
        return self._p_WG.copy()

    def R_WG(self) -> np.ndarray:
        """Rotation matrix of the tool site in world at the loaded q."""
        return self._R_WG_flat.reshape(3, 3).copy()

    def J_WG(self) -> np.ndarray:
        """Spatial Jacobian (6, 7) of the tool site at the loaded q; a new array.

        Rows are [v; ω]: the velocity of the tool-site origin [m/s] and the angular velocity
        [rad/s], both expressed in world, per unit joint velocity [rad/s].
        """
        J = np.empty((6, self.nv))
        mujoco.mj_jacSite(self.model, self.data, J[:3], J[3:], self.tool_site_id)
        return J


def _rotation_vector_W(
    qw: float, qx: float, qy: float, qz: float, tw: float, tx: float, ty: float, tz: float
) -> tuple[float, float, float]:
    """World-frame rotation vector [rad] taking quaternion q onto t (both wxyz, unit).

    Plain float math: log(t ⊗ q⁻¹) on the short way round, i.e. with e = t ⊗ q⁻¹ = (w, v)
    and w ≥ 0, the vector 2·atan2(‖v‖, w)·v/‖v‖ (zero when v is).
    """
    w = tw * qw + tx * qx + ty * qy + tz * qz
    x = tx * qw - tw * qx - ty * qz + tz * qy
    y = ty * qw - tw * qy - tz * qx + tx * qz
    z = tz * qw - tw * qz - tx * qy + ty * qx
    if w < 0.0:  # q and -q are the same rotation: take the short way round
        w, x, y, z = -w, -x, -y, -z
    norm = math.sqrt(x * x + y * y + z * z)
    if norm == 0.0:
        return 0.0, 0.0, 0.0
    scale = 2.0 * math.atan2(norm, w) / norm
    return scale * x, scale * y, scale * z


def rotation_vector_W(quat_from: np.ndarray, quat_to: np.ndarray) -> np.ndarray:
    """World-frame rotation vector [rad] of the shortest rotation taking ``quat_from`` to
    ``quat_to`` (both wxyz): log(R_to R_fromᵀ), shape (3,)."""
    qw, qx, qy, qz = quat_from.tolist()
    tw, tx, ty, tz = quat_to.tolist()
    return np.array(_rotation_vector_W(qw, qx, qy, qz, tw, tx, ty, tz))


def pose_error_W_floats(
    x_WG: Sequence[float], x_WG_target: Sequence[float]
) -> tuple[float, float, float, float, float, float]:
    """:func:`pose_error_W` in plain Python floats.

    Args:
        x_WG: Current pose [qw, qx, qy, qz, x, y, z] ([-], [m]).
        x_WG_target: Target pose, same layout.

    Returns:
        Position error [m] (3 floats), then the world-frame rotation vector [rad] (3 floats).
    """
    qw, qx, qy, qz, px, py, pz = x_WG
    tw, tx, ty, tz, p_tx, p_ty, p_tz = x_WG_target
    wx, wy, wz = _rotation_vector_W(qw, qx, qy, qz, tw, tx, ty, tz)
    return p_tx - px, p_ty - py, p_tz - pz, wx, wy, wz


def pose_error_W(x_WG: np.ndarray, x_WG_target: np.ndarray) -> np.ndarray:
    """Error (6,) between two poses given as wxyz_xyz vectors (see :meth:`SE3.wxyz_xyz`).

    Returns [p_target − p; log(R_target Rᵀ)]: the position error [m] and the world-frame
    rotation vector [rad] that takes R_WG onto R_WG_target. Plain float math (7-element NumPy
    operations cost more in call overhead than in arithmetic); a new array.
    """
    return np.array(pose_error_W_floats(x_WG.tolist(), x_WG_target.tolist()))


def rotation_angle(quat_a: np.ndarray, quat_b: np.ndarray) -> np.ndarray:
    """Angle [rad] of the rotation between orientations ``quat_a`` and ``quat_b`` (wxyz).

    Equal to ‖rotation_vector_W(quat_a, quat_b)‖, for single quaternions (4,) or stacks
    (..., 4): with q = q_b ⊗ q_a⁻¹ = (w, v), the angle is 2·atan2(‖v‖, |w|) (q and −q are the
    same rotation), accurate near 0 as well as near π.
    """
    a = np.asarray(quat_a, dtype=float)
    b = np.asarray(quat_b, dtype=float)
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    w = aw * bw + ax * bx + ay * by + az * bz
    # Vector part of q_b ⊗ q_a⁻¹: a_w b_v − b_w a_v + a_v × b_v.
    vx = aw * bx - bw * ax + ay * bz - az * by
    vy = aw * by - bw * ay + az * bx - ax * bz
    vz = aw * bz - bw * az + ax * by - ay * bx
    return 2.0 * np.arctan2(np.sqrt(vx * vx + vy * vy + vz * vz), np.abs(w))
