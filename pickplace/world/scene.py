"""The scene a run simulates: a world with a robot composed into it, and the handles it needs.

A scene is a world file — bins, brick, floor, lights, cameras and physics options
(``scenes/world.xml``) — with a robot composed into it by :mod:`pickplace.robot.compose` (the arm at
the origin, the gripper on its flange, calibrated in simulation). :func:`build_scene` resolves
what the pipeline touches: the world's contract (:class:`WorldNames`: the brick and the two
bins) and everything about the robot, sized from the robot itself (its joints, limits,
actuators, gripper commands, pads and tool site: :class:`~pickplace.robot.compose.Robot`). It adds
one
robot–world contact sensor per world body. :func:`pickplace.sim.loader.load_scene` is the way to
get a scene (cached by file content, home posture chosen); every missing world name raises
:class:`~pickplace.errors.UnknownNameError` listing the names of that kind that do exist.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import mujoco
import numpy as np
from mink.lie import SE3, SO3

from pickplace.errors import SceneError, UnknownNameError
from pickplace.robot.compiled import compile_cached
from pickplace.robot.mjcf import file_stamps, parse_world
from pickplace.robot.model import Composition, Robot
from pickplace.robot.physics import ROBOT_CONAFFINITY, ROBOT_CONTYPE
from pickplace.robot.registry import DEFAULT_WORLD
from pickplace.world.objects import ObjectGeometry

if TYPE_CHECKING:
    from pickplace.world.cell import ObstacleCell

__all__ = [
    "BRICK_MASS_RANGE",
    "ROBOT_CONAFFINITY",
    "ROBOT_CONTYPE",
    "BinGeometry",
    "Contact",
    "Scene",
    "WorldFile",
    "WorldNames",
    "build_scene",
    "check_world",
    "name_to_id",
    "names_of",
    "read_world",
]

_OBJ_KIND = {
    mujoco.mjtObj.mjOBJ_JOINT: "joint",
    mujoco.mjtObj.mjOBJ_ACTUATOR: "actuator",
    mujoco.mjtObj.mjOBJ_SITE: "site",
    mujoco.mjtObj.mjOBJ_BODY: "body",
    mujoco.mjtObj.mjOBJ_GEOM: "geom",
    mujoco.mjtObj.mjOBJ_KEY: "keyframe",
    mujoco.mjtObj.mjOBJ_SENSOR: "sensor",
}

_OBJ_COUNT = {
    mujoco.mjtObj.mjOBJ_JOINT: "njnt",
    mujoco.mjtObj.mjOBJ_ACTUATOR: "nu",
    mujoco.mjtObj.mjOBJ_SITE: "nsite",
    mujoco.mjtObj.mjOBJ_BODY: "nbody",
    mujoco.mjtObj.mjOBJ_GEOM: "ngeom",
    mujoco.mjtObj.mjOBJ_KEY: "nkey",
    mujoco.mjtObj.mjOBJ_SENSOR: "nsensor",
}

# Contact sensor fields the loop reads (bits of sensor_intprm[0]).
_CONTACT_FOUND = 1 << int(mujoco.mjtConDataField.mjCONDATA_FOUND)
_CONTACT_FORCE = 1 << int(mujoco.mjtConDataField.mjCONDATA_FORCE)
# sensor_intprm[1] of a contact sensor that keeps the contact with the largest force.
_REDUCE_MAXFORCE = 2
ROBOT_WORLD_SENSOR_PREFIX = "robot_world/"
"""Names of the robot-world contact sensors :func:`build_scene` adds, one per world body."""


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
class WorldNames:
    """Names a world file must define (defaults: ``scenes/world.xml``).

    The world also carries a site ``home_tool`` where a robot without a home posture is sent
    by IK (:data:`pickplace.robot.home_ik.HOME_TOOL_SITE`), and, for the ``fault-obstacle``
    scenario,
    a mocap body ``obstacle`` (:class:`pickplace.sim.faults.Obstacle`).

    Attributes:
        brick_body: The brick's body (with a free joint).
        brick_geom: The brick's box geom (the gripper is calibrated on its size). The free
            body's collision geoms (:class:`~pickplace.world.objects.ObjectGeometry`) are
            what is grasped: this box, or another object put in its place (``--object``).
        source_bin: The bin the brick starts in: a body with a floor geom ``<bin>_floor`` and
            four box walls.
        target_bin: The bin it must end in, alike.
    """

    brick_body: str = "brick"
    brick_geom: str = "brick"
    source_bin: str = "bin1"
    target_bin: str = "bin2"


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
    """A compiled scene, the robot in it and the ids of everything the pipeline touches.

    The robot's arrays are sized by the robot: ``n`` arm joints (:attr:`n_joints`), as many
    gripper actuators and joints as its gripper has, any number of pads per side. The model
    may be changed by faults (a mass, a gain): :func:`pickplace.sim.loader.load_scene` gives every
    run its own copy; :attr:`arm_model` is shared and never changed.

    Attributes:
        model: The compiled MuJoCo model.
        path: The world file.
        robot: The composed robot (ids refer to ``model``; its ``q_home`` is the scene's home).
        names: The world names that were resolved.
        arm_model: The scene with only the arm joints left (nq = nv = n), for the IK; bodies,
            sites and geometry unchanged, so the tool site's kinematics equal the simulation's.
        gripper_qpos_adr: qpos addresses of the gripper's joints.
        pad_force_sensor_adr: sensordata addresses of every pad–brick contact sensor, the
            +y ("left") side's first; each holds ``pad_force_slots`` rows of
            [found, f_normal, f_t1, f_t2] (force on the pad in the contact frame [N]).
        pad_sensor_side: Per pad sensor, 0 for the +y side and 1 for the -y side.
        brick_body_id: Free body of the brick.
        brick_geom_id: The object's first collision geom (the brick's box).
        brick_qpos_adr: First qpos address of the brick's free joint (xyz, wxyz).
        brick_dof_adr: First dof address of the brick's free joint.
        brick_half_extents: Half sizes of the object's bounding box in O [m] (the brick's
            box sizes).
        brick_mass: Mass of the brick [kg].
        object: The free body's collision geometry, which every reader of its shape asks.
        source_bin: Bin the brick starts in.
        target_bin: Bin the brick must end in.
        robot_root_body_ids: The bodies under the world whose subtrees are the robot.
        robot_body_mask: Per body, True for the robot's bodies (arm and gripper).
        world_contact_body_ids: Bodies outside the robot and the brick that can collide: the
            world the robot must not touch.
        robot_world_sensor_adr: sensordata addresses of the robot-world contact sensors, one
            per robot root and world contact body, each [found, f_normal, f_t1, f_t2] of the
            contact with the largest force (force on the robot in the contact frame [N]).
        spec: The composed spec the model was compiled from, without the robot-world
            sensors (:func:`pickplace.world.obstacles.with_obstacles` adds to a copy of it);
            never changed.
        obstacles: The obstacles added to the world
            (:class:`~pickplace.world.cell.ObstacleCell`), or None.
    """

    model: mujoco.MjModel
    path: Path
    robot: Robot
    names: WorldNames
    arm_model: mujoco.MjModel = field(repr=False, compare=False)
    gripper_qpos_adr: np.ndarray
    pad_force_sensor_adr: np.ndarray
    pad_sensor_side: np.ndarray
    brick_body_id: int
    brick_geom_id: int
    brick_qpos_adr: int
    brick_dof_adr: int
    brick_half_extents: np.ndarray
    brick_mass: float
    object: ObjectGeometry
    source_bin: BinGeometry
    target_bin: BinGeometry
    robot_root_body_ids: np.ndarray
    robot_body_mask: np.ndarray = field(repr=False)
    world_contact_body_ids: np.ndarray
    robot_world_sensor_adr: np.ndarray
    spec: mujoco.MjSpec | None = field(default=None, repr=False, compare=False)
    obstacles: ObstacleCell | None = None

    def pad_sensor_rows(self, sensordata: np.ndarray) -> np.ndarray:
        """The pad sensors' contact slots from sensordata of shape (..., nsensordata).

        Returns:
            Shape (..., sensors, pad_force_slots, 4): one row per contact slot of
            [found, f_normal, f_t1, f_t2] (contact count; force on the pad in the contact
            frame [N]; unused slots are zero), sensors in :attr:`pad_force_sensor_adr` order.
        """
        n = 4 * self.robot.pad_force_slots
        rows = [sensordata[..., a : a + n] for a in self.pad_force_sensor_adr.tolist()]
        shape = (*sensordata.shape[:-1], len(rows), self.robot.pad_force_slots, 4)
        return np.stack(rows, axis=-2).reshape(shape)

    # ------------------------------------------------------------------ the world

    @property
    def brick_width(self) -> float:
        """Width of the object across the fingers along O's y [m]."""
        if self.object.box_half_extents is not None:
            return 2.0 * float(self.brick_half_extents[1])
        return self.object.support([0.0, 1.0, 0.0]) + self.object.support([0.0, -1.0, 0.0])

    def is_object_geom(self, geom_id: int) -> bool:
        """True if geom ``geom_id`` is one of the held object's collision geoms."""
        return bool(np.isin(geom_id, self.object.geom_ids))

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

    def set_brick_pose(self, data: mujoco.MjData, X_WO: SE3) -> None:
        """Write the brick's pose ``X_WO`` into ``data.qpos`` (call mj_forward afterwards)."""
        adr = self.brick_qpos_adr
        data.qpos[adr : adr + 3] = X_WO.translation()
        data.qpos[adr + 3 : adr + 7] = X_WO.rotation().wxyz  # position and quaternion

    def make_data(self) -> mujoco.MjData:
        """Fresh MjData of this scene's model reset to the home keyframe."""
        return self.robot.make_data(self.model)


@dataclass(frozen=True)
class WorldFile:
    """A world file read and parsed once, at the edge of a request.

    Attributes:
        path: The file, resolved.
        content: Its bytes (the scene cache's key).
        spec: Its parsed spec; never changed (the composition works on a copy).
    """

    path: Path
    content: bytes = field(repr=False)
    spec: mujoco.MjSpec = field(repr=False, compare=False)

    @property
    def timestep(self) -> float:
        """The world's physics timestep [s] (``<option timestep>``)."""
        return float(self.spec.option.timestep)

    @property
    def self_contained(self) -> bool:
        """True if :attr:`content` is all the world is read from: the file names no other
        MJCF file (no ``<include>``, no ``<model>`` asset), whose content it would not hold.
        Asset files (meshes, textures) are digested from the spec where a key needs them."""
        return b"<include" not in self.content and b"<model" not in self.content


_WORLDS: dict[Path, tuple[tuple[tuple[str, int, int], ...], WorldFile]] = {}


def read_world(path: str | Path | None = None) -> WorldFile:
    """Read and parse a world file (default ``scenes/world.xml``), once per process while
    its modification time and size stay the same.

    Raises:
        SceneError: The file is missing, not a file or not valid MJCF.
    """
    resolved = (Path(path) if path is not None else DEFAULT_WORLD).resolve()
    stamps = file_stamps([resolved])
    known = _WORLDS.get(resolved)
    if known is not None and stamps is not None and known[0] == stamps:
        return known[1]  # unchanged since it was read: its spec is never changed
    spec = parse_world(resolved)
    try:
        content = resolved.read_bytes()
    except OSError as exc:
        raise SceneError(f"scene file '{resolved}' cannot be read: {exc.strerror}") from exc
    world = WorldFile(resolved, content, spec)
    if stamps is not None:
        _WORLDS[resolved] = (stamps, world)
    return world


BRICK_MASS_RANGE = (1e-3, 1e3)
"""Mass of the world's brick [kg]: from a gram to a tonne (``--vary brick_mass`` takes
[0.01, 100])."""


def check_world(spec: mujoco.MjSpec, path: Path, names: WorldNames | None = None) -> None:
    """Check the world file on its own, before a robot is composed into it, so that its
    problems are reported as the world file's (not the robot's): it compiles alone, its
    numbers are finite, the brick is a box of positive size and mass on a free body, and its
    footprint fits in both bins.

    Args:
        spec: The parsed world (:func:`read_world`); copied, not changed.
        path: The world file, named in messages.
        names: World names; default :class:`WorldNames`.

    Raises:
        SceneError: One of those does not hold; the message names the element.
        UnknownNameError: The brick or a bin is missing.
    """
    names = names or WorldNames()
    try:
        model = spec.copy().compile()
    except ValueError as exc:
        detail = " ".join(str(exc).split())
        raise SceneError(
            f"scene file '{path}' does not compile on its own: {detail}; valid: a world file "
            "that MuJoCo compiles without a robot"
        ) from exc
    for what, values in (
        ("body positions", model.body_pos),
        ("body orientations", model.body_quat),
        ("geom positions", model.geom_pos),
        ("geom sizes", model.geom_size),
        ("body masses", model.body_mass),
    ):
        bad = np.flatnonzero(~np.isfinite(values).reshape(len(values), -1).all(axis=1))
        if bad.size:
            kind = mujoco.mjtObj.mjOBJ_BODY if what.startswith("body") else mujoco.mjtObj.mjOBJ_GEOM
            name = mujoco.mj_id2name(model, kind, int(bad[0])) or f"#{int(bad[0])}"
            raise SceneError(
                f"scene file '{path}': {what} of '{name}' are not finite "
                f"({values[int(bad[0])].tolist()}); valid: finite numbers"
            )
    obj = mujoco.mjtObj
    body = name_to_id(model, obj.mjOBJ_BODY, names.brick_body)
    joint = int(model.body_jntadr[body])
    if joint < 0 or model.jnt_type[joint] != mujoco.mjtJoint.mjJNT_FREE:
        raise SceneError(
            f"scene file '{path}': brick body '{names.brick_body}' has no free joint; valid: a "
            "body with <freejoint/>"
        )
    lo, hi = BRICK_MASS_RANGE
    mass = float(model.body_mass[body])
    if not lo <= mass <= hi:
        raise SceneError(
            f"scene file '{path}': brick body '{names.brick_body}' has mass {mass:g} kg; "
            f"valid: [{lo:g}, {hi:g}] kg"
        )
    shape = ObjectGeometry.from_model(model, body)
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    for bin_name in (names.source_bin, names.target_bin):
        inner = _bin_geometry(model, data, bin_name).inner_half_extents
        half = shape.footprint_half(0.0)
        fits = bool(np.all(half <= inner) or np.all(shape.footprint_half(0.5 * np.pi) <= inner))
        if not fits:
            raise SceneError(
                f"scene file '{path}': the object '{names.brick_body}' is "
                f"{2 * half[0]:g} x {2 * half[1]:g} m, larger than bin '{bin_name}' "
                f"({2 * inner[0]:g} x {2 * inner[1]:g} m inside); valid: an object whose "
                "footprint fits in both bins"
            )


def _world_contact_bodies(model: mujoco.MjModel, robot: np.ndarray, brick_body: int) -> list[int]:
    """Bodies outside the robot and the brick that have geoms: the world the robot must not
    touch (the world body's floor, the bins, an obstacle a fault may bring in)."""
    has_geom = np.zeros(model.nbody, dtype=bool)
    has_geom[model.geom_bodyid] = True
    return [b for b in range(model.nbody) if has_geom[b] and not robot[b] and b != brick_body]


def _add_robot_world_sensors(
    spec: mujoco.MjSpec, model: mujoco.MjModel, roots: np.ndarray, bodies: list[int]
) -> list[str]:
    """One contact sensor per robot root and world body: the root's subtree against that body,
    reporting the number of contacts and the largest normal force (``found force``,
    ``maxforce``)."""
    names = []
    taken = {s.name for s in spec.sensors}
    for root_id in roots.tolist():
        root = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, root_id)
        for b in bodies:
            body = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or "world"
            name = f"{ROBOT_WORLD_SENSOR_PREFIX}{body}"
            if len(roots) > 1:
                name += f"/{root}"
            if name in taken:
                raise SceneError(f"the world already has a sensor '{name}'; valid: another name")
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


def build_scene(
    composition: Composition,
    path: Path,
    names: WorldNames | None = None,
    arm_model: mujoco.MjModel | None = None,
) -> Scene:
    """Resolve a composed scene: the world's names, the robot, the robot–world sensors.

    Args:
        composition: The world with the robot composed into it
        (:func:`pickplace.robot.compose.load_robot`);
            its spec is copied, not changed.
        path: The world file (reported in the scene).
        names: World names to resolve; default :class:`WorldNames`.
        arm_model: The arm-only model of the IK when it is known already (the same robot in
            a world with more obstacles); default: the composition's.

    Raises:
        SceneError: The brick or a bin is structurally wrong, or the scene does not compile.
        UnknownNameError: A world name is missing (the message lists those that exist).
    """
    names = names or WorldNames()
    robot = composition.robot
    model = composition.model
    obj = mujoco.mjtObj
    brick_body = name_to_id(model, obj.mjOBJ_BODY, names.brick_body)
    brick_jnt = int(model.body_jntadr[brick_body])
    if brick_jnt < 0 or model.jnt_type[brick_jnt] != mujoco.mjtJoint.mjJNT_FREE:
        raise SceneError(f"brick body '{names.brick_body}' must have a free joint")
    shape = ObjectGeometry.from_model(model, brick_body)
    mask = np.zeros(model.nbody, dtype=bool)
    mask[robot.robot_body_ids] = True
    roots = np.unique(model.body_rootid[robot.robot_body_ids])
    world_bodies = _world_contact_bodies(model, mask, brick_body)
    spec = composition.spec.copy()
    sensor_names = _add_robot_world_sensors(spec, model, roots, world_bodies)

    def compile_now(s: mujoco.MjSpec) -> mujoco.MjModel:
        try:
            return s.compile()  # the same model, with the robot-world contact sensors
        except ValueError as exc:
            detail = " ".join(str(exc).split())
            raise SceneError(
                f"scene file '{path}' with the robot does not compile: {detail}"
            ) from exc

    key = composition.derived_key("robot-world sensors", tuple(sensor_names), roots.tolist())
    model = compile_cached(spec, key, compile_now)
    world_sensor_adr = np.array(
        [model.sensor_adr[name_to_id(model, obj.mjOBJ_SENSOR, n)] for n in sensor_names],
        dtype=int,
    )
    pad_adr = np.concatenate(robot.pad_force_sensor_adr).astype(int)
    pad_side = np.concatenate(
        [np.full(len(adr), side, dtype=int) for side, adr in enumerate(robot.pad_force_sensor_adr)]
    )
    robot.write_home(model, robot.q_home, robot.home_width)  # the spec's keyframe is empty
    data = robot.make_data(model)
    return Scene(
        model=model,
        path=path,
        robot=robot,
        names=names,
        arm_model=composition.arm_model if arm_model is None else arm_model,
        gripper_qpos_adr=model.jnt_qposadr[robot.gripper_joint_ids].copy(),
        pad_force_sensor_adr=pad_adr,
        pad_sensor_side=pad_side,
        brick_body_id=brick_body,
        brick_geom_id=int(shape.geom_ids[0]),
        brick_qpos_adr=int(model.jnt_qposadr[brick_jnt]),
        brick_dof_adr=int(model.jnt_dofadr[brick_jnt]),
        brick_half_extents=shape.half_extents.copy(),
        brick_mass=float(model.body_mass[brick_body]),
        object=shape,
        source_bin=_bin_geometry(model, data, names.source_bin),
        target_bin=_bin_geometry(model, data, names.target_bin),
        robot_root_body_ids=roots,
        robot_body_mask=mask,
        world_contact_body_ids=np.array(world_bodies, dtype=int),
        robot_world_sensor_adr=world_sensor_adr,
        spec=composition.spec,
    )
