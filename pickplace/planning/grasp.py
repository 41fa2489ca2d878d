"""Grasp geometry: where the tool site G goes relative to the brick O.

Frames:

* O, the brick: a box about 0.075 (x) × 0.05 (y) × 0.05 (z) m, origin at its centre, lying
  flat (O's z up).
* G, the tool site: origin midway between the finger pads, +z along the approach direction
  (out of the gripper), fingers closing along G's y axis.

The top-down grasp is ``R_OG = Rx(π)`` (G's x = O's x, G's y = -O's y, G's z = -O's z) and
``p_OG = (0, 0, grasp_height)``, so the fingers close across the 0.05 m width. The brick is
symmetric under a rotation by π about O's z, which gives a second, equivalent grasp.

Gripper yaw (``yaw_of``) is the world-frame heading of G's x axis projected on the world xy
plane, ``atan2(x_y, x_x)``. For a downward-pointing gripper this is the rotation about world z
that the wrist has to perform, and :func:`pickplace.geometry.top_down_rotation` has exactly
that yaw.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from mink.lie import SE3, SO3

from pickplace.errors import PlanError
from pickplace.geometry import half_turn, require_pose, vertical_axis, wrap_angle

_HORIZONTAL_TOL = 1e-9
"""Below this horizontal length [-], G's x axis is considered vertical in ``yaw_of``."""


def yaw_of(R_WG: SO3) -> float:
    """Gripper yaw: world heading of G's x axis projected on the world xy plane [rad].

    Well defined whenever G's x axis is not vertical, which always holds for a gripper
    pointing down. If it is vertical, the heading of G's y axis plus π/2 is used instead
    (which equals the yaw of a top-down gripper).

    Args:
        R_WG: Orientation of G in world.

    Returns:
        Yaw in [-π, π] [rad].
    """
    M = R_WG.as_matrix()
    x_x, x_y = float(M[0, 0]), float(M[1, 0])
    if math.hypot(x_x, x_y) > _HORIZONTAL_TOL:
        return math.atan2(x_y, x_x)
    return wrap_angle(math.atan2(float(M[1, 1]), float(M[0, 1])) + 0.5 * math.pi)


def top_down_grasps(grasp_height: float = 0.0) -> tuple[SE3, SE3]:
    """The two symmetric top-down grasps ``X_OG``.

    Args:
        grasp_height: Height of G's origin above the brick centre, along O's z [m].

    Returns:
        ``(X_OG, Rz_O(π) · X_OG)`` with ``R_OG = Rx(π)``, ``p_OG = (0, 0, grasp_height)``.

    Raises:
        PlanError: ``grasp_height`` is not finite.
    """
    if not math.isfinite(grasp_height):
        raise PlanError(f"grasp_height must be a finite number [m], got {grasp_height!r}")
    p_OG = np.array([0.0, 0.0, float(grasp_height)], dtype=np.float64)
    X_OG = SE3.from_rotation_and_translation(SO3.from_x_radians(math.pi), p_OG)
    return X_OG, SE3.from_rotation(SO3.from_z_radians(math.pi)) @ X_OG


def _yaw_change(X_WG: SE3, yaw: float) -> float:
    return abs(wrap_angle(yaw_of(X_WG.rotation()) - yaw))


def choose_grasp(X_WO: SE3, X_WG_current: SE3, grasp_height: float = 0.0) -> SE3:
    """Pick the symmetric top-down grasp that needs the smaller wrist yaw change.

    Args:
        X_WO: Pose of the brick in world.
        X_WG_current: Current pose of the tool site in world.
        grasp_height: Height of G's origin above the brick centre, along O's z [m].

    Returns:
        ``X_OG`` whose world yaw ``yaw_of(R_WO R_OG)`` is closest to ``yaw_of(R_WG_current)``
        (a difference of at most π/2 for a flat brick; ties keep the ``Rx(π)`` grasp).

    Raises:
        PlanError: Invalid pose or grasp height.
    """
    require_pose("X_WO", X_WO)
    require_pose("X_WG_current", X_WG_current)
    yaw = yaw_of(X_WG_current.rotation())
    first, second = top_down_grasps(grasp_height)
    if _yaw_change(X_WO @ second, yaw) < _yaw_change(X_WO @ first, yaw):
        return second
    return first


def choose_place_pose(X_WO_goal: SE3, X_OG: SE3, X_WG_reference: SE3, other: bool = False) -> SE3:
    """Tool pose ``X_WG`` that puts the held brick at ``X_WO_goal``, up to its π symmetry.

    Args:
        X_WO_goal: Goal pose of the brick in world.
        X_OG: Grasp (tool site in brick frame) the brick is held with.
        X_WG_reference: Pose to compare yaws with, normally the pick pose.
        other: Return the option with the larger yaw change instead.

    Returns:
        ``X_WO_goal · X_OG`` or ``X_WO_goal · H · X_OG``, H the half turn about the brick's
        axis nearest vertical (``Rz(π)`` lying with its z up: the same physical brick pose),
        whichever has the smaller yaw change from ``X_WG_reference`` (ties keep the first);
        with ``other``, the one not chosen so.

    Raises:
        PlanError: Invalid pose.
    """
    require_pose("X_WO_goal", X_WO_goal)
    require_pose("X_OG", X_OG)
    require_pose("X_WG_reference", X_WG_reference)
    yaw = yaw_of(X_WG_reference.rotation())
    first = X_WO_goal @ X_OG
    # A half turn about the brick's vertical axis (its z when it lies with its z up).
    second = X_WO_goal @ SE3.from_rotation(half_turn(vertical_axis(X_WO_goal.rotation()))) @ X_OG
    if (_yaw_change(second, yaw) < _yaw_change(first, yaw)) != other:
        return second
    return first


def brick_width_across(X_OG: SE3, half_extents: npt.ArrayLike) -> float:
    """Width of the brick between the fingers under grasp ``X_OG`` [m]: the box's extent along
    the tool's closing axis (G's y), 2 Σᵢ |y_G · eᵢ| hᵢ for half extents hᵢ along O's axes eᵢ."""
    y_O = X_OG.rotation().as_matrix()[:, 1]  # G's closing axis in the brick frame
    return float(2.0 * np.abs(y_O) @ np.asarray(half_extents, dtype=np.float64))
