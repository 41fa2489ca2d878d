"""Robots from published files, unmodified: MuJoCo Menagerie's, shipped in robots/menagerie/.

robosuite 1.5.2's Panda, xArm and Robotiq 140 grippers, unmodified in robots/robosuite/, are
composed on Menagerie's iiwa 14: each is calibrated as its geometry needs and picks and places.

The bundled ``menagerie-*`` robots are described in a few lines over Menagerie's own files
(their nominal pick-and-place and random seeds run in tests/test_bundled_robots.py with every
bundled robot). Here: what composing published files needs — geoms without names addressed by
body and index, the flange's default and its message, an arm file with its own hand refused,
the squeeze a description gives, the base lifted off a floor it would touch, and the
calibration read back from disk by a second process.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from pickplace.errors import RobotError
from pickplace.robot.compose import ARM_FLOOR_CLEARANCE, load_robot
from pickplace.robot.description import RobotDescription
from pickplace.robot.registry import DEFAULT_WORLD, ROBOTS_DIR, bundled_robots
from pickplace.run.runner import RunRequest, run

MENAGERIE = ROBOTS_DIR / "menagerie"
PANDA = MENAGERIE / "franka_emika_panda"
PUBLISHED = [r for r in bundled_robots() if r.startswith("menagerie-")]


def _description(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "robot.toml"
    path.write_text(text, encoding="utf-8")
    return path


PANDA_ARM = f"""
name = "panda"
[arm]
mjcf = "{PANDA / "panda_nohand.xml"}"
speed_limits = [2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61]
"""


def test_three_published_robots_are_bundled_with_their_licences() -> None:
    assert {"menagerie-iiwa14-2f85", "menagerie-panda-hand", "menagerie-ur5e-2f85"} <= set(
        PUBLISHED
    )
    for model in MENAGERIE.iterdir():
        assert (model / "LICENSE").is_file(), model
    for robot in PUBLISHED:
        lines = (ROBOTS_DIR / robot / "robot.toml").read_text(encoding="utf-8").splitlines()
        fields = [ln for ln in lines if ln.strip() and not ln.lstrip().startswith("#")]
        assert len(fields) <= 12, robot


def test_unnamed_pads_are_addressed_by_body_and_index() -> None:
    robot = load_robot("menagerie-panda-hand").robot
    pads = robot.calibration.pads
    assert pads[0] and pads[1]
    assert all("/geom[" in name for side in pads for name in side), pads
    assert any(
        r.endswith("unnamed geoms named by body and index (body/geom[k])") for r in robot.repairs
    )


def test_the_flange_defaults_to_attachment_site_and_a_missing_one_lists_the_choices(
    tmp_path: Path,
) -> None:
    desc = RobotDescription.from_toml(
        _description(tmp_path, PANDA_ARM + f'[gripper]\nmjcf = "{PANDA / "hand.xml"}"\n')
    )
    robot = load_robot(desc).robot
    assert any("no [arm] flange given: the site 'attachment_site'" in r for r in robot.repairs)
    wrong = _description(
        tmp_path,
        PANDA_ARM.replace("[arm]\n", '[arm]\nflange = "hand"\n')
        + f'[gripper]\nmjcf = "{PANDA / "hand.xml"}"\n',
    )
    with pytest.raises(RobotError, match=r"'hand' is no body or site.*attachment_site.*attachment"):
        load_robot(wrong)


def test_an_arm_file_with_its_own_hand_is_refused_naming_the_hand_and_the_arm_only_file(
    tmp_path: Path,
) -> None:
    # Menagerie's panda.xml is panda_nohand.xml with hand.xml on its attachment site; built
    # the same way from the two files (the hand's names prefixed), beside the arm-only file.
    arm = mujoco.MjSpec.from_file(str(PANDA / "panda_nohand.xml"))
    hand = mujoco.MjSpec.from_file(str(PANDA / "hand.xml"))
    arm.site("attachment_site").attach_body(hand.body("hand"), "hand/", "")
    arm.meshdir = str(PANDA / "assets")
    (tmp_path / "panda.xml").write_text(arm.to_xml(), encoding="utf-8")
    (tmp_path / "panda_nohand.xml").write_text(
        (PANDA / "panda_nohand.xml").read_text(encoding="utf-8"), encoding="utf-8"
    )
    text = PANDA_ARM.replace(str(PANDA / "panda_nohand.xml"), str(tmp_path / "panda.xml"))
    path = _description(tmp_path, text + f'[gripper]\nmjcf = "{PANDA / "hand.xml"}"\n')
    with pytest.raises(RobotError) as err:
        load_robot(path)
    message = str(err.value)
    assert "already has a gripper below the flange 'attachment'" in message
    assert "hand/left_finger, hand/right_finger" in message
    assert "panda_nohand.xml" in message


def test_squeeze_force_gives_the_published_hand_its_real_squeeze() -> None:
    robot = load_robot("menagerie-panda-hand").robot
    assert robot.measured_squeeze_force == pytest.approx(70.0, rel=0.05)
    assert any("[gripper] squeeze_force" in r for r in robot.repairs)


def test_the_base_is_raised_off_a_floor_its_shoulder_would_touch(tmp_path: Path) -> None:
    world = mujoco.MjSpec.from_file(str(DEFAULT_WORLD))
    floor = next(g for g in world.worldbody.geoms if g.type == mujoco.mjtGeom.mjGEOM_PLANE)
    floor.pos = [0.0, 0.0, 0.1]  # above the iiwa's link 1 (77 mm up), which swivels
    comp = load_robot("menagerie-iiwa14-2f85", world)
    base_z = float(comp.robot.p_W_base[2])
    link1 = comp.model.body("arm/link1").id
    geoms = [g for g in range(comp.model.ngeom) if comp.model.geom_bodyid[g] == link1]
    data = mujoco.MjData(comp.model)
    mujoco.mj_kinematics(comp.model, data)
    lowest = min(
        float(data.geom_xpos[g][2] - comp.model.geom_rbound[g])
        for g in geoms
        if comp.model.geom_contype[g] or comp.model.geom_conaffinity[g]
    )
    assert lowest > 0.1, lowest  # clear of the raised floor (bounding spheres: conservative)
    default = load_robot("menagerie-iiwa14-2f85").robot
    assert float(default.p_W_base[2]) == pytest.approx(0.1575, abs=1e-9)  # joint 1, not raised
    assert not any("arm base raised" in r for r in default.repairs)
    lift = base_z - float(default.p_W_base[2])
    assert lift == pytest.approx(0.1 + ARM_FLOOR_CLEARANCE - 0.077, abs=2e-3)
    assert any("arm base raised" in r for r in comp.robot.repairs)


@pytest.mark.slow  # composes every robot, or starts CLI processes
def test_a_second_process_reads_the_calibration_from_disk(tmp_path: Path) -> None:
    script = (
        "import json, sys\n"
        "from pickplace.robot.compose import load_robot\n"
        "c = load_robot(sys.argv[1]).robot.calibration\n"
        "print(json.dumps([c.pos_BG.tolist(), c.close_time, c.sim_time]))\n"
    )
    env = dict(os.environ, PICKPLACE_CACHE_DIR=str(tmp_path))

    def calibrate() -> list[object]:
        out = subprocess.run(
            [sys.executable, "-c", script, "menagerie-iiwa14-2f85"],
            capture_output=True,
            text=True,
            check=True,
            env=env,
        )
        return list(json.loads(out.stdout))

    first = calibrate()
    files = list(tmp_path.glob("calibration-*.json"))
    assert len(files) == 1
    assert calibrate() == first  # bit for bit, sim_time included: read, not measured again
    files[0].write_text("{not json", encoding="utf-8")
    assert calibrate() == first  # an unreadable file is measured again and rewritten
    assert np.isfinite(json.loads(files[0].read_text(encoding="utf-8"))["close_time"])


# robosuite 1.5.2's grippers, unmodified (robots/robosuite/<model>/), on Menagerie's iiwa 14.
ROBOSUITE = ROBOTS_DIR / "robosuite"
IIWA14 = f"""
[arm]
mjcf = "{MENAGERIE / "kuka_iiwa_14" / "iiwa14.xml"}"
speed_limits = [1.4835299, 1.4835299, 1.7453293, 1.3089969, 2.2689280, 2.3561945, 2.3561945]
accel_limits = [8.57, 8.57, 8.74, 11.36, 12.23, 15.72, 15.72]
"""


def _robosuite(tmp_path: Path, model: str) -> Path:
    assert (ROBOSUITE / model / "LICENSE").is_file()
    return _description(
        tmp_path,
        f'name = "iiwa14-{model}"\n{IIWA14}[gripper]\n'
        f'mjcf = "{ROBOSUITE / model / (model + ".xml")}"\nangle = "radian"\n',
    )


def _picks_and_places(path: Path) -> None:
    result = run(RunRequest(scenario="pick-place", robot=str(path)))
    assert result.success, result.summary()["events"][-2:]
    assert result.metrics["place_error_m"] < 0.005


@pytest.mark.slow
def test_robosuite_xarm_gripper_opens_its_85_mm_between_its_pad_boxes(tmp_path: Path) -> None:
    # Its inner knuckles, nearer the palm, reach within 23 mm of each other: not level with
    # the fingertips, they do not bound the opening.
    path = _robosuite(tmp_path, "xarm7_gripper")
    cal = load_robot(path).robot.calibration
    assert cal.open_width == pytest.approx(0.0855, abs=2e-3)
    assert {p.split("_pad")[0] for side in cal.pads for p in side} == {
        "left_finger",
        "right_finger",
    }
    _picks_and_places(path)


@pytest.mark.slow
def test_robosuite_robotiq_140_closes_on_the_brick_with_its_squeeze(tmp_path: Path) -> None:
    # Its fingers cross when closed free and its actuators have no force range: a commanded
    # gap of 0 is short of the closed command, so the command closes at the brick's width.
    path = _robosuite(tmp_path, "robotiq_gripper_140")
    robot = load_robot(path).robot
    cal = robot.calibration
    assert cal.closed_width < 0.0
    assert cal.squeeze_width == pytest.approx(2.0 * cal.brick_half_extents[1])
    np.testing.assert_array_equal(robot.ctrl_for_width(0.0), cal.closed_command)
    assert cal.close_time <= 2.0 and min(cal.squeeze_per_side) > 10.0
    _picks_and_places(path)


@pytest.mark.slow
def test_robosuite_panda_gripper_is_measured_on_its_pad_boxes_clear_of_its_palm(
    tmp_path: Path,
) -> None:
    # The probe at the fingertips first meets the finger meshes, which reach 8 mm past the
    # 16 mm pad boxes; midway between them (79 mm from the root) a brick would stand in the
    # palm. The fingers' reach puts the tool point where the brick clears the floor, there the
    # brick finds the pad boxes, and the tool point is midway between them (93.4 mm).
    path = _robosuite(tmp_path, "panda_gripper")
    cal = load_robot(path).robot.calibration
    assert cal.pads == (("finger2_pad_collision",), ("finger1_pad_collision",))
    np.testing.assert_allclose(cal.pos_BG, [0.0, 0.0, 0.0934], atol=5e-4)
    assert "hand_collision" not in cal.other_contacts
    _picks_and_places(path)


XARM7 = MENAGERIE / "ufactory_xarm7"  # only its hand: hand.xml and the 7 meshes it names


@pytest.mark.slow
def test_menagerie_xarm_hand_is_measured_at_its_finger_meshes_inner_faces(tmp_path: Path) -> None:
    # Each finger is one mesh whose own frame (its principal axes) is turned 19 degrees about
    # the hand's x: its bounding box's corner lay 11.6 mm inside the inner face, and the pads
    # were measured 25.7 mm apart squeezing the 50 mm brick. The gap is the mesh vertices':
    # the brick's width squeezing it, and at the open command what the innermost vertices of
    # the two fingers are apart along the closing axis.
    assert (XARM7 / "LICENSE").is_file()
    path = _description(
        tmp_path, f'name = "iiwa14-xarm-hand"\n{IIWA14}[gripper]\nmjcf = "{XARM7 / "hand.xml"}"\n'
    )
    comp = load_robot(path)
    robot, m = comp.robot, comp.model
    cal = robot.calibration
    assert cal.pads == (("left_finger/geom[0]",), ("right_finger/geom[0]",))
    width = 2.0 * cal.brick_half_extents[1]
    assert width - 5e-4 < cal.gap_on_brick <= width  # the stiff pads sink in by < 0.5 mm
    d = mujoco.MjData(m)
    d.qpos[m.jnt_qposadr[robot.gripper_joint_ids]] = robot.qpos_for_width(cal.open_width)
    mujoco.mj_kinematics(m, d)
    y_W = d.site_xmat[robot.tool_site_id].reshape(3, 3)[:, 1]
    inner = []
    for side, pads in zip((-1.0, 1.0), cal.pads, strict=True):
        g = m.geom("gripper/" + pads[0]).id
        mesh = m.geom_dataid[g]
        v = m.mesh_vert[m.mesh_vertadr[mesh] : m.mesh_vertadr[mesh] + m.mesh_vertnum[mesh]]
        along = (d.geom_xpos[g] + v @ d.geom_xmat[g].reshape(3, 3).T) @ y_W
        inner.append(side * float(np.max(side * along)))
    # The faces are found squeezing the brick, where the loaded linkage (soft loop constraints
    # under 390 N a side) tilts each finger a little: open, their plane lies 0.13 mm a side
    # inside the innermost vertex (measured), against 11.6 mm for the bounding box's corner.
    assert inner[0] - inner[1] == pytest.approx(cal.open_width, abs=5e-4)
    _picks_and_places(path)
