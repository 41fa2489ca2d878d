"""Open a pick-and-place scene and resolve the named handles the pipeline needs.

The scene contract (names a scene file must define) is :class:`SceneNames`; its defaults match
``scenes/scene.xml``. Every missing name raises :class:`~pickplace.errors.UnknownNameError`
listing the names of that kind that do exist.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import mujoco
import numpy as np
from mink.lie import SE3, SO3

from pickplace.errors import SceneError, UnknownNameError


def _scenes_dir() -> Path:
    """``scenes/`` of a source checkout, or the copy installed as ``pickplace/scenes``."""
    here = Path(__file__).resolve().parent
    for candidate in (here.parent / "scenes", here / "scenes"):
        if (candidate / "scene.xml").is_file():
            return candidate
    return here.parent / "scenes"


SCENES_DIR = _scenes_dir()
DEFAULT_SCENE = SCENES_DIR / "scene.xml"

_OBJ_KIND = {
    mujoco.mjtObj.mjOBJ_JOINT: "joint",
    mujoco.mjtObj.mjOBJ_ACTUATOR: "actuator",
    mujoco.mjtObj.mjOBJ_SITE: "site",
    mujoco.mjtObj.mjOBJ_BODY: "body",
    mujoco.mjtObj.mjOBJ_GEOM: "geom",
    mujoco.mjtObj.mjOBJ_NUMERIC: "custom numeric",
    mujoco.mjtObj.mjOBJ_KEY: "keyframe",
    mujoco.mjtObj.mjOBJ_SENSOR: "sensor",
}

_OBJ_COUNT = {
    mujoco.mjtObj.mjOBJ_JOINT: "njnt",
    mujoco.mjtObj.mjOBJ_ACTUATOR: "nu",
    mujoco.mjtObj.mjOBJ_SITE: "nsite",
    mujoco.mjtObj.mjOBJ_BODY: "nbody",
    mujoco.mjtObj.mjOBJ_GEOM: "ngeom",
    mujoco.mjtObj.mjOBJ_NUMERIC: "nnumeric",
    mujoco.mjtObj.mjOBJ_KEY: "nkey",
    mujoco.mjtObj.mjOBJ_SENSOR: "nsensor",
}

# The contype bit every robot collision geom (arm and gripper) carries; world geoms (bins,
# floor, brick) have conaffinity with it, robot geoms do not, so the robot never collides
# with itself.
ROBOT_CONTYPE = 2

# Contact sensor fields the loop reads (bits of sensor_intprm[0]).
_CONTACT_FOUND = 1 << int(mujoco.mjtConDataField.mjCONDATA_FOUND)
_CONTACT_FORCE = 1 << int(mujoco.mjtConDataField.mjCONDATA_FORCE)
# sensor_intprm[1] of a contact sensor that keeps the contact with the largest force.
_REDUCE_MAXFORCE = 2
# Names of the robot-world contact sensors load_scene adds, one per world body.
ROBOT_WORLD_SENSOR_PREFIX = "robot_world/"


def names_of(model: mujoco.MjModel, obj: mujoco.mjtObj) -> list[str]:
    """Return the non-empty names of every object of type ``obj`` in ``model``."""
    count = int(getattr(model, _OBJ_COUNT[obj]))
    names = (mujoco.mj_id2name(model, obj, i) for i in range(count))
    return [n for n in names if n]


def name_to_id(model: mujoco.MjModel, obj: mujoco.mjtObj, name: str) -> int:
    """Return the id of the object ``name`` of type ``obj``.

    Raises:
        UnknownNameError: The name does not exist; the message lists those that do.
    """
    idx = mujoco.mj_name2id(model, obj, name)
    if idx < 0:
        raise UnknownNameError(_OBJ_KIND[obj], name, names_of(model, obj))
    return int(idx)


@dataclass(frozen=True)
class SceneNames:
    """Names a pick-and-place scene must define (defaults: ``scenes/scene.xml``)."""

    arm_joints: tuple[str, ...] = tuple(f"joint{i}" for i in range(1, 8))
    arm_actuators: tuple[str, ...] = tuple(f"joint{i}" for i in range(1, 8))
    speed_limits: str = "arm_joint_speed_limits"
    accel_limits: str = "arm_joint_accel_limits"
    gripper_actuator: str = "wsg50/fingers"
    finger_joints: tuple[str, str] = ("wsg50/left_finger", "wsg50/right_finger")
    pad_geoms: tuple[str, str] = ("wsg50/left_pad", "wsg50/right_pad")
    pad_force_sensors: tuple[str, str] = ("left_pad_force", "right_pad_force")
    tool_site: str = "wsg50/tool"
    flange_site: str = "attachment_site"
    brick_body: str = "brick"
    brick_geom: str = "brick"
    source_bin: str = "bin1"
    target_bin: str = "bin2"
    home_key: str = "home"


@dataclass(frozen=True)
class Contact:
    """A contact (or a near contact within the geoms' margins) between two geoms.

    Attributes:
        geom: The robot's (or the held object's) geom.
        other: The geom it touches.
        dist: Signed distance [m]: negative when they penetrate.
        pos_W: Contact point in world [m].
    """

    geom: int
    other: int
    dist: float
    pos_W: np.ndarray


@dataclass(frozen=True)
class BinGeometry:
    """An open-top bin: a floor box and four walls, described in the bin body's frame B.

    Attributes:
        name: Body name of the bin.
        X_WB: Pose of the bin frame in world (z up, origin below the floor centre).
        inner_half_extents: Half-lengths [m] of the free floor area along B's x and y,
            measured between the inner faces of the walls.
        floor_top_z: Height [m] of the floor's top face in world.
        wall_top_z: Height [m] of the walls' top faces in world.
    """

    name: str
    X_WB: SE3
    inner_half_extents: np.ndarray
    floor_top_z: float
    wall_top_z: float

    def to_bin_frame(self, p_W: np.ndarray) -> np.ndarray:
        """Express world points ``p_W`` (..., 3) in the bin frame B."""
        X_BW = self.X_WB.inverse()
        R_BW = X_BW.rotation().as_matrix()
        return np.asarray(p_W) @ R_BW.T + X_BW.translation()

    def contains_xy(self, p_W: np.ndarray, margin: float = 0.0) -> bool:
        """True if every point of ``p_W`` (N, 3) lies over the floor, ``margin`` [m] inside."""
        p_B = self.to_bin_frame(np.atleast_2d(p_W))
        limit = self.inner_half_extents - margin
        return bool(np.all(np.abs(p_B[:, :2]) <= limit))

    @property
    def center_W(self) -> np.ndarray:
        """Centre of the floor's top face in world [m]."""
        p = self.X_WB.translation().copy()
        p[2] = self.floor_top_z
        return p


def _bin_geometry(model: mujoco.MjModel, data: mujoco.MjData, name: str) -> BinGeometry:
    body_id = name_to_id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    geom_ids = [g for g in range(model.ngeom) if model.geom_bodyid[g] == body_id]
    floor_name = f"{name}_floor"
    floor_id = name_to_id(model, mujoco.mjtObj.mjOBJ_GEOM, floor_name)
    walls = [
        g for g in geom_ids if g != floor_id and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX
    ]
    if len(walls) < 4:
        raise SceneError(
            f"bin '{name}' needs a floor geom '{floor_name}' and 4 box walls, "
            f"found {len(walls)} walls"
        )
    # Inner faces: for each wall, the face nearer the bin centre along its thin axis.
    inner = np.array([np.inf, np.inf])
    wall_top = -np.inf
    for g in walls:
        pos, size = model.geom_pos[g], model.geom_size[g]
        axis = int(np.argmin(size[:2]))  # the wall's thickness direction in B
        inner[axis] = min(inner[axis], abs(pos[axis]) - size[axis])
        wall_top = max(wall_top, pos[2] + size[2])
    floor_top = model.geom_pos[floor_id][2] + model.geom_size[floor_id][2]
    X_WB = SE3.from_rotation_and_translation(
        SO3(np.array(data.xquat[body_id])), np.array(data.xpos[body_id])
    )
    base_z = float(data.xpos[body_id][2])
    return BinGeometry(
        name=name,
        X_WB=X_WB,
        inner_half_extents=inner,
        floor_top_z=base_z + float(floor_top),
        wall_top_z=base_z + float(wall_top),
    )


@dataclass(frozen=True)
class Scene:
    """A compiled scene and the ids of everything the pipeline touches.

    Attributes:
        model: The compiled MuJoCo model.
        path: The scene file.
        names: The names that were resolved.
        arm_joint_ids: Joint ids of the 7 arm joints, base to flange.
        arm_qpos_adr: qpos addresses of the arm joints.
        arm_dof_adr: dof (qvel) addresses of the arm joints.
        q_min: Lower joint limits [rad].
        q_max: Upper joint limits [rad].
        v_max: Joint speed limits [rad/s], from the model's custom numeric data.
        a_max: Joint acceleration limits [rad/s²], from the model's custom numeric data, or
            None when the scene gives none.
        arm_actuator_ids: Position actuators of the arm joints.
        gripper_actuator_id: Position actuator of the finger gap [m].
        finger_joint_ids: The two finger joints (slides; gap = sum of their positions).
        finger_qpos_adr: qpos addresses of the two finger joints (gap = sum) [m].
        gripper_max_gap: Largest commandable finger gap [m].
        gripper_force_limit: Actuator force bound = squeeze per jaw [N].
        finger_outer_offset: Distance from a closed finger's inner pad face to its outer face
            along the closing axis [m]: an open finger reaches gap/2 + this from the centre.
        pad_geom_ids: Geoms of the left and right finger pads.
        pad_force_sensor_adr: sensordata addresses of the left and right pad–brick contact
            sensors; each holds ``pad_force_slots`` rows of [found, f_normal, f_t1, f_t2]
            (force on the pad in the contact frame [N]).
        pad_force_slots: Contacts each pad sensor reports.
        tool_site_id: Site at the grasp point, z along the approach direction.
        flange_site_id: Site at the arm's flange.
        brick_body_id: Free body of the brick.
        brick_geom_id: Box geom of the brick.
        brick_qpos_adr: First qpos address of the brick's free joint (xyz, wxyz).
        brick_dof_adr: First dof address of the brick's free joint.
        brick_half_extents: Half sizes of the brick box [m].
        brick_mass: Mass of the brick [kg].
        source_bin: Bin the brick starts in.
        target_bin: Bin the brick must end in.
        home_key_id: Keyframe with the arm's home posture.
        p_W_base: Point on the first arm joint's (vertical) axis, in world [m].
        robot_root_body_id: The body under the world whose subtree is the robot (arm and
            gripper).
        robot_body_mask: Per body, True for the robot's bodies.
        world_contact_body_ids: Bodies outside the robot and the brick that can collide: the
            world the robot must not touch.
        robot_world_sensor_adr: sensordata addresses of the robot-world contact sensors, one
            per world contact body, each [found, f_normal, f_t1, f_t2] of the contact with
            the largest force (force on the robot in the contact frame [N]).
        q_home: Arm joint positions of the home keyframe [rad].
    """

    model: mujoco.MjModel
    path: Path
    names: SceneNames
    arm_joint_ids: np.ndarray
    arm_qpos_adr: np.ndarray
    arm_dof_adr: np.ndarray
    q_min: np.ndarray
    q_max: np.ndarray
    v_max: np.ndarray
    a_max: np.ndarray | None
    arm_actuator_ids: np.ndarray
    gripper_actuator_id: int
    finger_joint_ids: np.ndarray
    finger_qpos_adr: np.ndarray
    gripper_max_gap: float
    gripper_force_limit: float
    finger_outer_offset: float
    pad_geom_ids: tuple[int, int]
    pad_force_sensor_adr: tuple[int, int]
    pad_force_slots: int
    tool_site_id: int
    flange_site_id: int
    brick_body_id: int
    brick_geom_id: int
    brick_qpos_adr: int
    brick_dof_adr: int
    brick_half_extents: np.ndarray
    brick_mass: float
    source_bin: BinGeometry
    target_bin: BinGeometry
    home_key_id: int
    p_W_base: np.ndarray
    robot_root_body_id: int
    robot_body_mask: np.ndarray = field(repr=False)
    world_contact_body_ids: np.ndarray
    robot_world_sensor_adr: np.ndarray
    q_home: np.ndarray = field(repr=False)

    @cached_property
    def arm_model(self) -> mujoco.MjModel:
        """The scene compiled with only the arm joints left (nq = nv = 7), for the IK.

        Fingers, the brick's free joint and everything that refers to them (actuators,
        tendons, equalities, sensors, keyframes) are removed; bodies, sites and geometry are
        unchanged, so the tool site's forward kinematics equal the simulation's. Compiled once
        per scene and shared (read-only) by every controller and planner.
        """
        spec = mujoco.MjSpec.from_file(str(self.path))
        for collection in (
            "actuators",
            "tendons",
            "equalities",
            "sensors",
            "keys",
            "pairs",
            "excludes",
        ):
            for element in list(getattr(spec, collection)):
                spec.delete(element)
        keep = set(self.names.arm_joints)
        for joint in list(spec.joints):
            if joint.name not in keep:
                spec.delete(joint)
        model = spec.compile()
        order = tuple(names_of(model, mujoco.mjtObj.mjOBJ_JOINT))
        if order != self.names.arm_joints:
            raise SceneError(f"arm joints {order} are not in the order {self.names.arm_joints}")
        return model

    @property
    def brick_width(self) -> float:
        """Width of the brick across the fingers (its y extent) [m]."""
        return 2.0 * float(self.brick_half_extents[1])

    def is_robot_geom(self, geom_id: int) -> bool:
        """True if geom ``geom_id`` belongs to a body of the robot (arm or gripper)."""
        return bool(self.robot_body_mask[self.model.geom_bodyid[geom_id]])

    def is_world_geom(self, geom_id: int) -> bool:
        """True if geom ``geom_id`` is part of the world the robot must not touch (a geom of
        :attr:`world_contact_body_ids`)."""
        return bool(np.isin(self.model.geom_bodyid[geom_id], self.world_contact_body_ids))

    def robot_world_contacts(self, model: mujoco.MjModel, data: mujoco.MjData) -> list[Contact]:
        """Contacts in ``data`` between a robot geom and a world geom, deepest first.

        ``model`` and ``data`` may be this scene's or a kinematic copy of it (same geoms),
        after :func:`mujoco.mj_collision` (contacts within the geoms' margins are included,
        with their positive distance).
        """
        out = []
        bodies = model.geom_bodyid
        world = set(self.world_contact_body_ids.tolist())
        for i in range(data.ncon):
            c = data.contact[i]
            g1, g2 = int(c.geom1), int(c.geom2)
            if self.robot_body_mask[bodies[g1]] and bodies[g2] in world:
                robot, other = g1, g2
            elif self.robot_body_mask[bodies[g2]] and bodies[g1] in world:
                robot, other = g2, g1
            else:
                continue
            out.append(Contact(robot, other, float(c.dist), np.array(c.pos)))
        return sorted(out, key=lambda c: c.dist)

    def geom_name(self, geom_id: int) -> str:
        """Name of geom ``geom_id`` (``geom<id>`` when it has none)."""
        return mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_GEOM, geom_id) or f"geom{geom_id}"

    @property
    def arm_joint_names(self) -> tuple[str, ...]:
        """Names of the arm joints, base to flange."""
        return self.names.arm_joints

    def finger_gap(self, qpos: np.ndarray) -> np.ndarray:
        """Finger gap [m] (sum of the two finger joints) from qpos of shape (..., nq)."""
        a, b = self.finger_qpos_adr
        return np.asarray(qpos[..., a] + qpos[..., b])

    def finger_qpos(self, width: float) -> np.ndarray:
        """Finger joint positions [m] that open the gap to ``width`` [m] (each finger takes half
        of it, within its range): the values for :attr:`finger_qpos_adr`."""
        half = 0.5 * float(width)
        lo, hi = self.model.jnt_range[self.finger_joint_ids].T
        return np.clip(np.full(len(self.finger_joint_ids), half), lo, hi)

    def pad_sensor_rows(self, sensordata: np.ndarray) -> np.ndarray:
        """The pad sensors' contact slots from sensordata of shape (..., nsensordata).

        Returns:
            Shape (..., 2, pad_force_slots, 4): left and right pad, one row per contact slot of
            [found, f_normal, f_t1, f_t2] (contact count; force on the pad in the contact
            frame [N]; unused slots are zero).
        """
        n = 4 * self.pad_force_slots
        rows = [sensordata[..., a : a + n] for a in self.pad_force_sensor_adr]
        return np.stack(rows, axis=-2).reshape(*sensordata.shape[:-1], 2, self.pad_force_slots, 4)

    def pad_normal_forces(self, sensordata: np.ndarray) -> np.ndarray:
        """Normal force [N] of the brick on the left and right pad, shape (..., 2), from
        sensordata of shape (..., nsensordata)."""
        return self.pad_sensor_rows(sensordata)[..., 1].sum(axis=-1)

    def set_brick_pose(self, data: mujoco.MjData, X_WO: SE3) -> None:
        """Write the brick's pose ``X_WO`` into ``data.qpos`` (call mj_forward afterwards)."""
        adr = self.brick_qpos_adr
        data.qpos[adr : adr + 3] = X_WO.translation()
        data.qpos[adr + 3 : adr + 7] = X_WO.rotation().wxyz

    def make_data(self) -> mujoco.MjData:
        """Return fresh MjData reset to the home keyframe."""
        data = mujoco.MjData(self.model)
        mujoco.mj_resetDataKeyframe(self.model, data, self.home_key_id)
        mujoco.mj_forward(self.model, data)
        return data


def _finger_outer_offset(model: mujoco.MjModel, finger_joint: int) -> float:
    """Outer extent of a finger's box geoms along its joint axis, from the joint's zero [m]."""
    body = model.jnt_bodyid[finger_joint]
    axis = model.jnt_axis[finger_joint]
    extent = 0.0
    for g in range(model.ngeom):
        if model.geom_bodyid[g] == body and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
            extent = max(
                extent, float(model.geom_pos[g] @ axis + np.abs(axis) @ model.geom_size[g])
            )
    return extent


def _pad_force_sensors(
    model: mujoco.MjModel, names: SceneNames, pad_ids: tuple[int, int], brick_geom: int
) -> tuple[tuple[int, int], int]:
    """sensordata addresses of the two pad-force sensors and their number of contact slots.

    Raises:
        UnknownNameError: A sensor is missing.
        SceneError: A sensor is not a ``found force`` contact sensor between its pad and the
            brick, or the two report different numbers of contacts.
    """
    adr: list[int] = []
    slots: list[int] = []
    for name, pad in zip(names.pad_force_sensors, pad_ids, strict=True):
        i = name_to_id(model, mujoco.mjtObj.mjOBJ_SENSOR, name)
        fields, num = int(model.sensor_intprm[i, 0]), int(model.sensor_intprm[i, 2])
        geoms = {int(model.sensor_objid[i]), int(model.sensor_refid[i])}
        if (
            model.sensor_type[i] != mujoco.mjtSensor.mjSENS_CONTACT
            or fields != _CONTACT_FOUND | _CONTACT_FORCE
            or model.sensor_objtype[i] != mujoco.mjtObj.mjOBJ_GEOM
            or model.sensor_reftype[i] != mujoco.mjtObj.mjOBJ_GEOM
            or geoms != {pad, brick_geom}
        ):
            pad_name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, pad)
            raise SceneError(
                f"sensor '{name}' must be <contact geom1=\"{pad_name}\" "
                f'geom2="{names.brick_geom}" data="found force" num="N"/>'
            )
        adr.append(int(model.sensor_adr[i]))
        slots.append(num)
    if slots[0] != slots[1]:
        raise SceneError(f"pad force sensors report different numbers of contacts: {slots}")
    return (adr[0], adr[1]), slots[0]


def parse_scene(path: Path) -> mujoco.MjSpec:
    """Parse an MJCF file into a spec, turning every failure into a :class:`SceneError`."""
    path = path.resolve()  # MuJoCo misresolves nested <model file=...> for relative paths.
    if not path.exists():
        raise SceneError(f"scene file '{path}' does not exist")
    if not path.is_file():
        raise SceneError(f"scene path '{path}' is not a file")
    try:
        return mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:  # MuJoCo reports parse errors as ValueError.
        detail = " ".join(str(exc).split())
        raise SceneError(f"scene file '{path}' is not valid MJCF: {detail}") from exc


def _compile(spec: mujoco.MjSpec, path: Path) -> mujoco.MjModel:
    try:
        return spec.compile()
    except ValueError as exc:  # MuJoCo reports compile errors as ValueError.
        detail = " ".join(str(exc).split())
        raise SceneError(f"scene file '{path}' is not valid MJCF: {detail}") from exc


def compile_scene(path: Path) -> mujoco.MjModel:
    """Compile an MJCF file, turning every failure into a :class:`SceneError`."""
    return _compile(parse_scene(path), path.resolve())


def _robot_root(model: mujoco.MjModel, joint_id: int) -> int:
    """The body under the world whose subtree holds joint ``joint_id`` (the robot's root)."""
    return int(model.body_rootid[model.jnt_bodyid[joint_id]])


def _world_contact_bodies(model: mujoco.MjModel, robot_root: int, brick_body: int) -> list[int]:
    """Bodies outside the robot and the brick that have geoms: the world the robot must not
    touch (the world body's floor, the bins, an obstacle a fault may bring in)."""
    out = []
    for b in range(model.nbody):
        if (b and model.body_rootid[b] == robot_root) or b == brick_body:
            continue
        if np.any(model.geom_bodyid == b):
            out.append(b)
    return out


def _add_robot_world_sensors(
    spec: mujoco.MjSpec, model: mujoco.MjModel, robot_root: int, bodies: list[int]
) -> list[str]:
    """One contact sensor per world body: the robot's subtree against that body, reporting
    the number of contacts and the largest normal force (``found force``, ``maxforce``)."""
    names = []
    root = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, robot_root)
    for b in bodies:
        body = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or "world"
        name = f"{ROBOT_WORLD_SENSOR_PREFIX}{body}"
        spec.add_sensor(
            name=name,
            type=mujoco.mjtSensor.mjSENS_CONTACT,
            objtype=mujoco.mjtObj.mjOBJ_XBODY,  # subtree of the robot's root
            objname=root,
            reftype=mujoco.mjtObj.mjOBJ_BODY,
            refname=body,
            intprm=[_CONTACT_FOUND | _CONTACT_FORCE, _REDUCE_MAXFORCE, 1],
        )
        names.append(name)
    return names


def load_scene(path: str | Path | None = None, names: SceneNames | None = None) -> Scene:
    """Compile a scene file and resolve every handle of the scene contract.

    Args:
        path: MJCF file; default ``scenes/scene.xml``.
        names: Names to resolve; default :class:`SceneNames`.

    Raises:
        SceneError: The file is missing, not valid MJCF or structurally wrong.
        UnknownNameError: A required name is missing (the message lists those that exist).
    """
    path = (Path(path) if path is not None else DEFAULT_SCENE).resolve()
    names = names or SceneNames()
    spec = parse_scene(path)
    model = _compile(spec, path)
    obj = mujoco.mjtObj

    joint_ids = np.array([name_to_id(model, obj.mjOBJ_JOINT, j) for j in names.arm_joints])
    for j, name in zip(joint_ids, names.arm_joints, strict=True):
        if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE or not model.jnt_limited[j]:
            raise SceneError(f"arm joint '{name}' must be a limited hinge joint")
    act_ids = np.array([name_to_id(model, obj.mjOBJ_ACTUATOR, a) for a in names.arm_actuators])

    num_id = name_to_id(model, obj.mjOBJ_NUMERIC, names.speed_limits)
    adr, size = model.numeric_adr[num_id], model.numeric_size[num_id]
    v_max = np.array(model.numeric_data[adr : adr + size], dtype=float)
    if v_max.shape != (len(joint_ids),) or np.any(v_max <= 0):
        raise SceneError(
            f"custom numeric '{names.speed_limits}' must hold {len(joint_ids)} positive joint "
            f"speed limits [rad/s], got {v_max.tolist()}"
        )

    a_max = None
    acc_id = mujoco.mj_name2id(model, obj.mjOBJ_NUMERIC, names.accel_limits)
    if acc_id >= 0:
        adr, size = model.numeric_adr[acc_id], model.numeric_size[acc_id]
        a_max = np.array(model.numeric_data[adr : adr + size], dtype=float)
        if a_max.shape != (len(joint_ids),) or np.any(a_max <= 0):
            raise SceneError(
                f"custom numeric '{names.accel_limits}' must hold {len(joint_ids)} positive "
                f"joint acceleration limits [rad/s²], got {a_max.tolist()}"
            )

    grip_id = name_to_id(model, obj.mjOBJ_ACTUATOR, names.gripper_actuator)
    finger_ids = [name_to_id(model, obj.mjOBJ_JOINT, j) for j in names.finger_joints]
    pad_ids = (
        name_to_id(model, obj.mjOBJ_GEOM, names.pad_geoms[0]),
        name_to_id(model, obj.mjOBJ_GEOM, names.pad_geoms[1]),
    )
    brick_body = name_to_id(model, obj.mjOBJ_BODY, names.brick_body)
    brick_geom = name_to_id(model, obj.mjOBJ_GEOM, names.brick_geom)
    brick_jnt = int(model.body_jntadr[brick_body])
    if brick_jnt < 0 or model.jnt_type[brick_jnt] != mujoco.mjtJoint.mjJNT_FREE:
        raise SceneError(f"brick body '{names.brick_body}' must have a free joint")
    if model.geom_type[brick_geom] != mujoco.mjtGeom.mjGEOM_BOX:
        raise SceneError(f"brick geom '{names.brick_geom}' must be a box")
    home = name_to_id(model, obj.mjOBJ_KEY, names.home_key)
    robot_root = _robot_root(model, int(joint_ids[0]))
    world_bodies = _world_contact_bodies(model, robot_root, brick_body)
    sensor_names = _add_robot_world_sensors(spec, model, robot_root, world_bodies)
    model = _compile(spec, path)  # the same model, with the robot-world contact sensors
    sensor_adr, slots = _pad_force_sensors(model, names, pad_ids, brick_geom)
    world_sensor_adr = np.array(
        [model.sensor_adr[name_to_id(model, obj.mjOBJ_SENSOR, n)] for n in sensor_names],
        dtype=int,
    )

    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, home)
    mujoco.mj_forward(model, data)
    qpos_adr = model.jnt_qposadr[joint_ids].copy()
    return Scene(
        model=model,
        path=path,
        names=names,
        arm_joint_ids=joint_ids,
        arm_qpos_adr=qpos_adr,
        arm_dof_adr=model.jnt_dofadr[joint_ids].copy(),
        q_min=model.jnt_range[joint_ids, 0].copy(),
        q_max=model.jnt_range[joint_ids, 1].copy(),
        v_max=v_max,
        a_max=a_max,
        arm_actuator_ids=act_ids,
        gripper_actuator_id=grip_id,
        finger_joint_ids=np.array(finger_ids, dtype=int),
        finger_qpos_adr=model.jnt_qposadr[finger_ids].copy(),
        gripper_max_gap=float(model.actuator_ctrlrange[grip_id, 1]),
        gripper_force_limit=float(model.actuator_forcerange[grip_id, 1]),
        finger_outer_offset=_finger_outer_offset(model, finger_ids[0]),
        pad_geom_ids=pad_ids,
        pad_force_sensor_adr=sensor_adr,
        pad_force_slots=slots,
        tool_site_id=name_to_id(model, obj.mjOBJ_SITE, names.tool_site),
        flange_site_id=name_to_id(model, obj.mjOBJ_SITE, names.flange_site),
        brick_body_id=brick_body,
        brick_geom_id=brick_geom,
        brick_qpos_adr=int(model.jnt_qposadr[brick_jnt]),
        brick_dof_adr=int(model.jnt_dofadr[brick_jnt]),
        brick_half_extents=model.geom_size[brick_geom].copy(),
        brick_mass=float(model.body_mass[brick_body]),
        source_bin=_bin_geometry(model, data, names.source_bin),
        target_bin=_bin_geometry(model, data, names.target_bin),
        home_key_id=home,
        p_W_base=data.xanchor[joint_ids[0]].copy(),
        robot_root_body_id=robot_root,
        robot_body_mask=np.asarray(model.body_rootid == robot_root) & (np.arange(model.nbody) > 0),
        world_contact_body_ids=np.array(world_bodies, dtype=int),
        robot_world_sensor_adr=world_sensor_adr,
        q_home=data.qpos[qpos_adr].copy(),
    )
