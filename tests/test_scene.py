"""Scenes: the world with a robot composed into it compiles, steps quietly, and holds what the
pipeline needs: the lecture's arm, gripper and bins for the default robot, and any robot's
joints, gripper and pads sized from the robot."""

from __future__ import annotations

import itertools
from pathlib import Path

import mujoco
import numpy as np
import pytest

from pickplace.errors import SceneError, UnknownNameError
from pickplace.robot.registry import DEFAULT_WORLD, bundled_robots
from pickplace.sim import loader
from pickplace.sim.loader import load_scene
from pickplace.sweep.sweep import SweepRequest, run_sweep
from pickplace.world.scene import WorldNames

# Sum of the iiwa 14 joint offsets along z plus the flange: the flange height at q = 0.
FLANGE_HEIGHT_AT_ZERO = 0.1575 + 0.2025 + 0.2045 + 0.2155 + 0.1845 + 0.2155 + 0.081 + 0.045


@pytest.mark.parametrize("robot", bundled_robots())
def test_every_composed_scene_compiles_and_steps_one_second_without_warnings(robot: str) -> None:
    messages: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(messages.append)
    try:
        scene = load_scene(robot=robot)
        model = scene.model
        data = scene.make_data()
        for _ in range(round(1.0 / model.opt.timestep)):
            mujoco.mj_step(model, data)
    finally:
        mujoco.set_mju_user_warning(previous)
    assert messages == []
    assert [w.number for w in data.warning] == [0] * len(data.warning)
    assert np.all(np.isfinite(data.qpos))
    # Held by its position actuators, the arm stays at home; nothing touches the world.
    np.testing.assert_allclose(data.qpos[scene.robot.arm_qpos_adr], scene.robot.q_home, atol=2e-3)
    assert not data.sensordata[scene.robot_world_sensor_adr].any()


@pytest.mark.parametrize("robot", bundled_robots())
def test_a_scene_is_sized_by_its_robot(robot: str) -> None:
    scene = load_scene(robot=robot)
    n = scene.robot.n_joints
    for array in (
        scene.robot.arm_joint_ids,
        scene.robot.q_min,
        scene.robot.q_max,
        scene.robot.v_max,
        scene.robot.q_home,
    ):
        assert array.shape == (n,)
    assert scene.arm_model.nq == scene.arm_model.nv == n
    assert len(scene.robot.gripper_actuator_ids) == scene.robot.ctrl_for_width(0.05).shape[0]
    assert scene.robot.qpos_for_width(0.05).shape == scene.gripper_qpos_adr.shape
    # The home keyframe holds the gripper open as the plans open it (at most 0.10 m).
    data = scene.make_data()
    assert scene.robot.gap(data) == pytest.approx(min(0.10, scene.robot.open_width), abs=1e-4)
    # Robot bodies are the arm's and the gripper's; every other body with geoms is the world.
    robot_bodies = set(np.flatnonzero(scene.robot_body_mask).tolist())
    assert set(scene.robot.robot_body_ids.tolist()) == robot_bodies
    assert not robot_bodies & set(scene.world_contact_body_ids.tolist())
    assert scene.brick_body_id not in scene.world_contact_body_ids


def test_every_call_gets_its_own_model_and_shares_the_arm_model() -> None:
    a, b = load_scene(), load_scene()
    assert a.model is not b.model and a.arm_model is b.arm_model
    a.model.body_mass[a.brick_body_id] = 30.0
    assert b.model.body_mass[b.brick_body_id] == pytest.approx(0.2)


def test_scene_options_suit_a_friction_grasp(scene) -> None:
    opt = scene.model.opt
    assert opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert opt.impratio >= 10
    assert opt.timestep <= 0.002


def test_arm_has_seven_limited_hinges_in_one_chain(scene) -> None:
    m = scene.model
    assert len(scene.robot.arm_joint_ids) == 7
    bodies = [m.jnt_bodyid[j] for j in scene.robot.arm_joint_ids]
    for parent, child in itertools.pairwise(bodies):
        assert m.body_parentid[child] == parent
    for j in scene.robot.arm_joint_ids:
        assert m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE
        assert m.jnt_limited[j]
    np.testing.assert_allclose(
        np.rad2deg(scene.robot.q_max), [170, 120, 170, 120, 170, 120, 175], atol=1e-3
    )
    np.testing.assert_allclose(
        np.rad2deg(scene.robot.v_max), [85, 85, 100, 75, 130, 135, 135], atol=1e-5
    )
    for b in bodies:
        assert m.body_gravcomp[b] == 1.0


def test_tool_site_lies_between_the_pads_with_z_along_the_approach(scene) -> None:
    data = scene.make_data()
    p_tool = data.site_xpos[scene.robot.tool_site_id]
    p_pads = data.geom_xpos[np.concatenate(scene.robot.pad_geom_ids)]
    np.testing.assert_allclose(p_tool, p_pads.mean(axis=0), atol=1e-9)
    z_tool = data.site_xmat[scene.robot.tool_site_id].reshape(3, 3)[:, 2]
    p_flange = data.site_xpos[scene.model.site("arm/attachment_site").id]
    approach = (p_tool - p_flange) / np.linalg.norm(p_tool - p_flange)
    np.testing.assert_allclose(z_tool, approach, atol=1e-9)


def test_brick_starts_inside_bin1_and_stays_at_rest(scene) -> None:
    m = scene.model
    data = scene.make_data()
    p0 = data.xpos[scene.brick_body_id].copy()
    assert scene.source_bin.contains_xy(p0[None])
    for _ in range(round(1.0 / m.opt.timestep)):
        mujoco.mj_step(m, data)
    assert np.linalg.norm(data.xpos[scene.brick_body_id] - p0) < 1e-3
    v = data.qvel[scene.brick_dof_adr : scene.brick_dof_adr + 6]
    assert np.linalg.norm(v) < 1e-3


# The Menagerie 2F-85's linkage keeps closing for a second after the calibration judged it at
# rest: the empty fingers end 2.8 mm past the closed width it measured. Stated, not skipped:
# the case must fail (strict) until the calibration follows the linkage to the end.
_CREEPS_PAST_CLOSED = pytest.mark.xfail(
    strict=True, reason="2F-85 linkage closes 2.8 mm past the calibrated closed width"
)


@pytest.mark.parametrize(
    ("robot", "gap"),
    [
        pytest.param(r, g, marks=_CREEPS_PAST_CLOSED)
        if r.startswith("menagerie-") and r.endswith("-2f85") and g == 0.0
        else (r, g)
        for r in bundled_robots()
        for g in (0.0, 0.03, 0.07)
    ],
)
def test_empty_gripper_reaches_the_commanded_gap(robot: str, gap: float) -> None:
    scene = load_scene(robot=robot)
    m = scene.model
    data = scene.make_data()
    data.ctrl[scene.robot.gripper_actuator_ids] = scene.robot.ctrl_for_width(gap)
    for _ in range(round(1.0 / m.opt.timestep)):
        mujoco.mj_step(m, data)
    expected = max(gap, scene.robot.closed_width)
    assert abs(scene.robot.gap(data) - expected) < 0.002
    # The logged body poses give the same gap.
    batch = scene.robot.gap_from_body_poses(data.xpos[None], data.xquat[None])
    np.testing.assert_allclose(batch, [scene.robot.gap(data)], atol=1e-12)


def test_flange_at_zero_is_straight_above_the_base_and_the_jacobian_has_rank_three(
    scene,
) -> None:
    m = scene.model
    data = mujoco.MjData(m)
    mujoco.mj_forward(m, data)  # qpos0: every arm joint at 0
    assert np.all(data.qpos[scene.robot.arm_qpos_adr] == 0)
    flange = scene.model.site("arm/attachment_site").id
    p_flange = data.site_xpos[flange]
    p_base = data.xpos[m.body("arm/base").id]
    np.testing.assert_allclose(p_flange - p_base, [0, 0, FLANGE_HEIGHT_AT_ZERO], atol=1e-3)
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, data, jacp, jacr, flange)
    J = np.vstack([jacp, jacr])[:, scene.robot.arm_dof_adr]
    sigma = np.linalg.svd(J, compute_uv=False)
    assert np.all(sigma[:3] > 0.1)
    assert np.all(sigma[3:] < 1e-9)


def test_home_posture_is_bent_and_well_conditioned(scene) -> None:
    m = scene.model
    data = scene.make_data()
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, data, jacp, jacr, scene.robot.tool_site_id)
    sigma = np.linalg.svd(np.vstack([jacp, jacr])[:, scene.robot.arm_dof_adr], compute_uv=False)
    assert sigma[-1] > 0.1
    assert abs(scene.robot.q_home[3]) > 0.5  # elbow bent


def test_bins_are_reachable_open_boxes_on_two_sides(scene) -> None:
    for b in (scene.source_bin, scene.target_bin):
        assert b.wall_top_z > b.floor_top_z
        assert np.all(b.inner_half_extents > 0.1)
    a = scene.source_bin.center_W[:2] - scene.robot.p_W_base[:2]
    c = scene.target_bin.center_W[:2] - scene.robot.p_W_base[:2]
    swing = np.degrees(np.arccos(a @ c / np.linalg.norm(a) / np.linalg.norm(c)))
    assert swing >= 60.0


def test_unknown_world_name_lists_the_names_that_exist() -> None:
    with pytest.raises(UnknownNameError, match=r"unknown body 'bin3'; valid: .*bin1, bin2"):
        load_scene(names=WorldNames(target_bin="bin3"))
    with pytest.raises(UnknownNameError, match=r"unknown geom 'block'; valid: .*brick"):
        load_scene(names=WorldNames(brick_geom="block"))


def test_missing_and_invalid_world_files(tmp_path: Path) -> None:
    with pytest.raises(SceneError, match="does not exist"):
        load_scene(tmp_path / "missing.xml")
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><body></mujoco>")
    with pytest.raises(SceneError, match="not valid MJCF"):
        load_scene(bad)


def test_relative_world_path_loads(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(DEFAULT_WORLD.parent.parent)
    assert load_scene(Path("scenes") / "world.xml").model.nu == 8


def test_an_edited_world_is_composed_again(tmp_path: Path) -> None:
    """The cache is keyed by content: the same file name with other contents is another scene."""
    world = tmp_path / "world.xml"
    text = DEFAULT_WORLD.read_text()
    world.write_text(text)
    assert load_scene(world).source_bin.center_W[1] == pytest.approx(-0.55)
    world.write_text(
        text.replace('<body name="bin1" pos="0 -0.55 0">', '<body name="bin1" pos="0 -0.5 0">')
    )
    assert load_scene(world).source_bin.center_W[1] == pytest.approx(-0.5)


@pytest.mark.slow
def test_a_sweep_composes_its_robot_once_per_process(monkeypatch: pytest.MonkeyPatch) -> None:
    """Trials copy the cached scene's model; composing and calibrating happens once."""
    loader.clear_scene_cache()
    calls = []
    compose = loader.load_robot
    monkeypatch.setattr(loader, "load_robot", lambda *a, **k: calls.append(1) or compose(*a, **k))
    report = run_sweep(SweepRequest("pick-place", "qp", 3, 0, 1, robot="panda-hand"))
    assert report["successes"] == 3
    assert len(calls) == 1


def test_a_world_file_read_again_is_parsed_again_only_once_it_changed(tmp_path: Path) -> None:
    """read_world remembers a file's parse by its modification time and size: asked again,
    the same WorldFile; once the file changes, a new parse of the new content."""
    from pickplace.robot.registry import DEFAULT_WORLD
    from pickplace.world.scene import read_world

    path = tmp_path / "world.xml"
    text = DEFAULT_WORLD.read_text()
    path.write_text(text)
    first = read_world(path)
    assert read_world(path) is first
    # another size as well: two writes within the file system's clock tick share an mtime
    path.write_text(text.replace('timestep="0.002"', 'timestep="0.0010"'))
    changed = read_world(path)
    assert changed is not first and changed.timestep == 0.001
