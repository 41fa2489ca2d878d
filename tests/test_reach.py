"""Reach by IK: a pose made by forward kinematics is reached, and the bisection brackets the
reach limit of a line within its tolerance."""

from __future__ import annotations

import numpy as np
import pytest
from mink.lie import SE3

from pickplace.control.kinematics import ArmKinematics
from pickplace.control.reach import REACHED, ReachIK, farthest_reachable
from pickplace.errors import PlanError
from pickplace.sim.scenarios import LINE_HEIGHT, LINE_START, full_stretch_distance, reach_line
from pickplace.world.scene import Scene


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
