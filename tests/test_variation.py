"""Varied parameters change the world where they should: before planning, physically right."""

from __future__ import annotations

import math
from collections.abc import Callable

import mujoco
import numpy as np
import pytest

from pickplace.errors import InvalidInputError
from pickplace.geometry import box_corners, transform_points
from pickplace.planning.planner import PickPlacePlanner
from pickplace.run.runner import RunRequest, build_task, prepare, run
from pickplace.sim.loader import load_scene
from pickplace.sim.variation import apply_to_scene, brick_offset_W
from pickplace.sim.vary import ParameterDraw, parse_vary
from pickplace.world.placements import brick_on_floor, nominal_placement
from pickplace.world.scene import Scene
from tests.conftest import CliRun, finished, one_json

G = 9.81


def draw(seed: int = 0, **values: float) -> ParameterDraw:
    """The draw of ``NAME=VALUE`` grids of one value (pose noise gets its direction)."""
    return parse_vary([f"{k}={v}" for k, v in values.items()]).draw(seed)


def test_nothing_to_change_gives_the_same_scene(scene: Scene) -> None:
    assert apply_to_scene(scene, draw(speed=0.5)) is scene


def test_mass_scales_the_inertia_and_leaves_the_given_scene_alone(scene: Scene) -> None:
    varied = apply_to_scene(scene, draw(brick_mass=3.0))
    b = scene.brick_body_id
    assert varied.brick_mass == 3.0 == varied.model.body_mass[b]
    ratio = varied.model.body_inertia[b] / scene.model.body_inertia[b]
    np.testing.assert_allclose(ratio, 3.0 / scene.brick_mass)
    # mj_setConst refreshed the derived masses: the brick's subtree is the brick.
    assert varied.model.body_subtreemass[b] == pytest.approx(3.0)
    assert scene.model.body_mass[b] == pytest.approx(0.2)  # the original is unchanged


def test_size_scales_the_box_its_bounds_and_inertia_but_not_its_mass(scene: Scene) -> None:
    s = 1.3
    varied = apply_to_scene(scene, draw(brick_size=s))
    g, b = scene.brick_geom_id, scene.brick_body_id
    half = scene.brick_half_extents * s
    np.testing.assert_allclose(varied.brick_half_extents, half)
    np.testing.assert_allclose(varied.model.geom_size[g], half)
    assert varied.model.geom_rbound[g] == pytest.approx(float(np.linalg.norm(half)))
    np.testing.assert_allclose(varied.model.geom_aabb[g, 3:], half)
    # A solid box: I_x = m (b² + c²) / 3 with half sizes a, b, c.
    m = scene.brick_mass
    a, bb, c = half
    np.testing.assert_allclose(
        varied.model.body_inertia[b],
        [m * (bb**2 + c**2) / 3, m * (a**2 + c**2) / 3, m * (a**2 + bb**2) / 3],
        rtol=1e-9,
    )
    assert varied.brick_width == pytest.approx(scene.brick_width * s)


def test_a_bigger_brick_starts_resting_on_the_floor() -> None:
    req = RunRequest("pick-place", parameters=draw(brick_size=1.4))
    scene, task = build_task(req)
    z = task.X_WO_start.translation()[2]
    assert z == pytest.approx(scene.source_bin.floor_top_z + scene.brick_half_extents[2])
    _, _, sim = prepare(req)
    for _ in range(50):  # 0.1 s: settled on the floor
        mujoco.mj_step(sim.model, sim.data)
    a = scene.brick_qpos_adr
    # Resting on the floor, sunk by no more than MuJoCo's contact softness.
    assert sim.data.qpos[a + 2] == pytest.approx(z, abs=5e-4)
    touching = [
        sim.data.contact[i].dist
        for i in range(sim.data.ncon)
        if scene.brick_geom_id in (sim.data.contact[i].geom1, sim.data.contact[i].geom2)
    ]
    assert len(touching) == 4  # the four corners of its bottom face


def test_friction_is_the_pads_the_brick_keeps_its_own(scene: Scene) -> None:
    varied = apply_to_scene(scene, draw(friction=0.4))
    for pad in np.concatenate(scene.robot.pad_geom_ids).tolist():
        assert varied.model.geom_friction[pad, 0] == 0.4
        assert varied.model.geom_priority[pad] > varied.model.geom_priority[scene.brick_geom_id]
    g = scene.brick_geom_id
    np.testing.assert_array_equal(varied.model.geom_friction[g], scene.model.geom_friction[g])


@pytest.mark.parametrize(("force", "gain"), [(10.0, 1.0), (40.0, 1.0), (120.0, 3.0)])
def test_grip_force_sets_the_limit_and_keeps_the_grip_saturated(
    scene: Scene, force: float, gain: float
) -> None:
    varied = apply_to_scene(scene, draw(grip_force=force))
    assert varied.robot.squeeze_force == force
    ratio = force / scene.robot.squeeze_force
    for a in scene.robot.gripper_actuator_ids.tolist():
        np.testing.assert_allclose(
            varied.model.actuator_forcerange[a], ratio * scene.model.actuator_forcerange[a]
        )
        kp0, kp = scene.model.actuator_gainprm[a, 0], varied.model.actuator_gainprm[a, 0]
        assert kp == pytest.approx(gain * kp0)
        assert varied.model.actuator_biasprm[a, 1] == pytest.approx(-kp)
        kv0, kv = scene.model.actuator_biasprm[a, 2], varied.model.actuator_biasprm[a, 2]
        assert kv == pytest.approx(math.sqrt(gain) * kv0)  # the same damping ratio


@pytest.mark.slow
@pytest.mark.parametrize("force", [20.0, 80.0])
def test_the_held_brick_is_squeezed_with_the_varied_force(force: float) -> None:
    _, task, sim = prepare(RunRequest("pick-place", parameters=draw(grip_force=force)))
    result = sim.run()
    assert result.success, result.failure
    phases = task.plan.phases
    assert phases is not None
    k0 = math.ceil((phases.grip_closed + 0.3) / sim.dt)
    k1 = math.floor(phases.transport[1] / sim.dt)
    squeeze = sim.log.pad_force[k0:k1]
    np.testing.assert_allclose(squeeze, force, rtol=0.1)


def test_the_planner_slip_budget_knows_mass_friction_and_grip(scene: Scene) -> None:
    nominal = PickPlacePlanner(scene, "qp").slip_accel
    varied = apply_to_scene(scene, draw(brick_mass=0.8, friction=0.5, grip_force=60.0))
    planner = PickPlacePlanner(varied, "qp")
    # μ · 2 pads · F / m.
    assert planner.slip_accel == pytest.approx(0.5 * 2 * 60.0 / 0.8)
    assert nominal == pytest.approx(1.0 * 2 * 40.0 / 0.2)


@pytest.mark.slow
def test_a_brick_too_heavy_for_the_slip_budget_is_carried_with_a_warning() -> None:
    # The slip budget 2·μ·F / (m · safety 2) must hold g at rest: m < 80 / (2 g) = 4.08 kg.
    # Beyond it the plan is timed by the friction alone (to 8.2 kg), then by the robot alone;
    # the physics decides, and a brick far heavier than 80 N hold is never placed.
    limit = 2 * 1.0 * 40.0 / (2.0 * G)
    light = run(RunRequest("pick-place", parameters=draw(brick_mass=limit * 0.95)))
    assert light.success, light.failure
    assert not [e for e in light.events if e.kind == "plan" and "slip budget" in e.text]
    for mass, how in ((limit * 1.05, "without the slip safety factor"), (12.0, "limits alone")):
        heavy = run(RunRequest("pick-place-random", seed=4, parameters=draw(4, brick_mass=mass)))
        assert heavy.ticks > 0, heavy.failure  # planned and simulated, not refused
        (warning,) = [e for e in heavy.events if e.kind == "plan" and e.level == "warn"]
        assert "too heavy for the grip" in warning.text and how in warning.text
        assert warning.tick == 0
    assert heavy.failure is not None
    assert heavy.failure.value in ("dropped", "missed-grasp")


def test_pose_noise_moves_the_brick_after_planning() -> None:
    d = draw(9, pose_noise=0.02)
    offset = d.pose_offset_W
    assert offset is not None
    scene, task, sim = prepare(RunRequest("pick-place", seed=9, parameters=d))
    planned = task.X_WO_start.translation()
    sim.advance(1)
    moved = sim.data.qpos[scene.brick_qpos_adr : scene.brick_qpos_adr + 3]
    np.testing.assert_allclose(moved[:2] - planned[:2], offset[:2], atol=2e-4)
    assert task.parameters is not None
    np.testing.assert_allclose(task.parameters["pose_offset_applied_xy_m"], offset[:2])
    # The plan still aims at the planned pose.
    assert task.plan.trajectory.keyframes[2].X_WG.translation()[:2] == pytest.approx(
        planned[:2], abs=1e-9
    )


def test_pose_noise_keeps_the_brick_inside_the_bin() -> None:
    scene = load_scene()
    bin_ = scene.source_bin
    c = bin_.center_W
    hx, hy = scene.brick_half_extents[:2]
    X_WO = brick_on_floor(scene, nominal_placement(scene), bin_.floor_top_z)
    # From the centre a 10 cm push along +x stays inside (0.2 m half length of free floor
    # minus the brick's 3.75 cm); along +y (0.15 m half width minus 2.5 cm) it is cut at the
    # wall.
    np.testing.assert_allclose(
        brick_offset_W(scene, X_WO, np.array([0.1, 0.0, 0.0])), [0.1, 0.0, 0.0]
    )
    cut = brick_offset_W(scene, X_WO, np.array([0.0, 0.2, 0.0]))
    room_y = bin_.inner_half_extents[1] - hy
    np.testing.assert_allclose(cut, [0.0, room_y - (X_WO.translation()[1] - c[1]), 0.0], atol=1e-12)
    moved = X_WO.translation() + cut
    corners = transform_points(X_WO, box_corners([hx, hy, 0.0])) + cut
    assert bin_.contains_xy(corners, margin=-1e-9)
    assert moved[2] == X_WO.translation()[2]


@pytest.mark.slow
def test_a_run_records_its_parameters_and_the_cli_reproduces_them(
    cli: Callable[..., CliRun],
) -> None:
    plan = parse_vary(["brick_mass=0.2:1.5", "friction=0.6,1"])
    summary = run(RunRequest("pick-place-random", seed=6, parameters=plan.draw(6))).summary()
    assert summary["parameters"] == plan.draw(6).as_dict()
    proc = cli(
        "run", "--scenario", "pick-place-random", "--seed", "6",
        "--vary", "brick_mass=0.2:1.5", "--vary", "friction=0.6,1", "--json",
    )  # fmt: skip
    assert proc.returncode == (0 if summary["success"] else 1)
    printed = one_json(proc.stdout, proc.stderr)
    for key in ("parameters", "success", "failure", "brick_start_xyz", "place_error_m"):
        assert printed[key] == summary[key], key


def test_runs_without_variations_have_no_parameters_key() -> None:
    assert "parameters" not in finished().summary()  # the nominal run


@pytest.mark.parametrize(
    ("req", "message"),
    [
        (RunRequest(seed=3, parameters=draw(4, brick_mass=1.0)), "drawn for seed 4"),
        (RunRequest(speed=0.5, parameters=draw(speed=0.3)), "the speed is given and also varied"),
        (
            RunRequest(control_rate_hz=250.0, parameters=draw(control_rate=500)),
            "the control rate is given and also varied",
        ),
    ],
)
def test_conflicting_requests_are_refused(req: RunRequest, message: str) -> None:
    with pytest.raises(InvalidInputError, match=message):
        build_task(req)


def test_drawn_speed_and_control_rate_are_the_runs() -> None:
    req = RunRequest("pick-place", parameters=draw(speed=0.5, control_rate=250))
    assert req.run_speed == 0.5 and req.run_control_rate_hz == 250.0
    _, _, sim = prepare(req)
    assert sim.dt == pytest.approx(1 / 250)
    slow = sim.task.trajectory.end_time
    _, _, nominal = prepare(RunRequest("pick-place"))
    assert slow > 1.5 * nominal.task.trajectory.end_time


def test_bad_vary_on_the_cli_is_exit_2_with_the_valid_names(cli: Callable[..., CliRun]) -> None:
    proc = cli("run", "--vary", "mass=3")
    assert proc.returncode == 2
    (line,) = proc.stderr.strip().splitlines()
    for name in ("brick_mass [kg]", "brick_size [-]", "friction", "grip_force [N]",
                 "pose_noise [m]", "speed", "control_rate [Hz]"):  # fmt: skip
        assert name in line
    proc = cli("run", "--vary", "brick_mass=12:0.2")
    assert proc.returncode == 2 and "LOW must be below HIGH" in proc.stderr
