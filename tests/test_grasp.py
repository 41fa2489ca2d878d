"""Facts about the grasp geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mink.lie import SE3, SO3

from pickplace.errors import PlanError
from pickplace.geometry import top_down_rotation
from pickplace.planning.grasp import (
    choose_grasp,
    choose_place_pose,
    top_down_grasps,
    wrap_angle,
    yaw_of,
)
from pickplace.world.placements import brick_pose

BRICK_YAWS = np.linspace(-math.pi, math.pi, 721)
GRIPPER_YAWS = (-3.0, -math.pi / 2, -0.4, 0.0, 1.0, math.pi / 2, 2.9, math.pi)


def gripper_pose(yaw: float) -> SE3:
    return SE3.from_rotation_and_translation(top_down_rotation(yaw), np.array([0.4, 0.0, 0.5]))


def yaw_diff(a: float, b: float) -> float:
    return abs(wrap_angle(a - b))


def test_top_down_grasp_axes() -> None:
    X_OG, X_OG_flipped = top_down_grasps(grasp_height=0.01)
    R = X_OG.rotation().as_matrix()
    np.testing.assert_allclose(R[:, 0], [1, 0, 0], atol=1e-15)  # G's x = O's x
    np.testing.assert_allclose(R[:, 1], [0, -1, 0], atol=1e-15)  # fingers close along O's y
    np.testing.assert_allclose(R[:, 2], [0, 0, -1], atol=1e-15)  # approach = -O's z
    np.testing.assert_allclose(X_OG.translation(), [0, 0, 0.01], atol=0)
    R_flipped = X_OG_flipped.rotation().as_matrix()
    np.testing.assert_allclose(R_flipped[:, 0], [-1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(R_flipped[:, 2], [0, 0, -1], atol=1e-15)
    np.testing.assert_allclose(X_OG_flipped.translation(), [0, 0, 0.01], atol=1e-17)


@pytest.mark.parametrize("yaw", np.linspace(-3.0, 3.0, 13))
def test_top_down_rotation_points_down_with_the_given_yaw(yaw: float) -> None:
    R = top_down_rotation(yaw).as_matrix()
    np.testing.assert_allclose(R[:, 2], [0, 0, -1], atol=1e-15)
    np.testing.assert_allclose(R[:, 0], [math.cos(yaw), math.sin(yaw), 0], atol=1e-15)
    assert yaw_of(top_down_rotation(yaw)) == pytest.approx(yaw, abs=1e-12)


def test_yaw_of_falls_back_to_y_axis_when_x_is_vertical() -> None:
    # G's x axis points straight up; its y axis heads along world -y: yaw 0 like a top grasp.
    R = SO3.from_matrix(np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]]))
    assert yaw_of(R) == pytest.approx(0.0, abs=1e-12)


def test_brick_pose() -> None:
    X_WO = brick_pose(0.1, -0.2, 0.3, 0.7)
    np.testing.assert_allclose(X_WO.translation(), [0.1, -0.2, 0.3])
    np.testing.assert_allclose(X_WO.rotation().as_matrix()[:, 2], [0, 0, 1], atol=1e-15)
    assert X_WO.rotation().compute_yaw_radians() == pytest.approx(0.7, abs=1e-12)


@pytest.mark.parametrize("gripper_yaw", GRIPPER_YAWS)
def test_chosen_grasp_needs_the_smaller_wrist_yaw_change(gripper_yaw: float) -> None:
    X_WG_current = gripper_pose(gripper_yaw)
    options = top_down_grasps(0.005)
    for brick_yaw in BRICK_YAWS:
        X_WO = brick_pose(0.5, -0.3, 0.045, float(brick_yaw))
        X_OG = choose_grasp(X_WO, X_WG_current, grasp_height=0.005)
        assert any(option == X_OG for option in options)
        chosen = yaw_diff(yaw_of((X_WO @ X_OG).rotation()), gripper_yaw)
        other = min(yaw_diff(yaw_of((X_WO @ o).rotation()), gripper_yaw) for o in options)
        assert chosen <= math.pi / 2 + 1e-12
        assert chosen <= other + 1e-12  # ties (yaw difference π/2) may go either way
        # Both options put G at the same point on top of the brick, pointing down.
        X_WG = X_WO @ X_OG
        assert np.max(np.abs(X_WG.translation() - [0.5, -0.3, 0.05])) <= 1e-15
        assert np.max(np.abs(X_WG.rotation().as_matrix()[:, 2] - [0, 0, -1])) <= 1e-15


@pytest.mark.parametrize("reference_yaw", GRIPPER_YAWS)
def test_place_pose_is_the_goal_brick_pose_with_the_smaller_yaw_change_or_else_the_other(
    reference_yaw: float,
) -> None:
    X_OG = top_down_grasps(0.0)[0]
    X_WG_reference = gripper_pose(reference_yaw)
    flip = SE3.from_rotation(SO3.from_z_radians(math.pi))
    for goal_yaw in BRICK_YAWS[::8]:
        X_WO_goal = brick_pose(0.5, 0.3, 0.045, float(goal_yaw))
        X_WG = choose_place_pose(X_WO_goal, X_OG, X_WG_reference)
        candidates = (X_WO_goal @ X_OG, X_WO_goal @ flip @ X_OG)
        assert any(np.allclose(X_WG.wxyz_xyz, c.wxyz_xyz, atol=1e-15) for c in candidates)
        # The brick ends up where asked, up to its π symmetry about z.
        X_WO_placed = X_WG @ X_OG.inverse()
        assert np.max(np.abs(X_WO_placed.translation() - [0.5, 0.3, 0.045])) <= 1e-15
        placed_yaw = yaw_of(X_WO_placed.rotation())
        assert min(
            yaw_diff(placed_yaw, goal_yaw), yaw_diff(placed_yaw, goal_yaw + math.pi)
        ) == pytest.approx(0.0, abs=1e-12)
        change = yaw_diff(yaw_of(X_WG.rotation()), reference_yaw)
        assert change <= math.pi / 2 + 1e-12
        other = min(yaw_diff(yaw_of(c.rotation()), reference_yaw) for c in candidates)
        assert change <= other + 1e-12
        # Told to, the other of the two: the goal turned by half a turn, the larger change.
        X_WG_other = choose_place_pose(X_WO_goal, X_OG, X_WG_reference, other=True)
        pair = {tuple(np.round(x.wxyz_xyz, 12)) for x in (X_WG, X_WG_other)}
        assert pair == {tuple(np.round(c.wxyz_xyz, 12)) for c in candidates}
        assert yaw_diff(yaw_of(X_WG_other.rotation()), reference_yaw) >= change - 1e-12


def test_invalid_grasp_inputs_are_rejected() -> None:
    X_WO = brick_pose(0.5, 0.0, 0.05, 0.0)
    with pytest.raises(PlanError, match="grasp_height must be a finite number"):
        choose_grasp(X_WO, gripper_pose(0.0), grasp_height=math.nan)
    bad = SE3(np.array([0.9, 0.0, 0.0, 0.0, 0.5, 0.0, 0.05]))
    with pytest.raises(PlanError, match=r"X_WO quaternion norm 0\.9 must be 1"):
        choose_grasp(bad, gripper_pose(0.0))
    with pytest.raises(PlanError, match="X_WO_goal quaternion norm"):
        choose_place_pose(bad, top_down_grasps()[0], gripper_pose(0.0))
