"""Rerun archetypes and columns from MuJoCo data: geom shapes and colours, poses, scalars and
times as columns (one row per tick), entity path parts. Quaternions are stored xyzw."""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
import rerun as rr

PLANE_EXTENT = 2.0  # half extent drawn for an infinite plane [m]
_GEOM = mujoco.mjtGeom


SOLID = rr.components.FillMode.Solid


def xyzw(q_wxyz: np.ndarray) -> np.ndarray:
    """MuJoCo/mink wxyz quaternions (..., 4) → Rerun xyzw."""
    return np.asarray(q_wxyz)[..., [1, 2, 3, 0]]


def quat(q_wxyz: np.ndarray) -> rr.Quaternion:
    """One MuJoCo/mink wxyz quaternion as a Rerun quaternion."""
    return rr.Quaternion(xyzw=xyzw(q_wxyz))


def to_duration(t: np.ndarray) -> np.ndarray:
    """Seconds → timedelta64[ns], rounded (k·dt sums such as 0.09 + 0.01 land 1 ns short)."""
    return np.round(np.asarray(t, dtype=np.float64) * 1e9).astype("timedelta64[ns]")


def path_part(name: str) -> str:
    return str(rr.escape_entity_path_part(name))


def finite_or_nan(a: np.ndarray) -> np.ndarray:
    """Copy of ``a`` with ±inf replaced by NaN (drawn as a gap in a plot)."""
    out = np.array(a, dtype=np.float64)
    out[~np.isfinite(out)] = np.nan
    return out


# Component descriptors of the per-tick columns, taken once from the archetypes: building
# ComponentColumns from them directly costs a fifth of ``Archetype.columns(...)``.
_DESCRIPTORS = {
    c.component_descriptor().component: c.component_descriptor()
    for c in [
        *rr.Transform3D.columns(translation=np.zeros((1, 3)), quaternion=np.eye(4)[3:]),
        *rr.Scalars.columns(scalars=np.zeros(1)),
    ]
}


def transform_columns(p: np.ndarray, q_wxyz: np.ndarray) -> list[rr.ComponentColumn]:
    """Transform3D columns (translation, quaternion), one row per row of ``p`` (T, 3)."""
    offsets = np.arange(len(p) + 1, dtype=np.int32)
    return [
        rr.ComponentColumn(
            _DESCRIPTORS["Transform3D:translation"],
            rr.components.Translation3DBatch(p),
            offsets=offsets,
        ),
        rr.ComponentColumn(
            _DESCRIPTORS["Transform3D:quaternion"],
            rr.components.RotationQuatBatch(xyzw(q_wxyz)),
            offsets=offsets,
        ),
    ]


def scalar_columns(values: np.ndarray) -> list[rr.ComponentColumn]:
    """Scalars column of (T,) or (T, N) values (N lines); ±inf becomes NaN (a gap)."""
    v = finite_or_nan(values)
    width = 1 if v.ndim == 1 else v.shape[1]
    offsets = np.arange(0, v.size + 1, width, dtype=np.int32)
    batch = rr.components.ScalarBatch(v.reshape(-1))
    return [rr.ComponentColumn(_DESCRIPTORS["Scalars:scalars"], batch, offsets=offsets)]


def _vertex_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted per-vertex normals of a triangle mesh."""
    normals = np.zeros_like(verts)
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    face_n = np.cross(b - a, c - a)
    for k in range(3):
        np.add.at(normals, faces[:, k], face_n)
    norm = np.linalg.norm(normals, axis=1, keepdims=True)
    return normals / np.where(norm > 0.0, norm, 1.0)


def geom_archetype(model: mujoco.MjModel, g: int, rgba: np.ndarray) -> Any | None:
    """Rerun shape of geom ``g`` in its own frame, or None for an unsupported type."""
    typ = int(model.geom_type[g])
    s = model.geom_size[g]
    color = [rgba]
    if typ == _GEOM.mjGEOM_BOX:
        return rr.Boxes3D(half_sizes=[s], colors=color, fill_mode=SOLID)
    if typ == _GEOM.mjGEOM_SPHERE:
        return rr.Ellipsoids3D(half_sizes=[[s[0]] * 3], colors=color, fill_mode=SOLID)
    if typ == _GEOM.mjGEOM_ELLIPSOID:
        return rr.Ellipsoids3D(half_sizes=[s], colors=color, fill_mode=SOLID)
    if typ == _GEOM.mjGEOM_CAPSULE:
        # Rerun's capsule runs from its origin along +z; MuJoCo's is centred.
        return rr.Capsules3D(
            lengths=[2.0 * s[1]],
            radii=[s[0]],
            translations=[[0.0, 0.0, -s[1]]],
            colors=color,
            fill_mode=SOLID,
        )
    if typ == _GEOM.mjGEOM_CYLINDER:
        return rr.Cylinders3D(lengths=[2.0 * s[1]], radii=[s[0]], colors=color, fill_mode=SOLID)
    if typ == _GEOM.mjGEOM_PLANE:
        hx = s[0] if s[0] > 0 else PLANE_EXTENT
        hy = s[1] if s[1] > 0 else PLANE_EXTENT
        corners = [[-hx, -hy, 0.0], [hx, -hy, 0.0], [hx, hy, 0.0], [-hx, hy, 0.0]]
        return rr.Mesh3D(
            vertex_positions=corners,
            triangle_indices=[[0, 1, 2], [0, 2, 3]],
            vertex_normals=[[0.0, 0.0, 1.0]] * 4,
            albedo_factor=rgba,
        )
    if typ == _GEOM.mjGEOM_MESH and model.geom_dataid[g] >= 0:
        m = int(model.geom_dataid[g])
        va, vn = int(model.mesh_vertadr[m]), int(model.mesh_vertnum[m])
        fa, fn = int(model.mesh_faceadr[m]), int(model.mesh_facenum[m])
        verts = np.array(model.mesh_vert[va : va + vn], dtype=np.float64)
        faces = np.array(model.mesh_face[fa : fa + fn], dtype=np.int64)
        return rr.Mesh3D(
            vertex_positions=verts,
            triangle_indices=faces,
            vertex_normals=_vertex_normals(verts, faces),
            albedo_factor=rgba,
        )
    return None


def geom_rgba(model: mujoco.MjModel, g: int) -> np.ndarray:
    """Colour of geom ``g``: its material's when it has one, else ``geom_rgba``."""
    mat = int(model.geom_matid[g])
    return np.array(model.mat_rgba[mat] if mat >= 0 else model.geom_rgba[g], dtype=np.float64)


def element_names(model: mujoco.MjModel, obj: mujoco.mjtObj, count: int, prefix: str) -> list[str]:
    return [mujoco.mj_id2name(model, obj, i) or f"{prefix}{i}" for i in range(count)]
