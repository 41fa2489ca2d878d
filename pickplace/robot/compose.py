"""A robot composed into the world, calibrated, and resolved into what the pipeline needs.

:func:`compose` builds the scene with ``mujoco.MjSpec``: the world (bins, brick, floor, lights,
cameras, options), the arm attached at the origin under :data:`ARM_PREFIX`, the gripper on a
frame at the flange under :data:`~pickplace.robot.calibration.GRIPPER_PREFIX`, the calibrated
tool site, stiff pads, one pad–brick contact sensor per pad and a ``home`` keyframe.
:func:`load_robot` compiles it and resolves a :class:`Robot`: ids, limits, home posture,
gripper commands and measurements, everything sized from the loaded robot.

Gripper calibrations are cached per process by the content of the gripper file, its assets,
the description's gripper fields, the brick and the physics options.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import mujoco
import numpy as np

from pickplace.errors import RobotError
from pickplace.robot.calibration import (
    GRIPPER_PREFIX,
    CalibrationOptions,
    GripperCalibration,
    calibrate_gripper,
)
from pickplace.robot.description import RobotDescription
from pickplace.robot.mjcf import load_part, parse_world
from pickplace.robot.parts import PreparedArm, PreparedGripper, prepare_arm, prepare_gripper
from pickplace.robot.physics import set_stiff_pad, unique_name
from pickplace.robot.registry import DEFAULT_ROBOT, DEFAULT_WORLD, resolve_description

ARM_PREFIX = "arm/"
"""Prefix of the arm's element names in the composed scene."""

TOOL_SITE = "tool"
"""Name of the calibrated tool site in the gripper (``gripper/tool`` in the scene)."""

HOME_KEY = "home"
"""Keyframe of the composed scene with the home posture and the gripper open."""

HOME_TOOL_SITE = "home_tool"
"""World site whose pose IK reaches for a home posture when the description gives none."""

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
) -> str:
    g = desc.gripper
    parts = [
        digest,
        repr((g.pads, g.tcp, g.open_command, g.closed_command, g.couple_fingers)),
        repr(half.tolist()),
        repr(friction.tolist()),
        repr(opts),
    ]
    return hashlib.sha256("|".join(parts).encode()).hexdigest()


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
) -> _Composed:
    spec = _world_spec(world)
    brick = spec.geom(brick_geom)
    if brick is None or brick.type != mujoco.mjtGeom.mjGEOM_BOX:
        raise RobotError(
            f"the world has no box geom '{brick_geom}'; valid: a world with the brick as a box"
        )
    half = np.array(brick.size, dtype=float)
    friction = np.array(brick.friction, dtype=float)
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

    key = _calibration_key(grip_part.digest, desc, half, friction, options)
    calibration = _CALIBRATIONS.get(key)
    if calibration is None:
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

    spec.attach(arm.spec.copy(), prefix=ARM_PREFIX, frame=spec.worldbody.add_frame())
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
                reftype=mujoco.mjtObj.mjOBJ_GEOM,
                refname=brick_geom,
                intprm=[_CONTACT_DATA, _REDUCE_MAXFORCE, pad_slots],
            )
            names.append(name)
        sensors.append(tuple(names))
    repairs = tuple(
        [f"{arm_part.path.name}: {r}" for r in arm_part.repairs + arm.repairs]
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


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of (..., 3) arrays by components (about half its cost on small stacks)."""
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], axis=-1)


def _rotate(quat: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v`` (..., 3) by unit quaternions ``quat`` (..., 4, wxyz)."""
    w = quat[..., :1]
    u = quat[..., 1:]
    t = 2.0 * _cross(u, v)
    return v + w * t + _cross(u, t)


@dataclass(frozen=True)
class Robot:
    """Everything the pipeline needs about the composed robot, resolved from the model.

    Ids and addresses refer to the composed model. Arm arrays have one entry per arm joint
    (``n = len(arm_joint_names)``, root to flange).

    Attributes:
        name: The description's name.
        description: The description it was built from.
        arm_joint_names: Arm joints in the scene (prefixed), root to flange.
        arm_joint_ids: Their joint ids.
        arm_qpos_adr: Their qpos addresses.
        arm_dof_adr: Their dof (qvel) addresses.
        q_min: Lower limits [rad or m]; -inf for continuous (unlimited) joints.
        q_max: Upper limits; +inf for continuous joints.
        continuous: True for arm joints without a range (no position limit anywhere: their
            actuators' control range is unlimited too).
        v_max: Speed limits [rad/s or m/s] from the description.
        a_max: Acceleration limits [rad/s² or m/s²] from the description, or None.
        arm_actuator_ids: The position actuator of each arm joint.
        q_home: Home posture: the description's, or found by IK (``home_source``).
        home_source: ``"description"`` or ``"ik"``.
        home_candidates: The description's home, or every distinct IK home, best joint margin
            first (``q_home`` is the first; the scene loader may choose another).
        gripper_actuator_ids: The gripper's actuators (order of command vectors).
        gripper_joint_ids: The gripper's hinge and slide joints (order of
            :meth:`qpos_for_width`).
        gripper_kind: What the gripper is, in words (fingers, joints, actuators, coupling).
        open_command: Command that opens the gripper fully.
        closed_command: Command that closes it (full squeeze on an object).
        open_width: Gap between the pads at the open command [m].
        closed_width: Gap at the closed command with nothing between the fingers [m].
        squeeze_force: Squeeze per jaw to judge a grasp against [N]: the description's
            ``grip_force``, else the measured squeeze.
        measured_squeeze_force: Mean pad normal force on a brick-sized box, closed [N].
        gap_on_brick: Pad gap while squeezing a brick-sized box [m].
        pad_geom_ids: Pad geoms of the +y ("left") and -y ("right") sides of the tool frame.
        pad_body_ids: Bodies of those pads (same structure).
        pad_faces_body: Per side, each pad's face point in its body's frame [m], shape (k, 3).
        pad_force_sensor_ids: Per side, the pad–brick contact sensors (one per pad).
        pad_force_sensor_adr: Their sensordata addresses.
        pad_force_slots: Contacts each pad sensor reports.
        tool_site_name: The calibrated tool site (z approach, y closing axis).
        tool_site_id: Its id.
        tool_body_id: Its body (the gripper's root).
        y_tool_body: The tool's y axis in that body's frame.
        robot_body_ids: Every body of the arm and gripper.
        robot_geom_ids: Every collision geom of the arm and gripper.
        gripper_geom_ids: The gripper's collision geoms.
        footprint_G: The gripper's collision geoms at the open width as boxes in the tool
            frame, shape (k, 2, 3) [min corner, max corner] [m].
        p_W_base: Anchor of the first arm joint at the model's reference posture [m].
        flange_body_id: The arm body the gripper is mounted on.
        home_key_id: The ``home`` keyframe.
        home_width: Gripper gap of the ``home`` keyframe [m].
        calibration: The gripper calibration (gap map, pads, tool point, footprint).
        repairs: What composition changed in the files, one line each.
    """

    name: str
    description: RobotDescription = field(repr=False)
    arm_joint_names: tuple[str, ...]
    arm_joint_ids: np.ndarray
    arm_qpos_adr: np.ndarray
    arm_dof_adr: np.ndarray
    q_min: np.ndarray
    q_max: np.ndarray
    continuous: np.ndarray
    v_max: np.ndarray
    a_max: np.ndarray | None
    arm_actuator_ids: np.ndarray
    q_home: np.ndarray
    home_source: str
    home_candidates: tuple[np.ndarray, ...]
    gripper_actuator_ids: np.ndarray
    gripper_joint_ids: np.ndarray
    gripper_kind: str
    open_command: np.ndarray
    closed_command: np.ndarray
    open_width: float
    closed_width: float
    squeeze_force: float
    measured_squeeze_force: float
    gap_on_brick: float
    pad_geom_ids: tuple[np.ndarray, np.ndarray]
    pad_body_ids: tuple[np.ndarray, np.ndarray]
    pad_faces_body: tuple[np.ndarray, np.ndarray]
    pad_force_sensor_ids: tuple[np.ndarray, np.ndarray]
    pad_force_sensor_adr: tuple[np.ndarray, np.ndarray]
    pad_force_slots: int
    tool_site_name: str
    tool_site_id: int
    tool_body_id: int
    y_tool_body: np.ndarray
    robot_body_ids: np.ndarray
    robot_geom_ids: np.ndarray
    gripper_geom_ids: np.ndarray
    footprint_G: np.ndarray
    p_W_base: np.ndarray
    flange_body_id: int
    home_key_id: int
    home_width: float
    calibration: GripperCalibration = field(repr=False)
    repairs: tuple[str, ...] = ()

    @property
    def n_joints(self) -> int:
        """Number of arm joints."""
        return len(self.arm_joint_names)

    def write_home(self, model: mujoco.MjModel, q_home: np.ndarray, width: float) -> None:
        """Write the home posture ``q_home`` [rad] and the gripper at gap ``width`` [m] into
        ``model``'s ``home`` keyframe (positions and the commands that hold them; the rest of
        the keyframe is ``qpos0`` and no command). The one writer of the keyframe: the
        composition, the scene and the loader's home choice all call it."""
        key = self.home_key_id
        model.key_qpos[key, self.arm_qpos_adr] = q_home
        model.key_qpos[key, model.jnt_qposadr[self.gripper_joint_ids]] = self.qpos_for_width(width)
        model.key_ctrl[key, self.arm_actuator_ids] = q_home
        model.key_ctrl[key, self.gripper_actuator_ids] = self.ctrl_for_width(width)

    def ctrl_for_width(self, width: float) -> np.ndarray:
        """Gripper command that holds the free fingers at gap ``width`` [m].

        At or below ``closed_width`` it is the closed command (full squeeze on an object).
        """
        return self.calibration.ctrl_for_width(width)

    def ctrl_for_widths(self, widths: np.ndarray) -> np.ndarray:
        """:meth:`ctrl_for_width` of every entry of ``widths`` (k,) [m], shape (k, actuators)."""
        cal = self.calibration
        s = np.clip(np.interp(widths, cal.sweep_gap, cal.sweep_fraction), 0.0, 1.0)
        return cal.closed_command + s[:, None] * (cal.open_command - cal.closed_command)

    def qpos_for_width(self, width: float) -> np.ndarray:
        """Positions of the gripper joints (:attr:`gripper_joint_ids`) of the free fingers at
        gap ``width`` [m] (clipped to the calibrated range): what a kinematic copy sets."""
        return self.calibration.qpos_for_width(width)

    def gap_from_body_poses(
        self, body_pos: np.ndarray, body_quat: np.ndarray, y_W: np.ndarray | None = None
    ) -> np.ndarray:
        """Pad gap [m] from body poses, vectorised over leading axes.

        Args:
            body_pos: Body positions in world, shape (..., nbody, 3) (``data.xpos``).
            body_quat: Body orientations wxyz, shape (..., nbody, 4) (``data.xquat``).
            y_W: The tool's y axis in world, shape (..., 3), if known (the tool site's rotation
                matrix's second column); else computed from the tool body's orientation.

        Returns:
            Shape (...): the innermost +y pad face minus the innermost -y pad face, along the
            tool's y axis.
        """
        if y_W is None:
            y_W = _rotate(body_quat[..., self.tool_body_id, :], self.y_tool_body)
        bodies = np.concatenate(self.pad_body_ids)
        faces = np.concatenate(self.pad_faces_body)
        p = body_pos[..., bodies, :] + _rotate(body_quat[..., bodies, :], faces)  # both sides
        along = np.einsum("...ki,...i->...k", p, y_W)
        k = len(self.pad_body_ids[0])
        return along[..., :k].min(axis=-1) - along[..., k:].max(axis=-1)

    def gap(self, data: mujoco.MjData) -> float:
        """Current pad gap [m]."""
        return float(self.gap_from_body_poses(data.xpos, data.xquat))

    def pad_normal_forces(self, sensordata: np.ndarray) -> np.ndarray:
        """Normal force [N] of the brick on the +y and -y pads, shape (..., 2), from
        sensordata of shape (..., nsensordata)."""
        n = 4 * self.pad_force_slots
        out = []
        for adrs in self.pad_force_sensor_adr:
            total = 0.0
            for a in adrs:
                rows = sensordata[..., a : a + n].reshape(*sensordata.shape[:-1], -1, 4)
                total = total + rows[..., 1].sum(axis=-1)
            out.append(total)
        return np.stack(out, axis=-1)

    def make_data(self, model: mujoco.MjModel) -> mujoco.MjData:
        """Fresh MjData of ``model`` reset to the home keyframe."""
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, self.home_key_id)
        mujoco.mj_forward(model, data)
        return data


@dataclass(frozen=True)
class Composition:
    """A composed scene: its spec (for derived models), the compiled model, the robot."""

    spec: mujoco.MjSpec
    model: mujoco.MjModel
    robot: Robot

    @cached_property
    def arm_model(self) -> mujoco.MjModel:
        """The scene compiled with only the arm joints left (nq = nv = n), for the IK.

        Gripper joints, the brick's free joint and everything that refers to joints
        (actuators, tendons, equalities, sensors, keyframes) are removed; bodies, sites and
        geometry are unchanged, so the tool site's forward kinematics equal the simulation's.
        """
        spec = self.spec.copy()
        for collection in ("actuators", "tendons", "equalities", "sensors", "keys", "pairs"):
            for element in list(getattr(spec, collection)):
                spec.delete(element)
        for element in list(spec.excludes):
            spec.delete(element)
        keep = set(self.robot.arm_joint_names)
        for joint in list(spec.joints):
            if joint.name not in keep:
                spec.delete(joint)
        model = spec.compile()
        order = tuple(
            mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt)
        )
        if order != self.robot.arm_joint_names:
            raise RobotError(
                f"arm joints {order} are not in the order {self.robot.arm_joint_names}"
            )
        return model


def _ids(model: mujoco.MjModel, obj: mujoco.mjtObj, names: tuple[str, ...]) -> np.ndarray:
    out = []
    for n in names:
        i = mujoco.mj_name2id(model, obj, n)
        if i < 0:
            raise RobotError(f"composed scene lacks '{n}'")
        out.append(i)
    return np.array(out, dtype=int)


_IK_DAMPING = 1e-3
_IK_MAX_STEP = 0.3  # [rad] per iteration
_IK_ITERATIONS = 100
HOME_SEEDS = 8
"""Seeds of the IK that finds home candidates when a description gives no home."""
HOME_DISTINCT = 1e-3
"""Home candidates closer than this in every joint [rad] are the same posture."""


def _home_candidates(
    model: mujoco.MjModel,
    joint_ids: np.ndarray,
    site: int,
    q_min: np.ndarray,
    q_max: np.ndarray,
    src: str,
) -> list[np.ndarray]:
    """Arm postures that put the tool site on the world's ``home_tool`` site, best first.

    Damped least squares (λ = 1e-3, steps of at most 0.3 rad, 100 iterations) on position and
    orientation from :data:`HOME_SEEDS` deterministic seeds — the middle of each joint's range
    (0 for continuous joints; a zero seed fails where 0 is outside a range), then uniform draws
    over the middle half of the ranges — clamped to the limits each step. The seeds that reach
    the pose within 0.1 mm and 1 mrad give the candidates (postures within
    :data:`HOME_DISTINCT` of each other count once), ordered by their distance from the nearest
    joint limit relative to the range (continuous joints count ±π), largest first. Margin alone
    does not make a good home (``../shared/notes/robot-models.md``): the scene loader
    (:mod:`pickplace.sim.loader`) chooses among them by the pre-flight of the nominal plan.
    """
    target = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, HOME_TOOL_SITE)
    if target < 0:
        raise RobotError(
            f"{src}: [arm] home: not given, and the world has no '{HOME_TOOL_SITE}' site to find "
            f"one by IK; valid: set home = [...] (one value per arm joint)"
        )
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    p_goal = data.site_xpos[target].copy()
    q_goal = np.zeros(4)
    mujoco.mju_mat2Quat(q_goal, data.site_xmat[target])
    qadr, dadr = model.jnt_qposadr[joint_ids], model.jnt_dofadr[joint_ids]
    lo = np.where(np.isfinite(q_min), q_min, -np.pi)
    hi = np.where(np.isfinite(q_max), q_max, np.pi)
    mid = np.where(np.isfinite(q_min), 0.5 * (lo + hi), 0.0)
    rng = np.random.default_rng(0)
    seeds = [mid] + [
        mid + rng.uniform(-0.25, 0.25, mid.shape) * (hi - lo) for _ in range(HOME_SEEDS - 1)
    ]
    jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    eye = np.eye(6)
    found: list[tuple[float, np.ndarray]] = []
    for seed in seeds:
        q = seed.copy()
        for _ in range(_IK_ITERATIONS):
            data.qpos[qadr] = q
            mujoco.mj_kinematics(model, data)
            mujoco.mj_comPos(model, data)
            quat = np.zeros(4)
            mujoco.mju_mat2Quat(quat, data.site_xmat[site])
            e_rot_local = np.zeros(3)
            mujoco.mju_subQuat(e_rot_local, q_goal, quat)
            e = np.concatenate(
                [p_goal - data.site_xpos[site], data.site_xmat[site].reshape(3, 3) @ e_rot_local]
            )
            if np.linalg.norm(e[:3]) < 1e-4 and np.linalg.norm(e[3:]) < 1e-3:
                if all(np.max(np.abs(q - other)) > HOME_DISTINCT for _, other in found):
                    margin = float(np.min(np.minimum(q - lo, hi - q) / (hi - lo)))
                    found.append((margin, q.copy()))
                break
            mujoco.mj_jacSite(model, data, jacp, jacr, site)
            J = np.vstack([jacp[:, dadr], jacr[:, dadr]])
            dq = J.T @ np.linalg.solve(J @ J.T + _IK_DAMPING**2 * eye, e)
            step = float(np.max(np.abs(dq)))
            if step > _IK_MAX_STEP:
                dq *= _IK_MAX_STEP / step
            q = np.clip(q + dq, q_min, q_max)
    if not found:
        raise RobotError(
            f"{src}: [arm] home: not given, and IK found no posture that puts the tool on the "
            f"world's '{HOME_TOOL_SITE}' pose; valid: set home = [...] (one value per arm joint)"
        )
    found.sort(key=lambda item: -item[0])
    return [q for _, q in found]


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
) -> Composition:
    """Compose, calibrate and resolve a robot.

    Args:
        robot: A bundled robot's name (:func:`bundled_robots`), a ``robot.toml`` path, or a
            description.
        world: World MJCF file or spec; None: ``scenes/world.xml``.
        home_width: Gripper gap of the ``home`` keyframe [m]; None: the open width.
        brick_geom: The world's brick geom.
        pad_slots: Contacts each pad–brick sensor reports.

    Raises:
        RobotError: See :func:`compose`; also no home posture could be found.
    """
    desc = resolve_description(robot)
    src = str(desc.source)
    composed = _compose(world, desc, brick_geom, pad_slots)
    spec, calib = composed.spec, composed.calibration
    spec.add_key(name=HOME_KEY)  # filled in once the home is known (Robot.write_home)
    model = _compile(spec, src)
    obj = mujoco.mjtObj
    arm_names = tuple(ARM_PREFIX + j for j in composed.arm.joints)
    joint_ids = _ids(model, obj.mjOBJ_JOINT, arm_names)
    limited = model.jnt_limited[joint_ids].astype(bool)
    q_min = np.where(limited, model.jnt_range[joint_ids, 0], -np.inf)
    q_max = np.where(limited, model.jnt_range[joint_ids, 1], np.inf)
    tool_site = int(_ids(model, obj.mjOBJ_SITE, (composed.tool_site,))[0])
    if desc.arm.home is not None:
        candidates = [np.array(desc.arm.home, dtype=float)]
        home_source = "description"
    else:
        candidates = _home_candidates(model, joint_ids, tool_site, q_min, q_max, src)
        home_source = "ik"
    q_home = candidates[0]

    gripper_acts = _ids(
        model, obj.mjOBJ_ACTUATOR, tuple(GRIPPER_PREFIX + a for a in calib.actuators)
    )
    gripper_joints = _ids(model, obj.mjOBJ_JOINT, tuple(GRIPPER_PREFIX + j for j in calib.joints))
    width = calib.open_width if home_width is None else float(home_width)
    arm_acts = _ids(
        model, obj.mjOBJ_ACTUATOR, tuple(ARM_PREFIX + a for a in composed.arm.actuators)
    )

    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    pad_geoms = tuple(
        _ids(model, obj.mjOBJ_GEOM, tuple(GRIPPER_PREFIX + p for p in side)) for side in calib.pads
    )
    pad_bodies = tuple(model.geom_bodyid[g].copy() for g in pad_geoms)
    faces_body = []
    for geoms, faces in zip(pad_geoms, calib.pad_faces, strict=True):
        rotated = _rotate(model.geom_quat[geoms], faces)
        faces_body.append(model.geom_pos[geoms] + rotated)
    sensors = tuple(_ids(model, obj.mjOBJ_SENSOR, names) for names in composed.pad_sensors)
    tool_body = int(model.site_bodyid[tool_site])
    y_tool = _rotate(model.site_quat[tool_site], np.array([0.0, 1.0, 0.0]))
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
            flange_body_id=int(
                _ids(model, obj.mjOBJ_BODY, (ARM_PREFIX + composed.arm.flange_body,))[0]
            ),
            home_key_id=key,
            home_width=width,
            calibration=calib,
            repairs=composed.repairs,
        ),
    )
    composition.robot.write_home(model, q_home, width)
    return composition
