"""Spatial algebra shared by every layer: rotations, pose errors, pose checks and boxes.

Each quantity is written once here, in the forms the callers need side by side: on mink's
``SO3``/``SE3`` objects (the plan), on wxyz quaternion stacks (vectorised over the ticks of a
run) and in plain Python floats (the control tick, where six-element NumPy calls cost more in
call overhead than in arithmetic).

Conventions: quaternions are wxyz (mink and MuJoCo); poses as vectors are mink's
``wxyz_xyz`` = [qw, qx, qy, qz, x, y, z]; rotation vectors are axis · angle [rad] on the short
way round (angle in [0, π]); spatial velocities and pose errors are [linear; angular].
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from mink.lie import SE3, SO3

from pickplace.errors import PlanError

FloatArray = npt.NDArray[np.float64]

QUATERNION_NORM_TOL = 1e-9
"""Largest accepted deviation of a pose's quaternion norm from 1 [-]."""


# ------------------------------------------------------------------------------ angles


def wrap_angle(angle: float) -> float:
    """Wrap an angle to [-π, π] [rad]."""
    return math.remainder(angle, 2.0 * math.pi)


# ----------------------------------------------------------------------- rotation log


def rotation_log(R: SO3) -> FloatArray:
    """Axis-angle vector of ``R`` along the shortest arc (angle in [0, π]) [rad].

    Same as mink's ``SO3.log`` (which also flips the quaternion sign when ``w < 0``) except in
    two cases where mink returns zero: a rotation by exactly π (``w == 0``, since
    ``sign(0) == 0``) and rotations smaller than about 2e-10 rad (its epsilon cut-off). Here
    ``2·atan2(|v|, |w|)·v/|v|`` is used, which is accurate at every angle.
    """
    w = float(R.wxyz[0])
    v = np.array(R.wxyz[1:], dtype=np.float64)
    if w < 0.0:
        w, v = -w, -v
    norm = float(np.linalg.norm(v))
    if norm == 0.0:
        return np.zeros(3, dtype=np.float64)
    return np.asarray((2.0 * math.atan2(norm, w) / norm) * v, dtype=np.float64)


def rotation_vector_floats(
    qw: float, qx: float, qy: float, qz: float, tw: float, tx: float, ty: float, tz: float
) -> tuple[float, float, float]:
    """World-frame rotation vector [rad] taking quaternion q onto t (both wxyz, unit).

    The plain-float form of :func:`rotation_vector_W`: log(t ⊗ q⁻¹) on the short way round,
    i.e. with e = t ⊗ q⁻¹ = (w, v) and w ≥ 0, the vector 2·atan2(‖v‖, w)·v/‖v‖ (zero when v is).
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


def rotation_vector_W(quat_from: np.ndarray, quat_to: np.ndarray) -> FloatArray:
    """World-frame rotation vector [rad] of the shortest rotation taking ``quat_from`` to
    ``quat_to`` (both wxyz): log(R_to R_fromᵀ), shape (3,)."""
    qw, qx, qy, qz = quat_from.tolist()
    tw, tx, ty, tz = quat_to.tolist()
    return np.array(rotation_vector_floats(qw, qx, qy, qz, tw, tx, ty, tz))


# ---------------------------------------------------------------------- rotation angle


def rotation_angle(R_a: SO3, R_b: SO3) -> float:
    """Angle of the relative rotation ``R_a⁻¹ R_b``, in [0, π] [rad]."""
    return float(np.linalg.norm(rotation_log(R_a.inverse() @ R_b)))


def quaternion_angle(quat_a: npt.ArrayLike, quat_b: npt.ArrayLike) -> FloatArray:
    """Angle [rad] of the rotation between orientations ``quat_a`` and ``quat_b`` (wxyz).

    The vectorised form of :func:`rotation_angle`, equal to ‖rotation_vector_W(quat_a, quat_b)‖,
    for single quaternions (4,) or stacks (..., 4): with q = q_b ⊗ q_a⁻¹ = (w, v), the angle is
    2·atan2(‖v‖, |w|) (q and −q are the same rotation), accurate near 0 as well as near π.
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
    return np.asarray(2.0 * np.arctan2(np.sqrt(vx * vx + vy * vy + vz * vz), np.abs(w)))


def quaternion_step_W(quat: npt.ArrayLike, omega_W: npt.ArrayLike, dt: float) -> FloatArray:
    """Orientations (..., 4) wxyz turned for ``dt`` [s] at world-frame angular velocities
    ``omega_W`` (..., 3) [rad/s]: exp(ω dt) ⊗ q, vectorised."""
    q = np.asarray(quat, dtype=np.float64)
    w = np.asarray(omega_W, dtype=np.float64)
    speed = np.linalg.norm(w, axis=-1)
    half = 0.5 * speed * dt
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(speed > 0.0, np.sin(half) / np.where(speed > 0.0, speed, 1.0), 0.0)
    ew, ex, ey, ez = np.cos(half), k * w[..., 0], k * w[..., 1], k * w[..., 2]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            ew * qw - ex * qx - ey * qy - ez * qz,
            ew * qx + ex * qw + ey * qz - ez * qy,
            ew * qy + ey * qw + ez * qx - ex * qz,
            ew * qz + ez * qw + ex * qy - ey * qx,
        ],
        axis=-1,
    )


# ---------------------------------------------------------------------------- slerp


def slerp(R_a: SO3, R_b: SO3, alpha: float) -> SO3:
    """Shortest-arc spherical interpolation ``R_a · exp(alpha · log(R_a⁻¹ R_b))``.

    Args:
        R_a: Rotation at ``alpha = 0``.
        R_b: Rotation at ``alpha = 1``.
        alpha: Interpolation fraction [-], normally in [0, 1].
    """
    return R_a @ SO3.exp(alpha * rotation_log(R_a.inverse() @ R_b))


# ------------------------------------------------------------------------ pose error


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
    wx, wy, wz = rotation_vector_floats(qw, qx, qy, qz, tw, tx, ty, tz)
    return p_tx - px, p_ty - py, p_tz - pz, wx, wy, wz


def pose_error_W(x_WG: np.ndarray, x_WG_target: np.ndarray) -> FloatArray:
    """Error (6,) between two poses given as wxyz_xyz vectors (see :meth:`SE3.wxyz_xyz`).

    Returns [p_target − p; log(R_target Rᵀ)]: the position error [m] and the world-frame
    rotation vector [rad] that takes R_WG onto R_WG_target; a new array.
    """
    return np.array(pose_error_W_floats(x_WG.tolist(), x_WG_target.tolist()))


# ------------------------------------------------------------------------ pose checks


def require_pose(name: str, X: SE3) -> None:
    """Raise PlanError unless ``X`` is an SE3 with finite values and a unit quaternion.

    Args:
        name: How to call the pose in the error message (e.g. ``"X_WO_pick"``).
        X: Pose to check.
    """
    if not isinstance(X, SE3):
        raise PlanError(f"{name} must be a mink.lie.SE3, got {type(X).__name__}")
    if not np.all(np.isfinite(X.wxyz_xyz)):
        raise PlanError(f"{name} must be finite, got wxyz_xyz={X.wxyz_xyz.tolist()}")
    norm = float(np.linalg.norm(X.wxyz_xyz[:4]))
    if abs(norm - 1.0) > QUATERNION_NORM_TOL:
        raise PlanError(
            f"{name} quaternion norm {norm!r} must be 1 (within {QUATERNION_NORM_TOL:g})"
        )


# ------------------------------------------------------------------------------ boxes


def box_corners(half_extents: npt.ArrayLike) -> FloatArray:
    """The 8 corners (8, 3) of a box centred at its frame's origin [m].

    Args:
        half_extents: Half sizes along the frame's x, y, z [m]; a zero half size gives the
            corners of a rectangle (each corner twice), e.g. a footprint.
    """
    half = np.asarray(half_extents, dtype=np.float64)
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    return np.asarray(signs * half, dtype=np.float64)


def transform_points(X_WB: SE3, p_B: npt.ArrayLike) -> FloatArray:
    """Points ``p_B`` (N, 3) given in frame B, expressed in world: R_WB p_B + p_WB [m]."""
    R_WB = X_WB.rotation().as_matrix()
    return np.asarray(np.asarray(p_B) @ R_WB.T + X_WB.translation(), dtype=np.float64)


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of (..., 3) arrays by components (about half its cost on small stacks)."""
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], axis=-1)


def rotate_by_quat(quat: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v`` (..., 3) by unit quaternions ``quat`` (..., 4, wxyz)."""
    w = quat[..., :1]
    u = quat[..., 1:]
    t = 2.0 * cross3(u, v)
    return v + w * t + cross3(u, t)


def top_down_rotation(yaw: float) -> SO3:
    """Orientation ``R_WG = Rz(yaw) · Rx(π)`` of a gripper pointing straight down.

    Args:
        yaw: Gripper yaw [rad] (heading of G's x axis in the world xy plane).
    """
    return SO3.from_z_radians(yaw) @ SO3.from_x_radians(math.pi)


def _axis_rotations() -> tuple[FloatArray, ...]:
    """The 24 proper rotations that map the coordinate axes onto themselves (signed
    permutation matrices of determinant 1)."""
    out = []
    for perm in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
        for signs in np.ndindex(2, 2, 2):
            R = np.zeros((3, 3))
            for col, (row, s) in enumerate(zip(perm, signs, strict=True)):
                R[row, col] = -1.0 if s else 1.0
            if np.linalg.det(R) > 0.0:
                out.append(R)
    return tuple(out)


AXIS_ROTATIONS = _axis_rotations()
"""The 24 rotations of a box frame onto itself, up to the box's sizes (identity first)."""


def box_tilt(R_WO: SO3) -> float:
    """Angle [rad] between world z and the nearest of a box frame O's six face normals: 0 for
    a box lying flat on any face."""
    M = R_WO.as_matrix()
    return float(np.arccos(np.clip(np.abs(M[2, :]).max(), -1.0, 1.0)))


def upright_turn(R_WO: SO3) -> FloatArray:
    """The turn R of :data:`AXIS_ROTATIONS` that puts a box frame O's axis nearest world z as
    the z of ``O' = O · R``, the first such (the identity for a box lying with its z up).

    A box standing on a face its frame's z is not normal to (a brick on its end) is, in O',
    the same box lying with its z up (its sizes there: :func:`turned_half_extents`).
    """
    M = R_WO.as_matrix()
    ups = [float((M @ R)[2, 2]) for R in AXIS_ROTATIONS]
    return AXIS_ROTATIONS[int(np.argmax(ups))]


def turned_half_extents(half_extents: npt.ArrayLike, turn: npt.ArrayLike) -> FloatArray:
    """A box's half sizes along the axes of its frame turned to ``O' = O · turn`` [m]: ``|turn|ᵀ
    h`` for half sizes h along O's axes (``turn`` one of :data:`AXIS_ROTATIONS`)."""
    return np.abs(np.asarray(turn, dtype=np.float64)).T @ np.asarray(half_extents, dtype=float)


def vertical_axis(R_WO: SO3) -> int:
    """The index (0 x, 1 y, 2 z) of frame O's axis nearest world z: a half turn about it is a
    symmetry of a box resting on a face, and turns it about the vertical."""
    return int(np.argmax(np.abs(R_WO.as_matrix()[2, :])))


HALF_TURNS = tuple(np.diag([1.0 if i == axis else -1.0 for i in range(3)]) for axis in range(3))
"""The half turns about O's x, y and z, as rotation matrices in O."""


def half_turn(axis: int) -> SO3:
    """The half turn about O's axis ``axis`` (0 x, 1 y, 2 z)."""
    return (SO3.from_x_radians, SO3.from_y_radians, SO3.from_z_radians)[axis](math.pi)


def box_resting_frame(X_WO: SE3, half_extents: npt.ArrayLike) -> SE3 | None:
    """The box's frame turned onto the face it rests on, when that turn maps the box onto
    itself: ``X_WO · R`` with R one of :data:`AXIS_ROTATIONS` such that the box's sizes along
    the turned axes are the same (a half turn about any axis; a quarter turn about an axis
    across two equal sizes), chosen with its z axis nearest world z. A box lying on a face
    that no such turn brings down (a 75 × 50 × 50 mm brick standing on its end) has none.

    Args:
        X_WO: The box's pose in world.
        half_extents: Its half sizes along O's axes [m].

    Returns:
        The turned pose (``X_WO`` itself when its z is the nearest to world z), or None.
    """
    h = np.asarray(half_extents, dtype=float)
    M = X_WO.rotation().as_matrix()
    best: tuple[float, FloatArray] | None = None
    for R in AXIS_ROTATIONS:
        if not np.allclose(np.abs(R) @ h, h, rtol=0.0, atol=1e-9):
            continue
        up = float((M @ R)[2, 2])
        if best is None or up > best[0] + 1e-12:
            best = (up, R)
    assert best is not None  # the identity always qualifies
    up, R = best
    if up < float(np.abs(M[2, :]).max()) - 1e-9:
        return None  # another face is down, and no turn of the box's shape brings it there
    if np.array_equal(R, np.eye(3)):
        return X_WO
    return X_WO @ SE3.from_rotation(SO3.from_matrix(R))
