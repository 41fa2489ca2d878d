"""Damped least-squares IK of a site, within joint limits: the one solver behind the home
postures (:mod:`pickplace.robot.home_ik`) and the arm's reach (:mod:`pickplace.robot.reach`).

Each iteration loads q, measures the site's error to the goal — [p_goal − p; rotation vector of
R_goal Rᵀ], in world ([m], [rad]) — stops when the caller's test says the goal is reached, and
otherwise steps Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e, scaled down to at most ``max_step`` in any joint and
clamped to the joint limits.
"""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import numpy as np


def joint_ranges(q_min: np.ndarray, q_max: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint limits with a continuous joint's (±inf) taken as ±π, and the middle of each range
    (0 for a continuous joint; a zero seed fails where 0 is outside a range) [rad or m]: the
    IK's first seed.

    Returns:
        The lower and upper bounds and the middles, each of the joints' shape.
    """
    lo = np.where(np.isfinite(q_min), q_min, -np.pi)
    hi = np.where(np.isfinite(q_max), q_max, np.pi)
    return lo, hi, np.where(np.isfinite(q_min), 0.5 * (lo + hi), 0.0)


class SiteIK:
    """Damped least-squares IK of one site over some of a model's joints.

    Args:
        model: The model.
        site_id: The site driven to the goal.
        qpos_adr: qpos addresses of the joints it moves (hinge or slide joints).
        dof_adr: Their dof addresses, in the same order.
        q_min: Lower joint limits [rad or m] (−inf for a continuous joint).
        q_max: Upper joint limits.
        damping: λ² of the damped least squares [m², rad²].
        max_step: Largest change of any joint in one iteration [rad or m].
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        site_id: int,
        qpos_adr: np.ndarray,
        dof_adr: np.ndarray,
        q_min: np.ndarray,
        q_max: np.ndarray,
        damping: float,
        max_step: float,
    ) -> None:
        self.model = model
        self.data = mujoco.MjData(model)
        self.site_id = site_id
        self.qpos_adr = np.asarray(qpos_adr)
        self.dof_adr = np.asarray(dof_adr)
        self.q_min = np.asarray(q_min, dtype=float)
        self.q_max = np.asarray(q_max, dtype=float)
        self.damping = float(damping)
        self.max_step = float(max_step)
        self._jacp = np.zeros((3, model.nv))
        self._jacr = np.zeros((3, model.nv))
        self._quat = np.zeros(4)
        self._rot_local = np.zeros(3)

    def error(self, q: np.ndarray, p_goal: np.ndarray, quat_goal: np.ndarray) -> np.ndarray:
        """The site's error at ``q`` to the goal (position [m], wxyz quaternion), in world:
        [p_goal − p; rotation vector taking the site's orientation to the goal's] ([m], [rad]).
        Forward kinematics stay loaded at ``q``."""
        d, site = self.data, self.site_id
        d.qpos[self.qpos_adr] = q
        mujoco.mj_kinematics(self.model, d)
        mujoco.mju_mat2Quat(self._quat, d.site_xmat[site])
        mujoco.mju_subQuat(self._rot_local, quat_goal, self._quat)
        e = np.empty(6)
        e[:3] = p_goal - d.site_xpos[site]
        e[3:] = d.site_xmat[site].reshape(3, 3) @ self._rot_local
        return e

    def solve(
        self,
        p_goal: np.ndarray,
        quat_goal: np.ndarray,
        q0: np.ndarray,
        iterations: int,
        reached: Callable[[np.ndarray], bool],
    ) -> tuple[np.ndarray, np.ndarray, bool]:
        """IK from ``q0`` (clamped to the limits) towards the goal: ``iterations`` tests of
        ``reached``, each followed by a step while it fails.

        Args:
            p_goal: Goal position of the site in world [m].
            quat_goal: Goal orientation (wxyz).
            q0: Start [rad or m].
            iterations: Most iterations.
            reached: Whether an error (:meth:`error`) counts as on the goal.

        Returns:
            The joint positions last tested, their error, and whether it was reached.
        """
        q = np.clip(np.asarray(q0, dtype=float), self.q_min, self.q_max)
        eye = np.eye(6)
        e = self.error(q, p_goal, quat_goal)
        for i in range(iterations):
            if reached(e):
                return q, e, True
            if i == iterations - 1:
                break  # no step past the last test: q and e stay the pair it judged
            mujoco.mj_comPos(self.model, self.data)
            mujoco.mj_jacSite(self.model, self.data, self._jacp, self._jacr, self.site_id)
            J = np.vstack([self._jacp[:, self.dof_adr], self._jacr[:, self.dof_adr]])
            dq = J.T @ np.linalg.solve(J @ J.T + self.damping * eye, e)
            step = float(np.max(np.abs(dq)))
            if step > self.max_step:
                dq *= self.max_step / step
            q = np.clip(q + dq, self.q_min, self.q_max)
            e = self.error(q, p_goal, quat_goal)
        return q, e, False
