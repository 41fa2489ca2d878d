"""Home postures by IK when a description gives none: damped least squares from several seeds
to the world's ``home_tool`` site, distinct solutions best joint margin first (the loader
chooses among them by planning, :mod:`pickplace.planning.home`)."""

from __future__ import annotations

import mujoco
import numpy as np

from pickplace.errors import RobotError
from pickplace.robot.ik import SiteIK, joint_ranges

_IK_DAMPING = 1e-3


_IK_MAX_STEP = 0.3  # [rad] per iteration


_IK_ITERATIONS = 100


HOME_SEEDS = 8
"""Seeds of the IK that finds home candidates when a description gives no home."""


HOME_DISTINCT = 1e-3
"""Home candidates closer than this in every joint [rad] are the same posture."""


def home_candidates(
    model: mujoco.MjModel,
    joint_ids: np.ndarray,
    site: int,
    q_min: np.ndarray,
    q_max: np.ndarray,
    src: str,
) -> list[np.ndarray]:
    """Arm postures that put the tool site on the world's ``home_tool`` site, best first.

    Damped least squares (λ = 1e-3, steps of at most 0.3 rad, 100 iterations) on position and
    orientation from :data:`HOME_SEEDS` deterministic seeds — the middle of each joint's range
    (0 for continuous joints; a zero seed fails where 0 is outside a range), then uniform draws
    over the middle half of the ranges — clamped to the limits each step. The seeds that reach
    the pose within 0.1 mm and 1 mrad give the candidates, each also with its last joint at the
    middle of its range where that only turns the tool about its approach axis (the home's yaw
    about it is free: every plan turns the tool from there, and a wrist near an end of its
    range has no room to turn one way; postures within :data:`HOME_DISTINCT` of each other
    count once), ordered by their distance from the nearest
    joint limit relative to the range (continuous joints count ±π), largest first. Margin alone
    does not make a good home (``docs/physics-notes.md``): the scene loader
    (:mod:`pickplace.sim.loader`) chooses among them by the pre-flight of the nominal plan.
    """
    target = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, HOME_TOOL_SITE)
    if target < 0:
        raise RobotError(
            f"{src}: [arm] home: not given, and the world has no '{HOME_TOOL_SITE}' site to find "
            f"one by IK; valid: set home = [...] (one value per arm joint)"
        )
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    p_goal = data.site_xpos[target].copy()
    q_goal = np.zeros(4)
    mujoco.mju_mat2Quat(q_goal, data.site_xmat[target])
    ik = SiteIK(
        model,
        site,
        model.jnt_qposadr[joint_ids],
        model.jnt_dofadr[joint_ids],
        q_min,
        q_max,
        _IK_DAMPING**2,
        _IK_MAX_STEP,
    )
    lo, hi, mid = joint_ranges(q_min, q_max)
    rng = np.random.default_rng(0)
    seeds = [mid] + [
        mid + rng.uniform(-0.25, 0.25, mid.shape) * (hi - lo) for _ in range(HOME_SEEDS - 1)
    ]

    def on_pose(e: np.ndarray) -> bool:
        return bool(np.linalg.norm(e[:3]) < 1e-4 and np.linalg.norm(e[3:]) < 1e-3)

    z_goal = data.site_xmat[target].reshape(3, 3)[:, 2].copy()

    def wrist_centred(q: np.ndarray) -> np.ndarray | None:
        """``q`` with its last joint at the middle of its range, when that only turns the tool
        about its approach axis (the tool stays on the home position, pointing the same way);
        else None."""
        q_c = q.copy()
        q_c[-1] = mid[-1]
        e = ik.error(q_c, p_goal, q_goal)
        z = ik.data.site_xmat[site].reshape(3, 3)[:, 2]
        if np.linalg.norm(e[:3]) < 1e-4 and float(np.linalg.norm(z - z_goal)) < 1e-3:
            return q_c
        return None

    found: list[tuple[float, np.ndarray]] = []
    for seed in seeds:
        q, _, reached = ik.solve(p_goal, q_goal, seed, _IK_ITERATIONS, on_pose)
        if not reached:
            continue
        for posture in (q.copy(), wrist_centred(q)):
            if posture is not None and all(
                np.max(np.abs(posture - other)) > HOME_DISTINCT for _, other in found
            ):
                margin = float(np.min(np.minimum(posture - lo, hi - posture) / (hi - lo)))
                found.append((margin, posture))
    if not found:
        raise RobotError(
            f"{src}: [arm] home: not given, and IK found no posture that puts the tool on the "
            f"world's '{HOME_TOOL_SITE}' pose; valid: set home = [...] (one value per arm joint)"
        )
    found.sort(key=lambda item: -item[0])
    return [q for _, q in found]


HOME_TOOL_SITE = "home_tool"
"""World site whose pose IK reaches for a home posture when the description gives none."""
