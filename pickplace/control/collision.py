"""The robot–world collision limit of the QP controller: its geom pairs and its rows each tick.

The limit is mink's :class:`mink.CollisionAvoidanceLimit` (public API): for every geom pair
(a, b) within the detection distance D, with distance d and unit normal n from a to b, one
inequality row on the step Δq [rad]

    −n·(J_b − J_a) Δq ≤ gain_mink · (d − d_min) / dt      (d > d_min; else ≤ 0)

where J_a, J_b are the translational Jacobians of the two nearest points. mink 1.3 divides its
gain by dt although its variable is the step Δq, not a velocity, so the same gain would let
the distance close by gain/dt times its excess per tick (85 times at 100 Hz with mink's default
0.85: no brake until d is within a few µm of d_min). :class:`RobotWorldCollision` hands mink
``gain · dt``, so that a tick closes at most ``gain`` of the excess d − d_min: the distance
decays toward d_min geometrically and never crosses it to first order, at any control rate.

Pairs: every collision geom (contype or conaffinity set) of a robot body that some arm joint
moves — arm links, flange, palm, fingers, sized from the loaded robot; the base, welded to the
world, is left out (no joint changes its distance, and it stands on the floor) — against every
collision geom of the world's contact bodies (:attr:`~pickplace.world.scene.Scene.
world_contact_body_ids`: the floor, the bins, the obstacle; the brick is not one, the gripper
must reach it), filtered by mink's own rules (contype/conaffinity, not welded together, not
parent and child). The floor is kept: it is the same world the pre-flight checks, a low reach
outside the bins can come near it, and a plane pair is the cheapest there is; the links that
stand on it are the welded base, left out. The world's geoms on mocap bodies (an obstacle a
fault moves during the run) get a limit of their own, with larger distances: the plan was
pre-flighted 5 mm clear of the fixed world, but never saw these.

Each tick a broad phase drops the pairs whose robot geom's bounding sphere (MuJoCo's
``geom_rbound`` about its centre), grown by D, misses the world geom's world-aligned bounding
box (``geom_aabb`` turned into world axes, recomputed only when the world moves) — or, for a
plane, lies farther than D above it. Those pairs are farther than D apart, where mink's narrow
phase (``mj_geomDistance`` capped at D) gives no row, so the rows are exactly mink's; only the
survivors get ``mj_geomDistance`` and a Jacobian. Measured on the nominal run's states (iiwa,
133 pairs, a shared 2-core machine): this broad phase 13 µs, with the rows 15 µs; mink's
own (bounding spheres, then its rows) 42–48 µs. MuJoCo's ``mj_collision`` with margins would
cost 4 µs but is no broad phase for this: its box–box narrow phase misses pairs well within
its margin (a pad 28 mm from a bin floor, margin 60 mm).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mink
import mujoco
import numpy as np
from mink.limits.collision_avoidance_limit import compute_contact_normal_jacobian

from pickplace.errors import ControllerError
from pickplace.world.scene import Scene

# mink skips a pair whose capped distance equals the cap to within this [m] (its own test).
_AT_CAP = 1e-12


def collision_geoms(scene: Scene, model: mujoco.MjModel) -> tuple[list[int], list[int], list[int]]:
    """The robot's moving collision geoms and the world's collision geoms in ``model``.

    Args:
        scene: The scene (which bodies are the robot's and which the world's).
        model: The arm-only model (same bodies and geoms as the scene's model).

    Returns:
        (robot geom ids, fixed world geom ids, moving world geom ids: those of mocap bodies,
        which a fault may move during the run), each ascending.
    """
    collides = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
    body = model.geom_bodyid
    moving = model.body_weldid[body] != 0  # welded to the world: no joint moves it
    robot = scene.robot_body_mask[body] & moving & collides
    world = np.isin(body, scene.world_contact_body_ids) & collides
    mocap = model.body_mocapid[body] >= 0
    return (
        np.flatnonzero(robot).tolist(),
        np.flatnonzero(world & ~mocap).tolist(),
        np.flatnonzero(world & mocap).tolist(),
    )


@dataclass(frozen=True)
class Clearance:
    """The distances of a collision limit.

    Attributes:
        min_distance: d_min, the distance the limit keeps [m] (≥ 0).
        detection_distance: D, pairs closer than this get a row [m] (> d_min, finite).

    Raises:
        ControllerError: Out of range.
    """

    min_distance: float
    detection_distance: float

    def __post_init__(self) -> None:
        if not (0.0 <= self.min_distance < self.detection_distance < math.inf):
            raise ControllerError(
                f"collision limit: minimum distance {self.min_distance} m and detection "
                f"distance {self.detection_distance} m; valid: 0 <= minimum < detection, finite"
            )


class RobotWorldCollision:
    """The collision limit between the robot's geoms and the world's, for one controller.

    Two of mink's limits: the robot against the fixed world (which the plan was pre-flighted
    against) and against the world's moving bodies (mocap bodies, which a fault may put in
    the path during the run), each with its own distances; one broad phase for both.

    Args:
        scene: The scene.
        model: The controller's arm-only model.
        dt: Control period [s].
        fixed: Distances kept from the fixed world.
        moving: Distances kept from the moving bodies.
        gain: Fraction of d − d_min a tick may close [-], in (0, 1].

    Raises:
        ControllerError: The gain is out of range, or the robot or the world has no
            collision geom.
    """

    def __init__(
        self,
        scene: Scene,
        model: mujoco.MjModel,
        dt: float,
        fixed: Clearance,
        moving: Clearance,
        gain: float,
    ) -> None:
        if not 0.0 < gain <= 1.0:
            raise ControllerError(f"collision limit gain {gain}; valid: (0, 1]")
        robot, world_fixed, world_moving = collision_geoms(scene, model)
        if not robot or not (world_fixed or world_moving):
            raise ControllerError(
                f"collision limit: {len(robot)} moving robot collision geoms and "
                f"{len(world_fixed) + len(world_moving)} world collision geoms; valid: at "
                "least one of each"
            )
        self.model = model
        self.dt = dt
        self.gain = float(gain)
        # mink's bound is gain_mink (d − d_min) / dt on the step: gain · dt makes it gain of
        # the excess per tick (see the module's docstring).
        self.limits: list[mink.CollisionAvoidanceLimit] = []
        pairs: list[tuple[int, int]] = []
        d_min: list[float] = []
        D: list[float] = []
        for world, clearance in ((world_fixed, fixed), (world_moving, moving)):
            if not world:
                continue
            limit = mink.CollisionAvoidanceLimit(
                model,
                [(robot, world)],
                gain=self.gain * dt,
                minimum_distance_from_collisions=clearance.min_distance,
                collision_detection_distance=clearance.detection_distance,
            )
            self.limits.append(limit)
            group = sorted(limit.geom_id_pairs)
            pairs += group
            d_min += [clearance.min_distance] * len(group)
            D += [clearance.detection_distance] * len(group)
        self.pair_list: list[tuple[int, int]] = pairs
        self._pair_d_min = d_min
        self._pair_D = D
        self._gain_mink = self.gain * dt
        robot_set = set(robot)
        # Each pair as (robot geom, world geom), and a table of pair indices by (row, column)
        # of the broad phase's robot × world grid (−1: not a pair).
        robot_of = [a if a in robot_set else b for a, b in pairs]
        world_of = [b if a in robot_set else a for a, b in pairs]
        self._robot = np.array(sorted(set(robot_of)), dtype=int)
        world_ids = np.array(sorted(set(world_of)), dtype=int)
        is_plane = np.asarray(model.geom_type)[world_ids] == mujoco.mjtGeom.mjGEOM_PLANE
        self._planes = world_ids[is_plane]
        self._boxes = world_ids[~is_plane]
        r_index = {g: i for i, g in enumerate(self._robot.tolist())}
        box_index = {g: i for i, g in enumerate(self._boxes.tolist())}
        plane_index = {g: i for i, g in enumerate(self._planes.tolist())}
        self._box_pair = np.full((len(self._robot), len(self._boxes)), -1, dtype=int)
        self._plane_pair = np.full((len(self._robot), len(self._planes)), -1, dtype=int)
        for i, (r, w) in enumerate(zip(robot_of, world_of, strict=True)):
            if w in box_index:
                self._box_pair[r_index[r], box_index[w]] = i
            else:
                self._plane_pair[r_index[r], plane_index[w]] = i
        # A robot geom lies inside the sphere of radius rbound about its centre; grown by D.
        rbound = np.asarray(model.geom_rbound)[self._robot]
        if np.any(rbound <= 0.0):
            raise ControllerError(
                "collision limit: a robot collision geom without a bounding sphere (a plane or "
                "height field on the robot); valid: bounded geoms"
            )
        # Per cell of the grids: the robot geom's radius grown by the pair's D (0: no pair).
        D_arr = np.array(D)
        self._reach_sq = np.zeros(self._box_pair.shape)
        cells = self._box_pair >= 0
        reach = rbound[:, None] + D_arr[np.maximum(self._box_pair, 0)]
        self._reach_sq[cells] = reach[cells] ** 2
        self._reach = np.full(self._plane_pair.shape, -np.inf)
        cells = self._plane_pair >= 0
        reach = rbound[:, None] + D_arr[np.maximum(self._plane_pair, 0)]
        self._reach[cells] = reach[cells]
        self._box_lo = np.zeros((len(self._boxes), 3))
        self._box_hi = np.zeros((len(self._boxes), 3))
        self._plane_normal = np.zeros((len(self._planes), 3))
        self._plane_offset = np.zeros(len(self._planes))
        self._world_stale = True
        self._fromto = np.empty(6)
        self._normal = np.empty(3)
        self._jac_a = np.empty((3, model.nv))
        self._jac_b = np.empty((3, model.nv))
        self.survivors = 0  # pairs that passed the last broad phase
        self.active = 0  # rows of the last call

    @property
    def n_pairs(self) -> int:
        """Number of robot–world geom pairs the limit watches."""
        return len(self.pair_list)

    def world_moved(self) -> None:
        """The world's bodies may have moved (new mocap poses): the next call recomputes the
        world geoms' bounding boxes from the kinematics then loaded."""
        self._world_stale = True

    def _world_bounds(self, data: mujoco.MjData) -> None:
        """World-aligned bounding boxes of the world's non-plane geoms (``geom_aabb`` turned
        into world axes) and the planes' normals and offsets, from ``data``'s kinematics."""
        boxes = self._boxes
        if len(boxes):
            aabb = np.asarray(self.model.geom_aabb)[boxes]
            R = data.geom_xmat[boxes].reshape(-1, 3, 3)
            center = data.geom_xpos[boxes] + np.einsum("kij,kj->ki", R, aabb[:, :3])
            half = np.einsum("kij,kj->ki", np.abs(R), aabb[:, 3:])
            self._box_lo = center - half
            self._box_hi = center + half
        if len(self._planes):
            # A plane's normal is its frame's z axis; its surface is n·p = n·p_plane.
            normal = data.geom_xmat[self._planes].reshape(-1, 3, 3)[:, :, 2].copy()
            self._plane_normal = normal
            self._plane_offset = np.einsum("pi,pi->p", normal, data.geom_xpos[self._planes])
        self._world_stale = False

    def candidates(self, data: mujoco.MjData) -> list[int]:
        """Indices into :attr:`pair_list` of the pairs that may be within D (the broad phase):
        a robot geom's bounding sphere grown by D meets a world geom's bounding box, or
        reaches below a world plane's surface plus D.

        Args:
            data: Kinematics loaded (``geom_xpos``, ``geom_xmat``) in :attr:`model`'s data.
        """
        if self._world_stale:
            self._world_bounds(data)
        center = data.geom_xpos[self._robot]  # (robot geoms, 3)
        c = center[:, None, :]
        gap = np.maximum(self._box_lo - c, c - self._box_hi)
        np.maximum(gap, 0.0, out=gap)
        near = np.einsum("rbi,rbi->rb", gap, gap) <= self._reach_sq
        found = self._box_pair[near]
        if len(self._planes):
            height = center.dot(self._plane_normal.T) - self._plane_offset
            found = np.concatenate((found, self._plane_pair[height <= self._reach]))
        return [i for i in found.tolist() if i >= 0]  # (a cell without a pair never passes)

    def rows(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """The limit's rows G Δq ≤ h at the loaded kinematics: one per pair within D.

        Exactly the finite rows of mink's ``compute_qp_inequalities`` (same pairs, distances,
        normals, Jacobians and bounds); the others there are 0 ≤ ∞.

        Args:
            data: Kinematics and ``cdof`` loaded (mj_kinematics and mj_comPos).

        Returns:
            New arrays G (k, nv) [m/rad] and h (k,) [m].
        """
        model, dt, gain_mink = self.model, self.dt, self._gain_mink
        fromto, normal, jac_a, jac_b = self._fromto, self._normal, self._jac_a, self._jac_b
        survivors = self.candidates(data)
        self.survivors = len(survivors)
        G_rows: list[np.ndarray] = []
        h: list[float] = []
        pairs, pair_d_min, pair_D = self.pair_list, self._pair_d_min, self._pair_D
        for i in survivors:
            a, b = pairs[i]
            D, d_min = pair_D[i], pair_d_min[i]
            dist = mujoco.mj_geomDistance(model, data, a, b, D, fromto)
            if abs(dist - D) < _AT_CAP:
                continue
            row = compute_contact_normal_jacobian(model, data, a, b, fromto, normal, jac_a, jac_b)
            # As mink computes it (its bound relaxation is 0): gain (d − d_min) per tick.
            h.append(gain_mink * (dist - d_min) / dt if dist > d_min else 0.0)
            G_rows.append(-row if dist >= 0 else row)
        self.active = len(h)
        if not h:
            return np.zeros((0, model.nv)), np.zeros(0)
        return np.array(G_rows), np.array(h)


class GripperBodies:
    """Sets the fingers of the arm-only model at a gap, as the simulation's fingers are.

    The arm-only model has no gripper joints: its gripper bodies sit where the gripper's
    joints at 0 put them, which is neither open nor closed on the brick. For the collision
    limit the controller's own copy of that model gets, for the gap it is told, every gripper
    body that lost its joints placed relative to its parent as the full model's kinematics
    place it at that gap (the calibrated joint positions of every gripper joint,
    :meth:`~pickplace.robot.model.Robot.qpos_for_width`).

    Args:
        scene: The scene (its full model, with the gripper's joints).
        model: The controller's own arm-only model, changed by :meth:`set_width`.
    """

    def __init__(self, scene: Scene, model: mujoco.MjModel) -> None:
        full = scene.model
        self.scene = scene
        self.model = model
        self._data = mujoco.MjData(full)
        self.bodies = [
            b
            for b in range(model.nbody)
            if scene.robot_body_mask[b] and full.body_jntnum[b] > 0 and model.body_jntnum[b] == 0
        ]
        self.parents = [int(model.body_parentid[b]) for b in self.bodies]
        self.width = float("nan")
        self._quat_PW = np.empty(4)
        self._p = np.empty(3)

    def set_width(self, width: float) -> None:
        """Place the gripper bodies at finger gap ``width`` [m] (nothing to do if unchanged).

        The caller runs the kinematics afterwards (the controller does, every tick).
        """
        if width == self.width:
            return
        self.width = width
        full, d, m = self.scene.model, self._data, self.model
        d.qpos[self.scene.gripper_qpos_adr] = self.scene.robot.qpos_for_width(width)
        mujoco.mj_kinematics(full, d)
        quat_PW, p = self._quat_PW, self._p
        for b, parent in zip(self.bodies, self.parents, strict=True):
            # X_PB = X_WP⁻¹ X_WB: p_PB = R_WPᵀ (p_WB − p_WP), q_PB = q_WP⁻¹ q_WB.
            mujoco.mju_negQuat(quat_PW, d.xquat[parent])
            mujoco.mju_rotVecQuat(p, d.xpos[b] - d.xpos[parent], quat_PW)
            m.body_pos[b] = p
            mujoco.mju_mulQuat(m.body_quat[b], quat_PW, d.xquat[b])
