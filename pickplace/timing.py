"""Time-optimal timing of a path by the robot's limits (TOPP on the TOPP-RA discretisation).

A motion segment of a plan is a geometric path: the tool pose as a function of a path parameter
u ∈ [0, 1] (straight line and slerp), and the joint path q(u) the controller follows along it,
sampled by the pre-flight on a uniform grid u_k = k / N. A timing is a time law u(t). With
x = u̇² and w = ü, the joint velocities and accelerations are

    q̇ = q'(u) u̇,        q̈ = q''(u) x + q'(u) w,

so every limit is linear in (w, x) at a grid point: joint speeds |q'ⱼ| √x ≤ vⱼ, joint
accelerations −aⱼ ≤ q''ⱼ x + q'ⱼ w ≤ aⱼ, tool speed |p'| √x ≤ v, tool acceleration
|p'| |w| ≤ a (p'' = 0 on a straight line), angular speed and acceleration likewise with |φ|, and
for a carried brick the friction budget |p' w − g| ≤ A (the brick's acceleration against
gravity must stay within what the pads' friction can hold).

:func:`time_optimal_law` solves the TOPP-RA discretisation (Pham & Pham 2018: x_{k+1} = x_k +
2Δ w_k, constraints evaluated at u_k) with zero speed at both ends by a backward pass (the
largest speed at each grid point from which the end can still be reached, stopping within the
limits) and a forward pass (the largest speed reachable from the start). With only these box
constraints per grid point each pass is closed-form; ``tests/test_timing.py`` compares the result
with the ``toppra`` package. Between grid points the acceleration w is constant, so the law is
piecewise quadratic in time: :class:`TabulatedLaw`.
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pickplace.errors import InvalidInputError, PlanError, require_positive
from pickplace.geometry import rotation_log
from pickplace.plan import Phases, Plan
from pickplace.trajectory import Keyframe, PoseTrajectory

GRAVITY_W = np.array([0.0, 0.0, -9.81])
# Speeds below this count as zero when timing a grid interval [1/s].
_TINY = 1e-12


@dataclass(frozen=True)
class SegmentLimits:
    """Limits of one motion segment, in the units of the path.

    Attributes:
        v_max: Joint speed limits (n,) [rad/s].
        a_max: Joint acceleration limits (n,) [rad/s²].
        tool_speed: Largest tool speed [m/s], or None.
        tool_accel: Largest tool acceleration [m/s²], or None.
        tool_angular_speed: Largest tool angular speed [rad/s], or None.
        tool_angular_accel: Largest tool angular acceleration [rad/s²], or None.
        slip_accel: While a brick is carried: the largest |a − g| of the tool [m/s²] that the
            pads' friction holds (μ · 2 · grip force / (mass · safety factor)); None when
            nothing is carried.
    """

    v_max: np.ndarray
    a_max: np.ndarray
    tool_speed: float | None = None
    tool_accel: float | None = None
    tool_angular_speed: float | None = None
    tool_angular_accel: float | None = None
    slip_accel: float | None = None


@dataclass(frozen=True)
class TabulatedLaw:
    """u(t) through grid points u_k at times t_k, with speeds u̇_k and constant acceleration
    between them.

    Attributes:
        t: Times of the grid points [s], from 0, increasing (K + 1,).
        u: Path parameter at them [-] (K + 1,), from 0 to 1.
        u_dot: Path speed at them [1/s] (K + 1,), zero at both ends.
        u_ddot: Path acceleration on each interval [1/s²] (K,).
    """

    t: tuple[float, ...]
    u: tuple[float, ...]
    u_dot: tuple[float, ...]
    u_ddot: tuple[float, ...]

    @property
    def duration(self) -> float:
        """Time to run the whole segment [s]."""
        return self.t[-1]

    def __call__(self, t: float) -> tuple[float, float]:
        """(u, u̇) at local time ``t`` [s], clamped to [0, duration]."""
        times = self.t
        if t <= 0.0:
            return 0.0, 0.0
        if t >= times[-1]:
            return 1.0, 0.0
        k = bisect.bisect_right(times, t) - 1
        d = t - times[k]
        w = self.u_ddot[k]
        return self.u[k] + (self.u_dot[k] + 0.5 * w * d) * d, self.u_dot[k] + w * d


def path_derivatives(q: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """q'(u) and q''(u) on a uniform grid u_k = k / N from samples q (N + 1, n).

    Second-order central differences inside, second-order one-sided at the ends.

    Raises:
        PlanError: Fewer than 3 samples.
    """
    q = np.asarray(q, dtype=np.float64)
    if q.ndim != 2 or len(q) < 3:
        raise PlanError(f"a joint path needs at least 3 samples (N + 1, n), got {q.shape}")
    n = len(q) - 1
    h = 1.0 / n
    dq = np.empty_like(q)
    dq[1:-1] = (q[2:] - q[:-2]) / (2 * h)
    dq[0] = (-3 * q[0] + 4 * q[1] - q[2]) / (2 * h)
    dq[-1] = (3 * q[-1] - 4 * q[-2] + q[-3]) / (2 * h)
    ddq = np.empty_like(q)
    ddq[1:-1] = (q[2:] - 2 * q[1:-1] + q[:-2]) / h**2
    ddq[0], ddq[-1] = ddq[1], ddq[-2]
    return dq, ddq


def time_optimal_law(
    q: npt.ArrayLike, dp_W: npt.ArrayLike, phi_W: npt.ArrayLike, limits: SegmentLimits
) -> TabulatedLaw:
    """The fastest u(t) along a sampled joint path that respects every limit, at rest at both
    ends (see the module docstring).

    Args:
        q: Joint path at u_k = k / N, shape (N + 1, n) [rad].
        dp_W: Tool displacement over the segment, p' (3,) [m]: the line is p0 + u dp.
        phi_W: Tool rotation vector over the segment, in world (3,) [rad].
        limits: The segment's limits.

    Raises:
        PlanError: A limit leaves no motion possible (e.g. a zero speed limit).
    """
    dq, ddq = path_derivatives(q)
    n_grid = len(dq)
    h = 1.0 / (n_grid - 1)
    v_max = np.asarray(limits.v_max, dtype=np.float64)
    a_max = np.asarray(limits.a_max, dtype=np.float64)
    dp = np.asarray(dp_W, dtype=np.float64)
    lin, ang = float(np.linalg.norm(dp)), float(np.linalg.norm(phi_W))
    # Speed limits: x ≤ x_max.
    with np.errstate(divide="ignore"):
        x_max = np.min((v_max / np.abs(dq)) ** 2, axis=1)
    if limits.tool_speed is not None and lin > 0:
        x_max = np.minimum(x_max, (limits.tool_speed / lin) ** 2)
    if limits.tool_angular_speed is not None and ang > 0:
        x_max = np.minimum(x_max, (limits.tool_angular_speed / ang) ** 2)
    # Acceleration limits as c w + d x ≤ e, one row per bound: (K, m) arrays.
    c = np.concatenate([dq, -dq], axis=1)
    d = np.concatenate([ddq, -ddq], axis=1)
    e = np.concatenate([np.broadcast_to(a_max, dq.shape)] * 2, axis=1)
    w_lo, w_hi = -math.inf, math.inf
    if limits.tool_accel is not None and lin > 0:
        w_lo, w_hi = max(w_lo, -limits.tool_accel / lin), min(w_hi, limits.tool_accel / lin)
    if limits.tool_angular_accel is not None and ang > 0:
        bound = limits.tool_angular_accel / ang
        w_lo, w_hi = max(w_lo, -bound), min(w_hi, bound)
    if limits.slip_accel is not None and lin > 0:
        # |dp w − g|² ≤ A²: lin² w² − 2 (dp·g) w + |g|² − A² ≤ 0.
        b = float(dp @ GRAVITY_W)
        disc = b * b - lin * lin * (float(GRAVITY_W @ GRAVITY_W) - limits.slip_accel**2)
        if disc < 0:
            raise PlanError(
                f"the carried brick would slip even at rest (grip allows {limits.slip_accel:.2f} "
                "m/s² against gravity's 9.81): it is too heavy for the grip"
            )
        root = math.sqrt(disc)
        w_lo, w_hi = max(w_lo, (b - root) / lin**2), min(w_hi, (b + root) / lin**2)
    if not w_lo < w_hi:
        raise PlanError("the segment's acceleration limits leave no acceleration possible")
    x_max = np.minimum(x_max, _accel_feasible_x(c, d, e, w_lo, w_hi))
    x_max[0] = x_max[-1] = 0.0  # at rest at both ends
    if not np.all(np.isfinite(x_max)):
        raise PlanError("a motion segment has no finite speed limit (no joint moves?)")

    # Per grid point, the rows as plain floats: upper bounds w ≤ (e − d x)/c for c > 0, and
    # the backward pass's braking bounds for c < 0.
    rows = [
        list(zip(ck, dk, ek, strict=True))
        for ck, dk, ek in zip(c.tolist(), d.tolist(), e.tolist(), strict=True)
    ]

    def w_max(k: int, x: float) -> float:
        """Largest feasible acceleration at grid point k with speed² x."""
        hi = w_hi
        for ci, di, ei in rows[k]:
            if ci > _TINY:
                hi = min(hi, (ei - di * x) / ci)
        return hi

    # Backward pass: the largest x_k from which x_{k+1} is reached without braking harder than
    # allowed: w = (x_{k+1} − x_k)/(2h) ≥ every lower bound (e_j − d_j x_k)/c_j (c_j < 0) and
    # ≥ w_lo, each linear in x_k, so each gives x_k ≤ (x_{k+1} − 2h e_j/c_j)/(1 − 2h d_j/c_j).
    x = x_max.tolist()
    for k in range(n_grid - 2, -1, -1):
        bound = x[k]
        if math.isfinite(w_lo):
            bound = min(bound, x[k + 1] - 2 * h * w_lo)
        for ci, di, ei in rows[k]:
            if ci < -_TINY:
                alpha = 1.0 - 2 * h * di / ci
                rhs = x[k + 1] - 2 * h * ei / ci
                if alpha > _TINY:
                    bound = min(bound, rhs / alpha)
        x[k] = max(bound, 0.0)
    # Forward pass: the largest x at k + 1 reachable from x at k.
    for k in range(n_grid - 1):
        hi = w_max(k, x[k])
        if math.isfinite(hi):
            x[k + 1] = max(0.0, min(x[k + 1], x[k] + 2 * h * hi))
    return _law(np.array(x), h)


def _accel_feasible_x(
    c: np.ndarray, d: np.ndarray, e: np.ndarray, w_lo: float, w_hi: float
) -> np.ndarray:
    """Per grid point, the largest x ≥ 0 for which some w satisfies every c w + d x ≤ e and
    w_lo ≤ w ≤ w_hi (the maximum velocity curve of the acceleration limits).

    Each row with c > 0 bounds w from above by (e − d x)/c, each with c < 0 from below; a w
    exists iff every lower bound is at most every upper bound, a condition linear in x per
    pair of rows. Rows with c = 0 bound x directly: d x ≤ e.
    """
    k_grid = c.shape[0]
    box = np.ones((k_grid, 1))
    # Rows as w ≤ a + b x (upper, c > 0) or w ≥ a + b x (lower, c < 0), with the box appended.
    with np.errstate(divide="ignore", invalid="ignore"):
        a_rows = np.concatenate([e / c, w_hi * box, w_lo * box], axis=1)
        b_rows = np.concatenate([-d / c, 0 * box, 0 * box], axis=1)
    upper = np.concatenate([c > _TINY, box > 0, box < 0], axis=1)
    lower = np.concatenate([c < -_TINY, box < 0, box > 0], axis=1)
    a_rows = np.where(upper | lower, a_rows, 0.0)
    b_rows = np.where(upper | lower, b_rows, 0.0)
    # lower_j(x) ≤ upper_i(x)  ⇔  (b_j − b_i) x ≤ a_i − a_j, for every upper i and lower j.
    coef = b_rows[:, None, :] - b_rows[:, :, None]  # [k, i, j]
    with np.errstate(invalid="ignore"):
        rhs = a_rows[:, :, None] - a_rows[:, None, :]
    pair = upper[:, :, None] & lower[:, None, :] & (coef > _TINY)
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = np.where(pair, rhs / np.where(pair, coef, 1.0), np.inf)
    out = np.maximum(bound.reshape(k_grid, -1).min(axis=1), 0.0)
    flat = np.abs(c) <= _TINY
    with np.errstate(divide="ignore", invalid="ignore"):
        direct = np.where(flat & (d > _TINY), e / np.where(d > _TINY, d, 1.0), np.inf)
    return np.asarray(np.minimum(out, direct.min(axis=1)))


def _law(x: np.ndarray, h: float) -> TabulatedLaw:
    """The time law through speeds² x on the uniform grid of spacing h."""
    sd = np.sqrt(np.maximum(x, 0.0))
    dt = 2 * h / np.maximum(sd[:-1] + sd[1:], _TINY)
    if not np.all(np.isfinite(dt)) or np.any(sd[:-1] + sd[1:] <= _TINY):
        raise PlanError("the timing stalls: a stretch of the path admits no speed")
    t = np.concatenate([[0.0], np.cumsum(dt)])
    w = (x[1:] - x[:-1]) / (2 * h)
    u = np.linspace(0.0, 1.0, len(x))
    return TabulatedLaw(tuple(t.tolist()), tuple(u.tolist()), tuple(sd.tolist()), tuple(w.tolist()))


def scaled_law(law: TabulatedLaw, duration: float) -> TabulatedLaw:
    """The same path traversed in ``duration`` ≥ the law's own, uniformly slowed in time."""
    k = duration / law.duration
    if k < 1.0 - 1e-12:
        raise PlanError(f"a law cannot be sped up (asked {duration} s, fastest {law.duration} s)")
    return TabulatedLaw(
        tuple(t * k for t in law.t),
        law.u,
        tuple(v / k for v in law.u_dot),
        tuple(a / (k * k) for a in law.u_ddot),
    )


# ------------------------------------------------------------------------------ plans


@dataclass(frozen=True)
class TimingConfig:
    """How plans are timed by the robot.

    Attributes:
        speed: Speed override f ∈ (0, 1]: every speed limit is scaled by f and every
            acceleration limit by f², as a robot controller's override does (the path, and the
            gripper's own action times, stay the same).
        speed_margin: Fraction of each joint's speed limit the timing uses [-]: the rest is the
            controller's headroom for correcting its tracking error.
        tool_speed: Optional limit of the tool's speed [m/s] (None: none).
        tool_accel: Optional limit of the tool's acceleration [m/s²].
        tool_angular_speed: Optional limit of the tool's angular speed [rad/s].
        tool_angular_accel: Optional limit of the tool's angular acceleration [rad/s²].
        slip_safety_factor: The carried brick's acceleration against gravity may use 1 / this
            of what the pads' friction holds (μ · 2 pads · grip force / brick mass).
        default_accel_time: For a robot whose description gives no acceleration limits: each
            joint reaches its speed limit in this time [s] (a_max = v_max / this).
    """

    speed: float = 1.0
    speed_margin: float = 0.95
    tool_speed: float | None = None
    tool_accel: float | None = None
    tool_angular_speed: float | None = None
    tool_angular_accel: float | None = None
    slip_safety_factor: float = 2.0
    default_accel_time: float = 0.25

    def __post_init__(self) -> None:
        """Validate: ``speed`` in (0, 1], ``speed_margin`` in (0, 1], the rest > 0."""
        for name in ("speed", "speed_margin"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and 0.0 < v <= 1.0):
                raise InvalidInputError(
                    f"{name.replace('_', ' ')} must be a number in (0, 1], got {v!r}", field=name
                )
        for name in ("slip_safety_factor", "default_accel_time"):
            require_positive(name, getattr(self, name))
        for name in ("tool_speed", "tool_accel", "tool_angular_speed", "tool_angular_accel"):
            if getattr(self, name) is not None:
                require_positive(name, getattr(self, name))

    def limits(
        self, v_max: np.ndarray, a_max: np.ndarray | None, slip_accel: float | None
    ) -> SegmentLimits:
        """The limits of one segment under this configuration (``slip_accel`` [m/s²] is what
        the friction holds while carrying, before the safety factor; None: nothing carried)."""
        f = self.speed
        v = np.asarray(v_max, dtype=np.float64)
        a = (
            np.asarray(a_max, dtype=np.float64)
            if a_max is not None
            else v / self.default_accel_time
        )

        def scaled(x: float | None, power: int) -> float | None:
            return None if x is None else x * f**power

        return SegmentLimits(
            v_max=v * (f * self.speed_margin),
            a_max=a * f * f,
            tool_speed=scaled(self.tool_speed, 1),
            tool_accel=scaled(self.tool_accel, 2),
            tool_angular_speed=scaled(self.tool_angular_speed, 1),
            tool_angular_accel=scaled(self.tool_angular_accel, 2),
            slip_accel=None if slip_accel is None else slip_accel / self.slip_safety_factor,
        )


def retime(
    path_plan: Plan,
    times: np.ndarray,
    q: np.ndarray,
    holds: Sequence[float],
    limits: Callable[[bool], SegmentLimits],
) -> Plan:
    """The plan's path, timed by the robot: each motion segment time-optimally along the joint
    path the pre-flight found, each in-place segment (a gripper action) for its hold time.

    Args:
        path_plan: The plan as swept by the pre-flight: its keyframes lie on pre-flight ticks.
        times: The pre-flight's tick times [s] (n,), uniform.
        q: The joint path at those times [rad] (n, joints).
        holds: Per segment, the duration of an in-place segment [s] (ignored for motions).
        limits: The limits of a segment, given whether the brick is carried in it.

    Returns:
        The same keyframe poses and widths with new times, the motions under
        :class:`TabulatedLaw` time laws, and the phases moved with their keyframes.

    Raises:
        PlanError: The pre-flight ticks do not cover the plan, or a segment cannot be timed.
    """
    keyframes = path_plan.trajectory.keyframes
    if len(holds) != len(keyframes) - 1:
        raise PlanError(f"holds must have one entry per segment, got {len(holds)}")
    if len(times) < 2:
        raise PlanError("the pre-flight's joint path has fewer than 2 ticks")
    dt = float(times[1] - times[0])
    phases = path_plan.phases
    carry = (phases.grip_closed, phases.place_reached) if phases is not None else None
    new_times = [0.0]
    laws: list[TabulatedLaw | None] = []
    for i, (a, b) in enumerate(itertools.pairwise(keyframes)):
        dp = b.X_WG.translation() - a.X_WG.translation()
        phi = rotation_log(b.X_WG.rotation() @ a.X_WG.rotation().inverse())
        if float(np.linalg.norm(dp)) <= _STILL and float(np.linalg.norm(phi)) <= _STILL:
            new_times.append(new_times[-1] + holds[i])
            laws.append(None)
            continue
        k0, k1 = round(a.t / dt), round(b.t / dt)
        if k1 >= len(q) or k1 - k0 < 2:
            raise PlanError(
                f"segment '{a.name}' -> '{b.name}' has {k1 - k0 + 1} pre-flight samples "
                f"(need at least 3, and the path sweep must cover it)"
            )
        carried = carry is not None and carry[0] <= a.t and b.t <= carry[1]
        law = time_optimal_law(q[k0 : k1 + 1], dp, phi, limits(carried))
        new_times.append(new_times[-1] + law.duration)
        laws.append(law)
    old_times = [k.t for k in keyframes]
    retimed = [
        Keyframe(k.name, t, k.X_WG, k.gripper_width)
        for k, t in zip(keyframes, new_times, strict=True)
    ]

    def moved(t: float) -> float:
        return new_times[_index_of(old_times, t)]

    new_phases = None
    if phases is not None:
        new_phases = Phases(
            approach=(moved(phases.approach[0]), moved(phases.approach[1])),
            grip_closed=moved(phases.grip_closed),
            transport=(moved(phases.transport[0]), moved(phases.transport[1])),
            place_reached=moved(phases.place_reached),
            release=moved(phases.release),
        )
    trajectory = PoseTrajectory(retimed, path_plan.trajectory.profile, laws)
    return Plan(trajectory, new_phases, path_plan.X_OG)


# A segment whose ends differ by less than this (position [m], angle [rad]) stays in place.
_STILL = 1e-9


def _index_of(times: list[float], t: float) -> int:
    """Index of the keyframe at time ``t`` (phases lie on keyframes)."""
    i = min(range(len(times)), key=lambda j: abs(times[j] - t))
    if abs(times[i] - t) > 1e-9:
        raise PlanError(f"phase time {t!r} s is not a keyframe time")
    return i


def cycle_time_bound(
    keyframes: Sequence[Keyframe], dt: float, q: np.ndarray, v_max: np.ndarray
) -> float:
    """A lower bound on the time of a plan's motion along a joint path [s]: per segment between
    keyframes, the largest over the joints of its path length divided by its speed limit,
    summed, plus the in-place segments' own durations (the gripper's actions).

    Args:
        keyframes: The plan's keyframes (times on the run's clock).
        dt: The period of ``q``'s rows [s].
        q: Joint positions at times k·dt (n, joints), e.g. a run's commanded joints.
        v_max: Joint speed limits [rad/s].
    """
    total = 0.0
    for a, b in itertools.pairwise(keyframes):
        dp = b.X_WG.translation() - a.X_WG.translation()
        phi = rotation_log(b.X_WG.rotation() @ a.X_WG.rotation().inverse())
        if float(np.linalg.norm(dp)) <= _STILL and float(np.linalg.norm(phi)) <= _STILL:
            total += b.t - a.t
            continue
        k0, k1 = round(a.t / dt), min(round(b.t / dt), len(q) - 1)
        length = np.abs(np.diff(q[k0 : k1 + 1], axis=0)).sum(axis=0)
        total += float(np.max(length / np.asarray(v_max)))
    return total
