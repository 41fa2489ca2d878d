"""Where the object lies: a pose on a bin's floor, the nominal, target and random placements,
and the check that a placement lies inside the source bin."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from mink.lie import SE3, SO3

from pickplace.errors import InvalidInputError
from pickplace.geometry import box_corners, transform_points
from pickplace.world.scene import BinGeometry, Scene


def brick_pose(x: float, y: float, z: float, yaw: float) -> SE3:
    """Pose ``X_WO`` of a brick lying flat.

    Args:
        x: Centre x [m].
        y: Centre y [m].
        z: Centre z [m].
        yaw: Rotation about world z [rad].
    """
    return SE3.from_rotation_and_translation(
        SO3.from_z_radians(yaw), np.array([x, y, z], dtype=np.float64)
    )


@dataclass(frozen=True)
class BrickPlacement:
    """Brick pose on a bin floor: x, y [m] in world and yaw [rad]."""

    x: float
    y: float
    yaw: float


def brick_on_floor(scene: Scene, p: BrickPlacement, bin_floor_z: float) -> SE3:
    """Pose X_WO of the brick resting flat on a floor at height ``bin_floor_z`` [m]."""
    return brick_pose(p.x, p.y, bin_floor_z + scene.object.rest_height, p.yaw)


def check_brick_in_source_bin(scene: Scene, p: BrickPlacement) -> None:
    """Raise InvalidInputError unless the brick at ``p`` lies flat inside bin 1's inner walls.

    Whether it can be picked there (the open hand's whole footprint, the arm's reach) is the
    planner's question, answered by the pre-flight of its candidates.
    """
    values = (p.x, p.y, p.yaw)
    where = f"brick pose x={p.x:g} m, y={p.y:g} m, yaw={p.yaw:g} rad"
    if not all(math.isfinite(v) for v in values):
        raise InvalidInputError(f"{where}: the values must be finite numbers", field="brick")
    bin_ = scene.source_bin
    X_WO = brick_on_floor(scene, p, bin_.floor_top_z)
    if not footprint_inside(scene, X_WO, scene.source_bin):
        c = bin_.center_W
        h = bin_.inner_half_extents
        raise InvalidInputError(
            f"{where} puts the brick outside {bin_.name}: its footprint must lie within the "
            f"inner walls, centre x in [{c[0] - h[0]:.2f}, {c[0] + h[0]:.2f}] and y in "
            f"[{c[1] - h[1]:.2f}, {c[1] + h[1]:.2f}] m minus the object's half-size at its yaw",
            field="brick",
        )


def footprint_inside(scene: Scene, X_WO: SE3, bin_: BinGeometry, margin: float = 0.0) -> bool:
    """True if the object's footprint at ``X_WO`` lies inside ``bin_``'s inner walls,
    ``margin`` [m] inside them: the brick's box corners, another object's support along the
    bin's four wall normals."""
    box = scene.object.box_half_extents
    if box is not None:
        corners = box_corners([box[0], box[1], 0.0])
        return bin_.contains_xy(transform_points(X_WO, corners), margin)
    R_WB = bin_.X_WB.rotation().as_matrix()
    normals = np.concatenate([R_WB[:, :2].T, -R_WB[:, :2].T])  # +x, +y, -x, -y of B in W
    reach = scene.object.extent_W(X_WO, normals) - normals @ bin_.X_WB.translation()
    limit = np.concatenate([bin_.inner_half_extents, bin_.inner_half_extents]) - margin
    return bool(np.all(reach <= limit))


def target_placement(scene: Scene) -> BrickPlacement:
    """Bin 2's floor centre, yaw 0: where the pick-and-place scenarios put the brick."""
    c = scene.target_bin.center_W
    return BrickPlacement(float(c[0]), float(c[1]), 0.0)


def random_placement(scene: Scene, rng: np.random.Generator) -> BrickPlacement:
    """A yaw uniform in [-π, π), then x, y uniform over the part of bin 1's floor where the
    brick's footprint at that yaw lies inside the inner walls."""
    bin_ = scene.source_bin
    yaw = float(rng.uniform(-math.pi, math.pi))
    yaw_B = yaw - yaw_of_bin(bin_.X_WB)
    half = bin_.inner_half_extents - scene.object.footprint_half(yaw_B)
    u = rng.uniform(-half, half)
    p_W = bin_.X_WB.apply(np.array([u[0], u[1], 0.0]))
    return BrickPlacement(float(p_W[0]), float(p_W[1]), yaw)


def uniform_placement(scene: Scene, rng: np.random.Generator) -> BrickPlacement:
    """A pose drawn uniformly over every valid pose of the brick in bin 1: over the set of
    (x, y, yaw) whose footprint lies inside the inner walls, by rejection.

    x, y are drawn uniformly over the inner floor less the brick's smaller half size (no
    valid centre lies outside that) and the yaw uniformly in [-π, π), until the footprint
    lies inside (:func:`check_brick_in_source_bin`): every valid pose is equally likely,
    unlike :func:`random_placement`, which weights each yaw equally however little room it
    leaves. Whether it can be picked is not asked.
    """
    bin_ = scene.source_bin
    half = bin_.inner_half_extents - scene.object.min_footprint_half
    while True:
        u = rng.uniform(-half, half)
        yaw = float(rng.uniform(-math.pi, math.pi))
        p_W = bin_.X_WB.apply(np.array([u[0], u[1], 0.0]))
        p = BrickPlacement(float(p_W[0]), float(p_W[1]), yaw)
        try:
            check_brick_in_source_bin(scene, p)
        except InvalidInputError:
            continue
        return p


def yaw_of_bin(X_WB: SE3) -> float:
    """Rotation of a bin's frame about world z [rad]."""
    R = X_WB.rotation().as_matrix()
    return math.atan2(float(R[1, 0]), float(R[0, 0]))


def nominal_placement(scene: Scene) -> BrickPlacement:
    """Bin 1's floor centre, yaw 0."""
    c = scene.source_bin.center_W
    return BrickPlacement(float(c[0]), float(c[1]), 0.0)
