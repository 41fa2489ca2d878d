"""Obstacles in the cell: a divider wall between the bins, a shelf over bin 2, random boxes.

A :class:`~pickplace.world.cell.ObstacleCell` is a world parameter set: what stands in the
cell besides the bins and the brick. :func:`with_obstacles` adds it to a loaded scene with
:class:`mujoco.MjSpec` (new static bodies appended to the world body, after everything else,
so every id of the robot, the bins and the brick stays what it was) and compiles it again;
each obstacle is a collision geom of the world, with the bins' contact bits, so the
pre-flight's collision check, the robot–world contact sensors (one per world body) and the
run's collision check all see it.

The geometry is stated here once, and derived from the scene (the bins' footprints, the arm's
base axis):

- **divider**: a wall :data:`DIVIDER_THICKNESS` thick standing on the floor, along the
  bisector of the bins' azimuths around the base (the vertical half-plane between them that
  every transfer crosses), from :data:`DIVIDER_INNER_RADIUS` from the base axis out to
  :data:`DIVIDER_OVERHANG` past the farthest bin corner; its height is the parameter;
- **shelf**: a plate :data:`SHELF_THICKNESS` thick over bin 2, its footprint bin 2's plus
  :data:`SHELF_MARGIN` a side, its underside at the parameter's height, on two posts at the
  corners away from the base;
- **boxes**: upright boxes standing on the floor, each (half sizes, height, yaw, position)
  drawn by :func:`draw_boxes`, kept :data:`BOX_BIN_MARGIN` off every bin's outer footprint and
  :data:`BOX_BASE_RADIUS` off the base axis.
"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np

from pickplace.errors import InvalidInputError, SceneError
from pickplace.robot.model import Composition
from pickplace.world.cell import MAX_BOXES, Box, ObstacleCell
from pickplace.world.scene import Scene, build_scene

# The divider's thickness [m] and where it starts and ends radially [m].
DIVIDER_THICKNESS = 0.02
DIVIDER_INNER_RADIUS = 0.25
DIVIDER_OVERHANG = 0.10
# The shelf's plate thickness [m], its overhang past bin 2's walls [m] and its posts' half size
# [m].
SHELF_THICKNESS = 0.02
SHELF_MARGIN = 0.03
SHELF_POST_HALF = 0.015
# Random boxes: half sizes of the footprint [m], heights [m], the annulus around the base
# their centres are drawn in [m], what they keep off the bins and the base [m].
BOX_HALF_SIZE = (0.03, 0.07)
BOX_HEIGHT = (0.10, 0.35)
BOX_RADIUS = (0.30, 0.90)
BOX_BIN_MARGIN = 0.03
BOX_BASE_RADIUS = 0.30
# What boxes keep off the tool's point at home, horizontally [m]: the hands' half-lengths
# (73 mm for the WSG's palm, 90 mm for the Panda hand) and the clearance, rounded up.
BOX_HOME_MARGIN = 0.12
# Draws per box before giving up finding a free spot.
_BOX_DRAWS = 200
OBSTACLE_RGBA = (0.35, 0.45, 0.75, 1.0)
# Name prefix of every obstacle body and geom this module adds.
PREFIX = "cell_"


# ------------------------------------------------------------------------------ geometry


def _bin_footprint(model: mujoco.MjModel, body: int) -> tuple[np.ndarray, np.ndarray]:
    """A bin's outer footprint: its frame's rotation (2, 2) and translation (2,) in world,
    and its half sizes (2,) [m] in its frame (the union of its geoms' boxes)."""
    geoms = np.flatnonzero(model.geom_bodyid == body)
    half = np.max(np.abs(model.geom_pos[geoms, :2]) + model.geom_size[geoms, :2], axis=0)
    return half, geoms


def _bins(scene: Scene) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per bin (source, target): its frame's rotation (2, 2), origin (2,) and outer half
    sizes (2,) in world [m]."""
    out = []
    model = scene.model
    for bin_ in (scene.source_bin, scene.target_bin):
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, bin_.name)
        half, _ = _bin_footprint(model, body)
        R = bin_.X_WB.rotation().as_matrix()[:2, :2]
        out.append((R, bin_.X_WB.translation()[:2].copy(), half))
    return out


def _inside(points: np.ndarray, R: np.ndarray, origin: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Per point (N, 2): True if it lies in the rectangle (frame R, origin; half sizes)."""
    local = (points - origin) @ R
    return np.all(np.abs(local) <= half, axis=1)


def _overlaps(corners: np.ndarray, R: np.ndarray, origin: np.ndarray, half: np.ndarray) -> bool:
    """True if the convex quadrilateral ``corners`` (4, 2) and the rectangle overlap
    (separating-axis test on both shapes' edge normals)."""
    rect = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) * half @ R.T + origin
    for poly in (corners, rect):
        for i in range(4):
            edge = poly[(i + 1) % 4] - poly[i]
            n = np.array([-edge[1], edge[0]])
            a, b = corners @ n, rect @ n
            if a.max() < b.min() or b.max() < a.min():
                return False
    return True


def divider_axis(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """The divider's line on the floor: the base axis' point (2,) and the unit direction (2,)
    of the bisector of the bins' azimuths around it."""
    base = np.asarray(scene.robot.p_W_base, dtype=np.float64)[:2]
    dirs = []
    for bin_ in (scene.source_bin, scene.target_bin):
        d = bin_.X_WB.translation()[:2] - base
        dirs.append(d / np.linalg.norm(d))
    mean = dirs[0] + dirs[1]
    norm = float(np.linalg.norm(mean))
    if norm < 1e-6:
        raise SceneError("the bins lie on opposite sides of the base: no divider between them")
    return base, mean / norm


def divider_box(scene: Scene) -> tuple[np.ndarray, float, np.ndarray]:
    """The divider's centre (2,) [m], yaw [rad] and half sizes along and across it (2,) [m].

    Raises:
        SceneError: It would cut into a bin.
    """
    base, u = divider_axis(scene)
    bins = _bins(scene)
    reach = 0.0
    for R, origin, half in bins:
        corners = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) * half @ R.T + origin
        reach = max(reach, float(np.max((corners - base) @ u)))
    r0, r1 = DIVIDER_INNER_RADIUS, reach + DIVIDER_OVERHANG
    centre = base + 0.5 * (r0 + r1) * u
    yaw = math.atan2(u[1], u[0])
    half = np.array([0.5 * (r1 - r0), 0.5 * DIVIDER_THICKNESS])
    c, s = math.cos(yaw), math.sin(yaw)
    corners = (
        np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) * half @ np.array([[c, s], [-s, c]]) + centre
    )
    for (R, origin, bhalf), name in zip(bins, ("bin 1", "bin 2"), strict=True):
        if _overlaps(corners, R, origin, bhalf):
            raise SceneError(f"the divider between the bins would cut into {name}")
    return centre, yaw, half


def draw_boxes(scene: Scene, rng: np.random.Generator, count: int) -> tuple[Box, ...]:
    """``count`` boxes drawn from ``rng``: half sizes uniform in :data:`BOX_HALF_SIZE`, height
    in :data:`BOX_HEIGHT`, yaw in [-π, π), centre uniform over the annulus
    :data:`BOX_RADIUS` around the base axis, drawn again until the footprint keeps
    :data:`BOX_BIN_MARGIN` off every bin, :data:`BOX_BASE_RADIUS` off the base axis and
    :data:`BOX_HOME_MARGIN` off the tool at the robot's home (where every plan starts).

    Raises:
        InvalidInputError: ``count`` is not an integer in [0, :data:`MAX_BOXES`].
        SceneError: No free spot after :data:`_BOX_DRAWS` draws.
    """
    if isinstance(count, bool) or not isinstance(count, int | np.integer):
        raise InvalidInputError(f"box count must be an integer, got {count!r}")
    if not 0 <= count <= MAX_BOXES:
        raise InvalidInputError(f"box count must lie in [0, {MAX_BOXES}], got {count}")
    base = np.asarray(scene.robot.p_W_base, dtype=np.float64)[:2]
    bins = [(R, o, h + BOX_BIN_MARGIN) for R, o, h in _bins(scene)]
    home = _home_tool_xy(scene)
    r_lo, r_hi = BOX_RADIUS
    boxes: list[Box] = []
    for _ in range(int(count)):
        for _draw in range(_BOX_DRAWS):
            hx, hy = (float(v) for v in rng.uniform(*BOX_HALF_SIZE, size=2))
            height = float(rng.uniform(*BOX_HEIGHT))
            yaw = float(rng.uniform(-math.pi, math.pi))
            r = math.sqrt(float(rng.uniform(r_lo**2, r_hi**2)))  # uniform over the annulus
            azimuth = float(rng.uniform(-math.pi, math.pi))
            box = Box(
                float(base[0] + r * math.cos(azimuth)),
                float(base[1] + r * math.sin(azimuth)),
                yaw,
                hx,
                hy,
                height,
            )
            corners = box.corners_xy()
            if r - math.hypot(hx, hy) < BOX_BASE_RADIUS:
                continue
            if any(_overlaps(corners, R, o, h) for R, o, h in bins):
                continue
            c, s_ = math.cos(box.yaw), math.sin(box.yaw)
            local = np.array([[c, s_], [-s_, c]]) @ (home - [box.x, box.y])
            outside = np.maximum(np.abs(local) - [box.half_x, box.half_y], 0.0)
            if float(np.linalg.norm(outside)) < BOX_HOME_MARGIN:
                continue
            boxes.append(box)
            break
        else:
            raise SceneError(f"no free spot for obstacle box {len(boxes) + 1} in the cell")
    return tuple(boxes)


def _home_tool_xy(scene: Scene) -> np.ndarray:
    """The tool's point at the robot's home, horizontally (2,) [m]."""
    model, robot = scene.model, scene.robot
    data = mujoco.MjData(model)
    data.qpos[robot.arm_qpos_adr] = robot.q_home
    mujoco.mj_kinematics(model, data)
    return np.array(data.site_xpos[robot.tool_site_id][:2], dtype=np.float64)


# ------------------------------------------------------------------------------- the spec


def _add_box(
    spec: mujoco.MjSpec,
    name: str,
    centre: tuple[float, float, float],
    yaw: float,
    half: tuple[float, float, float],
    bits: tuple[int, int],
) -> None:
    """A static body with one box geom (the bins' contact bits), appended to the world body."""
    body = spec.worldbody.add_body(
        name=name, pos=list(centre), quat=[math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
    )
    body.add_geom(
        name=name,
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=list(half),
        rgba=list(OBSTACLE_RGBA),
        contype=bits[0],
        conaffinity=bits[1],
    )


def add_to_spec(spec: mujoco.MjSpec, scene: Scene, cell: ObstacleCell) -> list[str]:
    """Append the cell's obstacles to ``spec``'s world body (see the module docstring).

    Returns:
        The names of the bodies added (each has one geom of the same name).
    """
    floor = spec.geom(f"{scene.source_bin.name}_floor")
    bits = (int(floor.contype), int(floor.conaffinity))  # the bins' contact bits
    names: list[str] = []
    if cell.divider_height > 0.0:
        centre, yaw, half = divider_box(scene)
        h = 0.5 * cell.divider_height
        _add_box(spec, f"{PREFIX}divider", (*centre.tolist(), h), yaw, (*half.tolist(), h), bits)
        names.append(f"{PREFIX}divider")
    if cell.shelf_height > 0.0:
        bin_ = scene.target_bin
        body = mujoco.mj_name2id(scene.model, mujoco.mjtObj.mjOBJ_BODY, bin_.name)
        bhalf, _ = _bin_footprint(scene.model, body)
        R = bin_.X_WB.rotation().as_matrix()
        yaw = math.atan2(R[1, 0], R[0, 0])
        origin = bin_.X_WB.translation()
        hx, hy = float(bhalf[0]) + SHELF_MARGIN, float(bhalf[1]) + SHELF_MARGIN
        t = 0.5 * SHELF_THICKNESS
        plate = (float(origin[0]), float(origin[1]), cell.shelf_height + t)
        _add_box(spec, f"{PREFIX}shelf", plate, yaw, (hx, hy, t), bits)
        names.append(f"{PREFIX}shelf")
        # Posts at the two plate corners farthest from the base.
        base = np.asarray(scene.robot.p_W_base, dtype=np.float64)[:2]
        away = origin[:2] - base
        corners = []
        for sx, sy in ((1, 1), (1, -1), (-1, -1), (-1, 1)):
            local = np.array([sx * (hx - SHELF_POST_HALF), sy * (hy - SHELF_POST_HALF)])
            corners.append(R[:2, :2] @ local + origin[:2])
        corners.sort(key=lambda p: -float((p - origin[:2]) @ away))
        for i, p in enumerate(corners[:2]):
            post = f"{PREFIX}shelf_post{i + 1}"
            _add_box(
                spec,
                post,
                (float(p[0]), float(p[1]), 0.5 * cell.shelf_height),
                yaw,
                (SHELF_POST_HALF, SHELF_POST_HALF, 0.5 * cell.shelf_height),
                bits,
            )
            names.append(post)
    for i, box in enumerate(cell.boxes):
        name = f"{PREFIX}box{i + 1}"
        h = 0.5 * box.height
        _add_box(spec, name, (box.x, box.y, h), box.yaw, (box.half_x, box.half_y, h), bits)
        names.append(name)
    return names


def with_obstacles(scene: Scene, cell: ObstacleCell) -> Scene:
    """``scene`` with the cell's obstacles added to its world (see the module docstring): a
    new scene over a new model, the robot (its home included) and every id unchanged; the
    scene itself when the cell is empty.

    Raises:
        SceneError: The obstacles would cut into a bin, or moved an id of the scene, or the
            spec does not compile.
    """
    if cell.empty:
        return scene
    if scene.spec is None:
        raise SceneError("the scene keeps no spec to add obstacles to; load it with load_scene")
    spec = scene.spec.copy()
    add_to_spec(spec, scene, cell)
    arm_spec = spec.copy()  # (unused: the scene's arm model is kept)
    try:
        model = spec.compile()
    except ValueError as exc:
        raise SceneError(f"the cell with its obstacles does not compile: {exc}") from exc
    old = scene.model
    for kind, count in (
        (mujoco.mjtObj.mjOBJ_BODY, "nbody"),
        (mujoco.mjtObj.mjOBJ_GEOM, "ngeom"),
    ):
        n = int(getattr(old, count))
        same = all(
            mujoco.mj_id2name(model, kind, i) == mujoco.mj_id2name(old, kind, i) for i in range(n)
        )
        if not same:
            raise SceneError("the obstacles moved an id of the scene; valid: appended bodies")
    robot = scene.robot
    new = build_scene(
        Composition(spec, model, robot, arm_spec), scene.path, scene.names, scene.arm_model
    )
    robot.write_home(new.model, robot.q_home, robot.home_width)
    return dataclasses.replace(new, obstacles=cell)


__all__ = [
    "add_to_spec",
    "divider_axis",
    "divider_box",
    "draw_boxes",
    "with_obstacles",
]
