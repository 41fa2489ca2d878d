"""Every bundled robot, and one of our own, through the whole pipeline.

Each bundled robot picks and places the brick, succeeds on pick-place-random for at least 49 of
seeds 0-49 (the default robot: among tests/test_random_sweep.py's 300 seeds), and follows the
singular reach with qp while pinv exceeds a joint speed limit; the reach's far end lies 3 cm
past where the arm stops reaching with the tool pointing down. A small arm and gripper written
here as MJCF files (tests/toy_robot.py) and described in TOML pick and place too, with a home
found by IK and chosen by the pre-flight. Runs are the shared ones (``tests.conftest.finished``);
all but the cheap checks are in the full tier.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import mink
import numpy as np
import pytest
from mink.lie import SE3

from pickplace.control.kinematics import ArmKinematics
from pickplace.geometry import top_down_rotation
from pickplace.planning.grasp import yaw_of
from pickplace.planning.home import choose_home
from pickplace.planning.plan import PlanConfig
from pickplace.robot.calibration import (
    ACTION_HOLD,
    GRASP_OPEN_WIDTH,
    GRIP_FORCE_SHARE,
    MIN_PAD_CLEARANCE,
    PAD_CLEARANCE,
    RELEASE_CLEARANCE,
)
from pickplace.robot.registry import DEFAULT_ROBOT, bundled_robots
from pickplace.run.runner import RunRequest, prepare, run
from pickplace.sim.loader import load_scene
from pickplace.sim.scenarios import REACH_OVERSHOOT, SCENARIOS, full_stretch_distance
from pickplace.sweep.sweep import SweepRequest, run_sweep
from pickplace.world.placements import BrickPlacement
from pickplace.world.scene import Scene
from tests.conftest import finished
from tests.toy_robot import write_toy_robot

ROBOTS = bundled_robots()

# What the Menagerie robots do not do yet, stated rather than skipped: each case must fail
# (strict), so the mark goes the day the capability comes.
PASSIVE_2F85_SQUEEZES_WHEN_PUSHED = pytest.mark.xfail(
    strict=True,
    reason="Menagerie's 2F-85 with no actuator force on the UR5e: pushed onto the brick by the "
    "tilted approach, its passive linkage closes to a 41 mm gap with 48 and 24 N on the pads, "
    "so the grasp passes its check and the brick drops 90 ms into the lift (dropped)",
)

LINKAGE_CARRIES_THE_KNOCKED_BRICK = pytest.mark.xfail(
    strict=True,
    reason="Menagerie's 2F-85 on the UR5e (timed by UR's acceleration limits) carries the brick "
    "through the knock's 20 blows of 4.2 m/s: it slides 7 mm in the grip and is placed "
    "(success, not dropped)",
)


def _marked(marks: dict[str, pytest.MarkDecorator]) -> list[object]:
    """ROBOTS as parameters, with ``marks[robot]`` on the robots it names."""
    return [pytest.param(r, marks=marks[r]) if r in marks else r for r in ROBOTS]


RANDOM_SEEDS = 50
REACH_HEIGHT = 0.30  # the singular reach's tool height [m]


@pytest.mark.slow  # composes every robot, or starts CLI processes
def test_three_robots_are_bundled_with_six_and_seven_joints() -> None:
    assert {"iiwa14-wsg50", "panda-hand", "ur5e-2f85"} <= set(ROBOTS)
    assert {load_scene(robot=r).robot.n_joints for r in ROBOTS} == {6, 7}


@pytest.mark.slow
@pytest.mark.parametrize("robot", ROBOTS)
def test_pick_place_succeeds(robot: str) -> None:
    result = finished("pick-place", robot=robot).result
    assert result.success, result.summary()["events"][-2:]
    assert result.robot == robot
    assert result.metrics["place_error_m"] < 0.005
    assert result.metrics["max_robot_world_contact_force_n"] == 0.0


@pytest.mark.slow
@pytest.mark.parametrize("robot", [r for r in ROBOTS if r != DEFAULT_ROBOT])
def test_pick_place_random_succeeds_on_49_of_50_seeds(robot: str) -> None:
    """The default robot's seeds 0-49 are among test_random_sweep.py's 300 (299 of 300
    succeed), so they are not run twice."""
    report = run_sweep(
        SweepRequest("pick-place-random", "qp", RANDOM_SEEDS, 0, os.cpu_count() or 1, robot=robot)
    )
    assert report["robot"] == robot
    assert report["successes"] >= RANDOM_SEEDS - 1, report["failed_seeds"]


@pytest.mark.slow
@pytest.mark.parametrize("robot", ROBOTS)
def test_gripper_actions_take_the_gripper_s_calibrated_times(robot: str) -> None:
    """The plan closes and opens for the gripper's calibrated times; in the run, the grip is
    steady over the last ACTION_HOLD of closing and the pads clear the brick when it opens."""
    shared = finished("pick-place", robot=robot)
    sim = shared.sim
    scene, task = sim.scene, sim.task
    calib, floor = scene.robot.calibration, PlanConfig()
    t = {k.name: k.t for k in task.trajectory.keyframes}
    assert t["grip-closed"] - t["settle"] == pytest.approx(max(floor.close_time, calib.close_time))
    assert t["release"] - t["place"] == pytest.approx(max(floor.open_time, calib.open_time))
    result = shared.result
    assert result.success, result.summary()["events"][-2:]
    log = sim.log
    end = log.t[: result.ticks]
    holding = (end > t["grip-closed"] - ACTION_HOLD + log.dt / 2) & (end <= t["grip-closed"] + 1e-9)
    assert holding.sum() >= 2
    assert np.all(
        log.pad_force[: result.ticks][holding] >= GRIP_FORCE_SHARE * calib.squeeze_per_side
    )
    released = int(np.argmin(np.abs(end - t["release"])))
    clear = min(
        RELEASE_CLEARANCE, 0.25 * (min(calib.open_width, GRASP_OPEN_WIDTH) - scene.brick_width)
    )
    assert log.gripper_gap[released] >= scene.brick_width + 2 * clear


def _reach_error(scene: Scene, target: SE3) -> float:
    """Position error [m] after IK from home towards ``target`` (position and orientation,
    within the joint limits, steps capped at 0.1 rad)."""
    model = scene.arm_model
    cfg = mink.Configuration(model, scene.robot.q_home.copy())
    task = mink.FrameTask(
        scene.robot.tool_site_name, "site", position_cost=1.0, orientation_cost=1.0
    )
    task.set_target(target)
    limits = [mink.ConfigurationLimit(model)]
    for _ in range(400):
        v = mink.solve_ik(cfg, [task], 0.05, "daqp", damping=1e-6, limits=limits)
        step = float(np.abs(v).max()) * 0.05
        cfg.integrate_inplace(v * min(1.0, 0.1 / step) if step > 0 else v, 0.05)
    return float(np.linalg.norm(task.compute_error(cfg)[:3]))


@pytest.mark.slow
@pytest.mark.parametrize("robot", ROBOTS)
def test_full_stretch_is_where_the_tool_pointing_down_stops_reaching(robot: str) -> None:
    """2 mm inside the computed full stretch the tool reaches its pose exactly; 2 mm outside
    it falls short by about those 2 mm (mink's IK, within the joint limits: 2.0 mm for most
    arms, 2.7 mm for Menagerie's UR5e, whose joint limits bind there)."""
    scene = load_scene(robot=robot)
    r = full_stretch_distance(scene, REACH_HEIGHT)
    kin = ArmKinematics(scene)
    kin.update(scene.robot.q_home)
    X_home = kin.X_WG()
    p = X_home.translation() - scene.robot.p_W_base
    R = top_down_rotation(yaw_of(X_home.rotation()) + math.pi / 2 - math.atan2(p[1], p[0]))
    base = scene.robot.p_W_base
    inside, outside = (
        _reach_error(
            scene,
            SE3.from_rotation_and_translation(
                R, np.array([base[0], base[1] + r + dr, REACH_HEIGHT])
            ),
        )
        for dr in (-0.002, 0.002)
    )
    assert inside < 1e-5
    assert 0.0015 < outside < 0.003


@pytest.mark.slow
@pytest.mark.parametrize("robot", ROBOTS)
def test_singular_reach_qp_stays_within_limits_and_pinv_exceeds_a_speed_limit(robot: str) -> None:
    qp = finished("singular-reach", robot=robot)
    scene, task = qp.sim.scene, qp.sim.task
    far = task.trajectory.keyframes[3]
    assert far.name == "stretched"
    p_far = far.X_WG.translation() - scene.robot.p_W_base
    beyond = math.hypot(p_far[0], p_far[1]) - full_stretch_distance(scene, REACH_HEIGHT)
    assert beyond == pytest.approx(REACH_OVERSHOOT, abs=1e-9)
    result = qp.result
    assert result.success, result.summary()["events"][-2:]
    assert result.metrics["max_joint_speed_ratio"] <= 1 + 1e-6
    pinv = finished("singular-reach", "pinv", robot=robot).result
    assert pinv.failure is not None and pinv.failure.value == "limit-violated"
    failure = next(e.text for e in pinv.events if e.kind == "failure")
    assert "commanded at" in failure and "rad/s, limit" in failure  # a speed limit


@pytest.fixture(scope="module")
def toy_robot(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_toy_robot(tmp_path_factory.mktemp("toy"))


@pytest.mark.slow
def test_a_robot_of_our_own_picks_and_places(toy_robot: Path) -> None:
    scene = load_scene(robot=toy_robot)
    assert scene.robot.name == "toy-6dof" and scene.robot.n_joints == 6
    assert scene.robot.home_source == "ik"
    assert any(np.array_equal(scene.robot.q_home, q) for q in scene.robot.home_candidates)
    result = run(RunRequest(scenario="pick-place", robot=str(toy_robot)))
    assert result.success, result.summary()["events"][-2:]
    assert result.robot == "toy-6dof"
    assert result.metrics["place_error_m"] < 0.005


def test_the_preflight_chooses_among_home_candidates(scene: Scene) -> None:
    """A candidate with its last joint at the pre-flight's limit margin, though listed first,
    loses to one whose nominal plan is feasible."""
    good = scene.robot.q_home
    bad = good.copy()
    bad[-1] = scene.robot.q_max[-1] - 0.005
    assert np.array_equal(choose_home(scene, (bad, good)), good)
    assert np.array_equal(choose_home(scene, (good, bad)), good)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("robot", "scenario"),
    [
        pytest.param(r, s, marks=PASSIVE_2F85_SQUEEZES_WHEN_PUSHED)
        if (r, s) == ("menagerie-ur5e-2f85", "fault-gripper-disabled")
        else pytest.param(r, s, marks=LINKAGE_CARRIES_THE_KNOCKED_BRICK)
        if (r, s) == ("menagerie-ur5e-2f85", "fault-knock")
        else (r, s)
        for s in SCENARIOS
        if s.startswith("fault-")
        for r in ROBOTS
        if r != DEFAULT_ROBOT
    ],
)
def test_every_fault_has_its_documented_outcome_with_every_robot(robot: str, scenario: str) -> None:
    result = finished(scenario, robot=robot).result
    assert result.failure is not None
    assert result.failure.value == SCENARIOS[scenario].expected


@pytest.mark.slow
@pytest.mark.parametrize("robot", ["menagerie-panda-hand", "panda-hand"])
def test_an_80_mm_hand_closes_across_the_brick_s_length_beside_a_wall(robot: str) -> None:
    """A brick lying along bin 1's +y wall, 15 mm from it: the Panda hand's palm (its long
    side along the closing axis) fits only closing across the 75 mm length, open to all of its
    80 mm (2.5 mm a side, below PAD_CLEARANCE). The pads come down beside the end faces
    without touching the brick (0 N, the brick unmoved until the fingers close) and the
    pick and place succeeds."""
    scene = load_scene(robot=robot)
    bin1 = scene.source_bin
    centre, half = bin1.center_W, bin1.inner_half_extents
    y = float(centre[1] + half[1]) - float(scene.brick_half_extents[1]) - 0.015
    placement = BrickPlacement(float(centre[0]), y, 0.0)
    _, task, sim = prepare(RunRequest(scenario="pick-place", robot=robot, brick=placement))
    assert task.planning is not None and task.planning.chosen is not None
    grasp = task.planning.candidates[task.planning.chosen].label
    assert grasp.startswith("across the length")
    opening = sim.scene.robot.calibration.open_width
    length = 2.0 * float(scene.brick_half_extents[0])
    assert MIN_PAD_CLEARANCE <= 0.5 * (opening - length) < PAD_CLEARANCE
    result = sim.run()
    assert result.success, result.failure_text
    log, phases = sim.log, task.plan.phases
    assert phases is not None
    before = log.t[: sim.ticks] < phases.approach[1] + PlanConfig().settle_time
    assert float(log.pad_force[: sim.ticks][before].max()) == 0.0
    brick = sim.scene.brick_body_id
    p = log.body_pos[: sim.ticks][before][:, brick]
    assert float(np.linalg.norm(p - p[0], axis=1).max()) < 0.5e-3
