"""Grasp candidates from the object's geometry, and the cheap tests that rank them.

Frames: O the object (a box, origin at its centre, lying flat: O's z up), G the tool site
(origin midway between the pads, +z the approach out of the gripper, fingers closing along
G's y), W the world, B a bin's frame.

Candidates of the brick (:func:`box_grasps`; any other object: :func:`object_grasps`, the
same from its support patches at 12 closing directions): the pads on two opposite faces of
the box (antipodal: the faces' normals are the closing axis), for each pair of side faces
whose width plus a clearance on each side the gripper opens to
(:func:`~pickplace.robot.calibration.pad_clearance`: 6 mm where it opens that wide, down to 2 mm
where it does not), and, where that is more than 2 mm, its tight twin opened only 2 mm a side
(:attr:`GraspCandidate.tight`: the fingers open up to 8 mm less, for an object beside a wall):

* the approach from straight down (``R_OG = Ry(π)`` across the width) tilted about the
  closing axis by each angle of :data:`GRASP_TILTS`, either way: a rotation about the face
  normal keeps the pads flat on the faces, and leans the palm away from one side;
* the pads' centre offset along the face by each fraction of :data:`GRASP_OFFSET_FRACTIONS`
  of the travel that keeps the pad on the face (half its length minus the pad's half size);
* both wrist turns: ``X_OG`` and ``X_OG · Rz(π)``, the same pad placements with the fingers
  swapped (the wrist turned half a turn about the approach axis).

The cheap tests (:class:`HandFootprint`, :func:`gravity_torque`) need no IK: the open hand's
collision geoms' convex hulls (:func:`hull_of`) placed at the grasp against the bin's walls and
floor, and the object's weight about the pad axis. The wrist's margin needs the arm, and is
the planner's (:mod:`pickplace.planning.planner`). :class:`HandObjectGaps` does not depend on
where the object lies: the planner drops, once, the candidates whose hand touches the object
with more than its pads.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import mujoco
import numpy as np
import numpy.typing as npt
from mink.lie import SE3, SO3

from pickplace.robot.calibration import MIN_PAD_CLEARANCE, pad_clearance
from pickplace.world.objects import ObjectGeometry
from pickplace.world.scene import BinGeometry

GRASP_TILTS = tuple(math.radians(a) for a in (0.0, 15.0, 30.0, 45.0, 60.0))
"""Tilts of the approach from vertical about the closing axis [rad], each tried either way;
vertical first (the ranking prefers the smaller tilt). A tilt leans the palm away from a wall
the object lies along; 45° and 60° are what a hand whose palm is wide along the closing axis
has left in a corner, where the closing axis along one wall points the palm's end into the
other."""

GRASP_OFFSET_FRACTIONS = (0.0, 0.5, -0.5)
"""Offsets of the pads' centre along the face, as fractions of the largest offset that keeps
the pad on the face [-]; centred first. Not the face's end: gripped there (tried with ±1), the
Panda hands dropped the brick on 10 of 600 pick-place-random runs, the weight's torque about
the pads turning it out of them."""

GRAVITY = 9.81
"""Standard gravity [m/s²]."""

# The 12 edges of a box, as pairs of indices into its 8 corners (corner k has coordinate
# signs given by the bits of k: bit 0 x, bit 1 y, bit 2 z).
_BOX_EDGES = np.array(
    [(a, a | bit) for a in range(8) for bit in (1, 2, 4) if not a & bit], dtype=np.intp
)
_CORNER_SIGNS = np.array(
    [[1.0 if k & (1 << i) else -1.0 for i in range(3)] for k in range(8)], dtype=np.float64
)


@dataclass(frozen=True)
class GraspCandidate:
    """One way to grasp the object.

    Attributes:
        label: In words, e.g. ``"across the width, tilted 15°, turned 180°"``.
        X_OG: The tool site in the object frame.
        width: The object's width between the pads [m].
        open_width: Finger gap commanded when open around it: ``width`` plus twice
            :func:`~pickplace.robot.calibration.pad_clearance` [m].
        tilt: Tilt of the approach from vertical about the closing axis [rad].
        offset: Offset of the pads' centre along the face from the face's centre [m].
        turned: The wrist turned half a turn (fingers swapped).
        tight: A tight twin: the same pads as the candidate labelled without
            :data:`TIGHT_LABEL`, opened only :data:`~pickplace.robot.calibration.
            MIN_PAD_CLEARANCE` a side (the planner ranks it only where that one fails the
            footprint).
        other_place: Place the object at its goal turned by its half-turn symmetry about the
            vertical the other way from the one whose tool yaw is nearer the pick's (the
            tool leaning the other way at the place): the planner's second try of a
            candidate whose pre-flight failed after the lift (label ``"…, placed the other
            way round"``).
    """

    label: str
    X_OG: SE3
    width: float
    open_width: float
    tilt: float
    offset: float
    turned: bool
    other_place: bool = False
    tight: bool = False


def box_grasps(
    half_extents: npt.ArrayLike,
    max_open_width: float,
    pad_half_length: float,
    tilts: tuple[float, ...] = GRASP_TILTS,
    offset_fractions: tuple[float, ...] = GRASP_OFFSET_FRACTIONS,
    height_fractions: tuple[float, ...] = (0.0,),
    pad_half_height: float = 0.0,
) -> Iterator[GraspCandidate]:
    """Antipodal grasps of a box lying flat, pads on a pair of its side faces (module docstring).

    Across the width (O's y, ``R_OG = Ry(π)``: G's x = -O's x, G's y = O's y, G's z = -O's z)
    first, then across the length (O's x, ``R_OG = Rz(π/2) Ry(π)``); each with every tilt
    ``θ`` (``R_OG · Ry(±θ)``, G's y the closing axis), every offset ``s`` along the face
    (``p_OG = s · x_G``, G's x horizontal in O), both wrist turns, and each raised up the side
    by ``height_fractions`` of the travel that keeps the pad on it (``p_OG + u · z_O``).

    Args:
        half_extents: The box's half sizes along O's x, y, z [m].
        max_open_width: Widest gap the gripper opens to [m].
        pad_half_length: Half size of a pad along G's x [m] (along the face).
        tilts: Tilts from vertical [rad], each tried either way (0 once).
        offset_fractions: Offsets as fractions of the largest that keeps the pad on the face.
        height_fractions: Raises up the side, as fractions of the largest that keeps the pad
            on the face (the brick lying: centred only; a box standing taller,
            :data:`GRASP_HEIGHT_FRACTIONS`).
        pad_half_height: Half size of a pad along G's z [m] (up the face).

    Yields:
        The candidates, for each face pair whose width the gripper opens to with
        :func:`~pickplace.robot.calibration.pad_clearance` a side.
    """
    h = np.asarray(half_extents, dtype=np.float64)
    rise = max(0.0, float(h[2]) - pad_half_height)
    bases = (
        ("across the width", 1, SO3.from_y_radians(math.pi)),
        ("across the length", 0, SO3.from_z_radians(0.5 * math.pi) @ SO3.from_y_radians(math.pi)),
    )
    for name, axis, R_base in bases:
        width = 2.0 * float(h[axis])
        openings = _openings(width, max_open_width)
        if not openings:
            continue
        x_O = R_base.as_matrix()[:, 0]  # G's x in O: along the face, horizontal
        travel = max(0.0, float(np.abs(x_O) @ h) - pad_half_length)
        signed_tilts = [0.0] + [s * t for t in tilts if t > 0.0 for s in (1.0, -1.0)]
        for tilt in signed_tilts:
            R_OG = R_base @ SO3.from_y_radians(tilt)
            for fraction in offset_fractions:
                offset = fraction * travel
                if fraction and offset == 0.0:
                    continue
                X_OG = SE3.from_rotation_and_translation(R_OG, offset * x_O)
                for turned in (False, True):
                    X = X_OG @ SE3.from_rotation(SO3.from_z_radians(math.pi)) if turned else X_OG
                    label = _label(name, tilt, offset, turned)
                    for height in height_fractions:
                        up = height * rise
                        if height and up == 0.0:
                            continue
                        for open_width, tight in openings:
                            yield GraspCandidate(
                                label
                                + (f", {up * 1000:.0f} mm up" if up else "")
                                + (TIGHT_LABEL if tight else ""),
                                SE3.from_translation(np.array([0.0, 0.0, up])) @ X if up else X,
                                width,
                                open_width,
                                tilt,
                                offset,
                                turned,
                                tight=tight,
                            )


GRASP_YAWS = 12
"""Closing directions tried around an object that is not the brick: this many, evenly over
half a turn about O's z (the wrist turns give the other half)."""

GRASP_HEIGHT_FRACTIONS = (0.0, 0.5, 1.0)
"""Offsets of the pads' centre up the object's side, as fractions of the largest that keeps
the pad on the contact patch [-]: centred first, then higher (the fingertips farther from
the floor), up to the pad's top level with the patch's top (the hand above the pads then
farthest down past the object's top: a tall object clears a linkage's knuckles or a palm
only there, :class:`HandObjectGaps`)."""


def object_grasps(
    shape: ObjectGeometry,
    max_open_width: float,
    pad_half_size: tuple[float, float],
    friction: float,
    tilts: tuple[float, ...] = GRASP_TILTS,
    offset_fractions: tuple[float, ...] = GRASP_OFFSET_FRACTIONS,
) -> Iterator[GraspCandidate]:
    """Antipodal grasps of the object from its geometry (the brick: :func:`box_grasps`).

    For each closing direction ``d`` (G's y) horizontal in O at :data:`GRASP_YAWS` yaws, the
    pads touch the object where its support along ``±d`` is reached (:meth:`~pickplace.
    world.objects.ObjectGeometry.patch`: a face, a cylinder's side line, a sphere's point).
    The grasp is antipodal when a line along ``d`` meets both patches (the squeeze needs no
    friction), or else when the lateral gap between them over the width is at most half the
    pads' friction coefficient (a friction cone with a safety factor of 2); the tool sits
    midway between the patches, over their common part. Then, as for the box: every tilt
    about ``d`` either way, offsets along the patch horizontally (fractions of the travel that
    keeps the pad on it) and up it (:data:`GRASP_HEIGHT_FRACTIONS`), both wrist turns. The
    opening is the width plus :func:`~pickplace.robot.calibration.pad_clearance` a side, and a
    direction the gripper does not open to with the least of it is skipped.

    Args:
        shape: The object's geometry.
        max_open_width: Widest gap the gripper opens to [m].
        pad_half_size: Half sizes of a pad along G's x and G's z [m].
        friction: The pads' friction coefficient [-].
        tilts: Tilts from vertical [rad], each tried either way (0 once).
        offset_fractions: Horizontal offsets as fractions of the largest on the patch.
    """
    box = shape.box_half_extents
    if box is not None:
        yield from box_grasps(box, max_open_width, pad_half_size[0], tilts, offset_fractions)
        return
    z_O = np.array([0.0, 0.0, 1.0])
    signed_tilts = [0.0] + [s * t for t in tilts if t > 0.0 for s in (1.0, -1.0)]
    for k in range(GRASP_YAWS):
        yaw = math.pi * k / GRASP_YAWS
        R_base = SO3.from_z_radians(yaw) @ SO3.from_y_radians(math.pi)
        M = R_base.as_matrix()
        x_O, d = M[:, 0], M[:, 1]  # G's x (horizontal, along the pads) and the closing axis
        plus, minus = shape.support(d), shape.support(-d)
        width = plus + minus
        openings = _openings(width, max_open_width)
        if not openings:
            continue
        spans = []
        gap = 0.0
        (c1, h1), (c2, h2) = shape.patch(d), shape.patch(-d)
        for axis in (x_O, z_O):
            lo1, hi1 = c1 @ axis - np.abs(axis) @ h1, c1 @ axis + np.abs(axis) @ h1
            lo2, hi2 = c2 @ axis - np.abs(axis) @ h2, c2 @ axis + np.abs(axis) @ h2
            lo, hi = max(lo1, lo2), min(hi1, hi2)
            if lo <= hi + 1e-9:
                spans.append((0.5 * (lo + hi), max(0.0, 0.5 * (hi - lo))))
            else:
                gap = math.hypot(gap, lo - hi)
                spans.append((0.25 * (lo1 + hi1 + lo2 + hi2), 0.0))
        if gap > 0.5 * friction * width:
            continue  # not antipodal: the squeeze would need more friction than half the pads'
        (m_x, half_x), (m_z, half_z) = spans
        centre = 0.5 * (plus - minus) * d + m_x * x_O + m_z * z_O
        travel_x = max(0.0, half_x - pad_half_size[0])
        travel_z = max(0.0, half_z - pad_half_size[1])
        name = f"across at {math.degrees(yaw):.0f}°"
        for tilt in signed_tilts:
            R_OG = R_base @ SO3.from_y_radians(tilt)
            for fx in offset_fractions:
                for fz in GRASP_HEIGHT_FRACTIONS:
                    sx, sz = fx * travel_x, fz * travel_z
                    if (fx and sx == 0.0) or (fz and sz == 0.0):
                        continue
                    X_OG = SE3.from_rotation_and_translation(R_OG, centre + sx * x_O + sz * z_O)
                    label = _label(name, tilt, sx, False) + (
                        f", {sz * 1000:.0f} mm up" if sz else ""
                    )
                    for turned in (False, True):
                        X = (
                            X_OG @ SE3.from_rotation(SO3.from_z_radians(math.pi))
                            if turned
                            else X_OG
                        )
                        text = label + (", turned 180°" if turned else "")
                        for open_width, tight in openings:
                            yield GraspCandidate(
                                text + (TIGHT_LABEL if tight else ""),
                                X,
                                width,
                                open_width,
                                tilt,
                                sx,
                                turned,
                                tight=tight,
                            )


TIGHT_LABEL = f", opened {MIN_PAD_CLEARANCE * 1000:.0f} mm a side"
"""What a tight twin's label adds to its sibling's (:attr:`GraspCandidate.tight`)."""


def _openings(width: float, max_open_width: float) -> list[tuple[float, bool]]:
    """The gaps [m] the gripper opens to around a side ``width`` [m] wide, each with whether
    it is a tight twin: ``width`` plus :func:`~pickplace.robot.calibration.pad_clearance` a
    side, and, where that is more than :data:`~pickplace.robot.calibration.
    MIN_PAD_CLEARANCE`, also plus only that (the fingers open up to 8 mm less, for an object
    near a wall); none where the gripper does not open to the least of it."""
    clearance = pad_clearance(width, max_open_width)
    if clearance is None:
        return []
    out = [(width + 2.0 * clearance, False)]
    if clearance > MIN_PAD_CLEARANCE:
        out.append((width + 2.0 * MIN_PAD_CLEARANCE, True))
    return out


def _label(name: str, tilt: float, offset: float, turned: bool) -> str:
    parts = [name]
    if tilt:
        parts.append(f"tilted {math.degrees(tilt):+.0f}°")
    if offset:
        parts.append(f"off-centre {offset * 1000:+.0f} mm")
    if turned:
        parts.append("turned 180°")
    return ", ".join(parts)


def gravity_torque(X_WO: SE3, X_OG: SE3, p_O_com: npt.ArrayLike, mass: float) -> float:
    """Torque of the object's weight about the pad axis [N m]: ``|y_G · (r × F)|`` with ``r``
    the centre of mass from the tool site and ``F = -m g z_W``.

    Args:
        X_WO: The object's pose.
        X_OG: The grasp.
        p_O_com: Centre of mass in O [m].
        mass: Mass [kg].
    """
    X_WG = X_WO @ X_OG
    r = X_WO.apply(np.asarray(p_O_com, dtype=np.float64)) - X_WG.translation()
    force = np.array([0.0, 0.0, -mass * GRAVITY])
    y_W = X_WG.rotation().as_matrix()[:, 1]
    return float(abs(y_W @ np.cross(r, force)))


ROUND_SIDES = 16
"""Sides of the polytope :func:`hull_of` puts around a round geom (sphere, capsule, cylinder,
ellipsoid) about its axis; half as many latitude steps over a half turn."""


def _round_hull(
    kind: int, size: np.ndarray, sides: int = ROUND_SIDES
) -> tuple[np.ndarray, np.ndarray]:
    """A polytope around a sphere, capsule, cylinder or ellipsoid (MuJoCo's sizes), in its
    frame: rings of ``sides`` vertices scaled out so that the rings' polygons and the
    latitude steps circumscribe the round surface, and the edges along and between them."""
    theta = 2.0 * math.pi * np.arange(sides) / sides
    ring = np.stack([np.cos(theta), np.sin(theta)], axis=1) / math.cos(math.pi / sides)
    rings: list[tuple[float, float]] = []  # (radius, z) of each ring; radius 0: a pole
    if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        r, h = float(size[0]), float(size[1])
        rings = [(r, -h), (r, h)]
    else:
        steps = sides // 2
        scale = 1.0 / math.cos(0.5 * math.pi / steps)
        lat = -0.5 * math.pi + math.pi * np.arange(1, steps) / steps
        # A capsule: the lower hemisphere's rings about -h, the equator at both ends of the
        # cylinder between them, the upper hemisphere's about +h. A sphere or an ellipsoid:
        # the unit sphere's (h = 0, r = 1), scaled per axis below.
        r, h = (
            (float(size[0]), float(size[1]))
            if kind == mujoco.mjtGeom.mjGEOM_CAPSULE
            else (1.0, 0.0)
        )
        R = r * scale
        rings = [(R * math.cos(a), -h + R * math.sin(a)) for a in lat if a < 0.0]
        rings += [(R, -h), (R, h)] if h > 0.0 else [(R, 0.0)]
        rings += [(R * math.cos(a), h + R * math.sin(a)) for a in lat if a > 0.0]
        rings = [(0.0, -h - R), *rings, (0.0, h + R)]
    vertices: list[np.ndarray] = []
    edges: list[tuple[int, int]] = []
    previous: list[int] = []
    for radius, z in rings:
        if radius == 0.0:
            ids = [len(vertices)]
            vertices.append(np.array([0.0, 0.0, z]))
        else:
            ids = list(range(len(vertices), len(vertices) + sides))
            vertices.extend(np.array([radius * c, radius * s_, z]) for c, s_ in ring)
            edges.extend((ids[i], ids[(i + 1) % sides]) for i in range(sides))
        if previous:
            if len(previous) == 1 or len(ids) == 1:
                edges.extend((a, b) for a in previous for b in ids)
            else:
                edges.extend(zip(previous, ids, strict=True))
        previous = ids
    V = np.array(vertices)
    if kind in (mujoco.mjtGeom.mjGEOM_SPHERE, mujoco.mjtGeom.mjGEOM_ELLIPSOID):
        V = V * (size if kind == mujoco.mjtGeom.mjGEOM_ELLIPSOID else size[0])
    return V, np.array(edges, dtype=np.intp)


def hull_of(model: mujoco.MjModel, geom_id: int) -> tuple[np.ndarray, np.ndarray]:
    """A convex hull enclosing a geom, as vertices in the geom's frame [m] and edges (pairs of
    vertex indices): a box's corners; a mesh's convex hull as MuJoCo compiled it (the hull
    its collisions use); a polytope around a sphere, capsule, cylinder or ellipsoid
    (:data:`ROUND_SIDES`); anything else (a mesh compiled without a hull), its bounding box.

    Returns:
        The vertices, (v, 3), and the edges, (m, 2).
    """
    kind = int(model.geom_type[geom_id])
    size = model.geom_size[geom_id]
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        return _CORNER_SIGNS * size, _BOX_EDGES.copy()
    if kind in (
        mujoco.mjtGeom.mjGEOM_SPHERE,
        mujoco.mjtGeom.mjGEOM_CAPSULE,
        mujoco.mjtGeom.mjGEOM_CYLINDER,
        mujoco.mjtGeom.mjGEOM_ELLIPSOID,
    ):
        return _round_hull(kind, np.asarray(size, dtype=np.float64))
    if kind == mujoco.mjtGeom.mjGEOM_MESH:
        mesh = int(model.geom_dataid[geom_id])
        adr = int(model.mesh_graphadr[mesh])
        if adr >= 0:
            # mjModel.mesh_graph: numvert, numface, vert_edgeadr, vert_globalid, then each
            # vertex's neighbours (local ids), each list ended by -1.
            graph = model.mesh_graph[adr:]
            nv = int(graph[0])
            edge_adr = graph[2 : 2 + nv]
            global_id = graph[2 + nv : 2 + 2 * nv]
            neighbours = graph[2 + 2 * nv :]
            start = int(model.mesh_vertadr[mesh])
            V = model.mesh_vert[start + global_id].astype(np.float64)
            pairs = set()
            for i in range(nv):
                k = int(edge_adr[i])
                while neighbours[k] >= 0:
                    j = int(neighbours[k])
                    pairs.add((min(i, j), max(i, j)))
                    k += 1
            return V, np.array(sorted(pairs), dtype=np.intp).reshape(-1, 2)
    aabb = model.geom_aabb[geom_id]
    return aabb[:3] + _CORNER_SIGNS * aabb[3:], _BOX_EDGES.copy()


def _clipped_gaps(
    R_BG: np.ndarray,
    p_BG: np.ndarray,
    P_G: np.ndarray,
    edges: np.ndarray,
    top_z: float,
    floor_z: float,
    half: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One convex body (vertices ``P_G`` in G [m], ``edges`` joining them) at ``n`` tool poses
    in a bin's frame: its part below the walls' top ``top_z`` (the vertices below it and the
    points where the edges cross it) against the inner walls (half sizes ``half``), and its
    vertices against the floor at ``floor_z``.

    Returns:
        Per pose and point the distance to the walls [m] (inf for a point above the top, or
        a crossing that is not one), (n, v + m); per pose and vertex the height above the
        floor [m], (n, v); the points in B [m], (n, v + m, 3).
    """
    P = P_G @ R_BG.transpose(0, 2, 1) + p_BG[:, None, :]  # (n, v, 3)
    z = P[..., 2]
    A, Bp = P[:, edges[:, 0]], P[:, edges[:, 1]]  # (n, m, 3)
    za, zb = A[..., 2] - top_z, Bp[..., 2] - top_z
    crossing = za * zb < 0.0
    t = np.where(crossing, za / np.where(crossing, za - zb, 1.0), 0.0)
    pts = np.concatenate([P, A + t[..., None] * (Bp - A)], axis=1)  # (n, v + m, 3)
    below = np.concatenate([z < top_z, crossing], axis=1)
    walls = np.where(below, (half - np.abs(pts[..., :2])).min(axis=-1), np.inf)
    return walls, z - floor_z, pts


def _with_floor(walls: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """Walls' distances (…, v + m) with the vertices' (the first v) floor heights (…, v)
    taken in: the distance to the bin."""
    out = walls.copy()
    v = floor.shape[-1]
    out[..., :v] = np.minimum(out[..., :v], floor)
    return out


@dataclass(frozen=True)
class FootprintProblem:
    """Where the open hand meets a bin, at its worst point.

    Attributes:
        geom: The hand's geom.
        where: ``"the floor"`` or the wall, e.g. ``"bin1's -y wall"``.
        distance: The point's distance from it [m] (negative: inside it).
        point_W: The point [m].
    """

    geom: str
    where: str
    distance: float
    point_W: tuple[float, float, float]


class HandFootprint:
    """The open hand's collision geoms in the tool frame, at any open width.

    For the footprint (:meth:`distances`) each geom is its convex hull as vertices and edges
    in G (:func:`hull_of`: a box's corners, a mesh's hull as MuJoCo compiled it, a round
    geom's circumscribed polytope); for the separating-axis bounds of
    :class:`HandObjectGaps`, each geom's bounding box in its own frame (MuJoCo's
    ``geom_aabb``: exact for a box, enclosing for a mesh, capsule or cylinder,
    :meth:`corners_G`). Both are taken into G with the fingers at the width
    (:meth:`~pickplace.robot.model.Robot.qpos_for_width`), once per width.

    Args:
        model: A kinematic copy of the scene's model (never stepped).
        geom_ids: The hand's collision geoms.
        names: Their names.
        tool_site_id: The tool site G.
        gripper_qpos_adr: qpos addresses of the gripper's joints.
        qpos_for_width: Gripper joint positions for a finger gap [m].
        q_arm: Any arm posture, with its qpos addresses (G moves with the hand).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        geom_ids: npt.ArrayLike,
        names: list[str],
        tool_site_id: int,
        gripper_qpos_adr: np.ndarray,
        qpos_for_width: Callable[[float], np.ndarray],
        q_arm: tuple[np.ndarray, np.ndarray],
    ) -> None:
        self.model = model
        self.data = mujoco.MjData(model)
        self.geom_ids = np.asarray(geom_ids, dtype=np.intp)
        self.names = names
        self.tool_site_id = tool_site_id
        self.gripper_qpos_adr = gripper_qpos_adr
        self.qpos_for_width = qpos_for_width
        adr, q = q_arm
        self.data.qpos[adr] = q
        self._corners: dict[float, np.ndarray] = {}
        self._hulls: dict[float, list[np.ndarray]] = {}
        self._posed: float | None = None
        hulls = [hull_of(model, int(g)) for g in self.geom_ids]
        self._hull_local = [v for v, _ in hulls]
        self.hull_edges = [e for _, e in hulls]
        """Each geom's hull edges, as pairs of indices into its own vertices."""
        self.hull_geom = np.repeat(np.arange(len(hulls), dtype=np.intp), [len(v) for v, _ in hulls])
        """The hand geom (an index into :attr:`geom_ids`) of each vertex of :meth:`hull_G`."""
        # The geoms whose hull is tighter than their bounding box (all but boxes).
        self._hull_tighter = [
            j
            for j, g in enumerate(self.geom_ids)
            if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_BOX
        ]

    def pose(self, width: float) -> mujoco.MjData:
        """:attr:`data` with the fingers at gap ``width`` [m] and its kinematics computed
        (the bodies' and geoms' poses; a geom's pose written by a caller stands until the
        next width)."""
        if self._posed != width:
            self.data.qpos[self.gripper_qpos_adr] = self.qpos_for_width(width)
            mujoco.mj_kinematics(self.model, self.data)
            self._posed = width
        return self.data

    def _to_G(self, width: float, local: list[np.ndarray]) -> list[np.ndarray]:
        """Points given in each geom's frame, in G with the fingers at gap ``width`` [m]."""
        d = self.pose(width)
        R_WG = d.site_xmat[self.tool_site_id].reshape(3, 3)
        p_WG = d.site_xpos[self.tool_site_id]
        out = []
        for g, P in zip(self.geom_ids, local, strict=True):
            p_W = P @ d.geom_xmat[g].reshape(3, 3).T + d.geom_xpos[g]
            out.append((p_W - p_WG) @ R_WG)  # R_WGᵀ (p_W − p_WG), row-wise
        return out

    def corners_G(self, width: float) -> np.ndarray:
        """Corners of every geom's bounding box in G with the fingers at gap ``width`` [m],
        (k, 8, 3)."""
        cached = self._corners.get(width)
        if cached is not None:
            return cached
        # Batched, not through _to_G: its matrix product rounds the last bit differently, and
        # the pads' corners give the grasps' offsets, whose labels round at whole millimetres
        # (pick-place-random seed 8's golden reads +7 mm, not +8).
        m, d = self.model, self.pose(width)
        R_WG = d.site_xmat[self.tool_site_id].reshape(3, 3)
        p_WG = d.site_xpos[self.tool_site_id]
        g = self.geom_ids
        aabb = m.geom_aabb[g]  # (k, 6): centre and half sizes in the geom frame
        local = aabb[:, None, :3] + _CORNER_SIGNS[None] * aabb[:, None, 3:]  # (k, 8, 3)
        R_Wg = d.geom_xmat[g].reshape(-1, 3, 3)
        p_W = np.einsum("kij,knj->kni", R_Wg, local) + d.geom_xpos[g][:, None, :]
        corners = (p_W - p_WG) @ R_WG  # R_WGᵀ (p_W − p_WG), row-wise
        self._corners[width] = corners
        return corners

    def _hulls_G(self, width: float) -> list[np.ndarray]:
        """Each geom's hull vertices in G with the fingers at gap ``width`` [m]."""
        cached = self._hulls.get(width)
        if cached is None:
            cached = self._to_G(width, self._hull_local)
            self._hulls[width] = cached
        return cached

    def hull_G(self, width: float) -> np.ndarray:
        """Every geom's hull vertices in G with the fingers at gap ``width`` [m], (n, 3)
        (:attr:`hull_geom` says whose)."""
        return np.concatenate(self._hulls_G(width))

    def distances(
        self,
        R_BG: np.ndarray,
        p_BG: np.ndarray,
        width: float,
        bin_: BinGeometry,
        exact_below: float = math.inf,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The open hand at ``n`` tool poses in a bin's frame B: each pose's smallest distance
        to the bin's floor or inner walls [m].

        Below the walls' top, each geom's hull (clipped at the top's plane: its vertices
        below it and the points where its edges cross it) must lie inside the inner walls; a
        convex body lies inside the convex inner prism exactly when those points do. Every
        vertex must lie above the floor. Each geom's bounding box is tested first, the same
        way: the box encloses the hull, so its distance is a lower bound of the hull's, and a
        geom whose box is at least ``exact_below`` from the bin keeps the box's distance.

        Args:
            R_BG: Tool orientations in B, (n, 3, 3).
            p_BG: Tool positions in B [m], (n, 3).
            width: Finger gap [m].
            bin_: The bin.
            exact_below: Where a geom's box is nearer than this, its hull's distance [m]
                (default: everywhere).

        Returns:
            Per pose the smallest distance [m] (negative: into a wall or the floor), the geom
            index (into the hand's geoms) and the point in B [m], shapes (n,), (n,), (n, 3).
        """
        to_bin, _, points = self._per_geom(R_BG, p_BG, width, bin_, exact_below, -math.inf)
        which = np.argmin(to_bin, axis=1)
        rows = np.arange(len(R_BG))
        return to_bin[rows, which], which, points[rows, which]

    def clearances(
        self,
        R_BG: np.ndarray,
        p_BG: np.ndarray,
        width: float,
        bin_: BinGeometry,
        exact_below: float,
        walls_exact_below: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Each pose's smallest distance to the bin (as :meth:`distances`) and to its inner
        walls alone [m], both from one pass, shapes (n,), (n,); each exact where a geom's box
        is nearer than ``exact_below`` (the bin), respectively ``walls_exact_below`` (the
        walls), else that box's distance."""
        to_bin, to_walls, _ = self._per_geom(
            R_BG, p_BG, width, bin_, exact_below, walls_exact_below
        )
        return to_bin.min(axis=1), to_walls.min(axis=1)

    def _per_geom(
        self,
        R_BG: np.ndarray,
        p_BG: np.ndarray,
        width: float,
        bin_: BinGeometry,
        exact_below: float,
        walls_exact_below: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per pose and geom the distance to the bin and to its walls alone [m], (n, k) each,
        and the point of the former in B [m], (n, k, 3) (:meth:`distances`, :meth:`clearances`:
        a geom's hull where its box is nearer than the thresholds, else its box)."""
        floor_z = float(bin_.to_bin_frame(bin_.center_W)[2])
        top_z = floor_z + bin_.wall_top_z - bin_.floor_top_z
        half = bin_.inner_half_extents
        boxes = self.corners_G(width)  # (k, 8, 3)
        n, k = len(R_BG), len(boxes)
        # Every geom's box at once: its 8 corners and 12 edges, one body per geom.
        corners = boxes.reshape(-1, 3)
        edges = (_BOX_EDGES[None] + 8 * np.arange(k)[:, None, None]).reshape(-1, 2)
        walls, floor, pts = _clipped_gaps(R_BG, p_BG, corners, edges, top_z, floor_z, half)
        # Regrouped per geom: its 8 corners, then its 12 edges' crossings, (n, k, 20).
        walls = np.concatenate(
            [walls[:, : 8 * k].reshape(n, k, 8), walls[:, 8 * k :].reshape(n, k, 12)], axis=2
        )
        pts = np.concatenate(
            [pts[:, : 8 * k].reshape(n, k, 8, 3), pts[:, 8 * k :].reshape(n, k, 12, 3)], axis=2
        )
        to_bin = _with_floor(walls, floor.reshape(n, k, 8))
        at = np.argmin(to_bin, axis=2)
        points = np.take_along_axis(pts, at[..., None, None], axis=2)[:, :, 0]  # (n, k, 3)
        to_bin = np.take_along_axis(to_bin, at[..., None], axis=2)[..., 0]  # (n, k)
        to_walls = walls.min(axis=2)  # (n, k)
        hulls = self._hulls_G(width)
        for j in self._hull_tighter:
            bin_near = to_bin[:, j] < exact_below
            walls_near = to_walls[:, j] < walls_exact_below
            rows = np.flatnonzero(bin_near | walls_near)
            if len(rows):
                w, f, q = _clipped_gaps(
                    R_BG[rows], p_BG[rows], hulls[j], self.hull_edges[j], top_z, floor_z, half
                )
                g = _with_floor(w, f)
                i = np.argmin(g, axis=1)
                r = np.arange(len(rows))
                b, ws = bin_near[rows], walls_near[rows]
                to_bin[rows[b], j], points[rows[b], j] = g[r, i][b], q[r, i][b]
                to_walls[rows[ws], j] = w.min(axis=1)[ws]
        return to_bin, to_walls, points

    def problem(
        self, X_WG: SE3, width: float, bin_: BinGeometry, clearance: float
    ) -> FootprintProblem | None:
        """The open hand at ``X_WG`` against ``bin_`` (:meth:`distances`): its worst point
        when nearer than ``clearance`` [m] to the floor or a wall, else None."""
        R_BW = bin_.X_WB.inverse().rotation().as_matrix()
        R_BG = (R_BW @ X_WG.rotation().as_matrix())[None]
        p_BG = bin_.to_bin_frame(X_WG.translation())[None]
        distance, k, p_B = (a[0] for a in self.distances(R_BG, p_BG, width, bin_))
        if distance >= clearance:
            return None
        floor_z = float(bin_.to_bin_frame(bin_.center_W)[2])
        half = bin_.inner_half_extents
        if p_B[2] - floor_z <= float((half - np.abs(p_B[:2])).min()):
            where = f"{bin_.name}'s floor"
        else:
            a = int(np.argmin(half - np.abs(p_B[:2])))
            where = f"{bin_.name}'s {'+' if p_B[a] > 0 else '-'}{'xy'[a]} wall"
        p_W = bin_.X_WB.apply(p_B)
        point = (float(p_W[0]), float(p_W[1]), float(p_W[2]))
        return FootprintProblem(self.names[int(k)], where, float(distance), point)


HAND_OBJECT_MARGIN = 0.0
"""Least distance between the object and any of the hand's collision geoms other than the
pads, open around it and closed on it [m]: none may touch it, so that the pads alone hold
it (a linkage's knuckles on a tall can's side, a palm on its top carry it instead). Zero,
not more: a finger's other geoms beside the pads (a second pad box, a fingertip's pad
strips) lie flush with the pads, 1.5 mm from a face the pads close on.
"""


class HandObjectGaps:
    """The hand's collision geoms other than the pads against the object held by a grasp.

    The hand's geoms (a :class:`HandFootprint` of them, which places them in the tool frame
    G at a finger gap) and the object's collision geoms stand as a grasp ``X_OG`` puts them,
    with the fingers at the object's width (closed on it) and at the grasp's opening. First a
    lower bound for every candidate at once: each geom's box separated from the object's
    support function along the box's face normals, O's z and the direction from the object's
    centre to the box (horizontal and not); then, where that bound is below the margin, the
    exact distance (``mujoco.mj_geomDistance``, the hand as the model has it and the object's
    geoms placed by the grasp). A geom that touches the object there would carry what the
    pads should (a linkage's knuckles on a tall can, a palm on its top).

    Args:
        hand: The hand's collision geoms other than the pads, as boxes in G.
        shape: The object's geometry (its geom ids in ``hand.model``).
    """

    def __init__(self, hand: HandFootprint, shape: ObjectGeometry) -> None:
        if len(shape.geom_ids) != len(shape.geoms):
            raise ValueError(
                f"the object has {len(shape.geoms)} geoms but {len(shape.geom_ids)} geom ids; "
                "valid: one id per geom"
            )
        self.hand = hand
        self.shape = shape
        self._object_ids = [int(g) for g in shape.geom_ids]

    def gaps(
        self, R_OG: np.ndarray, p_OG: np.ndarray, widths: np.ndarray, margin: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """The smallest distance of the hand's geoms from the object at each grasp.

        Args:
            R_OG: The grasps' tool orientations in O, (n, 3, 3).
            p_OG: Their tool positions in O [m], (n, 3).
            widths: The finger gap at each [m], (n,).
            margin: Below this the distance is exact [m]; above it a lower bound.

        Returns:
            Per grasp the smallest distance [m] and the index of that geom among the hand's,
            shapes (n,), (n,).
        """
        n = len(R_OG)
        out = np.full(n, np.inf)
        which = np.zeros(n, dtype=np.intp)
        for width in np.unique(widths):
            sel = np.flatnonzero(widths == width)
            bound = self._lower_bounds(R_OG[sel], p_OG[sel], float(width))  # (m, k)
            near = bound < margin
            for row in np.flatnonzero(near.any(axis=1)):
                i, cols = int(sel[row]), np.flatnonzero(near[row])
                bound[row, cols] = self._exact(R_OG[i], p_OG[i], float(width), cols, margin)
            k = np.argmin(bound, axis=1)
            out[sel] = bound[np.arange(len(sel)), k]
            which[sel] = k
        return out, which

    def _lower_bounds(self, R_OG: np.ndarray, p_OG: np.ndarray, width: float) -> np.ndarray:
        """Separating-axis lower bounds of each geom box's distance from the object, (m, k)."""
        P_G = self.hand.corners_G(width)  # (k, 8, 3)
        P = P_G @ R_OG.transpose(0, 2, 1)[:, None] + p_OG[:, None, None]  # (m, k, 8, 3)
        centre = P.mean(axis=2)  # (m, k, 3)
        edges = P[:, :, [1, 2, 4]] - P[:, :, :1]  # the box's three axes (corner bits 0, 1, 2)
        radial = centre - self.shape.aabb_center
        flat = radial * np.array([1.0, 1.0, 0.0])
        z = np.broadcast_to(np.array([0.0, 0.0, 1.0]), centre.shape)[:, :, None]
        axes = np.concatenate([edges, -edges, radial[:, :, None], flat[:, :, None], z, -z], axis=2)
        norm = np.linalg.norm(axes, axis=-1, keepdims=True)
        valid = norm[..., 0] > 1e-12  # a flat box has a zero edge; a centred box no radial
        axes = np.where(valid[..., None], axes / np.where(valid[..., None], norm, 1.0), 0.0)
        axes[~valid] = (0.0, 0.0, 1.0)
        reach = self.shape.supports(axes.reshape(-1, 3)).reshape(axes.shape[:3])
        low = (P @ axes.transpose(0, 1, 3, 2)).min(axis=2)  # the box's least along each axis
        return np.where(valid, low - reach, -np.inf).max(axis=2)

    def _exact(
        self, R_OG: np.ndarray, p_OG: np.ndarray, width: float, ks: np.ndarray, margin: float
    ) -> np.ndarray:
        """The exact distances of the hand's geoms ``ks`` from the object [m] (the nearest of
        its geoms), each capped at ``margin``, at one grasp."""
        h = self.hand
        m, d = h.model, h.pose(width)
        R_WO = d.site_xmat[h.tool_site_id].reshape(3, 3) @ R_OG.T
        p_WO = d.site_xpos[h.tool_site_id] - R_WO @ p_OG
        for g, gid in zip(self.shape.geoms, self.shape.geom_ids, strict=True):
            d.geom_xpos[gid] = R_WO @ g.p_Og + p_WO
            d.geom_xmat[gid] = (R_WO @ g.R_Og).reshape(-1)
        hand = h.geom_ids[ks].tolist()
        return np.array(
            [
                min(
                    [margin]
                    + [mujoco.mj_geomDistance(m, d, a, b, margin, None) for b in self._object_ids]
                )
                for a in hand
            ]
        )
