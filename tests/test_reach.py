"""Reach by IK: a pose made by forward kinematics is reached, and the bisection brackets the
reach limit of a line within its tolerance."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from mink.lie import SE3

from pickplace.control.kinematics import ArmKinematics
from pickplace.errors import PlanError, RobotError
from pickplace.robot.compose import load_robot
from pickplace.robot.reach import REACHED, ReachIK, farthest_reachable, shortfall
from pickplace.sim.scenarios import LINE_HEIGHT, LINE_START, full_stretch_distance, reach_line
from pickplace.world.scene import Scene
from tests.toy_robot import TOY_TOML, write_toy_robot


def _ik(scene: Scene) -> ReachIK:
    r = scene.robot
    return ReachIK(scene.arm_model, r.tool_site_id, r.q_min, r.q_max)


def test_a_pose_made_by_forward_kinematics_is_reached_from_home(scene: Scene) -> None:
    robot = scene.robot
    ik, kin = _ik(scene), ArmKinematics(scene)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = robot.q_home + rng.uniform(-0.3, 0.3, robot.n_joints)
        q = np.clip(q, robot.q_min, robot.q_max)
        kin.update(q)
        X_WG = kin.X_WG()
        q_found, err = ik.solve(X_WG, robot.q_home)
        assert err < REACHED
        kin.update(q_found)
        assert np.linalg.norm(kin.p_WG() - X_WG.translation()) < REACHED
        assert np.all(q_found >= robot.q_min) and np.all(q_found <= robot.q_max)


def test_the_reach_limit_is_bracketed_within_its_tolerance(scene: Scene) -> None:
    ik, line = _ik(scene), reach_line(scene, LINE_HEIGHT)
    r = full_stretch_distance(scene, LINE_HEIGHT)
    q_home = scene.robot.q_home
    q_near, err = ik.solve(line(LINE_START), q_home)
    assert err < REACHED
    assert ik.solve(line(r - 0.002), q_near)[1] < REACHED
    short = ik.solve(line(r + 0.002), q_near)[1]
    assert 0.0015 < short < 0.0025  # out of reach by what lies beyond the limit


def test_a_bracket_that_does_not_bracket_is_refused(scene: Scene) -> None:
    ik, line = _ik(scene), reach_line(scene, LINE_HEIGHT)
    q_home = scene.robot.q_home
    with pytest.raises(PlanError, match="cannot reach the line's near end"):
        farthest_reachable(ik, line, q_home, 5.0, 6.0)
    with pytest.raises(PlanError, match="still reaches"):
        farthest_reachable(ik, line, q_home, LINE_START, LINE_START + 0.01)


def test_an_ik_needs_an_arm_only_model(scene: Scene) -> None:
    r = scene.robot
    with pytest.raises(PlanError, match="arm-only"):
        ReachIK(scene.model, r.tool_site_id, r.q_min, r.q_max)
    assert isinstance(reach_line(scene)(0.5), SE3)


def _refusal(tmp_path: Path, base_xy: tuple[float, float]) -> tuple[float, float, float]:
    """The toy arm stood at ``base_xy``: the bin distance, reach and lack its refusal states."""
    toml = TOY_TOML.replace(
        'angle = "degree"', f'angle = "degree"\nbase_pos = [{base_xy[0]}, {base_xy[1]}, 0]'
    )
    path = write_toy_robot(tmp_path, toml=toml)
    with pytest.raises(RobotError, match="cannot reach both bins") as caught:
        load_robot(path)
    found = re.search(
        r"is ([\d.]+) m from the arm's base axis .* reaches ([\d.]+) m towards it: it lacks "
        r"([\d.]+) m",
        str(caught.value),
    )
    assert found is not None, caught.value
    distance, reach, lack = (float(x) for x in found.groups())
    return distance, reach, lack


@pytest.mark.slow  # two refused compositions, 4 s each
def test_an_arm_too_far_from_the_bins_is_refused_with_what_it_lacks(tmp_path: Path) -> None:
    near = _refusal(tmp_path / "near", (-0.6, 0.6))
    far = _refusal(tmp_path / "far", (-0.7, 0.7))
    for (distance, reach, lack), base in ((near, 0.6), (far, 0.7)):
        # bin1 (0, -0.55) and bin2 (0.55, 0) are equally far from (-a, a)
        assert distance == pytest.approx(float(np.hypot(base, base + 0.55)), abs=1e-3)
        assert lack == pytest.approx(distance - reach, abs=2e-3)  # each rounded to 1 mm
        assert 0.0 < reach < distance
    # The reach is the arm's, wherever it stands: moving it away adds to what it lacks only.
    assert far[1] == pytest.approx(near[1], abs=2e-3)
    assert far[2] - near[2] == pytest.approx(far[0] - near[0], abs=2e-3)


def test_the_shortfall_of_a_point_within_reach_is_zero_and_beyond_it_is_the_excess(
    scene: Scene,
) -> None:
    robot = scene.robot
    ik = ReachIK(scene.model, robot.tool_site_id, robot.q_min, robot.q_max, robot.arm_joint_ids)
    R = reach_line(scene, LINE_HEIGHT)(LINE_START).rotation()
    base = robot.p_W_base
    r = full_stretch_distance(scene, LINE_HEIGHT)
    inside = np.array([base[0], base[1] + r - 0.05, LINE_HEIGHT])
    assert shortfall(ik, base, inside, [R], [robot.q_home]) == (0.0, pytest.approx(r - 0.05))
    beyond = np.array([base[0], base[1] + r + 0.1, LINE_HEIGHT])
    lack, distance = shortfall(ik, base, beyond, [R], [robot.q_home])
    assert distance == pytest.approx(r + 0.1)
    assert lack == pytest.approx(0.1, abs=1e-3)
