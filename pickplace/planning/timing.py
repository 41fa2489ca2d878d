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
from pickplace.geometry import rotation_log, rotation_vector_W
from pickplace.planning.plan import Plan
from pickplace.planning.trajectory import Keyframe, PoseTrajectory

GRAVITY_W = np.array([0.0, 0.0, -9.81])
# The speed override's range [-]: every motion takes about 1 / speed as long, so at the lower
# end the default robot's plan lasts close to an hour of simulated time, the most a plan may
# (pickplace.planning.preflight.MAX_PLAN_DURATION_S).
SPEED_RANGE = (1e-3, 1.0)
# Speeds below this count as zero when timing a grid interval [1/s].
_TINY = 1e-12


class GripTooWeakError(PlanError):
    """The pads' friction cannot hold the carried brick even at rest, within the slip budget:
    no timing of any path can carry it (it does not depend on the brick's pose or the grasp)."""


class TimingStallError(PlanError):
    """A stretch of a motion's path admits no speed within the limits: no timing of this
    path exists (another path, e.g. another grasp's, may have one).

    Args:
        text: What stalled (and, from :func:`retime`, the motion's keyframes).
        t: The stalled motion's start on the untimed plan's clock [s] (nan: unknown).
    """

    def __init__(self, text: str, t: float = math.nan):
        super().__init__(text)
        self.t = t


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
        u_dot: Path speed at them [1/s] (K + 1,): zero at an end where the tool stops.
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
            return 0.0, self.u_dot[0]
        if t >= times[-1]:
            return 1.0, self.u_dot[-1]
        k = bisect.bisect_right(times, t) - 1
        d = t - times[k]
        w = self.u_ddot[k]
        return self.u[k] + (self.u_dot[k] + 0.5 * w * d) * d, self.u_dot[k] + w * d


def path_derivatives(
    q: npt.ArrayLike, s: npt.ArrayLike | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """f'(s) and f''(s) from samples f (K, n) on a grid s (K,) (default: uniform on [0, 1]).

    Second-order three-point differences inside (for unequal spacing too), second-order
    one-sided at the ends, where f'' repeats its neighbour's.

    Raises:
        PlanError: Fewer than 3 samples, or a grid that is not increasing.
    """
    f = np.asarray(q, dtype=np.float64)
    if f.ndim != 2 or len(f) < 3:
        raise PlanError(f"a path needs at least 3 samples (K, n), got {f.shape}")
    grid = np.linspace(0.0, 1.0, len(f)) if s is None else np.asarray(s, dtype=np.float64)
    h = np.diff(grid)
    if grid.shape != (len(f),) or np.any(h <= 0):
        raise PlanError("a path's grid must increase strictly, one value per sample")
    h1, h2 = h[:-1, None], h[1:, None]
    fm, f0, fp = f[:-2], f[1:-1], f[2:]
    df = np.empty_like(f)
    ddf = np.empty_like(f)
    df[1:-1] = (
        (-h2 / (h1 * (h1 + h2))) * fm + ((h2 - h1) / (h1 * h2)) * f0 + (h1 / (h2 * (h1 + h2))) * fp
    )
    ddf[1:-1] = 2 * (fm / (h1 * (h1 + h2)) - f0 / (h1 * h2) + fp / (h2 * (h1 + h2)))
    a, b = h[0], h[1]
    df[0] = (
        (-(2 * a + b) / (a * (a + b))) * f[0]
        + ((a + b) / (a * b)) * f[1]
        - (a / (b * (a + b))) * f[2]
    )
    a, b = h[-1], h[-2]
    df[-1] = (
        ((2 * a + b) / (a * (a + b))) * f[-1]
        - ((a + b) / (a * b)) * f[-2]
        + (a / (b * (a + b))) * f[-3]
    )
    ddf[0], ddf[-1] = ddf[1], ddf[-2]
    return df, ddf


@dataclass(frozen=True)
class Profile:
    """The time-optimal motion along a path grid: times, speeds and accelerations.

    Attributes:
        s: The path grid (K,) [path units].
        t: Times at the grid points (K,) [s], from 0.
        s_dot: Path speeds there (K,) [1/s in path units].
        s_ddot: Path acceleration on each interval (K − 1,).
    """

    s: np.ndarray
    t: np.ndarray
    s_dot: np.ndarray
    s_ddot: np.ndarray

    def law(self, k0: int, k1: int) -> TabulatedLaw:
        """The part between grid points k0 and k1 as a law of u = (s − s_k0)/(s_k1 − s_k0)."""
        span = float(self.s[k1] - self.s[k0])
        return TabulatedLaw(
            tuple((self.t[k0 : k1 + 1] - self.t[k0]).tolist()),
            tuple(((self.s[k0 : k1 + 1] - self.s[k0]) / span).tolist()),
            tuple((self.s_dot[k0 : k1 + 1] / span).tolist()),
            tuple((self.s_ddot[k0:k1] / span).tolist()),
        )


def slip_box(slip_accel: float) -> np.ndarray:
    """Half-sizes (3,) [m/s²] of the per-axis box on a − g that stays inside the ball
    ``|a − g| ≤ slip_accel`` the pads' friction holds, and contains a = 0 (at rest).

    The cube of half-size ``slip_accel / √3`` when that holds gravity; otherwise the axis of
    gravity gets the larger half-size (``slip_accel`` + |g|) / 2, so the brick may still be
    held at rest and accelerate up and down a little, and the other axes what is left of the
    ball: √((slip_accel² − v²) / 2).

    Raises:
        GripTooWeakError: ``slip_accel`` ≤ |g|: the friction cannot hold the brick even at rest.
    """
    g_abs = float(np.linalg.norm(GRAVITY_W))
    if slip_accel <= g_abs:
        raise GripTooWeakError(
            f"the carried brick would slip even at rest: the slip budget (the pads' friction "
            f"over the safety factor) holds {slip_accel:.2f} m/s² against gravity's "
            f"{g_abs:.2f} m/s²; the brick is too heavy for the grip"
        )
    axis = int(np.argmax(np.abs(GRAVITY_W)))
    v = max(slip_accel / math.sqrt(3.0), 0.5 * (slip_accel + g_abs))
    half = np.full(3, math.sqrt(max(slip_accel**2 - v**2, 0.0) / 2.0))
    half[axis] = v
    return half


def time_optimal_profile(
    q: npt.ArrayLike,
    s: npt.ArrayLike,
    p_W: npt.ArrayLike,
    r_W: npt.ArrayLike,
    limits: SegmentLimits,
) -> Profile:
    """The fastest motion along a sampled path that respects every limit, at rest at both
    ends (see the module docstring).

    Args:
        q: Joint path at the grid points, shape (K, n) [rad].
        s: The grid (K,), increasing [path units, e.g. m].
        p_W: Tool positions at the grid points (K, 3) [m].
        r_W: Tool orientation as an accumulated world rotation vector (K, 3) [rad].
        limits: The limits.

    Raises:
        PlanError: A limit leaves no motion possible, or the grid is not increasing.
    """
    grid = np.asarray(s, dtype=np.float64)
    dq, ddq = path_derivatives(q, grid)
    dp, ddp = path_derivatives(p_W, grid)
    dr, ddr = path_derivatives(r_W, grid)
    n_grid = len(dq)
    h = np.diff(grid)
    v_max = np.asarray(limits.v_max, dtype=np.float64)
    a_max = np.asarray(limits.a_max, dtype=np.float64)
    with np.errstate(divide="ignore"):
        x_max = np.min((v_max / np.abs(dq)) ** 2, axis=1)
        if limits.tool_speed is not None:
            x_max = np.minimum(x_max, (limits.tool_speed / np.linalg.norm(dp, axis=1)) ** 2)
        if limits.tool_angular_speed is not None:
            speed = np.linalg.norm(dr, axis=1)
            x_max = np.minimum(x_max, (limits.tool_angular_speed / speed) ** 2)
    # Acceleration limits as rows c w + d x ≤ e (K, m): each joint both ways; the tool's
    # linear and angular acceleration per axis, within limit / √3 (a cube inside the limit's
    # ball), and the carried brick's a − g within a box inside its ball (see slip_box).
    cs, ds, es = [dq, -dq], [ddq, -ddq], [np.broadcast_to(a_max, dq.shape)] * 2
    root3 = math.sqrt(3.0)
    if limits.tool_accel is not None:
        bound = np.full(dp.shape, limits.tool_accel / root3)
        cs += [dp, -dp]
        ds += [ddp, -ddp]
        es += [bound, bound]
    if limits.tool_angular_accel is not None:
        bound = np.full(dr.shape, limits.tool_angular_accel / root3)
        cs += [dr, -dr]
        ds += [ddr, -ddr]
        es += [bound, bound]
    if limits.slip_accel is not None:
        g = np.broadcast_to(GRAVITY_W, dp.shape)
        cs += [dp, -dp]
        ds += [ddp, -ddp]
        half = slip_box(limits.slip_accel)
        es += [half + g, half - g]
    c = np.concatenate(cs, axis=1)
    d = np.concatenate(ds, axis=1)
    e = np.concatenate(es, axis=1)
    x_max = np.minimum(x_max, _accel_feasible_x(c, d, e))
    x_max[0] = x_max[-1] = 0.0  # at rest at both ends
    if not np.all(np.isfinite(x_max)):
        raise PlanError("a motion has no finite speed limit (nothing moves along it?)")
    rows = [
        list(zip(ck, dk, ek, strict=True))
        for ck, dk, ek in zip(c.tolist(), d.tolist(), e.tolist(), strict=True)
    ]
    # Backward pass: the largest x_k from which x_{k+1} is reached without braking harder than
    # allowed: w = (x_{k+1} − x_k)/(2h) ≥ every lower bound (e_j − d_j x_k)/c_j (c_j < 0),
    # each linear in x_k: x_k ≤ (x_{k+1} − 2h e_j/c_j)/(1 − 2h d_j/c_j).
    x = x_max.tolist()
    hs = h.tolist()
    for k in range(n_grid - 2, -1, -1):
        bound_k, hk = x[k], hs[k]
        for ci, di, ei in rows[k]:
            if ci < -_TINY:
                alpha = 1.0 - 2 * hk * di / ci
                if alpha > _TINY:
                    bound_k = min(bound_k, (x[k + 1] - 2 * hk * ei / ci) / alpha)
        x[k] = max(bound_k, 0.0)
    # Forward pass: the largest x_{k+1} reachable from x_k: w ≤ every upper bound.
    for k in range(n_grid - 1):
        hi = math.inf
        for ci, di, ei in rows[k]:
            if ci > _TINY:
                hi = min(hi, (ei - di * x[k]) / ci)
        if math.isfinite(hi):
            x[k + 1] = max(0.0, min(x[k + 1], x[k] + 2 * hs[k] * hi))
    xs = np.array(x)
    sd = np.sqrt(np.maximum(xs, 0.0))
    pair = sd[:-1] + sd[1:]
    if np.any(pair <= _TINY):
        raise TimingStallError("the timing stalls: a stretch of the path admits no speed")
    t = np.concatenate([[0.0], np.cumsum(2 * h / pair)])
    return Profile(grid, t, sd, (xs[1:] - xs[:-1]) / (2 * h))


def time_optimal_law(
    q: npt.ArrayLike, dp_W: npt.ArrayLike, phi_W: npt.ArrayLike, limits: SegmentLimits
) -> TabulatedLaw:
    """The fastest u(t) along a joint path sampled at u_k = k / N on a straight segment (tool
    displacement ``dp_W`` [m], rotation vector ``phi_W`` [rad]), at rest at both ends."""
    q = np.asarray(q, dtype=np.float64)
    u = np.linspace(0.0, 1.0, len(q))
    p = u[:, None] * np.asarray(dp_W, dtype=np.float64)
    r = u[:, None] * np.asarray(phi_W, dtype=np.float64)
    return time_optimal_profile(q, u, p, r, limits).law(0, len(q) - 1)


def _accel_feasible_x(c: np.ndarray, d: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Per grid point, the largest x ≥ 0 for which some w satisfies every c w + d x ≤ e (the
    maximum velocity curve of the acceleration limits).

    Each row with c > 0 bounds w from above by (e − d x)/c, each with c < 0 from below; a w
    exists iff every lower bound is at most every upper bound, a condition linear in x per
    pair of rows. Rows with c = 0 bound x directly: d x ≤ e.
    """
    k_grid = c.shape[0]
    upper, lower = c > _TINY, c < -_TINY
    with np.errstate(divide="ignore", invalid="ignore"):
        a_rows = np.where(upper | lower, e / np.where(upper | lower, c, 1.0), 0.0)
        b_rows = np.where(upper | lower, -d / np.where(upper | lower, c, 1.0), 0.0)
    # lower_j(x) ≤ upper_i(x)  ⇔  (b_j − b_i) x ≤ a_i − a_j, for every upper i and lower j.
    coef = b_rows[:, None, :] - b_rows[:, :, None]  # [k, i, j]
    rhs = a_rows[:, :, None] - a_rows[:, None, :]
    pair = upper[:, :, None] & lower[:, None, :] & (coef > _TINY)
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = np.where(pair, rhs / np.where(pair, coef, 1.0), np.inf)
    out = np.maximum(bound.reshape(k_grid, -1).min(axis=1), 0.0)
    flat = ~(upper | lower)
    with np.errstate(divide="ignore", invalid="ignore"):
        direct = np.where(flat & (d > _TINY), e / np.where(d > _TINY, d, 1.0), np.inf)
    return np.asarray(np.minimum(out, direct.min(axis=1)))


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
        """Validate: ``speed`` in :data:`SPEED_RANGE`, ``speed_margin`` in (0, 1], the rest
        > 0."""
        check_speed(self.speed)
        for name in ("speed_margin",):
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


def check_speed(speed: object) -> float:
    """Return the speed override ``speed`` as float if it lies in :data:`SPEED_RANGE`.

    Raises:
        InvalidInputError: It does not (field ``speed``).
    """
    lo, hi = SPEED_RANGE
    if not (isinstance(speed, int | float) and not isinstance(speed, bool) and lo <= speed <= hi):
        raise InvalidInputError(
            f"speed must be a number in [{lo:g}, {hi:g}] (a fraction of the robot's speed "
            f"limits; below {lo:g} a plan lasts hours), got {speed!r}",
            field="speed",
        )
    return float(speed)


def retime(
    path_plan: Plan,
    times: np.ndarray,
    q: np.ndarray,
    limits: Callable[[bool], SegmentLimits],
) -> Plan:
    """The plan's path, timed by the robot: each motion time-optimally along the joint path
    the pre-flight found (along its own joint path, for a segment that moves in joint space),
    each in-place segment (a gripper action) for its keyframe's hold.

    A motion runs from one stop to the next: consecutive moving segments joined at keyframes
    the tool passes through are timed as one path (the path parameter is the segments' chord
    length, under which their geometry is C1) and its profile is then cut at the keyframes.

    Args:
        path_plan: The plan as swept by the pre-flight: its keyframes lie on pre-flight ticks,
            each segment traversed at constant parameter speed.
        times: The pre-flight's tick times [s] (n,), uniform.
        q: The joint path at those times [rad] (n, joints).
        limits: The limits of a motion, given whether the brick is carried in it.

    Returns:
        The same keyframes (poses, widths, stops) with new times, the motions under
        :class:`TabulatedLaw` time laws, and the phases moved with their keyframes.

    Raises:
        PlanError: The pre-flight ticks do not cover the plan, or a motion cannot be timed.
    """
    keyframes = path_plan.trajectory.keyframes
    sample = path_plan.trajectory.sample
    joint_segments = path_plan.trajectory.joint_segments
    n_seg = len(keyframes) - 1
    if len(times) < 2:
        raise PlanError("the pre-flight's joint path has fewer than 2 ticks")
    dt = float(times[1] - times[0])
    phases = path_plan.phases
    carry = (phases.grip_closed, phases.place_reached) if phases is not None else None
    ticks = [round(k.t / dt) for k in keyframes]
    if ticks[-1] >= len(q):
        raise PlanError("the pre-flight's joint path ends before the plan does")
    durations: list[float] = [0.0] * n_seg
    laws: list[TabulatedLaw | None] = [None] * n_seg
    i = 0
    while i < n_seg:
        if not _moves(keyframes[i], keyframes[i + 1]):
            durations[i] = keyframes[i + 1].hold
            i += 1
            continue
        j = i  # the motion: segments i..j, joined at keyframes the tool passes through
        while (
            j + 1 < n_seg
            and not keyframes[j + 1].stop
            and _moves(keyframes[j + 1], keyframes[j + 2])
        ):
            j += 1
        grid, bounds = [0.0], [0]
        for m in range(i, j + 1):
            a, b = keyframes[m], keyframes[m + 1]
            n = ticks[m + 1] - ticks[m]
            if n < 2:
                raise PlanError(
                    f"segment '{a.name}' -> '{b.name}' has {n + 1} pre-flight samples (need 3)"
                )
            length = _path_length(a, b)
            grid += (grid[-1] + length * np.arange(1, n + 1) / n).tolist()
            bounds.append(bounds[-1] + n)
        k0, k1 = ticks[i], ticks[j + 1]
        poses = np.array([sample(float(times[k]))[0] for k in range(k0, k1 + 1)])
        q_motion = q[k0 : k1 + 1]
        for m in range(i, j + 1):
            js = joint_segments[m]
            if js is not None:  # its own joint path, at the sweep's u = (k − k_m) / n
                if q_motion is q[k0 : k1 + 1]:
                    q_motion = q_motion.copy()
                n = bounds[m - i + 1] - bounds[m - i]
                for step in range(n + 1):
                    q_motion[bounds[m - i] + step] = js.sample(step / n, 0.0)[2]
        carried = (
            carry is not None and carry[0] <= keyframes[i].t and keyframes[j + 1].t <= carry[1]
        )
        try:
            profile = time_optimal_profile(
                q_motion, grid, poses[:, 4:], _accumulated_rotation(poses[:, :4]), limits(carried)
            )
        except TimingStallError as exc:
            raise TimingStallError(
                f"{exc} within the robot's limits, from '{keyframes[i].name}' to "
                f"'{keyframes[j + 1].name}'",
                keyframes[i].t,
            ) from exc
        for m in range(i, j + 1):
            law = profile.law(bounds[m - i], bounds[m - i + 1])
            laws[m], durations[m] = law, law.duration
        i = j + 1
    new_times = [0.0, *itertools.accumulate(durations)]
    old_times = [k.t for k in keyframes]
    retimed = [
        Keyframe(k.name, t, k.X_WG, k.gripper_width, k.stop, k.curve, k.hold)
        for k, t in zip(keyframes, new_times, strict=True)
    ]

    def moved(t: float) -> float:
        return new_times[_index_of(old_times, t)]

    new_phases = None if phases is None else phases.mapped(moved)
    trajectory = PoseTrajectory(
        retimed, path_plan.trajectory.profile, laws, path_plan.trajectory.joint_segments
    )
    return Plan(trajectory, new_phases, path_plan.X_OG)


# A segment whose ends differ by less than this (position [m], angle [rad]) stays in place.
_STILL = 1e-9
# A pure turn counts this much path per radian in a motion's grid [m/rad].
_TURN_LENGTH = 0.1


def _moves(a: Keyframe, b: Keyframe) -> bool:
    """True if the tool moves (or turns) between keyframes a and b."""
    return _path_length(a, b) > _STILL


def _path_length(a: Keyframe, b: Keyframe) -> float:
    """The segment's length in the motion grid: its chord [m], or for a pure turn its angle
    times _TURN_LENGTH."""
    chord = float(np.linalg.norm(b.X_WG.translation() - a.X_WG.translation()))
    if chord > _STILL:
        return chord
    return _TURN_LENGTH * float(
        np.linalg.norm(rotation_log(a.X_WG.rotation().inverse() @ b.X_WG.rotation()))
    )


def _accumulated_rotation(quats: np.ndarray) -> np.ndarray:
    """World rotation vectors (K, 3) accumulated step by step along orientations (K, 4) wxyz."""
    steps = [rotation_vector_W(quats[k], quats[k + 1]) for k in range(len(quats) - 1)]
    return np.vstack([np.zeros(3), np.cumsum(steps, axis=0)]) if steps else np.zeros((1, 3))


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
    return _motion_time(keyframes, dt, q, v_max, lambda steps: float(np.max(steps.sum(axis=0))))


def cycle_time_at_speed_limits(
    keyframes: Sequence[Keyframe], dt: float, q: np.ndarray, v_max: np.ndarray
) -> float:
    """The time of a plan's motion along a joint path at the joint speed limits alone [s]:
    at every step the path moves as fast as its tightest joint allows, with no acceleration
    limit, so each motion takes ∫ max_j |dqⱼ| / vⱼ (the per-step maximum, summed), plus the
    in-place segments' own durations.

    It lies between :func:`cycle_time_bound` (the maximum taken per segment, after summing)
    and the time of any timing of the path within the speed limits; what a timing takes
    beyond it is spent in the acceleration limits (starting, stopping, turning) and in any
    speed margin. Arguments as :func:`cycle_time_bound`.
    """
    return _motion_time(keyframes, dt, q, v_max, lambda steps: float(steps.max(axis=1).sum()))


def _motion_time(
    keyframes: Sequence[Keyframe],
    dt: float,
    q: np.ndarray,
    v_max: np.ndarray,
    moving: Callable[[np.ndarray], float],
) -> float:
    """In-place segments' durations plus ``moving`` of each moving segment's joint steps
    |Δq| / v_max (ticks, joints) [s]."""
    total = 0.0
    for a, b in itertools.pairwise(keyframes):
        if not _moves(a, b):
            total += b.t - a.t
            continue
        k0, k1 = round(a.t / dt), min(round(b.t / dt), len(q) - 1)
        total += moving(np.abs(np.diff(q[k0 : k1 + 1], axis=0)) / np.asarray(v_max))
    return total
