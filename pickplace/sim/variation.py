"""A trial's drawn parameters (:mod:`pickplace.sim.vary`) applied to its scene and task.

The runner calls :func:`apply_to_scene` right after loading the scene, before anything is
planned, so the planner, its pre-flight, the checks and the verdict all see the varied world
(the planner's slip budget knows the brick's mass, its friction and the grip force); and
:func:`apply_to_task` after planning, for what the plan must not know (the pose noise).
``speed``, ``control_rate`` and ``attempts`` are the run request's own fields
(``RunRequest.speed``, ``RunRequest.control_rate_hz``, ``RunRequest.attempts``); the runner
takes them from the draw.

=================  ==========================================================================
parameter          what changes
=================  ==========================================================================
``brick_mass``     the brick body's mass; its inertia scales with it (same shape)
``brick_size``     the brick geom's three half sizes × s (its bounding sphere and box too),
                   the body's inertia × s² (mass unchanged); :attr:`Scene.brick_half_extents`
                   follows, so the start pose on the floor, the grasp width, the
                   missed-grasp gap and the placement verdict use the varied brick
``friction``       the sliding friction μ of the gripper's pads (they have contact priority,
                   so theirs is the pad–brick friction; the brick's own friction on the bin
                   floors is unchanged)
``grip_force``     the squeeze per jaw F: every gripper actuator's force range × F / F₀, F₀
                   the robot's squeeze (:attr:`Scene.squeeze_force`, which becomes F: the
                   missed-grasp threshold is a fraction of it); when F > F₀ the position gains
                   scale by F / F₀ too (the damping by √(F / F₀): the same damping ratio), so
                   a closed grip squeezes with F as the robot's squeezes with F₀
``pose_noise``     a :class:`~pickplace.sim.faults.BrickShifted` fault: after planning the brick
                   lies the drawn planar offset away, kept (each coordinate in bin 1's frame)
                   so that its footprint stays inside bin 1's inner walls
``divider_height`` the obstacle cell's divider wall between the bins
                   (:mod:`pickplace.world.obstacles`), added with ``MjSpec`` before planning
``shelf_height``   the cell's shelf over bin 2, likewise
``obstacle_boxes`` the cell's random boxes: this many, drawn by
                   :func:`~pickplace.world.obstacles.draw_boxes` from the parameter's own
                   stream (:func:`~pickplace.sim.vary.parameter_stream`)
=================  ==========================================================================

A scenario may bring an obstacle cell of its own (``pick-place-obstacles``); a varied obstacle
parameter takes the place of the cell's (:func:`apply_world`).

Model edits are followed by ``mj_setConst`` (derived constants such as subtree masses), on a
copy of the model: the scene given is left as it was.
"""

from __future__ import annotations

import copy
import dataclasses
import math

import mujoco
import numpy as np
from mink.lie import SE3

from pickplace.sim.faults import BrickShifted
from pickplace.sim.task import Task
from pickplace.sim.vary import ParameterDraw, parameter_stream
from pickplace.world.cell import ObstacleCell
from pickplace.world.objects import ObjectGeometry
from pickplace.world.obstacles import draw_boxes, with_obstacles
from pickplace.world.scene import Scene

# Parameters that change the scene (the others: the task, or the run request's own fields).
SCENE_PARAMETERS = ("brick_mass", "brick_size", "friction", "grip_force")
# Parameters that add obstacles to the world.
WORLD_PARAMETERS = ("divider_height", "shelf_height", "obstacle_boxes")


def obstacle_cell(
    scene: Scene, draw: ParameterDraw | None, cell: ObstacleCell | None = None
) -> ObstacleCell | None:
    """The obstacle cell of a run: the scenario's ``cell`` (or none) with every obstacle
    parameter the draw varies in its place; None when there is neither."""
    values = {} if draw is None else {k: v for k, v in draw.values.items() if k in WORLD_PARAMETERS}
    if not values:
        return cell
    cell = cell or ObstacleCell()
    if "divider_height" in values:
        cell = dataclasses.replace(cell, divider_height=values["divider_height"])
    if "shelf_height" in values:
        cell = dataclasses.replace(cell, shelf_height=values["shelf_height"])
    if "obstacle_boxes" in values and draw is not None:
        rng = parameter_stream(draw.seed, "obstacle_boxes")
        cell = dataclasses.replace(
            cell, boxes=draw_boxes(scene, rng, int(values["obstacle_boxes"]))
        )
    return cell


def apply_world(
    scene: Scene, draw: ParameterDraw | None, cell: ObstacleCell | None = None
) -> Scene:
    """The run's world before planning: the obstacles (:func:`obstacle_cell`) added with
    ``MjSpec``, then the scene parameters applied (:func:`apply_to_scene`) to the new model."""
    obstacles = obstacle_cell(scene, draw, cell)
    if obstacles is not None:
        scene = with_obstacles(scene, obstacles)
    return scene if draw is None else apply_to_scene(scene, draw)


def _box_object(shape: ObjectGeometry, half: np.ndarray) -> ObjectGeometry:
    """The brick's geometry with its box's half sizes ``half`` [m]."""
    if np.array_equal(half, shape.half_extents):
        return shape
    return ObjectGeometry((dataclasses.replace(shape.geoms[0], size=half.copy()),), shape.geom_ids)


def apply_to_scene(scene: Scene, draw: ParameterDraw) -> Scene:
    """The scene with ``draw``'s scene parameters applied (see the module docstring).

    Returns ``scene`` itself when the draw varies none of them; otherwise a new
    :class:`~pickplace.world.scene.Scene` over a changed copy of the model.
    """
    if not any(name in draw.values for name in SCENE_PARAMETERS):
        return scene
    model = copy.deepcopy(scene.model)
    body, geom = scene.brick_body_id, scene.brick_geom_id
    half = scene.brick_half_extents.copy()
    mass = float(model.body_mass[body])
    squeeze = scene.robot.squeeze_force

    shape = scene.object
    size = draw.get("brick_size")
    if size is not None and shape.box_half_extents is not None:
        half = half * size
        model.geom_size[geom] = half
        model.geom_rbound[geom] = float(np.linalg.norm(half))
        model.geom_aabb[geom, 3:] = half
        model.body_inertia[body] *= size * size
    elif size is not None:  # every geom of another object, about its origin
        meshes = set()
        for g in shape.geom_ids.tolist():
            model.geom_size[g] *= size
            model.geom_pos[g] *= size
            model.geom_rbound[g] *= size
            model.geom_aabb[g] *= size
            if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
                meshes.add(int(model.geom_dataid[g]))
        for m in meshes:
            adr, n = int(model.mesh_vertadr[m]), int(model.mesh_vertnum[m])
            model.mesh_vert[adr : adr + n] *= size
        model.body_ipos[body] *= size
        model.body_inertia[body] *= size * size
        shape = ObjectGeometry.from_model(model, body)
        half = shape.half_extents.copy()
    new_mass = draw.get("brick_mass")
    if new_mass is not None:
        model.body_inertia[body] *= new_mass / mass
        model.body_mass[body] = new_mass
        mass = new_mass
    mu = draw.get("friction")
    if mu is not None:
        for pad in np.concatenate(scene.robot.pad_geom_ids).tolist():
            model.geom_friction[pad, 0] = mu
    force = draw.get("grip_force")
    if force is not None:
        ratio = force / squeeze
        gain = max(1.0, ratio)
        for a in scene.robot.gripper_actuator_ids.tolist():
            model.actuator_forcerange[a] *= ratio
            model.actuator_gainprm[a, 0] *= gain
            model.actuator_biasprm[a, 1] *= gain
            model.actuator_biasprm[a, 2] *= math.sqrt(gain)
        squeeze = force
    # Derived constants (subtree masses, inverse weights, ...) from the new masses and sizes.
    mujoco.mj_setConst(model, mujoco.MjData(model))
    return dataclasses.replace(
        scene,
        model=model,
        brick_half_extents=half,
        brick_mass=float(mass),
        object=shape if shape.box_half_extents is None else _box_object(shape, half),
        robot=dataclasses.replace(scene.robot, squeeze_force=float(squeeze)),
    )


def brick_offset_W(scene: Scene, X_WO_start: SE3, offset_W: np.ndarray) -> np.ndarray:
    """The planar offset [m] that moves the brick from ``X_WO_start`` by ``offset_W`` as far as
    its footprint stays inside the source bin's inner walls (each coordinate of the moved
    centre clamped in the bin's frame); ``offset_W`` itself (z = 0) when it stays inside.

    Plain float arithmetic, so the result is the same bit for bit in every process.
    """
    bin_ = scene.source_bin
    R = bin_.X_WB.rotation().as_matrix()
    yaw = math.atan2(float(R[1, 0]), float(R[0, 0]))  # bins stand upright
    cb, sb = math.cos(yaw), math.sin(yaw)
    tx, ty = (float(v) for v in bin_.X_WB.translation()[:2])
    p = X_WO_start.translation()
    px, py = float(p[0]), float(p[1])
    Ro = X_WO_start.rotation().as_matrix()
    yaw_O = math.atan2(float(Ro[1, 0]), float(Ro[0, 0])) - yaw
    hx, hy = (float(v) for v in scene.brick_half_extents[:2])
    # Half size of the brick's footprint along the bin's axes.
    reach_x = abs(math.cos(yaw_O)) * hx + abs(math.sin(yaw_O)) * hy
    reach_y = abs(math.sin(yaw_O)) * hx + abs(math.cos(yaw_O)) * hy
    if scene.object.box_half_extents is None:  # another object: its own footprint
        reach_x, reach_y = (float(v) for v in scene.object.footprint_half(yaw_O))
    room_x = max(float(bin_.inner_half_extents[0]) - reach_x, 0.0)
    room_y = max(float(bin_.inner_half_extents[1]) - reach_y, 0.0)
    dx, dy = float(offset_W[0]), float(offset_W[1])
    qx, qy = px + dx - tx, py + dy - ty
    bx, by = cb * qx + sb * qy, -sb * qx + cb * qy  # the moved centre in the bin frame
    if abs(bx) <= room_x and abs(by) <= room_y:
        return np.array([dx, dy, 0.0])
    bx, by = min(max(bx, -room_x), room_x), min(max(by, -room_y), room_y)
    mx, my = tx + cb * bx - sb * by, ty + sb * bx + cb * by
    return np.array([mx - px, my - py, 0.0])


def apply_to_task(scene: Scene, task: Task, draw: ParameterDraw) -> Task:
    """The task with ``draw`` applied and recorded (:attr:`Task.parameters`, the summary's
    ``parameters``: the draw's JSON form, see :meth:`ParameterDraw.as_dict`).

    ``pose_noise`` adds a :class:`~pickplace.sim.faults.BrickShifted` fault, its offset kept inside
    bin 1 (:func:`brick_offset_W`; the offset applied is recorded as
    ``pose_offset_applied_xy_m``).
    """
    record = draw.as_dict()
    faults = tuple(task.faults)
    offset = draw.pose_offset_W
    if offset is not None:
        applied = brick_offset_W(scene, task.X_WO_start, offset)
        faults = (*faults, BrickShifted(scene, applied))
        record["pose_offset_applied_xy_m"] = [float(applied[0]), float(applied[1])]
    return dataclasses.replace(task, faults=faults, parameters=record)


__all__ = [
    "SCENE_PARAMETERS",
    "WORLD_PARAMETERS",
    "apply_to_scene",
    "apply_to_task",
    "apply_world",
    "brick_offset_W",
    "obstacle_cell",
]
