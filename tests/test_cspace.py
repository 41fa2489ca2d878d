"""C-space paths around obstacles: the spline, the joint segment, OMPL's planning, the plan."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest
from mink.lie import SE3

from pickplace.control.kinematics import ArmKinematics
from pickplace.geometry import rotation_vector_W
from pickplace.planning import cspace
from pickplace.planning.cspace import (
    CSpaceConfig,
    CSpaceResult,
    JointMotion,
    JointPath,
    plan_joint_path,
)
from pickplace.planning.planner import PickPlacePlanner, PlanningReport
from pickplace.signals import Interrupted
from pickplace.sim.loader import load_scene
from pickplace.world.cell import ObstacleCell
from pickplace.world.obstacles import with_obstacles
from pickplace.world.placements import brick_on_floor, nominal_placement, target_placement
from pickplace.world.scene import Scene
from tests.conftest import uniform_task

# Tall enough that the Cartesian transfer's brick runs into it (measured: the via-point path
# passes 8 mm over a 0.22 m divider), low enough to clear the hand at home (0.29 m).
DIVIDER = 0.26


@cache
def divided() -> Scene:
    return with_obstacles(load_scene(), ObstacleCell(divider_height=DIVIDER))


@cache
def divided_report() -> tuple[PickPlacePlanner, PlanningReport]:
    scene = divided()
    planner = PickPlacePlanner(scene, "qp", seed=3)
    X_pick = brick_on_floor(scene, nominal_placement(scene), scene.source_bin.floor_top_z)
    X_place = brick_on_floor(scene, target_placement(scene), scene.target_bin.floor_top_z)
    return planner, planner.plan(X_pick, X_place)


def _knots() -> np.ndarray:
    rng = np.random.default_rng(5)
    return np.cumsum(rng.uniform(-0.4, 0.4, size=(6, 7)), axis=0)


# ----------------------------------------------------------------------------- the spline


def test_the_spline_passes_through_its_knots_in_order_of_scaled_chord_length() -> None:
    knots, w = _knots(), np.linspace(1.2, 0.3, 7)
    path = JointPath(knots, w)
    chords = np.linalg.norm(np.diff(knots, axis=0) * w, axis=1)
    s = np.concatenate([[0.0], np.cumsum(chords)]) / chords.sum()
    for u, q in zip(s, knots, strict=True):
        np.testing.assert_allclose(path.at(float(u))[0], q, atol=1e-12)
    assert path.length == pytest.approx(chords.sum())


def test_the_splines_derivative_is_its_finite_difference_and_its_curvature_is_continuous() -> None:
    path = JointPath(_knots(), np.ones(7))
    h = 1e-6
    for u in np.linspace(0.01, 0.99, 37):
        q_minus, q_plus = path.at(u - h)[0], path.at(u + h)[0]
        np.testing.assert_allclose(path.at(u)[1], (q_plus - q_minus) / (2 * h), atol=1e-5)

    # q'' from either side of an inner knot agrees (C²), and is 0 at both ends (natural).
    def second(u: float, side: float) -> np.ndarray:
        e = 1e-4
        return (path.at(u + side * e)[1] - path.at(u)[1]) / (side * e)

    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path.knots, axis=0), axis=1))])
    for u in (s / s[-1])[1:-1]:
        scale = 1.0 + float(np.abs(second(u, 1.0)).max())
        assert np.abs(second(u, 1.0) - second(u, -1.0)).max() < 1e-2 * scale
    assert np.abs(second(0.0, 1.0)).max() < 1e-2 * (1.0 + np.abs(second(0.5, 1.0)).max())


def test_a_spline_refuses_too_few_or_repeated_knots() -> None:
    with pytest.raises(Exception, match="knots"):
        JointPath(np.zeros((1, 3)), np.ones(3))
    with pytest.raises(Exception, match="differ"):
        JointPath(np.zeros((3, 3)), np.ones(3))


def test_the_joint_segments_pose_and_velocity_are_the_forward_kinematics_of_its_path() -> None:
    """V_WG = J q'(u) u̇ equals the finite difference of FK(q(u)) (position and rotation)."""
    scene = divided()
    q0 = scene.robot.q_home
    knots = np.array([q0, q0 + 0.3, q0 + np.linspace(-0.4, 0.4, len(q0))])
    motion = JointMotion(JointPath(knots, np.ones(len(q0))), ArmKinematics(scene))
    u_dot, h = 0.7, 1e-6
    for u in (0.1, 0.45, 0.8):
        x, V, q, q_dot = motion.sample(u, u_dot)
        x_minus, x_plus = motion.sample(u - h, u_dot)[0], motion.sample(u + h, u_dot)[0]
        np.testing.assert_allclose(V[:3], (x_plus[4:] - x_minus[4:]) / (2 * h) * u_dot, atol=1e-5)
        omega = rotation_vector_W(x_minus[:4], x_plus[:4]) / (2 * h) * u_dot
        np.testing.assert_allclose(V[3:], omega, atol=1e-5)
        np.testing.assert_allclose(q_dot, motion.path.at(u)[1] * u_dot)
        kin = ArmKinematics(scene)
        kin.update(q)
        np.testing.assert_allclose(x, kin.wxyz_xyz(), atol=1e-12)


# ---------------------------------------------------------------------------- the planner


def test_the_divider_blocks_the_cartesian_transfer_and_the_cspace_one_passes() -> None:
    _, report = divided_report()
    assert report.feasible
    chosen = report.candidates[report.chosen or 0]
    assert chosen.cspace is not None
    assert chosen.cspace.cartesian_problem.kind == "collision"
    assert "cell_divider" in chosen.cspace.cartesian_problem.text
    planners = {(m.start, m.end): m.planner for m in chosen.motions()}
    assert planners[("lift", "pre-place")] == "c-space"
    assert list(planners.values()).count("c-space") == 1
    assert report.planner_time_s["c-space"] > 0 and report.planner_time_s["cartesian"] > 0
    d = report.as_dict()["candidates"][report.chosen or 0]
    assert d["motions"] and d["c_space"]["found"]


def test_a_transfer_through_a_singularity_is_planned_in_cspace_instead() -> None:
    """panda-hand, a uniform pose on bin 1's far side (seed 98670): the Cartesian transfer
    takes the wrist to σmin 0.016 (the pre-flight's floor is 0.02) with every candidate; a
    joint-space path between the same lift and pre-place configurations keeps σmin above
    the floor, and the plan is feasible."""
    _, planner, X_pick, X_place = uniform_task("panda-hand", 98670)
    report = planner.plan(X_pick, X_place)
    assert report.feasible
    chosen = report.candidates[report.chosen or 0]
    assert chosen.cspace is not None
    assert chosen.cspace.cartesian_problem.kind == "singularity"
    assert {(m.start, m.end): m.planner for m in chosen.motions()}[("lift", "pre-place")] == (
        "c-space"
    )
    floor = planner.preflight.config.min_singular_value
    assert chosen.preflight.min_singular_value >= floor


@pytest.mark.slow
def test_a_cspace_transfer_whose_timing_stalls_is_that_candidate_s_problem() -> None:
    """menagerie-panda-hand, the can at uniform seed 98023: the first candidate's singular
    transfer, planned in C-space, leaves a lift no speed within the limits can time (it
    raised out of the planner and lost the sweep's trial); it is that candidate's
    ``speed-limit`` problem, and the next candidate plans."""
    from pickplace.run.runner import RunRequest, plan_report

    report = plan_report(
        RunRequest(
            scenario="pick-place-uniform", robot="menagerie-panda-hand", object="can", seed=98023
        )
    )
    first = report.candidates[0]
    assert first.cspace is not None and first.cspace.cartesian_problem.kind == "singularity"
    assert first.preflight.problem is not None
    assert first.preflight.problem.kind == "speed-limit"
    assert "stalls" in first.preflight.problem.text
    assert report.feasible and report.chosen is not None and report.chosen > 0


def test_the_cspace_path_keeps_the_clearance_with_the_held_brick_everywhere() -> None:
    """Checked independently of the planner's own check: half its step along the spline."""
    planner, report = divided_report()
    chosen = report.candidates[report.chosen or 0]
    traj = chosen.plan.trajectory
    k = next(i for i, js in enumerate(traj.joint_segments) if js is not None)
    motion = traj.joint_segments[k]
    assert isinstance(motion, JointMotion)
    scene, pf = planner.scene, planner.preflight
    assert chosen.plan.X_OG is not None
    X_GO = chosen.plan.X_OG.inverse()
    X_pick = brick_on_floor(scene, nominal_placement(scene), scene.source_bin.floor_top_z)
    X_place = brick_on_floor(scene, target_placement(scene), scene.target_bin.floor_top_z)
    kinds = pf.pair_kinds(X_pick, X_place)
    kin = ArmKinematics(scene)
    w = planner.lever_arms
    u, lowest = 0.0, math.inf
    while u <= 1.0:
        q, dq = motion.path.at(u)
        kin.update(q)
        d, _ = pf.clearance(q, scene.brick_width, kin.X_WG() @ X_GO, kinds, True)
        lowest = min(lowest, d)
        u += 0.005 / max(float(np.sum(np.abs(dq) * w)), 0.005)
    assert lowest >= pf.config.clearance
    # The segment's ends are the keyframes' poses exactly.
    for key, uu in ((traj.keyframes[k], 0.0), (traj.keyframes[k + 1], 1.0)):
        np.testing.assert_allclose(motion.sample(uu, 0.0)[0][4:], key.X_WG.translation(), atol=1e-9)


def test_the_timed_cspace_motion_stays_within_the_joint_speed_and_acceleration_limits() -> None:
    planner, report = divided_report()
    traj = report.plan.trajectory
    k = next(i for i, js in enumerate(traj.joint_segments) if js is not None)
    t0, t1 = traj.keyframes[k].t, traj.keyframes[k + 1].t
    robot = planner.scene.robot
    assert robot.a_max is not None
    ts = np.linspace(t0, t1, 801)[1:-1]
    qd = np.array([traj.joint_sample(float(t))[1] for t in ts])  # type: ignore[index]
    assert np.abs(qd).max(axis=0) / robot.v_max == pytest.approx(
        np.minimum(np.abs(qd).max(axis=0) / robot.v_max, 1.0 + 0.02)
    )
    assert (np.abs(qd) / robot.v_max).max() <= planner.timing.speed_margin + 0.02
    qdd = np.diff(qd, axis=0) / np.diff(ts)[:, None]
    assert (np.abs(qdd) / robot.a_max).max() <= 1.05
    # At rest at both ends, and the pose continuous across them.
    for t in (t0, t1):
        before, after = traj.sample(t - 1e-9), traj.sample(t + 1e-9)
        np.testing.assert_allclose(before[0][4:], after[0][4:], atol=1e-6)
        assert np.abs(after[1]).max() < 1e-3 and np.abs(before[1]).max() < 1e-3


def test_the_same_seed_gives_the_same_path_and_another_seed_another() -> None:
    scene = divided()
    X_pick = brick_on_floor(scene, nominal_placement(scene), scene.source_bin.floor_top_z)
    X_place = brick_on_floor(scene, target_placement(scene), scene.target_bin.floor_top_z)

    def knots(seed: int) -> np.ndarray:
        report = PickPlacePlanner(scene, "qp", seed=seed).plan(X_pick, X_place)
        js = next(j for j in report.plan.trajectory.joint_segments if j is not None)
        assert isinstance(js, JointMotion)
        return js.path.knots

    a, b, c = knots(11), knots(11), knots(12)
    np.testing.assert_array_equal(a, b)
    assert a.shape != c.shape or not np.array_equal(a, c)


def _check_free(q: np.ndarray) -> tuple[float, None]:
    return 1.0, None


def test_a_start_in_collision_is_refused_naming_the_pair() -> None:
    def check(q: np.ndarray) -> tuple[float, tuple[str, str, tuple[float, ...]] | None]:
        return (-0.01, ("arm/link4", "cell_box1", (0.0, 0.0, 0.0))) if q[0] < 0.5 else (1.0, None)

    result = plan_joint_path(
        check, np.zeros(2), np.ones(2), -np.ones(2), 2 * np.ones(2), np.ones(2), 0.005, 1
    )
    assert result.path is None and result.problem is not None
    assert "start" in result.problem and "arm/link4" in result.problem
    assert "cell_box1" in result.problem


@pytest.mark.parametrize("start", [np.array([3.0, 0.0]), np.array([np.nan, 0.0])])
def test_an_end_outside_the_search_bounds_is_refused_before_any_check(start: np.ndarray) -> None:
    """A start outside the bounds (or not a number) would leave RRT-Connect nothing to grow
    from until the wall-time bound ends it: it is the problem at once, no check made."""
    calls: list[np.ndarray] = []

    def check(q: np.ndarray) -> tuple[float, tuple[str, str, tuple[float, ...]] | None]:
        calls.append(q)
        return 1.0, None

    result = plan_joint_path(
        check, start, np.ones(2), -np.ones(2), 2 * np.ones(2), np.ones(2), 0.005, 1
    )
    assert result.path is None and result.problem is not None
    assert "start (the lift) lies outside the search's joint bounds: joint 0" in result.problem
    assert not calls and result.checks == 0


def test_a_refinement_that_does_not_reach_its_pose_is_none() -> None:
    """The C-space path's ends are refined to their keyframes' poses: exactly where the arm
    reaches (the forward kinematics there is the pose), None for a pose 3 m away (the steps
    run off instead of converging)."""
    scene = load_scene()
    planner = PickPlacePlanner(scene, "qp")
    kin = ArmKinematics(scene)
    q_home = scene.robot.q_home
    kin.update(q_home + 0.05)
    X_near = kin.X_WG()
    q = planner._exact(q_home, X_near)
    assert q is not None
    kin.update(q)
    np.testing.assert_allclose(kin.X_WG().translation(), X_near.translation(), atol=1e-9)
    X_far = SE3.from_translation(np.array([3.0, 0.0, 0.5]))
    assert planner._exact(q_home, X_far) is None


def _wall(q: np.ndarray) -> tuple[float, tuple[str, str, tuple[float, ...]] | None]:
    """A wall at q₀ ∈ [0.45, 0.55] below q₁ = 0.8 in a 2-joint toy space."""
    if 0.45 <= q[0] <= 0.55 and q[1] < 0.8:
        return -0.01, ("toy/link", "wall", (0.0, 0.0, 0.0))
    return 1.0, None


def test_a_toy_wall_is_passed_over_every_spline_point_free() -> None:
    result = plan_joint_path(
        _wall, np.zeros(2), np.array([1.0, 0.0]), -np.ones(2), 2 * np.ones(2), np.ones(2), 0.0, 4
    )
    assert result.path is not None and result.problem is None
    qs = result.path.samples(4000)
    assert all(_wall(q)[0] >= 0.0 for q in qs)
    assert qs[:, 1].max() >= 0.8  # over the wall
    np.testing.assert_allclose(qs[0], [0, 0], atol=1e-12)
    np.testing.assert_allclose(qs[-1], [1, 0], atol=1e-12)


def _walled_off(q: np.ndarray) -> tuple[float, tuple[str, str, tuple[float, ...]] | None]:
    """A toy check: a wall across the whole space at q0 in [0.45, 0.55] (no way around)."""
    if 0.45 <= q[0] <= 0.55:
        return -0.01, ("toy/link", "wall", (0.0, 0.0, 0.0))
    return 1.0, None


def _plan_through_the_wall(config: CSpaceConfig) -> CSpaceResult:
    """From (0, 0) to (1, 0) through :func:`_walled_off`'s wall: no path exists."""
    return plan_joint_path(
        _walled_off,
        np.zeros(2),
        np.array([1.0, 0.0]),
        -np.ones(2),
        2 * np.ones(2),
        np.ones(2),
        0.0,
        4,
        config,
    )


def test_no_path_within_the_budget_names_what_refused_most() -> None:
    result = _plan_through_the_wall(CSpaceConfig(max_checks=500))
    assert result.path is None and result.problem is not None
    assert "within 500 collision checks" in result.problem and "wall" in result.problem
    assert result.checks <= 500 + 1  # the budget is counted, not timed: the same everywhere


def test_the_wall_time_bound_also_ends_a_planning() -> None:
    result = _plan_through_the_wall(CSpaceConfig(max_checks=10**9, budget_s=0.05))
    assert result.path is None and result.time_s < 1.0


def test_a_stop_request_ends_the_planning(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = {"n": 0}

    def stop() -> None:
        calls["n"] += 1
        if calls["n"] > 2:
            raise Interrupted(2)

    monkeypatch.setattr(cspace, "stop_point", stop)

    with pytest.raises(Interrupted):
        _plan_through_the_wall(CSpaceConfig(budget_s=30.0))


def test_the_config_is_validated() -> None:
    with pytest.raises(Exception, match="budget_s"):
        CSpaceConfig(budget_s=0.0)
    with pytest.raises(Exception, match="max_refinements"):
        CSpaceConfig(max_refinements=-1)
    with pytest.raises(Exception, match="max_checks"):
        CSpaceConfig(max_checks=0)


def test_a_run_over_the_divider_follows_the_joint_path_and_touches_nothing() -> None:
    """The loop gives the controller the C-space motion's joint path (its posture): the
    commanded joints converge onto it (from the null-space offset the IK's 100 Hz lift
    posture has from the pre-flight's 20 Hz one: 0.05 rad measured, without following it grows
    to 0.1 rad), and the physics sees no robot–world contact."""
    from pickplace.run.runner import RunRequest, prepare
    from pickplace.sim.vary import parse_vary

    draw = parse_vary([f"divider_height={DIVIDER}"]).draw(0)
    _, task, sim = prepare(RunRequest(parameters=draw))
    result = sim.run()
    assert result.success, result.failure_text
    assert result.metrics["max_robot_world_contact_force_n"] == 0.0
    traj = task.plan.trajectory
    k = next(i for i, js in enumerate(traj.joint_segments) if js is not None)
    t0, t1 = traj.keyframes[k].t, traj.keyframes[k + 1].t
    # q_cmd of tick i is the command for the next tick's time.
    ticks = [i for i in range(result.ticks) if t0 + 0.4 < (i + 1) * sim.dt < t1]
    assert len(ticks) > 50
    deviation = max(
        float(np.abs(sim.log.q_cmd[i] - traj.joint_sample((i + 1) * sim.dt)[0]).max())  # type: ignore[index]
        for i in ticks
    )
    assert deviation < 0.005  # [rad]
