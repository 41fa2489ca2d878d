"""The held object's geometry: its collision geoms, and what every reader of its shape asks.

The world's free body (the "brick" of :class:`~pickplace.world.scene.WorldNames`) may be any
body with collision geoms: boxes, spheres, capsules, cylinders, ellipsoids and (convex) meshes,
one or several. :class:`ObjectGeometry` holds them in the object frame O (the body frame) and
answers with exact support functions, never with a bounding box unless it says so:

* :meth:`ObjectGeometry.support`: the object's extent along a direction of O [m]
  (``max_{p ∈ object} p · d``), from each primitive's closed form (a mesh: its vertices);
* :meth:`ObjectGeometry.patch`: the set where that maximum is reached (a face, an edge, a line
  along a cylinder's side, a point), as a box in O: where flat pads pressing along ``-d``
  touch the object;
* the width between the pads of a grasp, the height at which it rests on a floor, the
  footprint at a yaw, its lowest point and its footprint's corners at any pose.

The brick (one box geom at the body's origin, axes aligned) keeps its box formulas
bit for bit (:attr:`ObjectGeometry.box_half_extents`).

Bundled objects (:data:`BUNDLED_OBJECTS`): ``brick`` (the world's own), ``can`` (a cylinder
60 mm across, 100 mm tall), ``ball`` (a sphere 60 mm across), ``jar`` (a convex mesh 64 mm
across, 72 mm tall, written by ``scripts/make_jar.py``), files in ``scenes/objects/``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
import numpy.typing as npt
from mink.lie import SE3

from pickplace.errors import ObjectError, SceneError

__all__ = [
    "BUNDLED_OBJECTS",
    "OBJECTS_DIR",
    "SUPPORTED_GEOMS",
    "ObjectGeom",
    "ObjectGeometry",
    "object_file",
    "with_object",
]

OBJECTS_DIR = Path(__file__).resolve().parents[2] / "scenes" / "objects"
"""Where the bundled objects' MJCF files are."""

BUNDLED_OBJECTS = ("brick", "can", "ball", "jar")
"""Names ``--object`` takes besides a file: ``brick`` is the world's own box."""

SUPPORTED_GEOMS = {
    int(mujoco.mjtGeom.mjGEOM_BOX): "box",
    int(mujoco.mjtGeom.mjGEOM_SPHERE): "sphere",
    int(mujoco.mjtGeom.mjGEOM_CAPSULE): "capsule",
    int(mujoco.mjtGeom.mjGEOM_CYLINDER): "cylinder",
    int(mujoco.mjtGeom.mjGEOM_ELLIPSOID): "ellipsoid",
    int(mujoco.mjtGeom.mjGEOM_MESH): "mesh",
}
"""Collision geom types an object may have (a mesh collides as its convex hull)."""

PATCH_TOLERANCE = 5e-4
"""Points within this of the support plane belong to the support patch [m]."""

_EPS = 1e-9


def object_file(name_or_path: str) -> Path | None:
    """The MJCF file of ``--object``: a bundled object's (None for ``brick``, the world's own)
    or the path given.

    Raises:
        ObjectError: Neither a bundled name nor an existing file; the message lists the
            names.
    """
    if name_or_path == "brick":
        return None
    if name_or_path in BUNDLED_OBJECTS:
        return OBJECTS_DIR / f"{name_or_path}.xml"
    path = Path(name_or_path)
    if path.suffix == ".xml" and path.is_file():
        return path.resolve()
    raise ObjectError(
        f"object '{name_or_path}' is neither a bundled object nor a readable .xml file; valid: "
        f"{', '.join(BUNDLED_OBJECTS)} or an MJCF file with one free body"
    )


OBJECT_PREFIX = "object/"
"""Prefix of the names an object file's elements get in the world."""


def _read_object(path: Path) -> tuple[mujoco.MjSpec, mujoco.MjsBody, ObjectGeometry]:
    """The object file's spec, its one body and its geometry, checked on their own."""
    valid = (
        "valid: an MJCF file whose worldbody holds one body with a free joint and collision geoms"
    )
    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except (ValueError, OSError) as exc:
        detail = " ".join(str(exc).split())
        raise ObjectError(f"object file '{path}' cannot be read: {detail}; {valid}") from exc
    for mesh in spec.meshes:  # the object's mesh files, wherever the world is
        if mesh.file and not Path(mesh.file).is_absolute():
            mesh.file = str((path.parent / (spec.meshdir or "") / mesh.file).resolve())
    spec.meshdir = ""
    bodies = list(spec.worldbody.bodies)
    if len(bodies) != 1 or spec.worldbody.geoms:
        raise ObjectError(
            f"object file '{path}' has {len(bodies)} bodies and {len(spec.worldbody.geoms)} "
            f"world geoms; {valid}"
        )
    body = bodies[0]
    body.pos, body.quat = [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]  # placed like the brick
    try:
        model = spec.copy().compile()
    except ValueError as exc:
        detail = " ".join(str(exc).split())
        raise ObjectError(f"object file '{path}' does not compile: {detail}; {valid}") from exc
    joint = int(model.body_jntadr[1])
    if joint < 0 or model.jnt_type[joint] != mujoco.mjtJoint.mjJNT_FREE or model.njnt != 1:
        raise ObjectError(f"object file '{path}': its body is not a free body; {valid}")
    if not 1e-3 <= float(model.body_mass[1]) <= 1e3:
        raise ObjectError(
            f"object file '{path}': its mass is {float(model.body_mass[1]):g} kg; valid: "
            "[0.001, 1000] kg"
        )
    try:
        shape = ObjectGeometry.from_model(model, 1)
    except SceneError as exc:
        raise ObjectError(f"object file '{path}': {exc}") from None
    return spec, body, shape


def with_object(spec: mujoco.MjSpec, brick_body: str, path: Path) -> mujoco.MjSpec:
    """A copy of the world ``spec`` with its brick body replaced by the object of ``path``
    (an MJCF file with one free body), resting upright where the brick rested and named as
    the brick was (its other elements prefixed :data:`OBJECT_PREFIX`).

    Raises:
        ObjectError: The file cannot be read, does not compile, holds not exactly one free
            body, or that body has no collision geom of a supported type.
    """
    obj, body, shape = _read_object(path)
    world = spec.copy()
    brick = world.body(brick_body)
    if brick is None:
        raise SceneError(f"the world has no body '{brick_body}' for the object to replace")
    model = spec.copy().compile()
    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, brick_body)
    floor = float(model.body_pos[b][2]) - ObjectGeometry.from_model(model, b).rest_height
    pos = [float(model.body_pos[b][0]), float(model.body_pos[b][1]), floor + shape.rest_height]
    name = body.name or "object"
    body.name = name
    world.delete(brick)
    world.attach(obj, prefix=OBJECT_PREFIX, frame=world.worldbody.add_frame(pos=pos))
    world.body(OBJECT_PREFIX + name).name = brick_body
    return world


@dataclass(frozen=True)
class ObjectGeom:
    """One collision geom of the object, in the object frame O.

    Attributes:
        kind: ``"box"``, ``"sphere"``, ``"capsule"``, ``"cylinder"``, ``"ellipsoid"`` or
            ``"mesh"``.
        size: MuJoCo's geom size [m] (box half sizes; sphere radius; capsule and cylinder
            radius and half length along the geom's z; ellipsoid semi-axes).
        R_Og: The geom frame's orientation in O (3, 3).
        p_Og: The geom frame's origin in O [m] (3,).
        vertices: A mesh's vertices in the geom frame [m] (k, 3); None for a primitive.
    """

    kind: str
    size: np.ndarray
    R_Og: np.ndarray
    p_Og: np.ndarray
    vertices: np.ndarray | None = None

    def support_local(self, u: np.ndarray) -> np.ndarray:
        """Support ``max p · u`` over the geom for unit directions ``u`` (n, 3) in its frame."""
        s = self.size
        if self.kind == "box":
            return np.abs(u) @ s
        if self.kind == "sphere":
            return np.full(len(u), s[0])
        if self.kind == "capsule":
            return s[0] + s[1] * np.abs(u[:, 2])
        if self.kind == "cylinder":
            return s[0] * np.hypot(u[:, 0], u[:, 1]) + s[1] * np.abs(u[:, 2])
        if self.kind == "ellipsoid":
            return np.sqrt(((u * s) ** 2).sum(axis=1))
        assert self.vertices is not None  # a mesh, checked on construction
        return (u @ self.vertices.T).max(axis=1)

    def patch_local(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where the support along unit ``u`` (3,) is reached, as a box in the geom frame:
        its centre and half sizes [m] (zero half sizes: a point)."""
        s = self.size
        if self.kind == "box":
            free = np.abs(u) <= _EPS
            return np.where(free, 0.0, np.sign(u) * s), np.where(free, s, 0.0)
        if self.kind == "sphere":
            return s[0] * u, np.zeros(3)
        if self.kind == "ellipsoid":
            return s**2 * u / float(np.linalg.norm(s * u)), np.zeros(3)
        if self.kind in ("capsule", "cylinder"):
            r, h = float(s[0]), float(s[1])
            rho = math.hypot(float(u[0]), float(u[1]))
            side = abs(float(u[2])) <= _EPS
            if self.kind == "capsule":
                if side:
                    return r * u, np.array([0.0, 0.0, h])
                return np.array([0.0, 0.0, math.copysign(h, float(u[2]))]) + r * u, np.zeros(3)
            if rho <= _EPS:  # a cap's disc
                return np.array([0.0, 0.0, math.copysign(h, float(u[2]))]), np.array([r, r, 0.0])
            radial = r * np.array([u[0] / rho, u[1] / rho, 0.0])
            if side:
                return radial, np.array([0.0, 0.0, h])
            return radial + np.array([0.0, 0.0, math.copysign(h, float(u[2]))]), np.zeros(3)
        assert self.vertices is not None
        dots = self.vertices @ u
        on = self.vertices[dots >= dots.max() - PATCH_TOLERANCE]
        lo, hi = on.min(axis=0), on.max(axis=0)
        return 0.5 * (lo + hi), 0.5 * (hi - lo)


class ObjectGeometry:
    """The held object's collision geoms in its frame O, and the questions asked of its shape.

    Args:
        geoms: Its collision geoms (at least one).
        geom_ids: Their ids in the scene's model.

    Raises:
        SceneError: No geom, an unknown kind, a mesh without vertices or a size that is not
            positive and finite.
    """

    def __init__(self, geoms: tuple[ObjectGeom, ...], geom_ids: npt.ArrayLike) -> None:
        if not geoms:
            raise SceneError(
                "the object has no collision geom; valid: a body with at least one geom of "
                f"type {', '.join(SUPPORTED_GEOMS.values())} that collides"
            )
        for g in geoms:
            if g.kind not in SUPPORTED_GEOMS.values():
                raise SceneError(
                    f"object geom of type '{g.kind}'; valid: {', '.join(SUPPORTED_GEOMS.values())}"
                )
            if g.kind == "mesh" and (g.vertices is None or len(g.vertices) < 4):
                raise SceneError("object mesh geom without vertices; valid: a mesh of 4 or more")
            if g.kind != "mesh" and not (np.all(np.isfinite(g.size)) and g.size[0] > 0):
                raise SceneError(f"object {g.kind} geom of size {g.size.tolist()}; valid: > 0")
        self.geoms = geoms
        self.geom_ids = np.asarray(geom_ids, dtype=np.intp)
        lo = np.array([-self.support(-e) for e in np.eye(3)])
        hi = np.array([self.support(e) for e in np.eye(3)])
        self.aabb_center = 0.5 * (lo + hi)
        """Centre of the object's axis-aligned bounding box in O [m]."""
        self.half_extents = 0.5 * (hi - lo)
        """Half sizes of the object's axis-aligned bounding box in O [m]."""

    @classmethod
    def from_model(cls, model: mujoco.MjModel, body_id: int) -> ObjectGeometry:
        """The collision geoms (contype or conaffinity set) of body ``body_id``, in its frame.

        Raises:
            SceneError: It has none, or one of an unsupported type (the message lists the
                valid types).
        """
        geoms, ids = [], []
        for g in np.flatnonzero(model.geom_bodyid == body_id).tolist():
            if not (model.geom_contype[g] or model.geom_conaffinity[g]):
                continue
            kind = SUPPORTED_GEOMS.get(int(model.geom_type[g]))
            if kind is None:
                name = mujoco.mjtGeom(int(model.geom_type[g])).name.removeprefix("mjGEOM_")
                raise SceneError(
                    f"the object's geom {g} is a {name.lower()}; valid: "
                    f"{', '.join(SUPPORTED_GEOMS.values())}"
                )
            R = np.zeros(9)
            mujoco.mju_quat2Mat(R, model.geom_quat[g])
            vertices = None
            if kind == "mesh":
                m = int(model.geom_dataid[g])
                adr, n = int(model.mesh_vertadr[m]), int(model.mesh_vertnum[m])
                vertices = np.array(model.mesh_vert[adr : adr + n], dtype=np.float64)
            geoms.append(
                ObjectGeom(
                    kind,
                    np.array(model.geom_size[g], dtype=np.float64),
                    R.reshape(3, 3),
                    np.array(model.geom_pos[g], dtype=np.float64),
                    vertices,
                )
            )
            ids.append(g)
        return cls(tuple(geoms), ids)

    # ------------------------------------------------------------------ the shape

    @property
    def box_half_extents(self) -> np.ndarray | None:
        """The half sizes [m] when the object is one box at O's origin with O's axes (the
        brick), else None."""
        if len(self.geoms) != 1:
            return None
        g = self.geoms[0]
        if g.kind != "box" or np.any(g.p_Og != 0.0) or not np.array_equal(g.R_Og, np.eye(3)):
            return None
        return g.size

    @property
    def is_round(self) -> bool:
        """True for one sphere centred at O: it rests the same in every orientation."""
        return (
            len(self.geoms) == 1
            and self.geoms[0].kind == "sphere"
            and not np.any(self.geoms[0].p_Og != 0.0)
        )

    @property
    def kinds(self) -> str:
        """The geoms' kinds in words, e.g. ``"cylinder"`` or ``"2 boxes and a sphere"``."""
        names = [g.kind for g in self.geoms]
        return names[0] if len(names) == 1 else f"{len(names)} geoms ({', '.join(names)})"

    def support(self, d_O: npt.ArrayLike) -> float:
        """The object's extent along direction ``d_O`` (made unit) of O: ``max p · d`` [m]."""
        return float(self.supports(np.atleast_2d(np.asarray(d_O, dtype=np.float64)))[0])

    def supports(self, d_O: np.ndarray) -> np.ndarray:
        """:meth:`support` for each row of ``d_O`` (n, 3) [m]."""
        d = d_O / np.linalg.norm(d_O, axis=1, keepdims=True)
        out = np.full(len(d), -np.inf)
        for g in self.geoms:
            out = np.maximum(out, d @ g.p_Og + g.support_local(d @ g.R_Og))
        return out

    def patch(self, d_O: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Where the object reaches its support along ``d_O``: the axis-aligned box in O
        around every geom's support set within :data:`PATCH_TOLERANCE` of the maximum, as its
        centre and half sizes [m]."""
        d = np.asarray(d_O, dtype=np.float64)
        d = d / np.linalg.norm(d)
        best = self.support(d)
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for g in self.geoms:
            u = g.R_Og.T @ d
            if float(d @ g.p_Og + g.support_local(u[None])[0]) < best - PATCH_TOLERANCE:
                continue
            c, h = g.patch_local(u)
            c_O = g.R_Og @ c + g.p_Og
            h_O = np.abs(g.R_Og) @ h
            lo, hi = np.minimum(lo, c_O - h_O), np.maximum(hi, c_O + h_O)
        return 0.5 * (lo + hi), 0.5 * (hi - lo)

    def width_across(self, X_OG: SE3) -> float:
        """The object's width between the pads of grasp ``X_OG``: its extent along the tool's
        closing axis G's y, both ways [m]."""
        y_O = X_OG.rotation().as_matrix()[:, 1]
        box = self.box_half_extents
        if box is not None:  # the brick's own formula, bit for bit
            return float(2.0 * np.abs(y_O) @ box)
        return self.support(y_O) + self.support(-y_O)

    @property
    def rest_height(self) -> float:
        """Height of O's origin above a floor the object rests on upright (O's z up) [m]."""
        box = self.box_half_extents
        return float(box[2]) if box is not None else self.support([0.0, 0.0, -1.0])

    @property
    def bounding_radius(self) -> float:
        """Farthest point of the object from O's origin [m] (its box's corner for the brick)."""
        box = self.box_half_extents
        if box is not None:
            return float(np.linalg.norm(box))
        d = _sphere_directions(2000)
        return float(self.supports(d).max())

    def footprint_half(self, yaw: float) -> np.ndarray:
        """Half sizes [m] of the object's footprint, lying upright turned by ``yaw`` [rad],
        along the axes of the frame it is turned in (x, y)."""
        box = self.box_half_extents
        c, s = math.cos(yaw), math.sin(yaw)
        if box is not None:
            c, s = abs(c), abs(s)
            return np.array([c * box[0] + s * box[1], s * box[0] + c * box[1]])
        # The frame's ±x, ±y in O: O is turned by yaw.
        dirs = np.array([[c, -s, 0.0], [-c, s, 0.0], [s, c, 0.0], [-s, -c, 0.0]])
        e = self.supports(dirs)
        return np.array([max(e[0], e[1]), max(e[2], e[3])])

    @property
    def min_footprint_half(self) -> float:
        """The smallest half size of the footprint at any yaw [m] (no valid centre lies
        closer than it to a wall)."""
        box = self.box_half_extents
        if box is not None:
            return float(np.min(box[:2]))
        a = np.linspace(0.0, math.pi, 361)
        d = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)
        return float(np.minimum(self.supports(d), self.supports(-d)).min())

    def extent_W(self, X_WO: SE3, d_W: np.ndarray) -> np.ndarray:
        """The object at ``X_WO``: its support along each world direction ``d_W`` (n, 3),
        measured from the world origin [m]."""
        R = X_WO.rotation().as_matrix()
        return self.supports(d_W @ R) + d_W @ X_WO.translation()


def _sphere_directions(n: int) -> np.ndarray:
    """``n`` unit directions spread evenly over the sphere (a Fibonacci lattice)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = math.pi * (1.0 + math.sqrt(5.0)) * k
    r = np.sqrt(1.0 - z**2)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
