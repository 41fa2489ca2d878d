"""The kinematic pre-flight against what it claims to predict: the loop's commanded path, MuJoCo's
distances, and the physics of runs it passes or refuses."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from mink.lie import SE3

from pickplace.control.controllers import POSTURE_GAIN_PERIOD, QPWeights
from pickplace.errors import ControllerError
from pickplace.planning.plan import grasp_width
from pickplace.planning.planner import Candidate, PickPlacePlanner
from pickplace.planning.preflight import Preflight, PreflightConfig, collision_model
from pickplace.run.runner import RunRequest, prepare
from pickplace.world.placements import BrickPlacement, brick_on_floor, target_placement
from pickplace.world.scene import Scene


def _bin1(scene: Scene, x_B: float, y_B: float, yaw: float) -> BrickPlacement:
    """A brick pose given in bin 1's frame (x, y from its floor centre [m]), yaw [rad]."""
    p = scene.source_bin.X_WB.apply(np.array([x_B, y_B, 0.0]))
    return BrickPlacement(float(p[0]), float(p[1]), yaw)


def _poses(scene: Scene, placement: BrickPlacement):  # type: ignore[no-untyped-def]
    X_pick = brick_on_floor(scene, placement, scene.source_bin.floor_top_z)
    X_place = brick_on_floor(scene, target_placement(scene), scene.target_bin.floor_top_z)
    return X_pick, X_place


@pytest.mark.parametrize(("controller", "atol"), [("qp-no-collision", 0.0), ("qp", 1e-8)])
def test_at_the_control_rate_it_predicts_the_commanded_joint_path_exactly(
    controller: str, atol: float
) -> None:
    """The IK integrates q_cmd open loop and never reads the physics: the pre-flight's joint
    path at the loop's rate is the run's commanded path, bit for bit for the controller it
    runs (qp without its collision limit); the qp run's, whose limit never acts on a plan the
    pre-flight passed, differs by the round-off of the limit's inactive rows in daqp only
    (measured 1.2e-9 rad)."""
    _, task, sim = prepare(RunRequest(controller=controller))
    config = PreflightConfig(rate_hz=1.0 / sim.dt, midpoint_feedforward=False)
    preflight = Preflight(sim.scene, controller, config)
    result = preflight.run(task.plan, task.X_WO_start, task.goal.X_WO_goal, stop_at_problem=False)
    n = min(400, len(result.q) - 1)
    sim.advance(n)
    # Row k of the pre-flight is the q the IK starts tick k from; the log's q_cmd[k] is the q
    # after tick k's step, i.e. the pre-flight's row k + 1.
    np.testing.assert_allclose(result.q[1 : n + 1], sim.log.q_cmd[:n], rtol=0.0, atol=atol)
    assert (getattr(sim.controller, "collision", None) is not None) == (controller == "qp")


def test_at_its_own_rate_it_predicts_a_redundant_arm_s_null_space_within_0_05_rad() -> None:
    """At 20 Hz the pre-flight's joint path is the 100 Hz run's, the 7-joint arm's elbow
    included: the posture task closes the same fraction of its error per second at both
    rates (with a gain per tick it closed five times less per second at 20 Hz, and the
    nominal plan's joints differed by 0.16 rad)."""
    _, task, sim = prepare(RunRequest())
    assert sim.scene.robot.n_joints == 7
    result = Preflight(sim.scene, "qp").run(
        task.plan, task.X_WO_start, task.goal.X_WO_goal, stop_at_problem=False
    )
    sim.advance()
    ticks = np.round(result.times / sim.dt).astype(int)
    inside = ticks < sim.ticks
    diff = np.abs(sim.log.q_cmd[ticks[inside]] - result.q[inside]).max()
    assert diff < 0.05


def test_the_posture_gain_closes_the_same_fraction_per_second_at_any_rate() -> None:
    w = QPWeights()
    assert w.posture_gain_at(POSTURE_GAIN_PERIOD) == w.posture_gain  # the stated gain, exactly
    for dt in (0.002, 0.01, 0.05, 0.1):
        left = (1.0 - w.posture_gain_at(dt)) ** round(0.1 / dt)  # after 0.1 s
        assert left == pytest.approx((1.0 - w.posture_gain) ** 10, rel=1e-12)
    for bad in (0.0, -0.1, 1.5):
        with pytest.raises(ControllerError, match=r"posture gain .*valid: \(0, 1\]"):
            QPWeights(posture_gain=bad)


def test_a_nominal_plan_is_feasible_with_stated_margins(scene: Scene) -> None:
    _, task, _ = prepare(RunRequest())
    cfg = PreflightConfig()
    r = Preflight(scene, "qp").run(task.plan, task.X_WO_start, task.goal.X_WO_goal)
    assert r.feasible, r.problem
    assert r.t_checked == pytest.approx(math.floor(task.trajectory.end_time * cfg.rate_hz) / 20)
    assert cfg.clearance <= r.min_clearance <= cfg.detection_distance
    assert r.min_joint_margin >= cfg.joint_margin
    assert 0.0 < r.peak_speed_ratio <= 1.0 + 1e-9
    assert r.min_singular_value >= cfg.min_singular_value


def _across_the_width(planner: PickPlacePlanner, X_pick: SE3, X_place: SE3) -> Candidate:
    """The vertical grasp across the width, pre-flighted whatever its cheap tests say (the
    planner would not pre-flight it where its footprint fails)."""
    grasp = next(g for g in planner.grasps() if g.label == "across the width")
    plan, result, warning = planner.timed_plan(X_pick, X_place, grasp)
    return Candidate(grasp.label, plan, result, warning)


def test_the_footprint_and_the_pre_flight_agree_on_the_palm_over_a_wall(scene: Scene) -> None:
    """60 mm from the far wall: the cheap footprint test refuses the grasp across the width,
    and its pre-flight finds the palm within the clearance of that wall."""
    planner = PickPlacePlanner(scene, "qp")
    X_pick, X_place = _poses(scene, _bin1(scene, 0.0, -0.09, 0.0))
    ranked = next(r for r in planner.rank(X_pick, X_place) if r.grasp.label == "across the width")
    assert ranked.problem is not None and ranked.clearance < 0.0
    problem = _across_the_width(planner, X_pick, X_place).preflight.problem
    assert problem is not None and problem.kind == "collision"
    assert "palm" in problem.text and "bin1_wall_ny" in problem.text


def test_clearance_is_mujocos_distance_between_the_named_geoms(scene: Scene) -> None:
    """The reported problem names two geoms; MuJoCo's own mj_geomDistance between them, at the
    problem's configuration, is the reported clearance."""
    planner = PickPlacePlanner(scene, "qp")
    X_pick, X_place = _poses(scene, _bin1(scene, 0.0, -0.09, 0.0))  # 60 mm from the far wall
    first = _across_the_width(planner, X_pick, X_place)
    problem = first.preflight.problem
    assert problem is not None and problem.kind == "collision"
    robot_geom, rest = problem.text.split(" comes within ")
    world_geom = rest.split(" of ")[1].split(" (")[0]
    clearance_mm = float(rest.split(" mm")[0])
    # Rebuild the configuration at the problem's time from the pre-flight's joint path.
    m = collision_model(scene, 0.1)
    d = mujoco.MjData(m)
    d.qpos[scene.robot.arm_qpos_adr] = first.preflight.q[-1]
    width = first.plan.trajectory.sample(problem.t)[2]
    d.qpos[scene.gripper_qpos_adr] = scene.robot.qpos_for_width(width)
    scene.set_brick_pose(d, X_pick)
    mujoco.mj_kinematics(m, d)
    g1, g2 = m.geom(robot_geom).id, m.geom(world_geom).id
    dist = mujoco.mj_geomDistance(m, d, g1, g2, 0.1, None)
    assert dist * 1000 == pytest.approx(clearance_mm, abs=0.06)
    assert dist < PreflightConfig().clearance
    assert scene.is_robot_geom(g1) and scene.is_world_geom(g2)


def test_a_palm_over_a_wall_is_refused_and_the_run_would_have_hit_it(scene: Scene) -> None:
    """The class-W failure: 60 mm from the far wall, the palm comes down on its top. The
    pre-flight says collision; the same plan executed anyway touches the wall."""
    planner = PickPlacePlanner(scene, "qp")
    X_pick, X_place = _poses(scene, _bin1(scene, 0.0, -0.09, 0.0))
    first = _across_the_width(planner, X_pick, X_place)
    assert first.preflight.problem is not None
    assert first.preflight.problem.kind == "collision"
    assert "bin1_wall" in first.preflight.problem.text
    _, task, sim = prepare(RunRequest())
    task = type(task)(task.scenario, 0, task.goal, first.plan, X_pick, faults=(), planning=None)
    from pickplace.control.controllers import make_controller
    from pickplace.sim.loop import Simulation

    result = Simulation(sim.scene, task, make_controller("qp", sim.scene, sim.dt)).run()
    assert result.failure is not None and result.failure.value == "collision"


def test_the_held_brick_is_checked_and_what_it_lies_beside_only_in_the_transport(
    scene: Scene,
) -> None:
    """Resting on bin 1's floor at the start and bin 2's at the goal is no problem; a held brick
    2 mm from a wall is, and the pair named is the brick and that wall. A wall the brick lies
    12 mm from at its start (within the clearance plus the tracking tolerance) is a problem in
    the transport but not in the vertical lift from beside it, where its distance is still
    reported."""
    planner = PickPlacePlanner(scene, "qp")
    X_pick, X_place = _poses(scene, _bin1(scene, 0.0, 0.0, 0.0))
    assert planner.plan(X_pick, X_place).feasible
    pf, cfg = planner.preflight, planner.preflight.config
    kinds = pf.pair_kinds(X_pick, X_place)
    brick = scene.brick_geom_id
    for floor in ("bin1_floor", "bin2_floor"):
        assert kinds[brick, scene.model.geom(floor).id] == 4  # it rests there
    wall = scene.model.geom("bin1_wall_px").id
    assert kinds[brick, wall] == 2
    # The brick held 2 mm from bin 1's +x wall, the arm at home: the brick is the problem.
    half = scene.source_bin.inner_half_extents
    near = _bin1(scene, float(half[0]) - 0.0375 - 0.002, 0.0, 0.0)
    X_near = brick_on_floor(scene, near, scene.source_bin.floor_top_z + 0.03)
    q_home = scene.robot.q_home
    for vertical in (False, True):  # the wall is not beside its start: it counts in the lift
        clearance, pair, nearest = pf._closest(q_home, 0.1, X_near, kinds, True, vertical)
        assert pair is not None and pair[:2] == ("brick", "bin1_wall_px")
        assert clearance == pytest.approx(0.002, abs=1e-6) and nearest == clearance
    _, pair_free, _ = pf._closest(q_home, 0.1, X_near, kinds, held=False)
    assert pair_free is None or pair_free[0] != "brick"
    # Lying 12 mm from that wall, it lies beside it.
    beside = _bin1(scene, float(half[0]) - 0.0375 - 0.012, 0.0, 0.0)
    X_beside = brick_on_floor(scene, beside, scene.source_bin.floor_top_z)
    assert cfg.clearance < 0.012 < cfg.clearance + cfg.tracking_tolerance
    kinds_beside = pf.pair_kinds(X_beside, X_place)
    assert kinds_beside[brick, wall] == 3
    _, pair, nearest = pf._closest(q_home, 0.1, X_near, kinds_beside, True, vertical=True)
    assert pair is None or pair[:2] != ("brick", "bin1_wall_px")
    assert nearest == pytest.approx(0.002, abs=1e-6)  # reported, not a problem
    clearance, pair, _ = pf._closest(q_home, 0.1, X_near, kinds_beside, True)
    assert pair is not None and pair[:2] == ("brick", "bin1_wall_px")
    assert clearance == pytest.approx(0.002, abs=1e-6)


def test_a_brick_lying_just_beyond_the_clearance_of_a_wall_is_lifted_from_beside_it(
    scene: Scene,
) -> None:
    """A uniform pose (seed 98617) 5.2 mm from bin 1's +y wall: the lift's drift off the plan
    (the IK trading the tool's pose against its posture) took the brick 0.1 mm nearer than
    the clearance, and every candidate was refused; lifted straight up beside the wall, it is
    planned."""
    from pickplace.world.placements import uniform_placement

    planner = PickPlacePlanner(scene, "qp")
    X_pick, X_place = _poses(scene, uniform_placement(scene, np.random.default_rng(98617)))
    cfg = planner.preflight.config
    gap = float(scene.source_bin.inner_half_extents[1]) - float(
        scene.source_bin.to_bin_frame(X_pick.translation())[1]
    )
    lying = gap - float(scene.object.footprint_half(_yaw_in_bin(scene, X_pick))[1])
    assert cfg.clearance < lying < cfg.clearance + cfg.tracking_tolerance
    assert planner.plan(X_pick, X_place).feasible


def _yaw_in_bin(scene: Scene, X_WO: SE3) -> float:
    """The brick's yaw in bin 1's frame [rad]."""
    R_BO = scene.source_bin.X_WB.inverse().rotation().as_matrix() @ X_WO.rotation().as_matrix()
    return math.atan2(R_BO[1, 0], R_BO[0, 0])


def test_a_wrist_wound_into_its_limit_is_refused(scene: Scene) -> None:
    """The class-Y failure: with the via-point on the shortest arc the wrist turns against the
    base swing into joint 7's limit; the pre-flight names the joint and the limit."""
    from pickplace.planning.plan import PlanConfig, plan_pick_place

    planner = PickPlacePlanner(scene, "qp")
    X_pick, X_place = _poses(scene, _bin1(scene, -0.121, 0.002, -0.212))
    found = []
    for grasp in planner.grasps():
        if grasp.tilt or grasp.offset:
            continue  # vertical and centred: both turns of both face pairs
        X_OG = grasp.X_OG
        plan = plan_pick_place(
            planner.X_WG_home,
            X_pick,
            X_place,
            planner.clearance_z,
            PlanConfig(),
            p_W_base=scene.robot.p_W_base,
            X_OG=X_OG,
            via="shortest",
        )
        r = planner.preflight.run(plan, X_pick, X_place)
        if r.problem is not None:
            found.append(r.problem)
    assert any(p.kind in ("joint-limit", "ik") for p in found), found
    limited = [p for p in found if p.kind == "joint-limit"]
    assert all(scene.robot.arm_joint_names[-1] in p.text for p in limited)


def test_config_is_validated() -> None:
    with pytest.raises(ValueError, match="pre-flight clearance must be a finite number > 0"):
        PreflightConfig(clearance=0.0)


def test_the_fingers_close_onto_the_brick_no_further(
    scene: Scene, monkeypatch: pytest.MonkeyPatch
) -> None:
    """From the pick until they let go, the fingers stand at the grasped brick's width where the
    plan commands less (the brick stops them, as the physics has it: a linkage's fingertips,
    which move along the approach as they close, were checked below the brick's width
    against the floor under it); before the pick, at the commanded width."""
    _, task, _ = prepare(RunRequest())
    pf = Preflight(scene, "qp")
    widths: list[float] = []
    closest = pf._closest

    def spy(q: np.ndarray, width: float, *rest: object) -> tuple[float, object, float]:
        widths.append(width)
        return closest(q, width, *rest)  # type: ignore[arg-type]

    monkeypatch.setattr(pf, "_closest", spy)
    pf.run(task.plan, task.X_WO_start, task.goal.X_WO_goal, stop_at_problem=False)
    phases, held = task.plan.phases, grasp_width(task.plan, scene)
    assert phases is not None
    times = np.arange(len(widths)) * pf.dt
    commanded = np.array([task.plan.trajectory.sample(float(t))[2] for t in times])
    on_brick = (times >= phases.approach[1]) & (times < phases.release)
    assert np.any(on_brick & (commanded < held - 1e-3))  # the plan closes past the brick
    np.testing.assert_array_equal(np.array(widths)[~on_brick], commanded[~on_brick])
    np.testing.assert_array_equal(np.array(widths)[on_brick], np.maximum(commanded[on_brick], held))
