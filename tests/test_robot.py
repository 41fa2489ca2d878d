"""Robot descriptions: composed with MjSpec, calibrated in simulation, bad files refused.

The bundled iiwa14-wsg50 must compose into a model equivalent to today's hand-written scene;
a small arm and gripper written here (published-file pitfalls included) must compose and
calibrate with no bundled-robot assumption; every bad file is one line naming file and field.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import mujoco
import numpy as np
import pytest

from pickplace.errors import PickPlaceError, RobotError
from pickplace.robot import (
    ARM_PREFIX,
    BRICK_GEOM,
    DEFAULT_ROBOT,
    HOME_TOOL_SITE,
    Composition,
    bundled_robots,
    load_robot,
)
from pickplace.robot_description import RobotDescription
from pickplace.robot_physics import (
    GRIPPER_MIN_ARMATURE,
    GRIPPER_MIN_DAMPING,
    ROBOT_CONAFFINITY,
    ROBOT_CONTYPE,
    arm_min_armature,
)
from pickplace.scene import Scene

TODAYS_OPEN_WIDTH = 0.10  # the plan's open gap, held by today's home keyframe [m]


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


def test_iiwa_joints_limits_and_actuators_equal_todays_scene(iiwa: Composition, scene: Scene):
    robot, m, old = iiwa.robot, iiwa.model, scene.model
    assert robot.arm_joint_names == tuple(ARM_PREFIX + j for j in scene.arm_joint_names)
    np.testing.assert_array_equal(robot.q_min, scene.q_min)
    np.testing.assert_array_equal(robot.q_max, scene.q_max)
    np.testing.assert_allclose(robot.v_max, scene.v_max, rtol=1e-7)
    assert not robot.continuous.any()
    np.testing.assert_array_equal(robot.q_home, scene.q_home)
    for field in ("actuator_gainprm", "actuator_biasprm", "actuator_forcerange"):
        np.testing.assert_array_equal(
            getattr(m, field)[robot.arm_actuator_ids], getattr(old, field)[scene.arm_actuator_ids]
        )
    np.testing.assert_array_equal(
        m.dof_armature[robot.arm_dof_adr], old.dof_armature[scene.arm_dof_adr]
    )
    np.testing.assert_allclose(robot.p_W_base, scene.p_W_base, atol=1e-12)
    assert robot.a_max is not None and robot.a_max.shape == (robot.n_joints,)


def test_iiwa_tool_site_at_home_matches_todays_within_a_millimetre(iiwa: Composition, scene):
    data, old = iiwa.robot.make_data(iiwa.model), scene.make_data()
    site, old_site = iiwa.robot.tool_site_id, scene.tool_site_id
    assert np.linalg.norm(data.site_xpos[site] - old.site_xpos[old_site]) < 1e-3
    R, R_old = data.site_xmat[site].reshape(3, 3), old.site_xmat[old_site].reshape(3, 3)
    angle = np.arccos(np.clip((np.trace(R_old.T @ R) - 1.0) / 2.0, -1.0, 1.0))
    assert angle < 1e-6


def test_iiwa_gripper_force_width_and_home_equal_todays(iiwa: Composition, scene: Scene):
    robot, m = iiwa.robot, iiwa.model
    assert robot.squeeze_force == pytest.approx(scene.gripper_force_limit, rel=1e-3)
    assert robot.open_width == pytest.approx(scene.gripper_max_gap, abs=1e-6)
    grip = robot.gripper_actuator_ids
    np.testing.assert_allclose(m.actuator_forcerange[grip], [[-40.0, 40.0]])
    key = robot.home_key_id
    np.testing.assert_allclose(m.key_ctrl[key, grip], [TODAYS_OPEN_WIDTH], atol=1e-6)
    data = robot.make_data(m)
    # Today's gap is the sum of the finger joints; the pad-face gap equals it.
    finger_sum = data.qpos[m.jnt_qposadr[robot.gripper_joint_ids]].sum()
    assert robot.gap(data) == pytest.approx(finger_sum, abs=1e-9)
    assert robot.gap(data) == pytest.approx(TODAYS_OPEN_WIDTH, abs=1e-6)


def test_iiwa_contact_bits_pads_and_sensors_equal_todays(iiwa: Composition, scene: Scene):
    robot, m, old = iiwa.robot, iiwa.model, scene.model
    for new_pad, old_pad in zip(robot.pad_geom_ids, scene.pad_geom_ids, strict=True):
        (g,) = new_pad
        for field in ("geom_priority", "geom_solref", "geom_solimp", "geom_friction", "geom_size"):
            np.testing.assert_array_equal(getattr(m, field)[g], getattr(old, field)[old_pad])
    assert set(m.geom_contype[robot.robot_geom_ids]) == {ROBOT_CONTYPE}
    assert set(m.geom_conaffinity[robot.robot_geom_ids]) == {ROBOT_CONAFFINITY}
    assert robot.pad_force_slots == scene.pad_force_slots
    for sensors, pads in zip(robot.pad_force_sensor_ids, robot.pad_geom_ids, strict=True):
        for s, pad in zip(sensors, pads, strict=True):
            assert m.sensor_type[s] == mujoco.mjtSensor.mjSENS_CONTACT
            np.testing.assert_array_equal(m.sensor_intprm[s], old.sensor_intprm[0])
            brick = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, BRICK_GEOM)
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

# A 6-DoF arm as published elsewhere: degrees without <compiler angle>, torque motors, an
# <option>, a keyframe, a floor on its worldbody, an attribute MuJoCo rejects (group on a
# default), a continuous joint, and a body (not a site) as flange.
TOY_ARM = """
<mujoco model="toy arm">
  <option timestep="0.001"/>
  <default>
    <default class="link" group="1">
      <joint damping="1" armature="0.05"/>
      <geom type="capsule" size="0.04" density="300"/>
    </default>
  </default>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1"/>
    <body name="pedestal" childclass="link">
      <geom type="cylinder" size="0.08 0.15" pos="0 0 0.15"/>
      <body name="l1" pos="0 0 0.3">
        <joint name="yaw" axis="0 0 1" range="-170 170"/>
        <geom fromto="0 0 0 0 0 0.05"/>
        <body name="l2" pos="0 0 0.05">
          <joint name="shoulder" axis="0 1 0" range="-110 110"/>
          <geom fromto="0 0 0 0 0 0.45"/>
          <body name="l3" pos="0 0 0.45">
            <joint name="elbow" axis="0 1 0" range="-150 150"/>
            <geom fromto="0 0 0 0 0 0.4"/>
            <body name="l4" pos="0 0 0.4">
              <joint name="wrist1" axis="0 0 1"/>
              <geom size="0.035" fromto="0 0 0 0 0 0.05"/>
              <body name="l5" pos="0 0 0.05">
                <joint name="wrist2" axis="0 1 0" range="-120 120"/>
                <geom size="0.035" fromto="0 0 0 0 0 0.05"/>
                <body name="hand_mount" pos="0 0 0.06">
                  <joint name="wrist3" axis="0 0 1" range="-350 350"/>
                  <geom type="cylinder" size="0.035 0.01"/>
                </body>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor joint="yaw" ctrlrange="-150 150"/>
    <motor joint="shoulder" ctrlrange="-75 75" gear="2"/>
    <motor joint="elbow" ctrlrange="-80 80"/>
    <motor joint="wrist1" ctrlrange="-20 20"/>
    <motor joint="wrist2" ctrlrange="-20 20"/>
    <motor joint="wrist3" ctrlrange="-20 20"/>
  </actuator>
  <keyframe><key name="rest" qpos="0 0 0 0 0 0"/></keyframe>
</mujoco>
"""

# Two independently position-controlled slide fingers with two pads each (side by side, set
# back from a finger link that reaches further), a mesh in a meshdir defined twice, radians.
TOY_GRIPPER = """
<mujoco model="toy gripper">
  <compiler angle="radian" meshdir="meshes"/>
  <asset>
    <mesh name="palm" file="palm.obj"/>
    <mesh name="palm" file="palm.obj"/>
  </asset>
  <default>
    <default class="finger">
      <joint type="slide" range="0 0.045" damping="5"/>
      <geom type="box" friction="1 0.005 0.0001"/>
    </default>
  </default>
  <worldbody>
    <body name="hand">
      <geom type="mesh" mesh="palm" contype="0" conaffinity="0" group="2"/>
      <geom name="palm" type="box" size="0.03 0.05 0.025" pos="0 0 0.025" mass="0.5"/>
      <body name="finger_a" pos="0 0 0.05">
        <joint name="finger_a" class="finger" axis="0 1 0"/>
        <geom class="finger" name="a_link" size="0.01 0.006 0.03" pos="0 0.012 0.03" mass="0.05"/>
        <geom class="finger" name="a_pad1" size="0.005 0.002 0.01" pos="-0.007 0.004 0.045"/>
        <geom class="finger" name="a_pad2" size="0.005 0.002 0.01" pos="0.007 0.004 0.045"/>
      </body>
      <body name="finger_b" pos="0 0 0.05">
        <joint name="finger_b" class="finger" axis="0 -1 0"/>
        <geom class="finger" name="b_link" size="0.01 0.006 0.03" pos="0 -0.012 0.03" mass="0.05"/>
        <geom class="finger" name="b_pad1" size="0.005 0.002 0.01" pos="-0.007 -0.004 0.045"/>
        <geom class="finger" name="b_pad2" size="0.005 0.002 0.01" pos="0.007 -0.004 0.045"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="a" joint="finger_a" kp="1000" ctrlrange="0 0.045" forcerange="-25 25"/>
    <position name="b" joint="finger_b" kp="1000" ctrlrange="0 0.045" forcerange="-25 25"/>
  </actuator>
</mujoco>
"""

# A 6 x 10 x 5 cm box as a Wavefront OBJ (the palm's visual mesh).
_CORNERS = ((-0.03, -0.05), (0.03, -0.05), (0.03, 0.05), (-0.03, 0.05))
PALM_OBJ = "\n".join(
    [f"v {x} {y} {z}" for z in (0, 0.05) for x, y in _CORNERS]
    + [
        "f 1 3 2", "f 1 4 3", "f 5 6 7", "f 5 7 8", "f 1 2 6", "f 1 6 5",
        "f 2 3 7", "f 2 7 6", "f 3 4 8", "f 3 8 7", "f 4 1 5", "f 4 5 8",
    ]
)  # fmt: skip

TOY_TOML = """
name = "toy-6dof"
[arm]
mjcf = "arm.xml"
flange = "hand_mount"
speed_limits = [2.0, 2.0, 2.5, 3.0, 3.0, 3.0]
angle = "degree"
[gripper]
mjcf = "gripper.xml"
mount_pos = [0, 0, 0.01]
"""

TOY_SPEED_LIMITS = [2.0, 2.0, 2.5, 3.0, 3.0, 3.0]
TOY_MOTOR_LIMITS = [150.0, 150.0, 80.0, 20.0, 20.0, 20.0]  # ctrlrange × gear [N·m]


def write_toy_robot(
    folder: Path,
    arm: str = TOY_ARM,
    gripper: str = TOY_GRIPPER,
    toml: str = TOY_TOML,
    mesh: str | None = PALM_OBJ,
) -> Path:
    """Write the toy arm, gripper, mesh and description into ``folder``; return the TOML."""
    (folder / "meshes").mkdir(parents=True, exist_ok=True)
    (folder / "arm.xml").write_text(arm)
    (folder / "gripper.xml").write_text(gripper)
    if mesh is not None:
        (folder / "meshes" / "palm.obj").write_text(mesh)
    path = folder / "robot.toml"
    path.write_text(toml)
    return path


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


BAD_CASES = {
    "missing arm file": (
        {"toml": TOY_TOML.replace('"arm.xml"', '"no-such-arm.xml"')},
        "[arm] mjcf",
        ("no-such-arm.xml", "does not exist"),
    ),
    "missing gripper file": (
        {"toml": TOY_TOML.replace('"gripper.xml"', '"nope.xml"')},
        "[gripper] mjcf",
        ("nope.xml",),
    ),
    "mesh file missing": ({"mesh": None}, "[gripper] mjcf", ("mesh 'palm'", "does not exist")),
    "mesh does not load": ({"mesh": "v 0 0 0\nf 1 1 1\n"}, "[gripper] mjcf", ("mesh 'palm'",)),
    "speed limits of the wrong length": (
        {"toml": TOY_TOML.replace("3.0, 3.0, 3.0]", "3.0, 3.0]")},
        "[arm] speed_limits",
        ("has 5 values", "6 positive numbers", "yaw", "wrist3"),
    ),
    "speed limits not positive": (
        {"toml": TOY_TOML.replace("[2.0, 2.0", "[2.0, -2.0")},
        "[arm] speed_limits",
        ("> 0",),
    ),
    "no chain from the root to the flange": (
        {"toml": TOY_TOML.replace('flange = "hand_mount"', 'flange = "pedestal"')},
        "[arm] flange",
        ("no hinge or slide joint", "pedestal"),
    ),
    "flange that does not exist": (
        {"toml": TOY_TOML.replace('flange = "hand_mount"', 'flange = "tool0"')},
        "[arm] flange",
        ("tool0", "hand_mount"),
    ),
    "no pads found": (
        {
            "gripper": TOY_GRIPPER.replace(
                '<geom type="box" friction', '<geom type="box" contype="0" conaffinity="0" friction'
            )
        },
        "[gripper] pads",
        ("no pads found",),
    ),
    "gripper that cannot open wider than the brick": (
        {
            "gripper": TOY_GRIPPER.replace('range="0 0.045"', 'range="0 0.02"').replace(
                'ctrlrange="0 0.045"', 'ctrlrange="0 0.02"'
            )
        },
        "[gripper] mjcf",
        ("cannot open wider than the brick", "50.0 mm"),
    ),
    "angle units unknown": (
        {"toml": TOY_TOML.replace('angle = "degree"\n', "")},
        "[arm] mjcf",
        ("<compiler angle>", "radian"),
    ),
    "angle contradicting the file": (
        {"toml": TOY_TOML.replace("mount_pos", 'angle = "degree"\nmount_pos')},
        "[gripper] angle",
        ("radian",),
    ),
    "unknown field": (
        {"toml": TOY_TOML.replace("[gripper]", "[gripper]\ngrip = 3")},
        "[gripper] grip",
        ("unknown field", "grip_force"),
    ),
    "home outside a joint range": (
        {
            "toml": TOY_TOML.replace(
                'angle = "degree"', 'angle = "degree"\nhome = [4, 0, 0, 0, 0, 0]'
            )
        },
        "[arm] home",
        ("yaw",),
    ),
}


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
