"""The bundled robot descriptions in robots/: files, kinematics, limits, gripper physics.

Composition here uses MuJoCo's MjSpec directly (a frame on the flange, the gripper attached under
a prefix, the arm attached to the world of scenes/world.xml), so these facts hold for the files
themselves, whatever loader reads them.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import mink
import mujoco
import numpy as np
import pytest
from mink.lie import SE3, SO3

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    tomllib = pytest.importorskip("tomli")

REPO = Path(__file__).resolve().parent.parent
ROBOTS_DIR = REPO / "robots"
WORLD = REPO / "scenes" / "world.xml"
ROBOTS = ("panda-hand", "ur5e-2f85")

# The robot.toml format (docs/robots.md): every key a bundled file may use.
ALLOWED_KEYS = {
    "": {"name", "arm", "gripper"},
    "arm": {"mjcf", "flange", "speed_limits", "accel_limits", "home", "angle"},
    "gripper": {"mjcf", "mount_pos", "mount_quat", "angle"},
}

# Published kinematics, written independently of the MJCF files.
# Franka Panda, modified (Craig) DH: per joint (a, d, alpha); T = Rx(alpha) Tx(a) Rz(q) Tz(d);
# the flange 0.107 m along the last z.
PANDA_MDH = [
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -math.pi / 2),
    (0.0, 0.316, math.pi / 2),
    (0.0825, 0.0, math.pi / 2),
    (-0.0825, 0.384, -math.pi / 2),
    (0.0, 0.0, math.pi / 2),
    (0.088, 0.0, math.pi / 2),
]
# UR5e, standard DH: per joint (d, a, alpha); T = Rz(q) Tz(d) Tx(a) Rx(alpha), ending at the flange.
UR5E_DH = [
    (0.1625, 0.0, math.pi / 2),
    (0.0, -0.425, 0.0),
    (0.0, -0.3922, 0.0),
    (0.1333, 0.0, math.pi / 2),
    (0.0997, 0.0, -math.pi / 2),
    (0.0996, 0.0, 0.0),
]
# Datasheet joint ranges [rad] and joint torque limits [N m].
EXPECTED_RANGES = {
    "panda-hand": [
        (-2.8973, 2.8973),
        (-1.7628, 1.7628),
        (-2.8973, 2.8973),
        (-3.0718, -0.0698),
        (-2.8973, 2.8973),
        (-0.0175, 3.7525),
        (-2.8973, 2.8973),
    ],
    "ur5e-2f85": [(-2 * math.pi, 2 * math.pi)] * 2
    + [(-math.pi, math.pi)]
    + [(-2 * math.pi, 2 * math.pi)] * 3,
}
EXPECTED_TORQUES = {"panda-hand": [87] * 4 + [12] * 3, "ur5e-2f85": [150] * 3 + [28] * 3}
# Smallest finger gap when open that the brief asks for [m] (the brick is 0.05 m wide).
MIN_OPEN_GAP = {"panda-hand": 0.08, "ur5e-2f85": 0.085}
BRICK_HALF = (0.0375, 0.025, 0.025)
BRICK_MASS = 0.2


def _rot(axis: str, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    T = np.eye(4)
    i, j = {"x": (1, 2), "z": (0, 1)}[axis]
    T[i, i], T[i, j], T[j, i], T[j, j] = c, -s, s, c
    return T


def _trans(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def panda_flange(q: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    for (a, d, alpha), qi in zip(PANDA_MDH, q, strict=True):
        T = T @ _rot("x", alpha) @ _trans(a, 0, 0) @ _rot("z", qi) @ _trans(0, 0, d)
    return T @ _trans(0, 0, 0.107)


def ur5e_flange(q: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    for (d, a, alpha), qi in zip(UR5E_DH, q, strict=True):
        T = T @ _rot("z", qi) @ _trans(0, 0, d) @ _trans(a, 0, 0) @ _rot("x", alpha)
    return T


DH_FLANGE = {"panda-hand": panda_flange, "ur5e-2f85": ur5e_flange}


def description(robot: str) -> dict[str, Any]:
    with open(ROBOTS_DIR / robot / "robot.toml", "rb") as f:
        return tomllib.load(f)


@contextmanager
def warnings_caught() -> Iterator[list[str]]:
    """Collect MuJoCo's warning messages while the block runs."""
    messages: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(messages.append)
    try:
        yield messages
    finally:
        mujoco.set_mju_user_warning(previous)


def chain_joints(model: mujoco.MjModel, flange_body: int) -> list[int]:
    """Joint ids on the chain from the root to the flange body, root first."""
    joints: list[int] = []
    body = flange_body
    while body != 0:
        start, n = model.body_jntadr[body], model.body_jntnum[body]
        joints[:0] = range(start, start + n)
        body = model.body_parentid[body]
    return joints


def robot_spec(robot: str) -> mujoco.MjSpec:
    """Arm with the gripper attached at the flange, as robot.toml describes."""
    desc = description(robot)
    folder = ROBOTS_DIR / robot
    arm = mujoco.MjSpec.from_file(str(folder / desc["arm"]["mjcf"]))
    gripper = mujoco.MjSpec.from_file(str(folder / desc["gripper"]["mjcf"]))
    frame = arm.body(desc["arm"]["flange"]).add_frame(
        pos=desc["gripper"].get("mount_pos", [0, 0, 0]),
        quat=desc["gripper"].get("mount_quat", [1, 0, 0, 0]),
    )
    arm.attach(gripper, prefix="gripper/", frame=frame)
    return arm


def world_spec() -> mujoco.MjSpec:
    """scenes/world.xml: bins, brick, floor, lights, cameras, options, no robot."""
    return mujoco.MjSpec.from_file(str(WORLD))


def composed(robot: str) -> mujoco.MjModel:
    """The world of the scene with the robot attached under the prefix "robot/"."""
    world = world_spec()
    world.attach(robot_spec(robot), prefix="robot/", frame=world.worldbody.add_frame())
    return world.compile()


def arm_joint_ids(model: mujoco.MjModel, robot: str, prefix: str = "") -> list[int]:
    flange = model.body(prefix + description(robot)["arm"]["flange"]).id
    return chain_joints(model, flange)


def joint_actuator(model: mujoco.MjModel, joint: int) -> int:
    """The one actuator that drives ``joint`` directly."""
    on_joint = model.actuator_trntype == mujoco.mjtTrn.mjTRN_JOINT
    (a,) = np.flatnonzero(on_joint & (model.actuator_trnid[:, 0] == joint))
    return int(a)


@pytest.mark.parametrize("robot", ROBOTS)
def test_description_uses_only_the_documented_format(robot: str) -> None:
    desc = description(robot)
    assert set(desc) <= ALLOWED_KEYS[""]
    assert {"name", "arm", "gripper"} <= set(desc)
    assert desc["name"] == robot
    for table in ("arm", "gripper"):
        assert set(desc[table]) <= ALLOWED_KEYS[table]
        assert (ROBOTS_DIR / robot / desc[table]["mjcf"]).is_file()
    assert np.isclose(np.linalg.norm(desc["gripper"].get("mount_quat", [1, 0, 0, 0])), 1.0)


@pytest.mark.parametrize("part", ["arm", "gripper"])
@pytest.mark.parametrize("robot", ROBOTS)
def test_each_file_compiles_standalone_in_radians_without_options(robot: str, part: str) -> None:
    path = ROBOTS_DIR / robot / description(robot)[part]["mjcf"]
    text = path.read_text()
    assert '<compiler angle="radian" autolimits="true"/>' in text
    assert "<option" not in text  # physics options belong to the scene
    with warnings_caught() as messages:
        model = mujoco.MjModel.from_xml_path(str(path))
    assert messages == []
    assert model.nu > 0


@pytest.mark.parametrize("robot", ROBOTS)
def test_arm_chain_matches_the_description(robot: str) -> None:
    desc = description(robot)
    model = mujoco.MjModel.from_xml_path(str(ROBOTS_DIR / robot / desc["arm"]["mjcf"]))
    joints = arm_joint_ids(model, robot)
    n = {"panda-hand": 7, "ur5e-2f85": 6}[robot]
    assert len(joints) == n == model.njnt
    assert all(model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE for j in joints)
    assert all(model.jnt_limited[j] for j in joints)
    np.testing.assert_allclose(model.jnt_range[joints], EXPECTED_RANGES[robot], atol=1e-5)
    speed = np.asarray(desc["arm"]["speed_limits"])
    assert speed.shape == (n,) and np.all(speed > 0)
    if "accel_limits" in desc["arm"]:
        accel = np.asarray(desc["arm"]["accel_limits"])
        assert accel.shape == (n,) and np.all(accel > 0)
    home = np.asarray(desc["arm"]["home"])
    assert home.shape == (n,)
    assert np.all(home > model.jnt_range[joints, 0]) and np.all(home < model.jnt_range[joints, 1])
    # One position actuator per joint: ctrl range = joint range, force range = torque limit.
    for j, torque in zip(joints, EXPECTED_TORQUES[robot], strict=True):
        a = joint_actuator(model, j)
        assert model.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE
        assert model.actuator_gainprm[a, 0] == pytest.approx(2000)
        np.testing.assert_allclose(model.actuator_ctrlrange[a], model.jnt_range[j])
        np.testing.assert_allclose(model.actuator_forcerange[a], [-torque, torque])
        assert model.dof_armature[model.jnt_dofadr[j]] == pytest.approx(0.1)
        assert model.body_gravcomp[model.jnt_bodyid[j]] == 1.0


@pytest.mark.parametrize("robot", ROBOTS)
def test_flange_follows_the_published_dh_table(robot: str) -> None:
    desc = description(robot)
    model = mujoco.MjModel.from_xml_path(str(ROBOTS_DIR / robot / desc["arm"]["mjcf"]))
    data = mujoco.MjData(model)
    flange = model.body(desc["arm"]["flange"]).id
    joints = arm_joint_ids(model, robot)
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = rng.uniform(model.jnt_range[joints, 0], model.jnt_range[joints, 1])
        data.qpos[model.jnt_qposadr[joints]] = q
        mujoco.mj_kinematics(model, data)
        T = DH_FLANGE[robot](q)
        np.testing.assert_allclose(data.xpos[flange], T[:3, 3], atol=1e-12)
        np.testing.assert_allclose(data.xmat[flange].reshape(3, 3), T[:3, :3], atol=1e-12)


@pytest.mark.parametrize("robot", ROBOTS)
def test_composed_with_the_world_steps_one_second_quietly_and_holds_home(robot: str) -> None:
    with warnings_caught() as messages:
        model = composed(robot)
        data = mujoco.MjData(model)
        joints = arm_joint_ids(model, robot, "robot/")
        home = np.asarray(description(robot)["arm"]["home"])
        data.qpos[model.jnt_qposadr[joints]] = home
        for j, q in zip(joints, home, strict=True):
            data.ctrl[joint_actuator(model, j)] = q
        mujoco.mj_forward(model, data)
        for _ in range(round(1.0 / model.opt.timestep)):
            mujoco.mj_step(model, data)
    assert messages == []
    assert [w.number for w in data.warning] == [0] * len(data.warning)
    assert np.all(np.isfinite(data.qpos))
    # Gravity compensation and stiff servos: the arm stays at home.
    np.testing.assert_allclose(data.qpos[model.jnt_qposadr[joints]], home, atol=2e-3)
    # Home has the tool pointing down, above the bins' walls (top at 0.13 m).
    tool = model.site("robot/gripper/tool").id
    assert data.site_xmat[tool].reshape(3, 3)[:, 2] @ [0, 0, -1] > 0.999
    assert data.site_xpos[tool][2] > 0.13 + 0.1


WORLD_WITH_CARRIER = """
<mujoco>
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.002" integrator="implicitfast" cone="elliptic" impratio="10"/>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1"/>
    <body name="carrier" pos="0 0 {z0}" gravcomp="1">
      <joint name="lift" type="slide" axis="0 0 1" armature="1"/>
      <inertial pos="0 0 0" mass="2" diaginertia="0.01 0.01 0.01"/>
    </body>
    <body name="brick" pos="1 1 {hz}">
      <freejoint/>
      <geom name="brick" type="box" size="{hx} {hy} {hz}" mass="{mass}" friction="1 0.005 0.0001"/>
    </body>
  </worldbody>
  <actuator>
    <position name="lift" joint="lift" kp="20000" dampratio="1"/>
  </actuator>
</mujoco>
"""


class GripperRig:
    """The gripper hanging tool-down from a lifting carrier over a brick on the floor."""

    def __init__(self, robot: str) -> None:
        gripper = mujoco.MjSpec.from_file(
            str(ROBOTS_DIR / robot / description(robot)["gripper"]["mjcf"])
        )
        p_tool = next(s for s in gripper.sites if s.name == "tool").pos
        hx, hy, hz = BRICK_HALF
        spec = mujoco.MjSpec.from_string(
            WORLD_WITH_CARRIER.format(z0=hz + p_tool[2], hx=hx, hy=hy, hz=hz, mass=BRICK_MASS)
        )
        frame = spec.body("carrier").add_frame(quat=[0, 1, 0, 0])  # tool z points down
        spec.attach(gripper, prefix="g/", frame=frame)
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.fingers = [a for a in range(m.nu) if m.actuator(a).name.startswith("g/")]
        self.pads = [m.geom("g/left_pad").id, m.geom("g/right_pad").id]
        self.brick_geom = m.geom("brick").id
        self.brick_qpos = m.jnt_qposadr[m.body_jntadr[m.body("brick").id]]
        self.tool = m.site("g/tool").id

    def step(self, seconds: float) -> None:
        for _ in range(round(seconds / self.model.opt.timestep)):
            mujoco.mj_step(self.model, self.data)

    def lift(self, height: float, seconds: float) -> None:
        """Raise the carrier by ``height`` [m] along a sine ramp (0.3 m in 1 s: peak 1.5 m/s²)."""
        lift = self.model.actuator("lift").id
        n = round(seconds / self.model.opt.timestep)
        for k in range(1, n + 1):
            self.data.ctrl[lift] = height * 0.5 * (1.0 - math.cos(math.pi * k / n))
            mujoco.mj_step(self.model, self.data)

    def command(self, end: int) -> None:
        """All finger actuators to one end of their control range (0 low, 1 high)."""
        self.data.ctrl[self.fingers] = self.model.actuator_ctrlrange[self.fingers, end]

    def gap(self) -> float:
        """Distance between the pads' inner faces along the tool's y axis [m]."""
        m, d = self.model, self.data
        R = d.site_xmat[self.tool].reshape(3, 3)
        y = [(R.T @ (d.geom_xpos[p] - d.site_xpos[self.tool]))[1] for p in self.pads]
        return float((y[0] - m.geom_size[self.pads[0], 1]) - (y[1] + m.geom_size[self.pads[1], 1]))

    def pad_forces(self) -> list[float]:
        """Normal force of the brick on each pad [N]."""
        f6 = np.zeros(6)
        forces = []
        for pad in self.pads:
            total = 0.0
            for i in range(self.data.ncon):
                c = self.data.contact[i]
                if {c.geom1, c.geom2} == {pad, self.brick_geom}:
                    mujoco.mj_contactForce(self.model, self.data, i, f6)
                    total += f6[0]
            forces.append(total)
        return forces

    def p_tool_brick(self) -> np.ndarray:
        d = self.data
        R = d.site_xmat[self.tool].reshape(3, 3)
        return R.T @ (d.xpos[self.model.body("brick").id] - d.site_xpos[self.tool])

    def open_end(self) -> int:
        """Which end of the control range opens the fingers (the wider gap)."""
        gaps = []
        for end in (0, 1):
            self.command(end)
            self.step(0.5)
            gaps.append(self.gap())
        return int(np.argmax(gaps))

    def put_brick_between_the_pads(self) -> None:
        d = self.data
        d.qpos[self.brick_qpos : self.brick_qpos + 7] = [0, 0, BRICK_HALF[2], 1, 0, 0, 0]
        d.qvel[:] = 0
        mujoco.mj_forward(self.model, d)


@pytest.mark.parametrize("robot", ROBOTS)
def test_gripper_opens_wide_and_squeezes_a_brick_through_a_lift(robot: str) -> None:
    rig = GripperRig(robot)
    with warnings_caught() as messages:
        opens = rig.open_end()
        rig.command(opens)
        rig.step(0.5)
        open_gap = rig.gap()
        rig.put_brick_between_the_pads()
        rig.command(1 - opens)
        rig.step(0.6)
        closed = rig.pad_forces()
        closed_gap = rig.gap()
        p0 = rig.p_tool_brick()
        rig.lift(0.3, 1.0)
        rig.step(0.5)
        lifted = rig.pad_forces()
        drift = rig.p_tool_brick() - p0
    assert messages == []
    assert open_gap >= MIN_OPEN_GAP[robot] - 1e-4
    # The fingers stop on the brick: the gap is its width, both pads push alike, the brick
    # sits on the tool site (midway between the pads) and stays there while lifted.
    assert closed_gap == pytest.approx(2 * BRICK_HALF[1], abs=5e-4)
    assert min(closed) > 10.0
    assert closed[0] == pytest.approx(closed[1], rel=0.02)
    np.testing.assert_allclose(p0, [0, 0, 0], atol=1e-3)
    assert lifted == pytest.approx(closed, rel=0.02)
    assert np.linalg.norm(drift) < 1e-3
    assert rig.data.xpos[rig.model.body("brick").id][2] > BRICK_HALF[2] + 0.29


def _down(p: np.ndarray, yaw: float) -> SE3:
    y = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    z = np.array([0.0, 0.0, -1.0])
    return SE3.from_rotation_and_translation(
        SO3.from_matrix(np.column_stack([np.cross(y, z), y, z])), p
    )


def _ik_error(model: mujoco.MjModel, q0: np.ndarray, target: SE3) -> float:
    """Largest of position [m] and orientation [rad] error after IK from ``q0`` towards
    ``target``, within the joint limits, steps capped at 0.1 rad."""
    cfg = mink.Configuration(model, q0.copy())
    task = mink.FrameTask("gripper/tool", "site", position_cost=1.0, orientation_cost=1.0)
    task.set_target(target)
    limits = [mink.ConfigurationLimit(model)]
    for _ in range(300):
        v = mink.solve_ik(cfg, [task], 0.05, "daqp", damping=1e-6, limits=limits)
        step = np.abs(v).max() * 0.05
        cfg.integrate_inplace(v * min(1.0, 0.1 / step) if step > 0 else v, 0.05)
    error = task.compute_error(cfg)
    return float(max(np.linalg.norm(error[:3]), np.linalg.norm(error[3:])))


@pytest.mark.slow
@pytest.mark.parametrize("robot", ROBOTS)
def test_tool_pointing_down_reaches_both_bin_floors_from_home(robot: str) -> None:
    model = robot_spec(robot).compile()
    joints = arm_joint_ids(model, robot)
    q0 = model.qpos0.copy()
    q0[model.jnt_qposadr[joints]] = description(robot)["arm"]["home"]
    brick_centre_z = 0.01 + BRICK_HALF[2]  # bin floors at z = 0.01 m
    for centre, bin_yaw in (((0.0, -0.55), 0.0), ((0.55, 0.0), math.pi / 2)):
        # Centre and corners of the inner floor (0.40 x 0.30 m) less 0.03 m, the brick's half width.
        for u, v in ((0, 0), (-0.17, -0.12), (-0.17, 0.12), (0.17, -0.12), (0.17, 0.12)):
            c, s = math.cos(bin_yaw), math.sin(bin_yaw)
            p = np.array([centre[0] + c * u - s * v, centre[1] + s * u + c * v, brick_centre_z])
            # Both closing directions; a parallel grasp at yaw and at yaw + pi is the same one.
            for yaw in (bin_yaw, bin_yaw + math.pi / 2):
                errors = [_ik_error(model, q0, _down(p, yaw + flip)) for flip in (0, math.pi)]
                assert min(errors) < 1e-4, (robot, p, yaw, errors)
