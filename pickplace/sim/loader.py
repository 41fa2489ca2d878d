"""Load a scene: a world file and a robot, composed, its home chosen, cached by file content.

:func:`load_scene` is the one way to get a :class:`~pickplace.world.scene.Scene`:

1. the world file (default ``scenes/world.xml``) is parsed, the robot (a bundled name, a
   ``robot.toml`` path or a description) composed into it and calibrated
   (:func:`pickplace.robot.compose.load_robot`), and the scene resolved
   (:func:`pickplace.world.scene.build_scene`);
2. a robot whose description gives no home has several IK home candidates; each is tried by
   the planner on the nominal pick-and-place (brick at bin 1's centre to bin 2's centre) with
   its kinematic pre-flight, and the home of the best plan is kept: feasible first, then the
   earlier grasp candidate, then the larger joint margin (``docs/physics-notes.md``:
   margin to the limits alone picked homes that ran the last joint into its limit);
3. the ``home`` keyframe holds that posture with the gripper open as plans open it
   (:func:`pickplace.planning.plan.for_gripper`).

The result is cached per process by the content of every file involved (the world file, the
description, the arm and gripper files with their includes and assets) and the arguments;
every call returns a scene with its own copy of the model, since faults change it (a mass, a
gain), while the arm-only model of the IK is shared. The home chosen in step 2 (a few tenths
of a second of planning) is also kept on disk (:mod:`pickplace.cache`), under the same key plus
the candidates and the source of the code that plans (:data:`HOME_CODE_PACKAGES`), so a second
process — every sweep worker — reads it instead of planning again.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
from pathlib import Path

import mujoco
import numpy as np

from pickplace.cache import read_json, source_digest, write_json
from pickplace.errors import SceneError, UnknownNameError
from pickplace.planning.home import choose_home
from pickplace.planning.plan import DEFAULT_PLAN_CONFIG, for_gripper
from pickplace.robot.compose import PAD_SENSOR_SLOTS, HeldObject, load_robot
from pickplace.robot.description import RobotDescription
from pickplace.robot.registry import (
    DEFAULT_ROBOT,
    description_digest,
    resolve_description,
)
from pickplace.world.scene import (
    Scene,
    WorldFile,
    WorldNames,
    build_scene,
    check_world,
    read_world,
)

_SCENES: dict[str, Scene] = {}

HOME_CODE_PACKAGES = ("control", "planning", "robot", "world")
"""Packages whose code decides which home candidate plans best: their source keys the home
kept on disk."""
_PACKAGE = Path(__file__).resolve().parent.parent


def clear_scene_cache() -> None:
    """Forget every cached scene (the next :func:`load_scene` composes again)."""
    _SCENES.clear()


def load_scene(
    world: str | Path | WorldFile | None = None,
    robot: str | Path | RobotDescription = DEFAULT_ROBOT,
    *,
    names: WorldNames | None = None,
    pad_slots: int = PAD_SENSOR_SLOTS,
    held: HeldObject | None = None,
) -> Scene:
    """The world with the robot composed into it, its home chosen (see the module docstring).

    Args:
        world: World MJCF file, or the file already read
            (:func:`~pickplace.world.scene.read_world`); default ``scenes/world.xml``.
        robot: A bundled robot's name (:func:`pickplace.robot.compose.bundled_robots`), a
            ``robot.toml`` path, or a description.
        names: World names to resolve; default :class:`~pickplace.world.scene.WorldNames`.
        pad_slots: Contacts each pad–brick sensor reports.
        held: The object that took the brick's place in ``world``
            (:func:`~pickplace.world.objects.with_object`; its content is part of the
            world file's), None for the world's own brick.

    Raises:
        SceneError: The world file is missing, not valid MJCF or structurally wrong.
        UnknownNameError: A world name is missing (the message lists those that exist).
        RobotError: The robot description or a file it names is missing or unusable (one line
            naming the file, the field and what would be valid).
    """
    file = world if isinstance(world, WorldFile) else read_world(world)
    desc = resolve_description(robot)
    names = names or WorldNames()
    key = hashlib.sha256(file.content)
    for part in (str(file.path), description_digest(desc), repr(names), str(pad_slots), repr(held)):
        key.update(part.encode())
    template = _SCENES.get(key.hexdigest())
    if template is None:
        world_key = key.hexdigest() if file.self_contained else None
        template = _compose(
            file.spec, file.path, desc, names, pad_slots, key.hexdigest(), held, world_key
        )
        _SCENES[key.hexdigest()] = template
    return dataclasses.replace(template, model=copy.deepcopy(template.model))


def _compose(
    spec: mujoco.MjSpec,
    path: Path,
    desc: RobotDescription,
    names: WorldNames,
    pad_slots: int,
    key: str,
    held: HeldObject | None,
    world_key: str | None,
) -> Scene:
    # The gripper is calibrated on the brick's size (an object in its place: on the world's).
    brick = spec.geom(names.brick_geom)
    if held is None and brick is None:
        raise UnknownNameError("geom", names.brick_geom, [g.name for g in spec.geoms if g.name])
    check_world(spec, path, names)  # the world's own problems, before the robot's
    if held is None and brick.type != mujoco.mjtGeom.mjGEOM_BOX:
        kind = mujoco.mjtGeom(int(brick.type)).name.removeprefix("mjGEOM_").lower()
        raise SceneError(
            f"scene file '{path}': brick geom '{names.brick_geom}' is a {kind}; valid: a box "
            "(the gripper is calibrated on its size; another object goes in with --object)"
        )
    composition = load_robot(
        desc,
        spec,
        brick_geom=names.brick_geom,
        pad_slots=pad_slots,
        bins=(names.source_bin, names.target_bin),
        held=held,
        world_key=world_key,
    )
    scene = build_scene(composition, path, names)
    robot = scene.robot
    q_home = robot.q_home
    if len(robot.home_candidates) > 1:
        q_home = _chosen_home(scene, key)
    width = for_gripper(DEFAULT_PLAN_CONFIG, robot.calibration).open_width
    robot = dataclasses.replace(robot, q_home=q_home.copy(), home_width=width)
    robot.write_home(scene.model, q_home, width)
    return dataclasses.replace(scene, robot=robot)


def _chosen_home(scene: Scene, scene_key: str) -> np.ndarray:
    """:func:`~pickplace.planning.home.choose_home` over the robot's candidates, read from the
    disk cache when it holds the choice for this scene, candidates and code (else chosen and
    kept). A cached posture is used only if it is one of the candidates, bit for bit."""
    candidates = scene.robot.home_candidates
    modules = [
        f"{package}/{f.name}"
        for package in HOME_CODE_PACKAGES
        for f in sorted((_PACKAGE / package).glob("*.py"))
    ]
    digest = hashlib.sha256(scene_key.encode())
    digest.update(source_digest(modules).encode())
    for q in candidates:
        digest.update(np.asarray(q, dtype=np.float64).tobytes())
    name = f"home-{digest.hexdigest()}.json"
    cached = read_json(name)
    if isinstance(cached, list):
        for q in candidates:
            if np.array_equal(np.asarray(q, dtype=np.float64), np.asarray(cached, dtype=float)):
                return q
    q_home = choose_home(scene, candidates)
    write_json(name, np.asarray(q_home, dtype=np.float64).tolist())
    return q_home
