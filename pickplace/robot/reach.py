"""How far the tool reaches along a line of poses, found by IK rather than assumed.

A closed form (upper arm plus forearm from the shoulder, the tool hanging below the wrist as at
home) holds only for arms whose pitch axes are in line with their links; Menagerie's iiwa 14 and
Panda have offsets that put its answer 13 and 25 mm beyond what they reach. Here the reach is
what the arm does: a pose is reachable when damped least-squares IK, within the joint limits,
brings the tool onto it, and the farthest reachable pose along a line is found by bisection,
each IK warm-started from the last reachable solution.
"""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import numpy as np
from mink.lie import SE3, SO3

from pickplace.errors import PlanError
from pickplace.robot.ik import SiteIK

REACHED = 1e-6
"""A pose counts as reached when the tool is within this of it, position [m] and orientation
[rad] together (the norm of the 6-vector error)."""

_MAX_ITERATIONS = 400
_MAX_STEP = 0.1  # largest joint step of one IK iteration [rad]
_DAMPING = 1e-6  # λ² of the damped least squares [m², rad²]


class ReachIK:
    """Damped least-squares IK of the tool site, within joint limits
    (:class:`~pickplace.robot.ik.SiteIK`), over every joint of an arm-only model or over the
    arm joints of a whole scene.

    Args:
        model: Arm-only model (every joint an arm joint, nq = nv), or any model when
            ``joint_ids`` are given.
        site_id: The tool site.
        q_min: Lower joint limits [rad] (−inf for a continuous joint).
        q_max: Upper joint limits [rad].
        joint_ids: The arm's joints in ``model`` (hinge or slide), the others staying where
            the model's ``qpos0`` has them; None: every joint of an arm-only model.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        site_id: int,
        q_min: np.ndarray,
        q_max: np.ndarray,
        joint_ids: np.ndarray | None = None,
    ) -> None:
        if joint_ids is None:
            if model.nq != model.nv:
                raise PlanError(f"reach IK needs an arm-only model (nq = nv), got nq {model.nq}")
            qpos_adr = dof_adr = np.arange(model.nv)
        else:
            qpos_adr, dof_adr = model.jnt_qposadr[joint_ids], model.jnt_dofadr[joint_ids]
        self.ik = SiteIK(model, site_id, qpos_adr, dof_adr, q_min, q_max, _DAMPING, _MAX_STEP)

    def solve(self, X_WG_target: SE3, q0: np.ndarray) -> tuple[np.ndarray, float]:
        """IK from ``q0`` towards ``X_WG_target``.

        Returns:
            The joint positions reached [rad] and the norm of the remaining error.
        """
        q, e, _ = self.ik.solve(
            X_WG_target.translation(),
            X_WG_target.rotation().wxyz,
            q0,
            _MAX_ITERATIONS,
            lambda e: bool(np.linalg.norm(e) < REACHED),
        )
        return q, float(np.linalg.norm(e))


def farthest_reachable(
    ik: ReachIK,
    pose_at: Callable[[float], SE3],
    q_start: np.ndarray,
    r_near: float,
    r_far: float,
    tolerance: float = 1e-4,
) -> float:
    """The largest r in [``r_near``, ``r_far``] whose pose ``pose_at(r)`` the IK reaches.

    Bisection on r: the reachable end of the bracket keeps its IK solution, from which the next
    trial starts, so each trial is a short step along the line.

    Args:
        ik: The IK.
        pose_at: The line of tool poses, by distance along it [m].
        q_start: Where the IK first starts (e.g. the home posture) [rad].
        r_near: A distance whose pose is reachable [m].
        r_far: A distance whose pose is not [m].
        tolerance: Width of the final bracket [m].

    Raises:
        PlanError: ``pose_at(r_near)`` is not reachable, or ``pose_at(r_far)`` is.
    """
    q_near, err = ik.solve(pose_at(r_near), q_start)
    if err >= REACHED:
        raise PlanError(
            f"the tool cannot reach the line's near end at {r_near:.3f} m (error {err:.2g}); "
            f"valid: a line that starts within reach"
        )
    if ik.solve(pose_at(r_far), q_near)[1] < REACHED:
        raise PlanError(f"the tool still reaches the line at {r_far:.3f} m: no reach limit on it")
    lo, hi = r_near, r_far
    while hi - lo > tolerance:
        mid = 0.5 * (lo + hi)
        q_mid, err = ik.solve(pose_at(mid), q_near)
        if err < REACHED:
            lo, q_near = mid, q_mid
        else:
            hi = mid
    return lo


REACH_SAMPLE = 0.05
"""Spacing [m] of the distances along a line tried for a first reachable pose
(:func:`shortfall`)."""


def shortfall(
    ik: ReachIK,
    p_W_axis: np.ndarray,
    p_W_target: np.ndarray,
    rotations: list[SO3],
    seeds: list[np.ndarray],
) -> tuple[float, float]:
    """How far the tool's reach falls short of a point, along the horizontal line from the
    arm's base axis to it, at its height.

    The line's poses are at distance r [m] from the vertical axis through ``p_W_axis``,
    towards ``p_W_target``, at its height, with each of ``rotations``. The point reached is
    the target itself when the IK brings the tool onto it from any seed; else the farthest
    sample every :data:`REACH_SAMPLE` along the line that some seed reaches, pushed out by
    :func:`farthest_reachable`, over every rotation.

    Args:
        ik: The IK.
        p_W_axis: A point of the base's vertical axis [m].
        p_W_target: The point to reach [m].
        rotations: Tool orientations to try (e.g. pointing down, at a few yaws).
        seeds: Joint positions the IK starts from [rad].

    Returns:
        The distance lacking [m] (0 when the target is reached) and the target's horizontal
        distance from the axis [m].
    """
    d_xy = np.asarray(p_W_target[:2], dtype=float) - np.asarray(p_W_axis[:2], dtype=float)
    distance = float(np.linalg.norm(d_xy))
    heading = d_xy / distance if distance > 0.0 else np.array([1.0, 0.0])
    best = 0.0
    for R in rotations:

        def at(r: float, R: SO3 = R) -> SE3:
            p = np.array([*(np.asarray(p_W_axis[:2]) + r * heading), p_W_target[2]])
            return SE3.from_rotation_and_translation(R, p)

        reached: list[tuple[float, np.ndarray]] = []
        for seed in seeds:
            q, err = ik.solve(at(distance), seed)
            if err < REACHED:
                return 0.0, distance
            for r in np.arange(distance - REACH_SAMPLE, best, -REACH_SAMPLE):
                q, err = ik.solve(at(float(r)), seed)
                if err < REACHED:
                    reached.append((float(r), q))
                    break
        for r, q in sorted(reached, key=lambda item: -item[0]):
            if r > best:
                try:
                    best = farthest_reachable(ik, at, q, r, distance)
                except PlanError:  # the target itself, reached along the line from r
                    return 0.0, distance
    return distance - best, distance
