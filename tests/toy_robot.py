"""A small arm and gripper of our own, written as published files are, and their description.

The arm is a 6-DoF arm as published elsewhere: degrees without <compiler angle>, torque
motors, an <option>, a keyframe, a floor on its worldbody, an attribute MuJoCo rejects (group on
a default), a continuous joint, and a body (not a site) as flange. The gripper has two
independently position-controlled slide fingers with two pads each, a mesh in a meshdir
defined twice. Nothing in them is a bundled robot's: tests compose, calibrate and run them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

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

# The toy arm stood where it reaches neither bin (both 1.3 m away, it reaches about 0.9 m).
TOY_TOO_FAR = TOY_TOML.replace('angle = "degree"', 'angle = "degree"\nbase_pos = [-0.6, 0.6, 0]')

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


# Bad robot files: changes to write_toy_robot's arguments, the description field the one-line
# error names, and fragments of its message.
BAD_CASES: dict[str, tuple[dict[str, Any], str, tuple[str, ...]]] = {
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
