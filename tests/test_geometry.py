"""Facts of the geometry layer: rotation vectors, angles, pose errors, slerp and boxes, in
their scalar, vectorised and plain-float forms."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from mink.lie import SE3, SO3

from pickplace.errors import PlanError
from pickplace.geometry import (
    AXIS_ROTATIONS,
    HALF_TURNS,
    box_corners,
    box_resting_frame,
    box_tilt,
    half_turn,
    pose_error_W,
    pose_error_W_floats,
    quaternion_angle,
    require_pose,
    rotation_angle,
    rotation_log,
    rotation_vector_W,
    slerp,
    transform_points,
    upright_turn,
    vertical_axis,
    wrap_angle,
)


def test_pose_error_is_position_difference_and_world_rotation_vector() -> None:
    rng = np.random.default_rng(4)
    for _ in range(200):
        quats = rng.normal(size=(2, 4))
        quats /= np.linalg.norm(quats, axis=1, keepdims=True)
        if rng.random() < 0.3:  # nearly equal orientations, either quaternion sign
            quats[1] = (quats[0] + rng.normal(0.0, 1e-7, 4)) * rng.choice([-1.0, 1.0])
            quats[1] /= np.linalg.norm(quats[1])
        x = np.concatenate([quats[0], rng.normal(size=3)])
        x_target = np.concatenate([quats[1], rng.normal(size=3)])
        error = pose_error_W(x, x_target)
        np.testing.assert_array_equal(error[:3], x_target[4:] - x[4:])
        R, R_target = SO3(wxyz=quats[0]), SO3(wxyz=quats[1])
        expected = (R_target @ R.inverse()).log()
        np.testing.assert_allclose(error[3:], expected, atol=1e-12)
        np.testing.assert_array_equal(rotation_vector_W(quats[0], quats[1]), error[3:])
        # Same as MuJoCo's quaternion routines (the previous implementation).
        conj, q_err, w = np.empty(4), np.empty(4), np.empty(3)
        mujoco.mju_negQuat(conj, quats[0])
        mujoco.mju_mulQuat(q_err, quats[1], conj)
        mujoco.mju_quat2Vel(w, q_err if q_err[0] >= 0.0 else -q_err, 1.0)
        np.testing.assert_allclose(error[3:], w, atol=1e-14)


def test_rotation_vector_at_identity_and_half_turn() -> None:
    q = np.array([0.5, 0.5, -0.5, 0.5])
    assert not np.any(rotation_vector_W(q, q))
    assert not np.any(rotation_vector_W(q, -q))  # −q is the same rotation
    half_turn = np.array([0.0, 0.0, 0.6, 0.8])
    np.testing.assert_allclose(
        rotation_vector_W(np.array([1.0, 0.0, 0.0, 0.0]), half_turn),
        np.pi * np.array([0.0, 0.6, 0.8]),
        atol=1e-15,
    )


def test_rotation_angle_is_the_norm_of_the_rotation_vector_for_stacks_too() -> None:
    rng = np.random.default_rng(5)
    a = rng.normal(size=(200, 4))
    b = rng.normal(size=(200, 4))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    expected = [np.linalg.norm(rotation_vector_W(x, y)) for x, y in zip(a, b, strict=True)]
    np.testing.assert_allclose(quaternion_angle(a, b), expected, atol=1e-12)
    # q and −q are one rotation; tiny angles keep their precision; a half turn is π.
    assert quaternion_angle(a[0], -a[0]) == pytest.approx(0.0, abs=1e-15)
    tiny = SO3.exp(np.array([1e-9, 0.0, 0.0])).wxyz
    assert quaternion_angle(np.array([1.0, 0, 0, 0]), tiny) == pytest.approx(1e-9, rel=1e-6)
    half = np.array([0.0, 0.0, 1.0, 0.0])
    assert quaternion_angle(np.array([1.0, 0, 0, 0]), half) == pytest.approx(np.pi)


def test_scalar_and_vectorised_rotation_angles_agree() -> None:
    """rotation_angle on SO3 objects, quaternion_angle on stacks and the norm of the plain-float
    rotation vector are the same angle."""
    rng = np.random.default_rng(6)
    for _ in range(100):
        qa, qb = rng.normal(size=(2, 4))
        qa, qb = qa / np.linalg.norm(qa), qb / np.linalg.norm(qb)
        angle = rotation_angle(SO3(qa), SO3(qb))
        assert quaternion_angle(qa, qb) == pytest.approx(angle, abs=1e-12)
        e = pose_error_W_floats([*qa, 0.0, 0.0, 0.0], [*qb, 0.0, 0.0, 0.0])
        assert math.hypot(*e[3:]) == pytest.approx(angle, abs=1e-12)
        assert 0.0 <= angle <= math.pi


def test_rotation_log_is_accurate_at_zero_and_at_a_half_turn() -> None:
    for angle in (0.0, 1e-12, 1e-6, 1.0, math.pi - 1e-9, math.pi):
        axis = np.array([0.0, 0.6, 0.8])
        R = SO3.exp(angle * axis) if angle < math.pi else SO3(np.array([0.0, *axis]))
        np.testing.assert_allclose(rotation_log(R), angle * axis, atol=1e-15 + 1e-12 * angle)


def test_slerp_hits_its_ends_and_turns_at_a_constant_rate() -> None:
    R_a, R_b = SO3.from_rpy_radians(0.3, -0.2, 1.0), SO3.from_rpy_radians(-1.0, 0.4, -2.0)
    total = rotation_angle(R_a, R_b)
    assert rotation_angle(slerp(R_a, R_b, 0.0), R_a) <= 1e-12
    assert rotation_angle(slerp(R_a, R_b, 1.0), R_b) <= 1e-12
    for alpha in np.linspace(0.0, 1.0, 11):
        R = slerp(R_a, R_b, float(alpha))
        assert rotation_angle(R_a, R) == pytest.approx(alpha * total, abs=1e-12)
        assert rotation_angle(R, R_b) == pytest.approx((1 - alpha) * total, abs=1e-12)


def test_wrap_angle_stays_in_range_and_keeps_the_direction() -> None:
    for angle in np.linspace(-20.0, 20.0, 401):
        w = wrap_angle(float(angle))
        assert -math.pi <= w <= math.pi
        assert math.remainder(w - angle, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)


def test_box_corners_span_the_box_and_transform_into_world() -> None:
    half = np.array([0.0375, 0.025, 0.025])
    corners = box_corners(half)
    assert corners.shape == (8, 3)
    np.testing.assert_array_equal(corners.max(axis=0), half)
    np.testing.assert_array_equal(corners.min(axis=0), -half)
    assert len({tuple(c) for c in corners}) == 8
    X = SE3.from_rotation_and_translation(SO3.from_z_radians(0.5), np.array([1.0, 2.0, 3.0]))
    p_W = transform_points(X, corners)
    for c, p in zip(corners, p_W, strict=True):
        np.testing.assert_allclose(p, X.apply(c), atol=1e-15)


def test_require_pose_names_what_is_wrong() -> None:
    require_pose("X", SE3.identity())
    with pytest.raises(PlanError, match=r"X must be a mink\.lie\.SE3"):
        require_pose("X", np.eye(4))  # type: ignore[arg-type]
    with pytest.raises(PlanError, match=r"X quaternion norm 2\.0 must be 1"):
        require_pose("X", SE3(np.array([2.0, 0, 0, 0, 0, 0, 0])))
    with pytest.raises(PlanError, match="X must be finite"):
        require_pose("X", SE3(np.array([1.0, 0, 0, 0, np.nan, 0, 0])))


def test_a_brick_standing_on_its_end_has_no_resting_frame_and_on_any_other_face_one() -> None:
    """Of the 24 turns of a 75 x 50 x 50 mm brick's frame, the 8 that keep its sizes (a half
    turn about any axis, a quarter turn about x) leave it lying as planned for; the others
    stand it on a 50 x 50 mm end, where the planner's box is not the brick."""
    half = np.array([0.0375, 0.025, 0.025])
    X_WO = SE3.from_rotation_and_translation(SO3.from_z_radians(0.7), np.array([0.1, -0.5, 0.035]))
    corners = box_corners(half)
    kept = 0
    for R in AXIS_ROTATIONS:
        lying = X_WO @ SE3.from_rotation(SO3.from_matrix(R))
        frame = box_resting_frame(lying, half)
        assert box_tilt(lying.rotation()) == pytest.approx(0.0, abs=1e-7)  # arccos near 1
        if np.allclose(np.abs(R) @ half, half):
            kept += 1
            assert frame is not None
            # The same box: its corners are the lying brick's, its z axis world z.
            assert frame.rotation().as_matrix()[2, 2] == pytest.approx(1.0, abs=1e-9)
            a = np.sort(transform_points(frame, corners).round(9), axis=0)
            b = np.sort(transform_points(lying, corners).round(9), axis=0)
            np.testing.assert_allclose(a, b, atol=1e-9)
        elif abs(lying.rotation().as_matrix()[2, 0]) > 0.5:  # its 75 mm axis up
            assert frame is None
    assert kept == 8


def test_upright_turn_puts_the_face_the_box_rests_on_under_a_z_up_frame_of_its_sizes() -> None:
    """For each of the 24 ways a 75 x 50 x 50 mm brick can rest, the turned frame O · R has
    its z up, the box's sizes along its axes are |R|ᵀ h (the corners the same points), and
    the half turn about the axis nearest vertical turns the box about world z onto itself."""
    half = np.array([0.0375, 0.025, 0.025])
    corners = box_corners(half)
    for R in AXIS_ROTATIONS:
        X_WO = SE3.from_rotation_and_translation(
            SO3.from_z_radians(-1.1), np.array([0.2, 0.3, 0.04])
        ) @ SE3.from_rotation(SO3.from_matrix(R))
        turn = upright_turn(X_WO.rotation())
        X_WOp = X_WO @ SE3.from_rotation(SO3.from_matrix(turn))
        assert X_WOp.rotation().as_matrix()[2, 2] == pytest.approx(1.0, abs=1e-12)
        a = np.sort(transform_points(X_WOp, box_corners(np.abs(turn).T @ half)).round(9), axis=0)
        b = np.sort(transform_points(X_WO, corners).round(9), axis=0)
        np.testing.assert_allclose(a, b, atol=1e-9)
        H = SO3.from_matrix(HALF_TURNS[vertical_axis(X_WO.rotation())])
        np.testing.assert_allclose(
            half_turn(vertical_axis(X_WO.rotation())).as_matrix(), H.as_matrix(), atol=1e-15
        )
        R_W = (X_WO.rotation() @ H @ X_WO.rotation().inverse()).as_matrix()
        np.testing.assert_allclose(R_W, np.diag([-1.0, -1.0, 1.0]), atol=1e-12)
        turned = SE3.from_rotation_and_translation(X_WO.rotation() @ H, X_WO.translation())
        c = np.sort(transform_points(turned, corners).round(9), axis=0)
        np.testing.assert_allclose(c, b, atol=1e-9)
