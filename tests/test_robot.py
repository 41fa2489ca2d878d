"""Robot descriptions: composed with MjSpec, calibrated in simulation, bad files refused.

The bundled iiwa14-wsg50 must compose into the arm and gripper its files and data sheet state;
a small arm and gripper of our own (tests/toy_robot.py, published-file pitfalls included) must
compose and calibrate with no bundled-robot assumption; every bad file is one line naming file
and field.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import mujoco
import numpy as np
import pytest

from pickplace.errors import PickPlaceError, RobotError
from pickplace.robot.calibration import PALM_CLEARANCE, TIP_CLEARANCE
from pickplace.robot.compose import ARM_PREFIX, BRICK_GEOM, load_robot
from pickplace.robot.description import RobotDescription
from pickplace.robot.home_ik import HOME_TOOL_SITE
from pickplace.robot.model import Composition
from pickplace.robot.physics import (
    GRIPPER_MIN_ARMATURE,
    GRIPPER_MIN_DAMPING,
    ROBOT_CONAFFINITY,
    ROBOT_CONTYPE,
    arm_min_armature,
)
from pickplace.robot.registry import DEFAULT_ROBOT, bundled_robots
from tests.toy_robot import (
    BAD_CASES,
    TOY_ARM,
    TOY_GRIPPER,
    TOY_MOTOR_LIMITS,
    TOY_SPEED_LIMITS,
    TOY_TOML,
    write_toy_robot,
)

TODAYS_OPEN_WIDTH = 0.10  # the plans' open gap for the iiwa (PlanConfig.open_width) [m]


@pytest.fixture(scope="module")
def iiwa() -> Composition:
    return load_robot(DEFAULT_ROBOT, home_width=TODAYS_OPEN_WIDTH)


def _step_quietly(model: mujoco.MjModel, data: mujoco.MjData, seconds: float) -> list[str]:
    messages: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(messages.append)
    try:
        for _ in range(round(seconds / model.opt.timestep)):
            mujoco.mj_step(model, data)
    finally:
        mujoco.set_mju_user_warning(previous)
    return messages


def _box_support(model: mujoco.MjModel, data: mujoco.MjData, g: int, u_W: np.ndarray) -> float:
    """Distance from a box geom's centre to its face along world direction ``u_W`` [m]."""
    R = data.geom_xmat[g].reshape(3, 3)
    return float(np.abs(R.T @ u_W) @ model.geom_size[g])


# --------------------------------------------------------------------------- iiwa14-wsg50


# The iiwa 14's data (robots/iiwa14-wsg50/arm.xml): ranges, torque limits, speed limits [deg/s].
IIWA_RANGES_DEG = [170, 120, 170, 120, 170, 120, 175]
IIWA_TORQUES = [320, 320, 176, 176, 110, 40, 40]
IIWA_SPEEDS_DEG = [85, 85, 100, 75, 130, 135, 135]


def test_iiwa_joints_limits_and_actuators_follow_its_data_sheet(iiwa: Composition) -> None:
    robot, m = iiwa.robot, iiwa.model
    assert robot.arm_joint_names == tuple(f"{ARM_PREFIX}joint{i}" for i in range(1, 8))
    np.testing.assert_allclose(np.rad2deg(robot.q_max), IIWA_RANGES_DEG, atol=1e-3)
    np.testing.assert_array_equal(robot.q_min, -robot.q_max)
    np.testing.assert_allclose(np.rad2deg(robot.v_max), IIWA_SPEEDS_DEG, atol=1e-5)
    assert not robot.continuous.any()
    np.testing.assert_array_equal(robot.q_home, robot.description.arm.home)
    acts = robot.arm_actuator_ids
    np.testing.assert_array_equal(m.actuator_gainprm[acts, 0], 2000.0)
    np.testing.assert_array_equal(m.actuator_biasprm[acts, 1], -2000.0)
    np.testing.assert_allclose(m.actuator_forcerange[acts, 1], IIWA_TORQUES)
    np.testing.assert_array_equal(m.dof_armature[robot.arm_dof_adr], 0.1)
    # Critical damping: kv = 2 sqrt(kp (armature + the link inertia the joint sees)) > 2 sqrt(kp a).
    assert np.all(-m.actuator_biasprm[acts, 2] > 2.0 * np.sqrt(2000.0 * 0.1))
    np.testing.assert_allclose(robot.p_W_base, [0.0, 0.0, 0.1575], atol=1e-12)
    assert robot.a_max is not None and robot.a_max.shape == (robot.n_joints,)


def test_iiwa_gripper_force_width_and_home(iiwa: Composition) -> None:
    robot, m = iiwa.robot, iiwa.model
    assert robot.squeeze_force == pytest.approx(40.0, rel=1e-3)
    assert robot.open_width == pytest.approx(0.11, abs=1e-6)  # ctrlrange of the finger tendon
    grip = robot.gripper_actuator_ids
    np.testing.assert_allclose(m.actuator_forcerange[grip], [[-40.0, 40.0]])
    key = robot.home_key_id
    np.testing.assert_allclose(m.key_ctrl[key, grip], [TODAYS_OPEN_WIDTH], atol=1e-6)
    data = robot.make_data(m)
    # The WSG-like gap is the sum of the finger joints; the pad-face gap equals it.
    finger_sum = data.qpos[m.jnt_qposadr[robot.gripper_joint_ids]].sum()
    assert robot.gap(data) == pytest.approx(finger_sum, abs=1e-9)
    assert robot.gap(data) == pytest.approx(TODAYS_OPEN_WIDTH, abs=1e-6)


def test_iiwa_contact_bits_pads_and_sensors(iiwa: Composition) -> None:
    robot, m = iiwa.robot, iiwa.model
    brick = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, BRICK_GEOM)
    for pads in robot.pad_geom_ids:
        (g,) = pads
        assert m.geom_priority[g] == 1
        np.testing.assert_allclose(m.geom_solref[g], [2.0 * m.opt.timestep, 1.0])
    assert set(m.geom_contype[robot.robot_geom_ids]) == {ROBOT_CONTYPE}
    assert set(m.geom_conaffinity[robot.robot_geom_ids]) == {ROBOT_CONAFFINITY}
    assert robot.pad_force_slots == 8
    for sensors, pads in zip(robot.pad_force_sensor_ids, robot.pad_geom_ids, strict=True):
        for s, pad in zip(sensors, pads, strict=True):
            assert m.sensor_type[s] == mujoco.mjtSensor.mjSENS_CONTACT
            assert int(m.sensor_intprm[s, 2]) == robot.pad_force_slots
            assert {int(m.sensor_objid[s]), int(m.sensor_refid[s])} == {int(pad), brick}


@pytest.mark.parametrize("name", bundled_robots())
def test_every_bundled_robot_composes_compiles_and_steps_one_second_quietly(name: str) -> None:
    messages: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(messages.append)
    try:
        composition = load_robot(name)
    finally:
        mujoco.set_mju_user_warning(previous)
    model, robot = composition.model, composition.robot
    data = robot.make_data(model)
    messages += _step_quietly(model, data, 1.0)
    assert messages == []
    assert [w.number for w in data.warning] == [0] * len(data.warning)
    assert np.all(np.isfinite(data.qpos))
    # Held by its position actuators, the arm stays at home.
    np.testing.assert_allclose(data.qpos[robot.arm_qpos_adr], robot.q_home, atol=2e-3)


# --------------------------------------------------------------------------- calibration facts


def test_tool_point_is_midway_between_the_pad_faces_at_the_brick_width(iiwa: Composition):
    robot, m = iiwa.robot, iiwa.model
    width = 2.0 * float(robot.calibration.brick_half_extents[1])
    data = mujoco.MjData(m)
    data.qpos[m.jnt_qposadr[robot.gripper_joint_ids]] = robot.calibration.qpos_for_width(width)
    mujoco.mj_kinematics(m, data)
    site = robot.tool_site_id
    p_WG, R_WG = data.site_xpos[site], data.site_xmat[site].reshape(3, 3)
    y_W = R_WG[:, 1]
    faces = []
    for sign, pads in zip((1.0, -1.0), robot.pad_geom_ids, strict=True):
        # Box pads: each face centre is the box centre moved inwards by its support.
        points = [data.geom_xpos[g] - sign * _box_support(m, data, g, y_W) * y_W for g in pads]
        faces.append(np.mean(points, axis=0))
    face_G = [(f - p_WG) @ R_WG for f in faces]
    np.testing.assert_allclose(0.5 * (face_G[0] + face_G[1]), 0.0, atol=1e-6)
    assert face_G[0][1] - face_G[1][1] == pytest.approx(width, abs=1e-6)


def test_squeeze_force_is_the_actuator_limit_for_the_wsg(iiwa: Composition) -> None:
    robot, m = iiwa.robot, iiwa.model
    (act,) = robot.gripper_actuator_ids
    tendon = int(m.actuator_trnid[act, 0])
    adr, num = m.tendon_adr[tendon], m.tendon_num[tendon]
    per_jaw = m.actuator_forcerange[act, 1] * np.abs(m.wrap_prm[adr : adr + num])
    np.testing.assert_allclose(robot.calibration.squeeze_per_side, per_jaw, rtol=1e-3)
    assert robot.measured_squeeze_force == pytest.approx(40.0, rel=1e-3)


def test_gap_map_is_monotone_and_its_inverse_holds_the_fingers_there(iiwa: Composition):
    robot, m = iiwa.robot, iiwa.model
    cal = robot.calibration
    assert np.all(np.diff(cal.sweep_gap) >= 0.0)
    assert cal.sweep_gap[-1] > 2.0 * cal.brick_half_extents[1]
    np.testing.assert_array_equal(robot.ctrl_for_width(-1.0), robot.closed_command)
    np.testing.assert_array_equal(robot.ctrl_for_width(1.0), robot.open_command)
    data = robot.make_data(m)
    for width in (0.03, 0.07):
        data.ctrl[robot.gripper_actuator_ids] = robot.ctrl_for_width(width)
        _step_quietly(m, data, 0.5)
        assert robot.gap(data) == pytest.approx(width, abs=2e-4)


def test_gap_from_logged_body_poses_is_vectorised(iiwa: Composition) -> None:
    robot, m = iiwa.robot, iiwa.model
    data = robot.make_data(m)
    pos, quat, gaps = [], [], []
    data.ctrl[robot.gripper_actuator_ids] = robot.closed_command
    for _ in range(5):
        _step_quietly(m, data, 0.02)
        pos.append(data.xpos.copy())
        quat.append(data.xquat.copy())
        gaps.append(robot.gap(data))
    batch = robot.gap_from_body_poses(np.array(pos), np.array(quat))
    np.testing.assert_allclose(batch, gaps, atol=1e-12)
    assert batch[0] > batch[-1]  # closing


def test_a_brick_in_the_closed_gripper_feels_the_calibrated_squeeze(iiwa: Composition):
    robot, m = iiwa.robot, iiwa.model
    data = robot.make_data(m)
    brick = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, BRICK_GEOM)
    adr = m.jnt_qposadr[m.body_jntadr[brick]]
    site = robot.tool_site_id
    data.qpos[adr : adr + 3] = data.site_xpos[site]
    mujoco.mju_mat2Quat(data.qpos[adr + 3 : adr + 7], data.site_xmat[site])
    data.ctrl[robot.gripper_actuator_ids] = robot.closed_command
    _step_quietly(m, data, 0.5)
    forces = robot.pad_normal_forces(data.sensordata)
    np.testing.assert_allclose(forces, robot.calibration.squeeze_per_side, rtol=0.02)
    assert robot.gap(data) == pytest.approx(robot.gap_on_brick, abs=2e-4)


def test_footprint_holds_every_gripper_collision_geom_at_the_open_width(iiwa: Composition):
    robot = iiwa.robot
    fp = robot.footprint_G
    assert fp.shape == (len(robot.gripper_geom_ids), 2, 3)
    assert np.all(fp[:, 1] >= fp[:, 0])
    # The open fingers reach past half the open width along the closing axis.
    assert fp[:, 1, 1].max() > robot.open_width / 2
    assert fp[:, 0, 1].min() < -robot.open_width / 2


def test_arm_model_keeps_only_the_arm_joints(iiwa: Composition) -> None:
    arm = iiwa.arm_model
    assert arm.nq == arm.nv == iiwa.robot.n_joints


# --------------------------------------------------------------------------- a robot of our own


@pytest.fixture(scope="module")
def toy(tmp_path_factory: pytest.TempPathFactory) -> Composition:
    return load_robot(write_toy_robot(tmp_path_factory.mktemp("toy")))


def test_toy_robot_arm_chain_units_and_actuators(toy: Composition) -> None:
    robot, m = toy.robot, toy.model
    names = ("yaw", "shoulder", "elbow", "wrist1", "wrist2", "wrist3")
    assert robot.arm_joint_names == tuple(ARM_PREFIX + n for n in names)
    assert robot.n_joints == 6
    np.testing.assert_array_equal(robot.v_max, TOY_SPEED_LIMITS)
    assert robot.a_max is None
    # Degrees read as the description says; the continuous joint has no limits.
    np.testing.assert_allclose(robot.q_max[[0, 1, 2, 4, 5]], np.deg2rad([170, 110, 150, 120, 350]))
    np.testing.assert_array_equal(robot.continuous, [False, False, False, True, False, False])
    assert robot.q_min[3] == -np.inf and robot.q_max[3] == np.inf
    # Motors became position actuators with the motors' torque limits.
    acts = robot.arm_actuator_ids
    np.testing.assert_allclose(m.actuator_forcerange[acts, 1], TOY_MOTOR_LIMITS)
    kp = m.actuator_gainprm[acts, 0]
    np.testing.assert_allclose(m.actuator_biasprm[acts, 1], -kp)
    assert np.all(m.actuator_biasprm[acts, 2] < 0)  # damped
    np.testing.assert_array_equal(m.actuator_gear[acts, 0], 1.0)
    assert not m.actuator_ctrllimited[acts[3]]  # continuous joint: unlimited target
    assert np.all(m.dof_armature[robot.arm_dof_adr] >= arm_min_armature(kp, m.opt.timestep))


def test_toy_robot_gripper_is_coupled_calibrated_and_physically_set_up(toy: Composition):
    robot, m = toy.robot, toy.model
    cal = robot.calibration
    (act,) = robot.gripper_actuator_ids  # the two finger actuators became one
    assert m.actuator_trntype[act] == mujoco.mjtTrn.mjTRN_TENDON
    assert m.neq == 1 and m.eq_type[0] == mujoco.mjtEq.mjEQ_JOINT
    assert cal.pads == (("a_pad1", "a_pad2"), ("b_pad1", "b_pad2"))
    # Both pads of a side face the brick at once: the tool point lies between their centres.
    np.testing.assert_allclose(cal.pos_BG, [0.0, 0.0, 0.05 + 0.045], atol=1e-6)
    assert cal.other_contacts == ()
    # Pad faces at 4 mm + 2 q: gap 4 mm closed, 94 mm open.
    assert robot.closed_width == pytest.approx(0.004, abs=1e-5)
    assert robot.open_width == pytest.approx(0.094, abs=1e-5)
    # kp 2000 on the tendon × 23 mm of travel left on the brick = 46 N < 50 N: 23 N a jaw.
    assert robot.measured_squeeze_force == pytest.approx(23.0, rel=0.01)
    assert robot.gap_on_brick == pytest.approx(0.05, abs=1e-4)
    grip_dofs = m.jnt_dofadr[robot.gripper_joint_ids]
    assert np.all(m.dof_armature[grip_dofs] >= GRIPPER_MIN_ARMATURE)
    assert np.all(m.dof_damping[grip_dofs] >= GRIPPER_MIN_DAMPING)
    assert np.all(m.body_gravcomp[robot.robot_body_ids] == 1.0)
    assert set(m.geom_contype[robot.robot_geom_ids]) == {ROBOT_CONTYPE}
    assert np.all(m.geom_priority[np.concatenate(robot.pad_geom_ids)] == 1)


def test_toy_robot_home_is_found_by_ik_and_its_repairs_are_reported(toy: Composition):
    robot, m = toy.robot, toy.model
    assert robot.home_source == "ik"
    data = robot.make_data(m)
    target = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, HOME_TOOL_SITE)
    assert np.linalg.norm(data.site_xpos[robot.tool_site_id] - data.site_xpos[target]) < 1e-3
    finite = ~robot.continuous
    assert np.all(robot.q_home[finite] > robot.q_min[finite])
    assert np.all(robot.q_home[finite] < robot.q_max[finite])
    text = "\n".join(robot.repairs)
    for fact in ("<option> removed", "<keyframe> removed", "'floor' removed", "'group'",
                 "defined twice identically", "coupled", "motor 'yaw' replaced"):  # fmt: skip
        assert fact in text, fact
    messages = _step_quietly(m, data, 1.0)
    assert messages == [] and [w.number for w in data.warning] == [0] * len(data.warning)


def test_overrides_replace_what_calibration_would_find(tmp_path: Path) -> None:
    toml = TOY_TOML + (
        'pads = [["b_pad1"], ["a_pad1", "a_pad2"]]\n'
        "grip_force = 15.0\n"
        "couple_fingers = false\n"
        "tcp = { pos = [0, 0, 0.09] }\n"
    )
    robot = load_robot(write_toy_robot(tmp_path, toml=toml)).robot
    cal = robot.calibration
    assert len(robot.gripper_actuator_ids) == 2  # not coupled
    assert not any("coupled" in r for r in robot.repairs)
    np.testing.assert_array_equal(robot.open_command, [0.045, 0.045])  # per finger, found
    assert cal.pads == (("a_pad1", "a_pad2"), ("b_pad1",))  # +y side first, by geometry
    assert "b_pad2" in cal.other_contacts
    np.testing.assert_array_equal(cal.pos_BG, [0.0, 0.0, 0.09])
    assert robot.squeeze_force == 15.0
    assert robot.measured_squeeze_force > 0.0


def test_calibration_is_cached_by_content(tmp_path: Path) -> None:
    first = load_robot(write_toy_robot(tmp_path / "a")).robot.calibration
    again = load_robot(write_toy_robot(tmp_path / "b")).robot.calibration
    assert again is first  # same files' contents elsewhere
    narrow = TOY_GRIPPER.replace('range="0 0.045"', 'range="0 0.04"').replace(
        'ctrlrange="0 0.045"', 'ctrlrange="0 0.04"'
    )
    changed = load_robot(write_toy_robot(tmp_path / "c", gripper=narrow)).robot
    assert changed.open_width == pytest.approx(0.084, abs=1e-5)


# --------------------------------------------------------------------------- bad robot files


def _one_line_error(path: Path, field: str, *fragments: str) -> Callable[[], None]:
    def check() -> None:
        with pytest.raises(RobotError) as info:
            load_robot(path)
        message = str(info.value)
        assert "\n" not in message
        assert str(path.resolve()) in message, message
        assert field in message, message
        assert "valid" in message, message
        for f in fragments:
            assert f in message, message

    return check


@pytest.mark.parametrize("case", BAD_CASES, ids=list(BAD_CASES))
def test_bad_robot_files_raise_one_line_naming_file_and_field(case: str, tmp_path: Path):
    changes, field, fragments = BAD_CASES[case]
    path = write_toy_robot(tmp_path, **changes)  # type: ignore[arg-type]
    _one_line_error(path, field, *fragments)()


def test_missing_and_malformed_descriptions(tmp_path: Path) -> None:
    with pytest.raises(RobotError, match="does not exist"):
        RobotDescription.from_toml(tmp_path / "robot.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("name = [")
    with pytest.raises(RobotError, match="not valid TOML"):
        RobotDescription.from_toml(bad)
    with pytest.raises(RobotError, match=r"unknown robot 'no-such-robot'.*iiwa14-wsg50"):
        load_robot("no-such-robot")
    assert issubclass(RobotError, PickPlaceError)


def test_the_documented_example_description_is_valid_and_sets_every_field(tmp_path: Path) -> None:
    doc = (Path(__file__).resolve().parent.parent / "docs" / "robots.md").read_text()
    section = doc.split("## Your own robot", 1)[1]
    example = section.split("```toml\n", 1)[1].split("```", 1)[0]
    write_toy_robot(tmp_path, toml=example)
    desc = RobotDescription.from_toml(tmp_path / "robot.toml")
    assert desc.name == "my-arm"
    assert (
        len(desc.arm.speed_limits) == len(desc.arm.accel_limits or ()) == len(desc.arm.home or ())
    )
    g = desc.gripper
    assert g.pads == (("left_pad",), ("right_pad",)) and g.tcp is not None and g.tcp.site
    assert g.open_command and g.closed_command and g.grip_force == 40.0 and g.couple_fingers


# ------------------------------------------------------- grippers as other projects publish them


def _toy_gripper(**changes: str) -> str:
    """TOY_GRIPPER with each ``old=new`` text replaced (keys are labels, values "old|new")."""
    text = TOY_GRIPPER
    for change in changes.values():
        old, new = change.split("|")
        assert old in text, old
        text = text.replace(old, new)
    return text


def test_default_flange_follows_the_branch_that_carries_the_arm(tmp_path: Path) -> None:
    # A head on one joint branches off the first link (as on Rethink's Sawyer) and a camera
    # mount without joints off the last: the arm's branch has more joints below it than the
    # others together, so the default flange is still the arm's last body.
    arm = TOY_ARM.replace(
        '<geom fromto="0 0 0 0 0 0.05"/>\n        <body name="l2"',
        '<geom fromto="0 0 0 0 0 0.05"/>\n        <body name="head" pos="0 0 0.05">\n'
        '          <joint name="head_pan" axis="0 0 1" range="-90 90"/>\n'
        '          <geom size="0.02" fromto="0 0 0 0.1 0 0"/>\n        </body>\n'
        '        <body name="l2"',
    ).replace(
        '<geom type="cylinder" size="0.035 0.01"/>\n                </body>',
        '<geom type="cylinder" size="0.035 0.01"/>\n                  <body name="camera"/>\n'
        '                  <body name="cable"/>\n                </body>',
    )
    assert "head_pan" in arm and 'name="camera"' in arm
    toml = TOY_TOML.replace('flange = "hand_mount"\n', "")
    robot = load_robot(write_toy_robot(tmp_path, arm=arm, toml=toml)).robot
    joints = ("yaw", "shoulder", "elbow", "wrist1", "wrist2", "wrist3")
    assert robot.arm_joint_names == tuple(ARM_PREFIX + j for j in joints)
    assert any("no [arm] flange given: the body 'hand_mount'" in r for r in robot.repairs)


def test_finger_geoms_not_level_with_the_fingertips_do_not_bound_the_opening(
    tmp_path: Path,
) -> None:
    # Each finger carries a crossbar near the palm that reaches past the midplane (robosuite's
    # Rethink gripper: the opening was measured to it, -14.2 mm). Only geoms level with the
    # probe bound it: the pads open 94 mm.
    gripper = _toy_gripper(
        a='name="a_link"|name="a_bar" size="0.004 0.03 0.004" pos="-0.006 -0.02 0.004"/>\n'
        '        <geom class="finger" name="a_link"',
        b='name="b_link"|name="b_bar" size="0.004 0.03 0.004" pos="0.006 0.02 0.004"/>\n'
        '        <geom class="finger" name="b_link"',
    )
    cal = load_robot(write_toy_robot(tmp_path, gripper=gripper)).robot.calibration
    assert cal.open_width == pytest.approx(0.094, abs=1e-4)
    assert not {"a_bar", "b_bar"} & set(cal.pads[0] + cal.pads[1])


def test_a_palm_between_short_pads_moves_the_tool_point_towards_the_fingertips(
    tmp_path: Path,
) -> None:
    # The palm's top (z 0.08 m) lies within half a brick (25 mm) of the pads' centre (z
    # 0.095 m): a brick centred between the pads would touch it (robosuite's Panda hand). The
    # grasp holds the brick nearer its top face instead, the palm 3 mm clear of it.
    gripper = _toy_gripper(
        palm='size="0.03 0.05 0.025" pos="0 0 0.025"|size="0.03 0.05 0.04" pos="0 0 0.04"'
    )
    robot = load_robot(write_toy_robot(tmp_path, gripper=gripper)).robot
    cal = robot.calibration
    palm_top, half = 0.08, cal.brick_half_extents[2]
    assert cal.pos_BG[2] == pytest.approx(palm_top + half + PALM_CLEARANCE, abs=2e-4)
    assert set(cal.pads[0] + cal.pads[1]) == {"a_pad1", "a_pad2", "b_pad1", "b_pad2"}
    assert cal.pos_BG[2] - half < 0.095 - 0.01  # the brick still covers the pads (z 0.085-0.105)


def test_fingers_reaching_past_a_brick_on_the_floor_move_the_tool_point(tmp_path: Path) -> None:
    # The finger links reach 35 mm beyond the pads' centre: with the brick centred between the
    # pads they would stand 10 mm into the floor it rests on. The tool point moves until they
    # stop TIP_CLEARANCE short of the brick's far face.
    gripper = _toy_gripper(
        a='size="0.01 0.006 0.03" pos="0 0.012 0.03"|size="0.01 0.006 0.04" pos="0 0.012 0.04"',
        b='size="0.01 0.006 0.03" pos="0 -0.012 0.03"|size="0.01 0.006 0.04" pos="0 -0.012 0.04"',
    )
    cal = load_robot(write_toy_robot(tmp_path, gripper=gripper)).robot.calibration
    tips = 0.05 + 0.08  # the finger links' far end in the root's frame [m]
    assert cal.pos_BG[2] == pytest.approx(
        tips + TIP_CLEARANCE - cal.brick_half_extents[2], abs=1e-6
    )
    default = load_robot(write_toy_robot(tmp_path / "default")).robot.calibration
    assert default.pos_BG[2] == pytest.approx(0.095, abs=1e-4)  # nothing to move: midway


def _sheared_pad_obj(side: int) -> str:
    """A pad as a sheared prism (OBJ) on the ``side`` (+1 / -1) finger, in its body's frame:
    its inner face flat at y = 2 mm, z 35-55 mm, its outer face at y = 12 mm, 10 mm higher,
    x +-12 mm. Its principal axes, the mesh's own frame, are turned about x."""
    corners = [
        (x, side * y, z)
        for x in (-0.012, 0.012)
        for y, z0 in ((0.002, 0.035), (0.012, 0.045))
        for z in (z0, z0 + 0.02)
    ]
    points = np.array(corners)
    centre = points.mean(axis=0)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = []
    for q in quads:
        for tri in ((q[0], q[1], q[2]), (q[0], q[2], q[3])):
            a, b, c = points[list(tri)]
            outward = np.cross(b - a, c - a) @ (a - centre) > 0
            faces.append(tri if outward else (tri[0], tri[2], tri[1]))
    return "\n".join(
        [f"v {x:g} {y:g} {z:g}" for x, y, z in corners]
        + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    )


def test_mesh_pads_turned_in_their_own_frame_are_measured_at_their_inner_face(
    tmp_path: Path,
) -> None:
    # Each finger's two box pads become one mesh pad whose inner face is flat at y = +-2 mm
    # (the finger's travel is 45 mm), but whose own frame (principal axes) is turned: the
    # corner of its bounding box along the closing axis lies inside that face (Menagerie's
    # xArm hand: its pads were measured 25.7 mm apart squeezing the 50 mm brick). The gap is
    # between the faces: 4 mm closed, 94 mm open, the brick's width squeezing it.
    gripper = TOY_GRIPPER.replace(
        '<mesh name="palm" file="palm.obj"/>\n  </asset>',
        '<mesh name="palm" file="palm.obj"/>\n    <mesh name="a_pad" file="a_pad.obj"/>\n'
        '    <mesh name="b_pad" file="b_pad.obj"/>\n  </asset>',
    )
    for side in ("a", "b"):
        pads = [ln for ln in gripper.splitlines() if f'geom class="finger" name="{side}_pad' in ln]
        assert len(pads) == 2
        mesh_pad = f'        <geom class="finger" name="{side}_pad" type="mesh" mesh="{side}_pad"/>'
        gripper = gripper.replace(pads[0], mesh_pad).replace(pads[1] + "\n", "")
    path = write_toy_robot(tmp_path, gripper=gripper)
    for side, sign in (("a", 1), ("b", -1)):
        (tmp_path / "meshes" / f"{side}_pad.obj").write_text(_sheared_pad_obj(sign))
    comp = load_robot(path)
    cal = comp.robot.calibration
    m = comp.model
    assert {cal.pads[0], cal.pads[1]} == {("a_pad",), ("b_pad",)}
    pad = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "gripper/a_pad")
    quat_mesh = m.geom_quat[pad]
    assert abs(quat_mesh[0]) < 1.0 - 1e-3  # the mesh's frame is turned
    assert cal.closed_width == pytest.approx(0.004, abs=1e-5)
    assert cal.open_width == pytest.approx(0.004 + 2 * 0.045, abs=1e-5)
    width = 2.0 * cal.brick_half_extents[1]
    assert width - 5e-4 < cal.gap_on_brick <= width  # the stiff pads sink in by < 0.5 mm


# Fingers that pass each other when closed free (free gap -16 mm) on position actuators without a
# force range: the squeeze is the gain times the command's travel past the brick, and the
# command for a gap of 0 (where a plan's close ends) leaves a third of it out (robosuite's
# Robotiq 140: kp 20 and no force range, its fingers crossing).
PASSING_GRIPPER = TOY_GRIPPER.replace('range="0 0.045"', 'range="-0.01 0.045"').replace(
    ' forcerange="-25 25"', ""
)


def test_a_gripper_short_of_its_squeeze_at_gap_0_closes_once_the_gap_reaches_the_brick(
    tmp_path: Path,
) -> None:
    robot = load_robot(write_toy_robot(tmp_path, gripper=PASSING_GRIPPER)).robot
    cal = robot.calibration
    width = 2.0 * cal.brick_half_extents[1]
    assert cal.closed_width == pytest.approx(-0.016, abs=1e-4)
    assert cal.squeeze_width == width  # the gap map alone never closes it in time
    np.testing.assert_array_equal(robot.ctrl_for_width(width), cal.closed_command)
    np.testing.assert_array_equal(
        robot.ctrl_for_widths(np.array([0.0, width]))[1], cal.closed_command
    )
    assert robot.ctrl_for_width(width + 1e-3)[0] > cal.closed_command[0]
    assert cal.close_time <= 1.0
    forced = load_robot(write_toy_robot(tmp_path / "wsg")).robot.calibration
    assert forced.squeeze_width == forced.closed_width  # a force range saturates: as mapped


def test_a_gripper_that_opens_less_than_a_grasp_needs_is_refused_in_one_line(
    tmp_path: Path,
) -> None:
    gripper = TOY_GRIPPER.replace('range="0 0.045"', 'range="0 0.024"')  # joints, ctrl
    path = write_toy_robot(tmp_path, gripper=gripper)
    with pytest.raises(RobotError) as err:
        load_robot(path)
    message = str(err.value)
    assert "\n" not in message and str(path) in message and "[gripper] mjcf" in message
    assert "opens to 52.0 mm" in message and "at least 54.0 mm" in message


def test_a_position_actuators_control_range_narrows_its_joints_range(tmp_path: Path) -> None:
    # MuJoCo clamps a position actuator's control to its range: the joint's target never
    # leaves it, so the loader makes it the joint's range (a degree file: written in degrees).
    arm = TOY_ARM.replace(
        '<motor joint="wrist1" ctrlrange="-20 20"/>',
        '<position joint="wrist1" kp="100" ctrlrange="-3 3"/>',
    ).replace(
        '<motor joint="elbow" ctrlrange="-80 80"/>',
        '<position joint="elbow" kp="500" ctrlrange="-2.5 2.6"/>',
    )
    robot = load_robot(write_toy_robot(tmp_path, arm=arm)).robot
    np.testing.assert_allclose(robot.q_min[[2, 3]], [-2.5, -3.0])
    np.testing.assert_allclose(robot.q_max[[2, 3]], [2.6, 3.0])
    assert not robot.continuous.any()
    np.testing.assert_allclose(robot.q_max[[0, 1]], np.deg2rad([170, 110]))  # motors: as read
    assert sum("narrowed to its actuator's control range" in r for r in robot.repairs) == 2
    toml = TOY_TOML.replace('angle = "degree"', 'angle = "degree"\nhome = [0, 0, 0, 3.5, 0, 0]')
    with pytest.raises(RobotError, match=r"wrist1 = 3.5 is outside its range; valid: \[-3, 3\]"):
        load_robot(write_toy_robot(tmp_path / "home", arm=arm, toml=toml))


def test_a_gripper_pointing_back_into_the_arm_is_refused_with_a_mount_that_points_out(
    tmp_path: Path,
) -> None:
    # Half a turn about the flange's x: the fingers point down the arm's last link.
    into = TOY_TOML.replace("mount_pos = [0, 0, 0.01]", "mount_quat = [0, 1, 0, 0]")
    with pytest.raises(RobotError) as refused:
        load_robot(write_toy_robot(tmp_path / "into", toml=into))
    text = str(refused.value)
    assert "[gripper] mount_quat: the gripper points back into the arm" in text
    # wrist3 turns about the tool axis at the flange: the way out starts at wrist2.
    assert "180°" in text and "from joint 'arm/wrist2' to the flange 'hand_mount'" in text
    # The mount it names (turned back; the flange's face, the 20 mm disc's half) composes.
    assert "mount_quat = [0, 0, 0, -1] (half a turn) with mount_pos = [0, 0, 0.01]" in text
    fixed = into.replace(
        "mount_quat = [0, 1, 0, 0]", "mount_quat = [0, 0, 0, -1]\nmount_pos = [0, 0, 0.01]"
    )
    assert load_robot(write_toy_robot(tmp_path / "out", toml=fixed)).robot.n_joints == 6
