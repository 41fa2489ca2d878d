"""Joint-space paths around obstacles: RRT-Connect (OMPL), shortcutting, a smooth spline.

When a candidate's Cartesian transfer (lift → pre-place) collides, the planner
(:mod:`pickplace.planning.planner`) asks for a path in the arm's configuration space between
the joint positions the IK has at the lift and at the pre-place. This module plans it:

1. **RRT-Connect** (OMPL's ``geometric.RRTConnect``) in the arm's joint space, scaled per joint
   by its lever arm ``w_j`` [m/rad] (:func:`lever_arms`: the longest distance a robot point or
   the held brick can have from joint j's axis), so distances are metres of motion;
2. **shortcutting** (OMPL's ``PathSimplifier.simplifyMax``: vertex reduction, shortcuts,
   B-spline smoothing of the polyline, each change collision-checked);
3. **smoothing**: a natural cubic spline q(u) through the simplified vertices, parameterised
   by the scaled chord length (C², so the timing sees finite joint accelerations), checked
   again densely; where it leaves the free space, the midpoints of the polyline's edge there
   and of its neighbours become knots, and it is fitted again (at most
   :attr:`CSpaceConfig.max_refinements` times).

Every configuration is checked with the pre-flight's own collision check (a
:class:`ClearanceCheck`: the kinematic copy of the scene, ``mj_collision`` with margins, the
robot and the held brick against the world) at the pre-flight's clearance. Motions are checked
at steps whose scaled L1 length Σ w_j |Δq_j| is at most :attr:`CSpaceConfig.check_step`: no
point of the robot or the brick moves farther than that between two checks, and a step of
twice the clearance cannot cross a wall without one check inside its clearance.

OMPL's random numbers come from its global seed, set from the run's seed before each planning
(``ompl.util.RNG.setSeed``), and its budget is a number of collision checks
(:attr:`CSpaceConfig.max_checks`), not time: the same seed gives the same path, or the same
refusal, in every process and on a busy or idle machine alike. :attr:`CSpaceConfig.budget_s`
is only a bound on the wall time, ten times what the check budget takes here, that a machine
far slower than this one could reach; a stop request (:func:`pickplace.signals.stop_point`)
ends a planning at the next check.
"""

from __future__ import annotations

import bisect
import math
import time
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from pickplace.control.kinematics import ArmKinematics
from pickplace.errors import PlanError, require_non_negative, require_positive
from pickplace.geometry import FloatArray
from pickplace.signals import stop_point

# A stop request is looked for every this many collision checks.
_STOP_CHECKS = 64
# The most knots a refinement may reach before giving up.
_MAX_KNOTS = 400


@dataclass(frozen=True)
class CSpaceConfig:
    """Budget and resolution of C-space planning.

    Attributes:
        max_checks: Most collision checks of one planning, RRT-Connect, simplification and
            the spline's refinement together: its budget, deterministic. A path for the
            bundled robots' obstacle cells takes about 11,000 checks (0.3 s at the 29 µs a
            check measured with ``scripts/bench.py``); 60,000 take about 1.7 s.
        budget_s: Bound on the wall time of one planning [s]: ten times what the check budget
            takes on this machine's kind, so it binds only on a far slower machine (then the
            refusal depends on that machine's speed).
        check_step: Largest scaled L1 length Σ w_j |Δq_j| between two collision checks of a
            motion [m]: no robot point moves farther between them.
        planner_range: RRT-Connect's longest edge, in the scaled joint space [m].
        max_refinements: How often the spline is fitted again with another knot where it
            leaves the free space.
        extra_clearance: What the path keeps from the world beyond the pre-flight's clearance
            [m]: the IK follows the joint path within a few mm at the tool (its null space
            starts up to 0.05 rad off and converges in about 0.3 s), and the pre-flight of
            the whole plan judges at its own clearance.
    """

    max_checks: int = 60_000
    budget_s: float = 20.0
    check_step: float = 0.01
    planner_range: float = 0.5
    max_refinements: int = 12
    extra_clearance: float = 0.003

    def __post_init__(self) -> None:
        """Validate: the budget, step and range finite and > 0, refinements ≥ 0."""
        for name in ("budget_s", "check_step", "planner_range"):
            require_positive(f"c-space {name}", getattr(self, name))
        require_non_negative("c-space extra_clearance", self.extra_clearance, PlanError)
        for name, least in (("max_refinements", 0), ("max_checks", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not (isinstance(value, int) and value >= least):
                raise PlanError(f"c-space {name} must be an integer >= {least}, got {value!r}")


class ClearanceCheck(Protocol):
    """The pre-flight's collision check at one configuration (see
    :meth:`pickplace.planning.preflight.Preflight.held_clearance`)."""

    def __call__(self, q: np.ndarray) -> tuple[float, tuple[str, str, tuple[float, ...]] | None]:
        """Smallest robot/brick–world distance [m] at ``q`` and its pair and point (or None
        when nothing is within the detection distance)."""


class JointPath:
    """A natural cubic spline q(u), u ∈ [0, 1], through joint-space knots.

    The spline parameter is the scaled chord length s (Σ over the knots of ‖w ⊙ Δq‖₂ [m]),
    u = s / L; q''(0) = q''(1) = 0.

    Args:
        knots: Joint positions (m, n) [rad], m ≥ 2, consecutive ones distinct.
        weights: Lever arms w (n,) [m/rad] of the scaled metric.

    Raises:
        PlanError: Fewer than 2 knots, non-finite values, repeated consecutive knots or bad
            weights.
    """

    def __init__(self, knots: np.ndarray, weights: np.ndarray) -> None:
        y = np.asarray(knots, dtype=np.float64)
        w = np.asarray(weights, dtype=np.float64)
        if y.ndim != 2 or len(y) < 2 or w.shape != (y.shape[1],):
            raise PlanError(f"a joint path needs (m >= 2, n) knots and n weights, got {y.shape}")
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(w)) and np.all(w > 0)):
            raise PlanError("a joint path's knots and weights must be finite, weights > 0")
        h = np.linalg.norm(np.diff(y, axis=0) * w, axis=1)
        if np.any(h <= 1e-12):
            raise PlanError("a joint path's consecutive knots must differ")
        self.knots = y.copy()
        self.weights = w.copy()
        self._s = np.concatenate([[0.0], np.cumsum(h)])
        self.length = float(self._s[-1])
        m = len(y)
        # Second derivatives M at the knots: natural spline (M_0 = M_{m-1} = 0).
        M = np.zeros_like(y)
        if m > 2:
            A = np.zeros((m - 2, m - 2))
            rhs = np.zeros((m - 2, y.shape[1]))
            for i in range(1, m - 1):
                r = i - 1
                A[r, r] = 2.0 * (h[i - 1] + h[i])
                if r > 0:
                    A[r, r - 1] = h[i - 1]
                if r < m - 3:
                    A[r, r + 1] = h[i]
                rhs[r] = 6.0 * ((y[i + 1] - y[i]) / h[i] - (y[i] - y[i - 1]) / h[i - 1])
            M[1:-1] = np.linalg.solve(A, rhs)
        # Per interval: q(s) = a + b t + c t² + d t³, t = s − s_i.
        hh = h[:, None]
        self._a = y[:-1]
        self._b = (y[1:] - y[:-1]) / hh - hh * (2.0 * M[:-1] + M[1:]) / 6.0
        self._c = 0.5 * M[:-1]
        self._d = (M[1:] - M[:-1]) / (6.0 * hh)
        self._s_list = self._s.tolist()

    def interval(self, u: float) -> int:
        """Index i of the knot interval [knot i, knot i + 1] that holds ``u``."""
        s = min(max(u, 0.0), 1.0) * self.length
        return min(max(bisect.bisect_right(self._s_list, s) - 1, 0), len(self._a) - 1)

    def at(self, u: float) -> tuple[FloatArray, FloatArray]:
        """(q [rad], dq/du [rad]) at ``u`` (clamped to [0, 1])."""
        s = min(max(u, 0.0), 1.0) * self.length
        i = min(max(bisect.bisect_right(self._s_list, s) - 1, 0), len(self._a) - 1)
        t = s - self._s_list[i]
        a, b, c, d = self._a[i], self._b[i], self._c[i], self._d[i]
        q = a + t * (b + t * (c + t * d))
        dq_ds = b + t * (2.0 * c + 3.0 * t * d)
        return q, dq_ds * self.length

    def scaled_l1_length(self, samples: int = 200) -> float:
        """Σ w_j ∫|dq_j| along the path [m], from ``samples`` points per knot interval."""
        qs = self.samples(samples * (len(self.knots) - 1))
        return float(np.sum(np.abs(np.diff(qs, axis=0)) * self.weights))

    def samples(self, count: int) -> FloatArray:
        """``count`` + 1 configurations at u = k / count (count + 1, n) [rad]."""
        return np.array([self.at(k / count)[0] for k in range(count + 1)])


class JointMotion:
    """A joint path as a trajectory segment (:class:`pickplace.planning.trajectory.
    JointSegment`): the tool pose by forward kinematics of q(u), V_WG = J(q) q'(u) u̇.

    Args:
        path: The joint path.
        kinematics: The arm's kinematics (tool pose and Jacobian at q); owned by this segment.
    """

    def __init__(self, path: JointPath, kinematics: ArmKinematics) -> None:
        self.path = path
        self.kinematics = kinematics

    def sample(
        self, u: float, u_dot: float
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """(x_WG wxyz_xyz [-, m], V_WG [m/s, rad/s], q [rad], q̇ [rad/s]) at ``u`` with path
        speed ``u_dot`` [1/s]; new arrays."""
        q, dq_du = self.path.at(u)
        kin = self.kinematics
        kin.update(q)
        q_dot = dq_du * u_dot
        return np.array(kin.wxyz_xyz_list()), kin.J_WG() @ q_dot, q, q_dot


@dataclass(frozen=True)
class CSpaceResult:
    """What a C-space planning found.

    Attributes:
        path: The smoothed joint path, or None.
        problem: Why there is none (what blocks, in words), or None.
        time_s: Wall time spent [s].
        checks: Collision checks made.
        vertices: Vertices of OMPL's path after simplification (0 without one).
        ompl_s: Wall time of OMPL's part, RRT-Connect and the simplifier [s] (the rest:
            the start and goal checks and the spline's fit and checks).
    """

    path: JointPath | None
    problem: str | None
    time_s: float
    checks: int
    vertices: int = 0
    ompl_s: float = 0.0


def lever_arms(kinematics: ArmKinematics, q: np.ndarray, hand_reach: float) -> FloatArray:
    """Per joint j, an upper bound of the distance of any point of the links after it (and of
    the held object) from its axis [m]: the link lengths from its anchor on, anchor to anchor
    (fixed in each link, whatever the posture), to the tool, plus ``hand_reach`` [m] (the
    farthest point of the hand or the held object from the tool)."""
    kinematics.update(q)
    n = len(q)
    anchors = kinematics.data.xanchor[:n].copy()
    p_tool = kinematics.p_WG()
    links = np.linalg.norm(np.diff(np.vstack([anchors, p_tool]), axis=0), axis=1)
    return np.array([links[j:].sum() + hand_reach for j in range(n)])


def _motion_steps(q0: np.ndarray, q1: np.ndarray, weights: np.ndarray, step: float) -> int:
    """Checks needed along the straight motion q0 → q1 so that each scaled L1 step ≤ step."""
    return max(1, math.ceil(float(np.sum(np.abs(q1 - q0) * weights)) / step))


def _describe(contact: tuple[str, str, tuple[float, ...]] | None, distance: float) -> str:
    if contact is None:
        return f"nothing within {distance * 1000:.0f} mm"
    a, b, _ = contact
    return f"{a} within {distance * 1000:.1f} mm of {b}"


def plan_joint_path(
    check: ClearanceCheck,
    q_start: np.ndarray,
    q_goal: np.ndarray,
    q_low: np.ndarray,
    q_high: np.ndarray,
    weights: np.ndarray,
    clearance: float,
    seed: int,
    config: CSpaceConfig | None = None,
) -> CSpaceResult:
    """A collision-free joint path from ``q_start`` to ``q_goal`` (see the module docstring).

    Args:
        check: The pre-flight's collision check.
        q_start: Start configuration [rad] (n,).
        q_goal: Goal configuration [rad] (n,).
        q_low: Lower joint bounds of the search [rad] (n,), finite.
        q_high: Upper joint bounds [rad] (n,), finite.
        weights: Lever arms of the scaled metric [m/rad] (n,) (:func:`lever_arms`).
        clearance: Smallest distance a valid configuration keeps from the world [m].
        seed: Seeds OMPL's random numbers (the run's seed and the attempt; 0 is mapped to 1).
        config: Budget and resolution.

    Returns:
        The path, or the problem: the start or the goal in collision (naming the pair), or no
        path within the budget (naming the pair that refused the most checks).

    Raises:
        Interrupted: A stop request arrived (:func:`pickplace.signals.stop_point`).
    """
    cfg = config or CSpaceConfig()
    t0 = time.perf_counter()
    deadline = t0 + cfg.budget_s
    w = np.asarray(weights, dtype=np.float64)
    counts = {"checks": 0}
    blockers: dict[tuple[str, str], int] = {}
    caught: list[BaseException] = []

    def clear(q: np.ndarray) -> bool:
        counts["checks"] += 1
        d, contact = check(q)
        if d >= clearance:
            return True
        key = (contact[0], contact[1]) if contact is not None else ("?", "?")
        blockers[key] = blockers.get(key, 0) + 1
        return False

    lo, hi = np.asarray(q_low), np.asarray(q_high)
    for what, q in (("start (the lift)", q_start), ("goal (the pre-place)", q_goal)):
        q = np.asarray(q, dtype=np.float64)
        outside = np.flatnonzero(~((q >= lo) & (q <= hi)))  # NaN is outside too
        if len(outside):
            j = int(outside[0])
            return CSpaceResult(
                None,
                f"the c-space path's {what} lies outside the search's joint bounds: joint {j} "
                f"at {q[j]:.3f} rad, bounds [{lo[j]:.3f}, {hi[j]:.3f}] rad",
                time.perf_counter() - t0,
                counts["checks"],
            )
        d, contact = check(q)
        counts["checks"] += 1
        if d < clearance:
            return CSpaceResult(
                None,
                f"the c-space path's {what} collides: {_describe(contact, d)} (clearance "
                f"{clearance * 1000:.0f} mm)",
                time.perf_counter() - t0,
                counts["checks"],
            )

    def expired() -> bool:
        return bool(caught) or counts["checks"] >= cfg.max_checks or time.perf_counter() > deadline

    def valid(q: np.ndarray) -> bool:
        if caught:
            return False
        if counts["checks"] % _STOP_CHECKS == 0:
            try:
                stop_point()
            except BaseException as exc:  # raised after OMPL returns, without this frame
                caught.append(exc.with_traceback(None))
                return False
        return clear(q)

    # OMPL's objects live in _rrt_connect's frame only, gone before anything is raised here.
    t_ompl = time.perf_counter()
    vertices = _rrt_connect(q_start, q_goal, q_low, q_high, w, seed, cfg, valid, expired)
    ompl_s = time.perf_counter() - t_ompl
    if caught:
        raise caught[0]
    if vertices is None:
        worst = max(blockers.items(), key=lambda kv: kv[1])[0] if blockers else ("?", "?")
        return CSpaceResult(
            None,
            f"no c-space path from the lift to the pre-place within {cfg.max_checks} "
            f"collision checks ({counts['checks']} made; most refused: {worst[0]} within "
            f"{clearance * 1000:.0f} mm of {worst[1]})",
            time.perf_counter() - t0,
            counts["checks"],
            ompl_s=ompl_s,
        )

    def free(q: np.ndarray) -> bool:
        return bool(np.all(q >= lo) and np.all(q <= hi)) and clear(q)

    smooth = _smoothed(vertices, w, free, cfg, expired)
    if caught:
        raise caught[0]
    elapsed = time.perf_counter() - t0
    if smooth is None:
        return CSpaceResult(
            None,
            "the c-space path could not be smoothed within the free space "
            f"({cfg.max_refinements} refinements, {cfg.max_checks} checks)",
            elapsed,
            counts["checks"],
            len(vertices),
            ompl_s,
        )
    return CSpaceResult(smooth, None, elapsed, counts["checks"], len(vertices), ompl_s)


def _rrt_connect(
    q_start: np.ndarray,
    q_goal: np.ndarray,
    q_low: np.ndarray,
    q_high: np.ndarray,
    w: np.ndarray,
    seed: int,
    cfg: CSpaceConfig,
    valid: object,
    expired: object,
) -> np.ndarray | None:
    """OMPL's RRT-Connect in the scaled joint space, then its path simplifier: the path's
    vertices (m, n) [rad], or None without an exact solution before ``expired``."""
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    assert callable(valid) and callable(expired)
    n = len(q_start)
    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(int(seed) % (2**31 - 1) or 1)
    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    for j in range(n):
        bounds.setLow(j, float(q_low[j] * w[j]))
        bounds.setHigh(j, float(q_high[j] * w[j]))
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)
    si.setStateValidityChecker(lambda state: valid(np.array([state[j] for j in range(n)]) / w))
    # OMPL checks motions at a fraction of the space's extent; an L2 step of check_step / √n
    # bounds the scaled L1 step by check_step.
    si.setStateValidityCheckingResolution(cfg.check_step / math.sqrt(n) / si.getMaximumExtent())
    si.setup()
    start, goal = si.allocState(), si.allocState()
    for j in range(n):
        start[j] = float(q_start[j] * w[j])
        goal[j] = float(q_goal[j] * w[j])
    pdef = ob.ProblemDefinition(si)
    pdef.setStartAndGoalStates(start, goal)
    planner = og.RRTConnect(si)
    planner.setRange(cfg.planner_range)
    planner.setProblemDefinition(pdef)
    planner.setup()
    ptc = ob.PlannerTerminationCondition(lambda: bool(expired()))
    status = planner.solve(ptc)
    if status.getStatus() != ob.PlannerStatus.EXACT_SOLUTION or expired():
        return None
    path = pdef.getSolutionPath()
    og.PathSimplifier(si).simplify(path, ptc)
    if expired():
        return None
    states = [path.getState(i) for i in range(path.getStateCount())]
    return np.array([[state[j] for j in range(n)] for state in states]) / w


def _dedup(points: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``points`` without consecutive repeats."""
    keep = [0]
    for i in range(1, len(points)):
        if float(np.linalg.norm((points[i] - points[keep[-1]]) * weights)) > 1e-9:
            keep.append(i)
    if keep[-1] != len(points) - 1:
        keep[-1] = len(points) - 1
    return points[keep]


def _smoothed(
    vertices: np.ndarray,
    weights: np.ndarray,
    clear: object,
    cfg: CSpaceConfig,
    expired: object,
) -> JointPath | None:
    """The spline through the polyline's vertices, refined until it is free (or None)."""
    assert callable(clear) and callable(expired)
    knots = _dedup(vertices, weights)
    for _ in range(cfg.max_refinements + 1):
        if expired():
            return None
        path = JointPath(knots, weights)
        bad = _first_collision(path, weights, clear, cfg.check_step, expired)
        if expired():
            return None
        if bad is None:
            return path
        if len(knots) >= _MAX_KNOTS:
            return None
        # The knot interval where the spline leaves the free space and its neighbours: the
        # polyline's edges there (free, OMPL checked them) get their midpoints as knots, which
        # pulls the spline onto the polyline around the corner it cut.
        i = path.interval(bad)
        for j in sorted({max(i - 1, 0), i, min(i + 1, len(knots) - 2)}, reverse=True):
            knots = np.insert(knots, j + 1, 0.5 * (knots[j] + knots[j + 1]), axis=0)
    return None


def _first_collision(
    path: JointPath, weights: np.ndarray, clear: object, step: float, expired: object
) -> float | None:
    """The first u at which ``path`` is not free, or None: checked at steps of u whose scaled
    L1 length, by the path's local speed Σ w_j |dq_j/du|, is at most ``step`` (0 when
    ``expired`` says the budget is spent)."""
    assert callable(clear) and callable(expired)
    u = 0.0
    while True:
        if expired():
            return u
        q, dq_du = path.at(u)
        if not clear(q):
            return u
        if u >= 1.0:
            return None
        speed = float(np.sum(np.abs(dq_du) * weights))
        u = min(1.0, u + step / max(speed, step))


__all__ = [
    "CSpaceConfig",
    "CSpaceResult",
    "ClearanceCheck",
    "JointMotion",
    "JointPath",
    "lever_arms",
    "plan_joint_path",
]
