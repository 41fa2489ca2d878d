"""The hulls the open hand's footprint is made of (:func:`pickplace.planning.candidates.
hull_of`): each encloses its geom, exactly for a box and a mesh (the hull MuJoCo collides
with), within the polytope's sides for a round geom; checked by support functions along many
directions against each geom's own."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from pickplace.planning.candidates import ROUND_SIDES, _round_hull, hull_of
from pickplace.planning.planner import PickPlacePlanner
from pickplace.robot.registry import bundled_robots
from pickplace.sim.loader import load_scene

RNG_SEED = 31
# A round geom's polytope: rings scaled out by 1/cos(π/sides) about the axis and by
# 1/cos(π/sides) again over the latitude steps (half as many over half a turn).
ROUND_SLACK = 1.0 / math.cos(math.pi / ROUND_SIDES) ** 2


def _directions(n: int) -> np.ndarray:
    u = np.random.default_rng(RNG_SEED).normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _true_support(kind: int, size: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Each round geom's own support function along unit directions ``u`` (n, 3)."""
    r, h = float(size[0]), float(size[1])
    if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        return np.full(len(u), r)
    if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
        return h * np.abs(u[:, 2]) + r
    if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        return h * np.abs(u[:, 2]) + r * np.linalg.norm(u[:, :2], axis=1)
    return np.linalg.norm(u * size, axis=1)  # an ellipsoid


@pytest.mark.parametrize(
    ("kind", "size"),
    [
        (mujoco.mjtGeom.mjGEOM_SPHERE, (0.03, 0.0, 0.0)),
        (mujoco.mjtGeom.mjGEOM_CAPSULE, (0.03, 0.06, 0.0)),
        (mujoco.mjtGeom.mjGEOM_CYLINDER, (0.02, 0.05, 0.0)),
        (mujoco.mjtGeom.mjGEOM_ELLIPSOID, (0.01, 0.02, 0.04)),
    ],
)
def test_a_round_geom_s_polytope_encloses_it_within_its_sides(
    kind: int, size: tuple[float, float, float]
) -> None:
    u = _directions(2000)
    V, E = _round_hull(kind, np.array(size))
    hull = (u @ V.T).max(axis=1)
    true = _true_support(kind, np.array(size), u)
    assert np.all(hull >= true - 1e-12)
    assert np.all(hull <= ROUND_SLACK * true + 1e-12)
    # Every edge joins two distinct vertices, and every vertex has one.
    assert np.all(E[:, 0] != E[:, 1])
    assert set(np.unique(E)) == set(range(len(V)))


@pytest.mark.parametrize("robot", bundled_robots())
def test_every_hand_geom_s_hull_encloses_it(robot: str) -> None:
    """A box's and a mesh's hull have the geom's own support (a mesh's: its vertices' largest
    extent, which is what MuJoCo's convex collisions use); a round geom's is at most
    :data:`ROUND_SLACK` larger. Every hull vertex is an end of an edge."""
    scene = load_scene(robot=robot)
    planner = PickPlacePlanner(scene, "qp")
    m = planner.hand.model
    u = _directions(500)
    kinds = set()
    for g in planner.hand.geom_ids:
        kind = int(m.geom_type[g])
        kinds.add(kind)
        V, E = hull_of(m, int(g))
        hull = (u @ V.T).max(axis=1)
        if kind == mujoco.mjtGeom.mjGEOM_MESH:
            mesh = int(m.geom_dataid[g])
            a, n = int(m.mesh_vertadr[mesh]), int(m.mesh_vertnum[mesh])
            true = (u @ m.mesh_vert[a : a + n].T).max(axis=1)
            np.testing.assert_allclose(hull, true, atol=1e-9)
        elif kind == mujoco.mjtGeom.mjGEOM_BOX:
            true = np.abs(u) @ m.geom_size[g]
            np.testing.assert_allclose(hull, true, atol=1e-12)
        else:
            true = _true_support(kind, m.geom_size[g], u)
            assert np.all(hull >= true - 1e-12) and np.all(hull <= ROUND_SLACK * true + 1e-12)
        assert set(np.unique(E)) == set(range(len(V)))
    assert kinds  # the hand has collision geoms


def test_a_hull_is_tighter_than_the_box_around_it() -> None:
    """The robosuite Panda hand's palm is a capsule: its polytope reaches less far along the
    box's diagonals than the capsule's bounding box, by about (√3 − 1)·r at the ends' corners."""
    scene = load_scene(robot="panda-hand")
    planner = PickPlacePlanner(scene, "qp")
    m = planner.hand.model
    caps = [
        int(g) for g in planner.hand.geom_ids if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE
    ]
    assert caps
    g = caps[0]
    V, _ = hull_of(m, g)
    r, h = m.geom_size[g][:2]
    diagonal = np.array([1.0, 1.0, 1.0]) / math.sqrt(3.0)
    box = float(np.array([r, r, r + h]) @ diagonal)
    assert float((V @ diagonal).max()) < box - 0.5 * (math.sqrt(3.0) - 1.0) * r
