"""A robot composed into the world, calibrated, and resolved into what the pipeline needs.

:func:`compose` builds the scene with ``mujoco.MjSpec``: the world (bins, brick, floor, lights,
cameras, options), the arm attached at the origin under :data:`ARM_PREFIX`, the gripper on a
frame at the flange under :data:`~pickplace.robot.calibration.GRIPPER_PREFIX`, the calibrated
tool site, stiff pads, one pad–brick contact sensor per pad and a ``home`` keyframe.
:func:`load_robot` compiles it and resolves a :class:`Robot`: ids, limits, home posture,
gripper commands and measurements, everything sized from the loaded robot.

Gripper calibrations are cached per process and on disk
(:mod:`pickplace.robot.calibration_cache`) by the content of the gripper file, its assets,
the description's gripper fields, the brick, the physics options and the measuring code.
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from pickplace.errors import RobotError
from pickplace.geometry import rotate_by_quat, top_down_rotation
from pickplace.robot import calibration_cache
from pickplace.robot.calibration import (
    GRIPPER_PREFIX,
    CalibrationOptions,
    GripperCalibration,
    calibrate_gripper,
)
from pickplace.robot.compiled import compile_cached
from pickplace.robot.description import RobotDescription
from pickplace.robot.home_ik import home_candidates
from pickplace.robot.ik import joint_ranges
from pickplace.robot.mjcf import load_part, parse_world
from pickplace.robot.model import Composition, Robot
from pickplace.robot.parts import PreparedArm, PreparedGripper, prepare_arm, prepare_gripper
from pickplace.robot.physics import scale_squeeze, set_stiff_pad, unique_name
from pickplace.robot.reach import ReachIK, shortfall
from pickplace.robot.registry import (
    DEFAULT_ROBOT,
    DEFAULT_WORLD,
    description_digest,
    resolve_description,
)

ARM_PREFIX = "arm/"
"""Prefix of the arm's element names in the composed scene."""

TOOL_SITE = "tool"
"""Name of the calibrated tool site in the gripper (``gripper/tool`` in the scene)."""

HOME_KEY = "home"
"""Keyframe of the composed scene with the home posture and the gripper open."""


BRICK_GEOM = "brick"
"""The world's brick: a box geom on a free body."""

PAD_SENSOR_SLOTS = 8
"""Contacts each pad sensor reports (a held brick touches a box pad in 4 points)."""

PAD_SIDES = ("left", "right")
"""Pad sensor name prefixes of the +y and -y sides of the tool frame."""

_CONTACT_DATA = (1 << int(mujoco.mjtConDataField.mjCONDATA_FOUND)) | (
    1 << int(mujoco.mjtConDataField.mjCONDATA_FORCE)
)
_REDUCE_MAXFORCE = 2


# --------------------------------------------------------------------------- composition


@dataclass(frozen=True)
class _Composed:
    spec: mujoco.MjSpec
    arm: PreparedArm
    gripper: PreparedGripper
    calibration: GripperCalibration
    tool_site: str
    pad_sensors: tuple[tuple[str, ...], tuple[str, ...]]
    repairs: tuple[str, ...]


_CALIBRATIONS: dict[str, GripperCalibration] = {}


def clear_calibration_cache() -> None:
    """Forget every cached gripper calibration (the next composition measures again)."""
    _CALIBRATIONS.clear()


def _world_spec(world: Path | mujoco.MjSpec | None) -> mujoco.MjSpec:
    if isinstance(world, mujoco.MjSpec):
        return world.copy()
    return parse_world(Path(world) if world is not None else DEFAULT_WORLD)


def _calibration_key(
    digest: str,
    desc: RobotDescription,
    half: np.ndarray,
    friction: np.ndarray,
    opts: CalibrationOptions,
    squeeze_ratio: float = 1.0,
) -> str:
    g = desc.gripper
    parts = [
        digest,
        repr((g.pads, g.tcp, g.open_command, g.closed_command, g.couple_fingers)),
        repr(squeeze_ratio),
        calibration_cache.code_digest(),
        repr(half.tolist()),
        repr(friction.tolist()),
        repr(opts),
    ]
    return hashlib.sha256("|".join(parts).encode()).hexdigest()


def _calibrated(
    gripper: PreparedGripper,
    digest: str,
    desc: RobotDescription,
    half: np.ndarray,
    friction: np.ndarray,
    options: CalibrationOptions,
    squeeze_ratio: float = 1.0,
) -> GripperCalibration:
    """The gripper's calibration, from the cache or measured (and then cached)."""
    key = _calibration_key(digest, desc, half, friction, options, squeeze_ratio)
    calibration = _CALIBRATIONS.get(key) or calibration_cache.load(key)
    if calibration is not None:
        _CALIBRATIONS[key] = calibration
        return calibration
    src = str(desc.source)
    g = desc.gripper
    calibration = calibrate_gripper(
        gripper,
        half,
        friction,
        options,
        src=src,
        pads=g.pads,
        tcp=g.tcp,
        open_command=(
            None
            if g.open_command is None
            else gripper.commands_from_file(g.open_command, "open_command", src)
        ),
        closed_command=(
            None
            if g.closed_command is None
            else gripper.commands_from_file(g.closed_command, "closed_command", src)
        ),
    )
    _CALIBRATIONS[key] = calibration
    calibration_cache.store(key, calibration)
    return calibration


ARM_FLOOR_CLEARANCE = 0.01
"""Without ``[arm] base_pos`` the arm stands at the origin, raised until the geoms that swivel
with its base joints (:attr:`PreparedArm.lowest_z`) are this far above the floor [m]: twice
the planner's 5 mm collision clearance. (Geoms welded to the base never collide with the
world, MuJoCo skips bodies welded together, so a base plate may rest on the floor.)"""


def _floor_z(spec: mujoco.MjSpec) -> float:
    """Height [m] of the world's floor: its highest upward plane geom, -inf without one."""
    heights = [
        float(g.pos[2])
        for g in spec.worldbody.geoms
        if g.type == mujoco.mjtGeom.mjGEOM_PLANE and abs(abs(float(g.quat[0])) - 1.0) < 1e-9
    ]
    return max(heights, default=-np.inf)


def _base_pos(
    spec: mujoco.MjSpec, arm: PreparedArm, desc: RobotDescription
) -> tuple[np.ndarray, str]:
    """The arm's base position [m] and, when it was raised off the floor, that in one line."""
    if desc.arm.base_pos is not None:
        return np.array(desc.arm.base_pos), ""
    lift = _floor_z(spec) + ARM_FLOOR_CLEARANCE - arm.lowest_z
    if not np.isfinite(lift) or lift <= 0.0:
        return np.zeros(3), ""
    return np.array([0.0, 0.0, lift]), (
        f"arm base raised {1000 * lift:.1f} mm off the origin so that '{arm.lowest_geom}' "
        f"clears the floor by {1000 * ARM_FLOOR_CLEARANCE:g} mm (set [arm] base_pos to choose)"
    )


def _mount_pose(arm: PreparedArm, desc: RobotDescription) -> tuple[np.ndarray, np.ndarray]:
    """Pose of the gripper's root in the flange body: flange pose then the mount offset."""
    quat_mount = np.array(desc.gripper.mount_quat)
    pos = np.zeros(3)
    mujoco.mju_rotVecQuat(pos, np.array(desc.gripper.mount_pos), arm.flange_quat)
    quat = np.zeros(4)
    mujoco.mju_mulQuat(quat, arm.flange_quat, quat_mount)
    return arm.flange_pos + pos, quat


def _compose(
    world: Path | mujoco.MjSpec | None,
    desc: RobotDescription,
    brick_geom: str,
    pad_slots: int = PAD_SENSOR_SLOTS,
    held: HeldObject | None = None,
) -> _Composed:
    spec = _world_spec(world)
    if held is None:
        brick = spec.geom(brick_geom)
        if brick is None or brick.type != mujoco.mjtGeom.mjGEOM_BOX:
            raise RobotError(
                f"the world has no box geom '{brick_geom}'; valid: a world with the brick as a box"
            )
        half = np.array(brick.size, dtype=float)
        friction = np.array(brick.friction, dtype=float)
    else:
        half, friction = held.calibration_half.copy(), held.calibration_friction.copy()
    opt = spec.option
    options = CalibrationOptions(
        timestep=float(opt.timestep),
        integrator=int(opt.integrator),
        cone=int(opt.cone),
        impratio=float(opt.impratio),
        noslip_iterations=int(opt.noslip_iterations),
    )
    arm_part = load_part(desc.arm.mjcf, "[arm] mjcf", desc.arm.angle, desc.source)
    grip_part = load_part(desc.gripper.mjcf, "[gripper] mjcf", desc.gripper.angle, desc.source)
    arm = prepare_arm(arm_part, desc, options.timestep)
    gripper = prepare_gripper(grip_part, desc)

    calibration = _calibrated(gripper, grip_part.digest, desc, half, friction, options)
    if desc.gripper.squeeze_force is not None:
        # The squeeze the description asks for: the actuators scaled by it over what the
        # file's squeeze measures, then the gripper measured again as it will run.
        ratio = desc.gripper.squeeze_force / calibration.squeeze_force
        scaled = gripper.spec.copy()
        scale_squeeze(scaled, ratio)
        gripper = dataclasses.replace(
            gripper,
            spec=scaled,
            repairs=(
                *gripper.repairs,
                f"squeeze {calibration.squeeze_force:.3g} N per jaw scaled to "
                f"{desc.gripper.squeeze_force:g} N ([gripper] squeeze_force): actuator "
                f"force ranges x {ratio:.3g}" + (f", gains x {ratio:.3g}" if ratio > 1 else ""),
            ),
        )
        calibration = _calibrated(
            gripper, grip_part.digest, desc, half, friction, options, squeeze_ratio=ratio
        )

    gspec = gripper.spec.copy()
    for pad in calibration.pads[0] + calibration.pads[1]:
        set_stiff_pad(gspec.geom(pad), options.timestep)
    tool = unique_name({s.name for s in gspec.sites}, TOOL_SITE)
    gspec.body(calibration.root_body).add_site(
        name=tool,
        pos=list(calibration.pos_BG),
        quat=list(calibration.quat_BG),
        size=[0.006, 0.006, 0.006],
        rgba=[1.0, 0.5, 0.0, 1.0],
        group=1,
    )

    base_pos, base_note = _base_pos(spec, arm, desc)
    base = spec.worldbody.add_frame(pos=list(base_pos), quat=list(desc.arm.base_quat))
    spec.attach(arm.spec.copy(), prefix=ARM_PREFIX, frame=base)
    flange = spec.body(ARM_PREFIX + arm.flange_body)
    pos, quat = _mount_pose(arm, desc)
    spec.attach(gspec, prefix=GRIPPER_PREFIX, frame=flange.add_frame(pos=pos, quat=quat))

    sensors: list[tuple[str, ...]] = []
    existing = {s.name for s in spec.sensors}
    for side, pads in zip(PAD_SIDES, calibration.pads, strict=True):
        names = []
        for i, pad in enumerate(pads):
            name = f"{side}_pad_force" + (f"_{i + 1}" if i else "")
            if name in existing:
                raise RobotError(
                    f"the world already has a sensor '{name}'; valid: a world without pad sensors"
                )
            spec.add_sensor(
                name=name,
                type=mujoco.mjtSensor.mjSENS_CONTACT,
                objtype=mujoco.mjtObj.mjOBJ_GEOM,
                objname=GRIPPER_PREFIX + pad,
                reftype=mujoco.mjtObj.mjOBJ_GEOM if held is None else mujoco.mjtObj.mjOBJ_BODY,
                refname=brick_geom if held is None else held.body,
                intprm=[_CONTACT_DATA, _REDUCE_MAXFORCE, pad_slots],
            )
            names.append(name)
        sensors.append(tuple(names))
    repairs = tuple(
        [f"{arm_part.path.name}: {r}" for r in arm_part.repairs + arm.repairs]
        + ([f"{arm_part.path.name}: {base_note}"] if base_note else [])
        + [f"{grip_part.path.name}: {r}" for r in grip_part.repairs + gripper.repairs]
    )
    return _Composed(
        spec=spec,
        arm=arm,
        gripper=gripper,
        calibration=calibration,
        tool_site=GRIPPER_PREFIX + tool,
        pad_sensors=(sensors[0], sensors[1]),
        repairs=repairs,
    )


@dataclass(frozen=True)
class HeldObject:
    """An object put in the brick's place (``--object``): the gripper is still calibrated on
    the world's brick box, and its pad sensors see every geom of the object's body.

    Attributes:
        body: The object's body in the world.
        calibration_half: Half sizes of the box the gripper is calibrated on [m].
        calibration_friction: That box's friction coefficients.
    """

    body: str
    calibration_half: np.ndarray
    calibration_friction: np.ndarray

    def key_fields(self) -> tuple[str, list[float], list[float]]:
        """Its fields with every float exact (``repr`` of an array rounds): part of a key."""
        return (self.body, self.calibration_half.tolist(), self.calibration_friction.tolist())


def compose(
    world: Path | mujoco.MjSpec | None, desc: RobotDescription, brick_geom: str = BRICK_GEOM
) -> mujoco.MjSpec:
    """The world with the robot composed into it (see the module docstring), no home key.

    Args:
        world: World MJCF file or spec (copied, not changed); None: ``scenes/world.xml``.
        desc: The robot.
        brick_geom: The world's brick geom (the gripper is calibrated on its size).

    Raises:
        RobotError: A file is missing or unusable, or calibration failed (one line naming
            the file, the field or element, and what would be valid).
    """
    return _compose(world, desc, brick_geom).spec


# --------------------------------------------------------------------------- the result


BIN_BODIES = ("bin1", "bin2")
"""The world's bins (``scenes/world.xml``): where the brick starts, where it must end."""

_REACH_YAWS = 4
"""Tool yaws, evenly over a half turn, at which the reach towards a bin is measured."""


def _refuse_short_reach(
    model: mujoco.MjModel,
    joint_ids: np.ndarray,
    tool_site: int,
    q_min: np.ndarray,
    q_max: np.ndarray,
    bins: tuple[str, ...],
    brick_geom: str,
    src: str,
) -> None:
    """Refuse an arm that cannot bring the tool over a bin's centre.

    For each bin, the tool pointing down with its point at the brick's centre height on the
    bin's floor centre (where the nominal pick and place grip it) is sought by IK
    (:func:`pickplace.robot.reach.shortfall`, yaws every 45°, seeds: the middle of the
    joint ranges and the reference posture); the farthest bin the arm falls short of is named
    with the distance it lacks.

    Raises:
        RobotError: A bin's centre is out of reach (one line: what the arm reaches, how far
            the bin is, what it lacks, what would be valid).
    """
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    p_W_axis = data.xanchor[joint_ids[0]].copy()
    brick = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, brick_geom)
    half_height = float(model.geom_size[brick][2]) if brick >= 0 else 0.0
    seeds = [joint_ranges(q_min, q_max)[2], model.qpos0[model.jnt_qposadr[joint_ids]]]
    rotations = [top_down_rotation(k * np.pi / _REACH_YAWS) for k in range(_REACH_YAWS)]
    ik = ReachIK(model, tool_site, q_min, q_max, joint_ids)
    worst: tuple[float, float, str, float] | None = None
    for name in bins:
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{name}_floor")
        if body < 0 or floor < 0:
            continue  # a world without this bin: the scene's own checks name it
        p_target = data.xpos[body].copy()
        p_target[2] = data.geom_xpos[floor][2] + model.geom_size[floor][2] + half_height
        lack, distance = shortfall(ik, p_W_axis, p_target, rotations, seeds)
        if lack > 0.0 and (worst is None or lack > worst[0]):
            worst = (lack, distance, name, float(p_target[2]))
    if worst is not None:
        lack, distance, name, z = worst
        raise RobotError(
            f"{src}: [arm]: the arm cannot reach both bins: {name}'s centre is {distance:.3f} m "
            f"from the arm's base axis and the tool, pointing down {z:.3f} m high, reaches "
            f"{distance - lack:.3f} m towards it: it lacks {lack:.3f} m; valid: an arm that "
            f"reaches both bins' centres, or [arm] base_pos nearer them"
        )


def _refuse_gripper_into_arm(
    model: mujoco.MjModel,
    joint_ids: np.ndarray,
    flange_body: int,
    arm: PreparedArm,
    tool_site: int,
    desc_quat: np.ndarray,
    src: str,
) -> None:
    """Refuse a gripper that points back into the arm (``desc_quat``: its ``mount_quat``).

    At the arm's zero posture, from an arm joint behind the flange (one whose anchor is not
    the flange itself) to the flange is the way out of the arm; a tool axis (the calibrated
    approach direction, z) with a negative component along it from both of the two nearest
    such joints points the gripper into the arm's own links, which the robot never collides
    with: every posture then carries the wrist beside the fingers. Menagerie's Gen3 has no
    attachment site, and its last body's z axis points into the arm (Kinova's tool frame is
    that body's -z, 61.5 mm out).

    Raises:
        RobotError: The tool axis points into the arm; the message names the joint, the
            flange, the angle and a mount that points the gripper out.
    """
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    R_WF = data.xmat[flange_body].reshape(3, 3)
    p_WF = data.xpos[flange_body] + R_WF @ arm.flange_pos
    z_tool_W = data.site_xmat[tool_site].reshape(3, 3)[:, 2]
    # The two nearest joint anchors behind the flange (an anchor at the flange says nothing):
    # the nearest alone may sit beside or even past the flange (robosuite's xArm7 has its
    # last anchor 27 mm behind the face its gripper hangs 153 mm down from), so both must
    # have the tool pointing back towards them.
    behind = [
        (int(j), p_WF - data.xanchor[j])
        for j in joint_ids[::-1]
        if np.linalg.norm(p_WF - data.xanchor[j]) > 1e-6
    ][:2]
    if not behind or any(float(out @ z_tool_W) >= 0.0 for _, out in behind):
        return
    j, out_W = behind[0]
    out_W = out_W / np.linalg.norm(out_W)
    # Flange frame: the flange body's frame turned by the flange's own orientation.
    R_BF = np.zeros(9)
    mujoco.mju_quat2Mat(R_BF, arm.flange_quat)
    R_WFl = R_WF @ R_BF.reshape(3, 3)
    away_F = R_WFl.T @ -z_tool_W  # where the gripper should point, in the flange frame
    depth = 0.0  # the flange body's collision geometry out along that way [m]
    for g in np.flatnonzero(model.geom_bodyid == flange_body):
        if model.geom_contype[g] == 0 and model.geom_conaffinity[g] == 0:
            continue
        mesh = int(model.geom_dataid[g]) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH else -1
        if mesh >= 0:  # its vertices: a mesh's box is loose once turned
            adr, n = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
            points_G = model.mesh_vert[adr : adr + n].astype(float)
        else:
            centre, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
            signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
            points_G = centre + signs * half
        points_W = data.geom_xpos[g] + points_G @ data.geom_xmat[g].reshape(3, 3).T
        depth = max(depth, float(((points_W - p_WF) @ R_WFl @ away_F).max()))
    angle = np.degrees(np.arccos(np.clip(out_W @ z_tool_W, -1.0, 1.0)))
    joint = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, int(j)) or f"#{j}"
    # Half a turn about an axis across the tool axis (the flange's y, else x), after the mount.
    across_F = np.array([0.0, 1.0, 0.0]) if abs(away_F[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    across_F -= (across_F @ away_F) * away_F
    turned = np.zeros(4)
    mujoco.mju_mulQuat(turned, np.r_[0.0, across_F / np.linalg.norm(across_F)], desc_quat)
    quat = ", ".join(f"{v:.4g}" for v in np.round(turned, 4) + 0.0)
    pos = ", ".join(f"{v:.4g}" for v in np.round(depth * away_F, 4) + 0.0)
    raise RobotError(
        f"{src}: [gripper] mount_quat: the gripper points back into the arm: its tool axis "
        f"is {angle:.0f}° from the way out of the arm (from joint '{joint}' to the flange "
        f"'{arm.flange_body}'); valid: a mount that points it out, e.g. mount_quat = [{quat}] "
        f"(half a turn) with mount_pos = [{pos}] (the flange body's face), or an [arm] flange "
        f"site whose z axis points out of the arm"
    )


def _ids(model: mujoco.MjModel, obj: mujoco.mjtObj, names: tuple[str, ...]) -> np.ndarray:
    out = []
    for n in names:
        i = mujoco.mj_name2id(model, obj, n)
        if i < 0:
            raise RobotError(f"composed scene lacks '{n}'")
        out.append(i)
    return np.array(out, dtype=int)


def _gripper_kind(model: mujoco.MjModel, joints: np.ndarray, gripper: PreparedGripper) -> str:
    """The gripper in words, e.g. ``"2 slide joints, 1 actuator"``."""
    types = model.jnt_type[joints]
    slides = int(np.sum(types == mujoco.mjtJoint.mjJNT_SLIDE))
    hinges = int(np.sum(types == mujoco.mjtJoint.mjJNT_HINGE))
    parts = [
        f"{k} {what} joint{'s' if k != 1 else ''}"
        for k, what in ((slides, "slide"), (hinges, "hinge"))
        if k
    ]
    acts = len(gripper.actuators)
    text = ("linkage of " if hinges else "") + " and ".join(parts)
    text += f", {acts} actuator{'s' if acts != 1 else ''}"
    if gripper.coupling is not None:
        text += " (independent fingers coupled by the loader)"
    return text


def _compile(spec: mujoco.MjSpec, src: str) -> mujoco.MjModel:
    try:
        return spec.compile()
    except ValueError as exc:
        detail = " ".join(str(exc).split())
        raise RobotError(f"{src}: composed scene does not compile: {detail}") from exc


def load_robot(
    robot: str | Path | RobotDescription = DEFAULT_ROBOT,
    world: Path | mujoco.MjSpec | None = None,
    *,
    home_width: float | None = None,
    brick_geom: str = BRICK_GEOM,
    pad_slots: int = PAD_SENSOR_SLOTS,
    bins: tuple[str, ...] = BIN_BODIES,
    held: HeldObject | None = None,
    world_key: str | None = None,
) -> Composition:
    """Compose, calibrate and resolve a robot.

    Args:
        robot: A bundled robot's name (:func:`bundled_robots`), a ``robot.toml`` path, or a
            description.
        world: World MJCF file or spec; None: ``scenes/world.xml``.
        home_width: Gripper gap of the ``home`` keyframe [m]; None: the open width.
        brick_geom: The world's brick geom.
        bins: The world's bin bodies, which the arm must reach (:func:`_refuse_short_reach`).
        pad_slots: Contacts each pad–brick sensor reports.
        held: Another object in the brick's place (None: the world's brick box).
        world_key: A digest of the content of ``world`` (the file and what took the brick's
            place in it): the compiled scene is then kept on disk and loaded by the next
            process (:mod:`pickplace.robot.compiled`); None: compiled, not kept.

    Raises:
        RobotError: See :func:`compose`; also no home posture could be found.
    """
    desc = resolve_description(robot)
    src = str(desc.source)
    composed = _compose(world, desc, brick_geom, pad_slots, held)
    spec, calib = composed.spec, composed.calibration
    spec.add_key(name=HOME_KEY)  # filled in once the home is known (Robot.write_home)
    arm_spec = spec.copy()  # before compiling: see Composition.arm_spec
    built_from = None
    if world_key is not None:
        built_from = hashlib.sha256(
            "\n".join(
                (
                    world_key,
                    description_digest(desc),
                    calibration_cache.digest(calib),
                    repr((brick_geom, pad_slots)),
                    "" if held is None else repr(held.key_fields()),
                )
            ).encode()
        ).hexdigest()
    model = compile_cached(spec, built_from, lambda s: _compile(s, src))
    obj = mujoco.mjtObj
    arm_names = tuple(ARM_PREFIX + j for j in composed.arm.joints)
    joint_ids = _ids(model, obj.mjOBJ_JOINT, arm_names)
    arm_acts = _ids(
        model, obj.mjOBJ_ACTUATOR, tuple(ARM_PREFIX + a for a in composed.arm.actuators)
    )
    limited = model.jnt_limited[joint_ids].astype(bool)
    q_min = np.where(limited, model.jnt_range[joint_ids, 0], -np.inf)
    q_max = np.where(limited, model.jnt_range[joint_ids, 1], np.inf)
    tool_site = int(_ids(model, obj.mjOBJ_SITE, (composed.tool_site,))[0])
    flange_body = int(_ids(model, obj.mjOBJ_BODY, (ARM_PREFIX + composed.arm.flange_body,))[0])
    _refuse_gripper_into_arm(
        model,
        joint_ids,
        flange_body,
        composed.arm,
        tool_site,
        np.array(desc.gripper.mount_quat, dtype=float),
        src,
    )
    if desc.arm.home is not None:
        candidates = [np.array(desc.arm.home, dtype=float)]
        home_source = "description"
    else:
        try:
            candidates = home_candidates(model, joint_ids, tool_site, q_min, q_max, src)
        except RobotError:
            _refuse_short_reach(model, joint_ids, tool_site, q_min, q_max, bins, brick_geom, src)
            raise
        home_source = "ik"
    q_home = candidates[0]

    gripper_acts = _ids(
        model, obj.mjOBJ_ACTUATOR, tuple(GRIPPER_PREFIX + a for a in calib.actuators)
    )
    gripper_joints = _ids(model, obj.mjOBJ_JOINT, tuple(GRIPPER_PREFIX + j for j in calib.joints))
    width = calib.open_width if home_width is None else float(home_width)

    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    pad_geoms = tuple(
        _ids(model, obj.mjOBJ_GEOM, tuple(GRIPPER_PREFIX + p for p in side)) for side in calib.pads
    )
    pad_bodies = tuple(model.geom_bodyid[g].copy() for g in pad_geoms)
    faces_body = []
    for geoms, faces in zip(pad_geoms, calib.pad_faces, strict=True):
        rotated = rotate_by_quat(model.geom_quat[geoms], faces)
        faces_body.append(model.geom_pos[geoms] + rotated)
    sensors = tuple(_ids(model, obj.mjOBJ_SENSOR, names) for names in composed.pad_sensors)
    tool_body = int(model.site_bodyid[tool_site])
    y_tool = rotate_by_quat(model.site_quat[tool_site], np.array([0.0, 1.0, 0.0]))
    body_names = [mujoco.mj_id2name(model, obj.mjOBJ_BODY, b) or "" for b in range(model.nbody)]
    robot_bodies = np.array(
        [b for b, n in enumerate(body_names) if n.startswith((ARM_PREFIX, GRIPPER_PREFIX))]
    )
    collide = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
    in_robot = np.isin(model.geom_bodyid, robot_bodies)
    in_gripper = np.array([body_names[b].startswith(GRIPPER_PREFIX) for b in model.geom_bodyid])
    key = mujoco.mj_name2id(model, obj.mjOBJ_KEY, HOME_KEY)
    g = desc.gripper
    composition = Composition(
        spec=spec,
        model=model,
        arm_spec=arm_spec,
        cache_key=built_from,
        robot=Robot(
            name=desc.name,
            description=desc,
            arm_joint_names=arm_names,
            arm_joint_ids=joint_ids,
            arm_qpos_adr=model.jnt_qposadr[joint_ids].copy(),
            arm_dof_adr=model.jnt_dofadr[joint_ids].copy(),
            q_min=q_min,
            q_max=q_max,
            continuous=~limited,
            v_max=np.array(desc.arm.speed_limits, dtype=float),
            a_max=None if desc.arm.accel_limits is None else np.array(desc.arm.accel_limits),
            arm_actuator_ids=arm_acts,
            q_home=q_home,
            home_source=home_source,
            home_candidates=tuple(candidates),
            gripper_actuator_ids=gripper_acts,
            gripper_joint_ids=gripper_joints,
            gripper_kind=_gripper_kind(model, gripper_joints, composed.gripper),
            open_command=calib.open_command.copy(),
            closed_command=calib.closed_command.copy(),
            open_width=calib.open_width,
            closed_width=calib.closed_width,
            squeeze_force=calib.squeeze_force if g.grip_force is None else g.grip_force,
            measured_squeeze_force=calib.squeeze_force,
            gap_on_brick=calib.gap_on_brick,
            pad_geom_ids=(pad_geoms[0], pad_geoms[1]),
            pad_body_ids=(pad_bodies[0], pad_bodies[1]),
            pad_faces_body=(faces_body[0], faces_body[1]),
            pad_force_sensor_ids=(sensors[0], sensors[1]),
            pad_force_sensor_adr=(
                model.sensor_adr[sensors[0]].copy(),
                model.sensor_adr[sensors[1]].copy(),
            ),
            pad_force_slots=pad_slots,
            tool_site_name=composed.tool_site,
            tool_site_id=tool_site,
            tool_body_id=tool_body,
            y_tool_body=y_tool,
            robot_body_ids=robot_bodies,
            robot_geom_ids=np.flatnonzero(in_robot & collide),
            gripper_geom_ids=np.flatnonzero(in_gripper & collide),
            footprint_G=calib.footprint_G.copy(),
            p_W_base=data.xanchor[joint_ids[0]].copy(),
            flange_body_id=flange_body,
            home_key_id=key,
            home_width=width,
            calibration=calib,
            repairs=composed.repairs,
        ),
    )
    composition.robot.write_home(model, q_home, width)
    return composition
