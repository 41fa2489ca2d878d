"""Motion profiles and the time-parameterised gripper pose trajectory through keyframes.

Segment ``i`` runs from keyframe ``i`` to keyframe ``i + 1``. Its progress ``s`` along its path
comes either from a motion profile ``s(τ)`` with ``τ = (t - t_i) / T_i`` (``s(0) = 0``,
``s(1) = 1``) or from the segment's time law (:class:`TimeLaw`, e.g. the robot's time-optimal
timing of :mod:`pickplace.planning.timing`). Then:

* position moves on the straight line ``p_WG = p_i + s (p_{i+1} - p_i)``, or, for a segment
  that ends at a ``curve`` keyframe, on a cubic Hermite curve that leaves and reaches
  pass-through keyframes along their path tangent;
* orientation follows the shortest-arc slerp ``R_WG = R_i · exp(s · φ_i)`` with
  ``φ_i = log(R_i⁻¹ R_{i+1})`` (angle in [0, π]); next to a pass-through keyframe ``s`` is
  replaced by a cubic progress ``g(s)`` that keeps the angular velocity continuous there.

The sine and minimum-jerk profiles have ``s'(0) = s'(1) = 0``: a segment timed by a profile
starts and ends at rest, so under a profile the gripper stops at every keyframe, and its
velocity is continuous. A time law stops only at keyframes marked ``stop`` and passes through
the others: the planner's plans stop only where the gripper acts and at their ends. Spatial
velocities are ``V_WG = [v_W; ω_W]``: linear velocity of G's origin then angular velocity,
both expressed in world (mink's tangent order).
"""

from __future__ import annotations

import bisect
import itertools
import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar, Protocol

import mujoco
import numpy as np
from mink.lie import SE3

from pickplace.errors import PlanError, UnknownNameError, require_finite
from pickplace.geometry import FloatArray, require_pose, rotation_log

# --------------------------------------------------------------------------- profiles


class MotionProfile(ABC):
    """Time scaling ``s(τ)`` of a segment, with ``τ ∈ [0, 1]``, ``s(0) = 0`` and ``s(1) = 1``.

    For a segment of length ``d`` (metres or radians) and duration ``T`` the peak speed is
    ``peak_speed_factor · d / T`` and the peak acceleration ``peak_accel_factor · d / T²``.
    These two factors are the single source of truth for segment timing.
    """

    name: ClassVar[str]
    peak_speed_factor: ClassVar[float]
    """Maximum of ``ds/dτ`` over ``[0, 1]`` [-]."""
    peak_accel_factor: ClassVar[float]
    """Maximum of ``|d²s/dτ²|`` over ``[0, 1]`` [-]; ``math.inf`` if unbounded."""

    @abstractmethod
    def s(self, tau: float) -> float:
        """Path parameter at normalised time ``tau`` ∈ [0, 1] [-]."""

    @abstractmethod
    def ds(self, tau: float) -> float:
        """Derivative ``ds/dτ`` at normalised time ``tau`` ∈ [0, 1] [-]."""

    def min_duration(self, distance: float, max_speed: float, max_accel: float) -> float:
        """Shortest segment duration that respects a speed and an acceleration limit.

        Args:
            distance: Length of the segment [m] or rotation angle [rad]; ≥ 0.
            max_speed: Speed limit [m/s] or [rad/s]; > 0.
            max_accel: Acceleration limit [m/s²] or [rad/s²]; > 0. Ignored when the
                profile's acceleration is unbounded (``peak_accel_factor`` infinite).

        Returns:
            ``max(c_v d / v_max, sqrt(c_a d / a_max))`` [s] (0 for a zero distance).
        """
        t_speed = self.peak_speed_factor * distance / max_speed
        if math.isinf(self.peak_accel_factor):
            return t_speed
        return max(t_speed, math.sqrt(self.peak_accel_factor * distance / max_accel))


@dataclass(frozen=True)
class SineProfile(MotionProfile):
    """``s(τ) = (1 - cos πτ) / 2``: peak speed ``π d / (2T)``, peak accel ``π² d / (2T²)``."""

    name: ClassVar[str] = "sine"
    peak_speed_factor: ClassVar[float] = math.pi / 2.0
    peak_accel_factor: ClassVar[float] = math.pi**2 / 2.0

    def s(self, tau: float) -> float:
        """Path parameter at normalised time ``tau`` [-]."""
        return 0.5 * (1.0 - math.cos(math.pi * tau))

    def ds(self, tau: float) -> float:
        """Derivative ``ds/dτ`` at normalised time ``tau`` [-]."""
        return 0.5 * math.pi * math.sin(math.pi * tau)


@dataclass(frozen=True)
class MinimumJerkProfile(MotionProfile):
    """``s(τ) = 10τ³ - 15τ⁴ + 6τ⁵``: peak speed ``1.875 d / T``, peak accel ``5.7735 d / T²``."""

    name: ClassVar[str] = "minimum-jerk"
    peak_speed_factor: ClassVar[float] = 1.875
    peak_accel_factor: ClassVar[float] = 10.0 / math.sqrt(3.0)

    def s(self, tau: float) -> float:
        """Path parameter at normalised time ``tau`` [-]."""
        return tau**3 * (10.0 + tau * (-15.0 + 6.0 * tau))

    def ds(self, tau: float) -> float:
        """Derivative ``ds/dτ`` at normalised time ``tau`` [-]."""
        return 30.0 * tau**2 * (1.0 - tau) ** 2


@dataclass(frozen=True)
class LinearProfile(MotionProfile):
    """``s(τ) = τ``: constant speed ``d / T``, unbounded acceleration at the ends (tests only)."""

    name: ClassVar[str] = "linear"
    peak_speed_factor: ClassVar[float] = 1.0
    peak_accel_factor: ClassVar[float] = math.inf

    def s(self, tau: float) -> float:
        """Path parameter at normalised time ``tau`` [-]."""
        return tau

    def ds(self, tau: float) -> float:
        """Derivative ``ds/dτ`` at normalised time ``tau`` [-]."""
        return 1.0


PROFILES: dict[str, MotionProfile] = {
    p.name: p for p in (SineProfile(), MinimumJerkProfile(), LinearProfile())
}


def profile_by_name(name: str) -> MotionProfile:
    """Return the motion profile called ``name``.

    Raises:
        UnknownNameError: ``name`` is not one of ``PROFILES``.
    """
    try:
        return PROFILES[name]
    except (KeyError, TypeError):
        raise UnknownNameError("profile", str(name), PROFILES) from None


# -------------------------------------------------------------------------- keyframes


@dataclass(frozen=True)
class Keyframe:
    """A pose the tool site passes through at a given time.

    Attributes:
        name: Label used in logs and recordings, e.g. ``"pick"`` (the run never reads it:
            what the run needs from the plan are its phases, see
            :class:`pickplace.planning.plan.Plan`).
        t: Time [s].
        X_WG: Pose of the tool site G in world (unit quaternion, copied on construction).
        gripper_width: Commanded finger gap at this keyframe [m].
        stop: The tool is at rest here; otherwise it passes through, its path and velocity
            continuous (a via point).
        curve: The segment that ends here is a smooth curve (a cubic Hermite that leaves and
            reaches pass-through keyframes along their path tangent), not a straight line.
        hold: The least time the segment ending here must last [s], e.g. the gripper's own
            time to close in place (0: as fast as the motion allows).
    """

    name: str
    t: float
    X_WG: SE3
    gripper_width: float
    stop: bool = True
    curve: bool = False
    hold: float = 0.0

    def __post_init__(self) -> None:
        """Validate and normalise the fields; raise PlanError naming the bad field."""
        if not isinstance(self.name, str) or not self.name:
            raise PlanError(f"keyframe name must be a non-empty string, got {self.name!r}")
        label = f"keyframe '{self.name}'"
        object.__setattr__(self, "t", require_finite(f"{label} time t [s]", self.t, PlanError))
        require_pose(f"{label} X_WG", self.X_WG)
        object.__setattr__(
            self, "X_WG", SE3(wxyz_xyz=np.array(self.X_WG.wxyz_xyz, dtype=np.float64))
        )
        width = require_finite(f"{label} gripper_width [m]", self.gripper_width, PlanError)
        if width < 0.0:
            raise PlanError(f"{label} gripper_width [m] must be >= 0, got {self.gripper_width!r}")
        object.__setattr__(self, "gripper_width", width)
        hold = require_finite(f"{label} hold [s]", self.hold, PlanError)
        if hold < 0.0:
            raise PlanError(f"{label} hold [s] must be >= 0, got {self.hold!r}")
        object.__setattr__(self, "hold", hold)


def validate_keyframes(keyframes: Sequence[Keyframe]) -> None:
    """Check that keyframes can define a trajectory: at least 2, times strictly increasing
    (each :class:`Keyframe` has validated its own fields).

    Raises:
        PlanError: Naming the offending keyframe.
    """
    if len(keyframes) < 2:
        raise PlanError(f"keyframes must contain at least 2 entries, got {len(keyframes)}")
    for end in (keyframes[0], keyframes[-1]):
        if isinstance(end, Keyframe) and not end.stop:
            raise PlanError(f"keyframe '{end.name}' is an end of the trajectory: it must stop")
    for previous, k in itertools.pairwise(keyframes):
        if not isinstance(k, Keyframe) or not isinstance(previous, Keyframe):
            raise PlanError(f"keyframes must be Keyframe objects, got {type(k).__name__}")
        if not k.t > previous.t:
            raise PlanError(
                f"keyframe '{k.name}' time t={k.t!r} s must be greater than the previous "
                f"keyframe '{previous.name}' t={previous.t!r} s (times strictly increasing)"
            )


# ------------------------------------------------------------------------- trajectory

# Two directions closer than this (1 − cos) count as the same [-].
_PARALLEL = 1e-9


def _via_tangents(
    keyframes: Sequence[Keyframe],
) -> tuple[list[FloatArray | None], list[tuple[float, float]]]:
    """Per keyframe, the unit path tangent where the tool passes through (None where it stops),
    and per segment the slopes (r0, r1) of its rotation progress at both ends.

    The tangent at a pass-through keyframe is the direction of a straight neighbouring segment
    (the line stays a line), or, between two curves, the direction from the previous keyframe
    to the next. The angular velocity there is kept continuous: its rate per metre of path is
    the mean of both segments' when both turn about one axis, zero otherwise.

    Raises:
        PlanError: A pass-through keyframe between two straight segments of different
            directions (a corner cannot be passed without stopping).
    """
    pos = [np.asarray(k.X_WG.translation(), dtype=np.float64) for k in keyframes]
    n = len(keyframes)
    lengths = [float(np.linalg.norm(pos[i + 1] - pos[i])) for i in range(n - 1)]
    phis = [
        np.asarray(
            keyframes[i]
            .X_WG.rotation()
            .apply(
                rotation_log(
                    keyframes[i].X_WG.rotation().inverse() @ keyframes[i + 1].X_WG.rotation()
                )
            )
        )
        for i in range(n - 1)
    ]
    tangents: list[FloatArray | None] = [None] * n
    rates = [[1.0, 1.0] for _ in range(n - 1)]
    for i in range(1, n - 1):
        k = keyframes[i]
        if k.stop:
            continue
        if lengths[i - 1] <= 1e-12 or lengths[i] <= 1e-12:
            raise PlanError(
                f"keyframe '{k.name}' passes through, but a neighbouring segment does not move"
            )
        incoming_line, outgoing_line = not k.curve, not keyframes[i + 1].curve
        d_in = (pos[i] - pos[i - 1]) / lengths[i - 1]
        d_out = (pos[i + 1] - pos[i]) / lengths[i]
        if incoming_line and outgoing_line and float(d_in @ d_out) < 1.0 - _PARALLEL:
            raise PlanError(
                f"keyframe '{k.name}' passes through a corner between two straight segments: "
                "it must stop, or one of them must be a curve"
            )
        if incoming_line:
            tangents[i] = d_in
        elif outgoing_line:
            tangents[i] = d_out
        else:
            across = pos[i + 1] - pos[i - 1]
            tangents[i] = across / float(np.linalg.norm(across))
        a, b = phis[i - 1], phis[i]
        na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
        rate = 0.0
        if na > 1e-12 and nb > 1e-12 and float(a @ b) / (na * nb) > 1.0 - _PARALLEL:
            rate = (na + nb) / (lengths[i - 1] + lengths[i])
        rates[i - 1][1] = rate * lengths[i - 1] / na if na > 1e-12 else 0.0
        rates[i][0] = rate * lengths[i] / nb if nb > 1e-12 else 0.0
    return tangents, [(r[0], r[1]) for r in rates]


def _curve(
    a: Keyframe,
    b: Keyframe,
    t_a: FloatArray | None,
    t_b: FloatArray | None,
    rates: tuple[float, float],
    curved: bool,
) -> tuple[tuple[float, ...], ...] | None:
    """The curve data of segment a → b (see :class:`_Segment`), or None for a plain line."""
    if not curved and rates == (1.0, 1.0):
        return None
    p0 = np.asarray(a.X_WG.translation(), dtype=np.float64)
    p1 = np.asarray(b.X_WG.translation(), dtype=np.float64)
    dp = p1 - p0
    length = float(np.linalg.norm(dp))
    m0 = t_a * length if (curved and t_a is not None) else dp
    m1 = t_b * length if (curved and t_b is not None) else dp
    # p(u) = A u³ + B u² + C u + D and g(u) = a u³ + b u² + r0 u (g(0) = 0, g(1) = 1).
    A = 2 * p0 + m0 - 2 * p1 + m1
    B = -3 * p0 - 2 * m0 + 3 * p1 - m1
    r0, r1 = rates
    return (_xyz(A), _xyz(B), _xyz(m0), _xyz(p0), (r0 + r1 - 2.0, 3.0 - 2.0 * r0 - r1, r0))


def _xyz(v: FloatArray) -> tuple[float, float, float]:
    """A 3-vector as a tuple of Python floats."""
    x, y, z = v.tolist()
    return x, y, z


@dataclass(frozen=True)
class _Segment:
    """Precomputed data of one segment (world-frame quantities, as floats for the fast path).

    Attributes:
        t0: Start time [s].
        inv_duration: 1 / duration [1/s].
        law: The segment's time law, or None for the trajectory's profile.
        q0: Orientation at the start (wxyz).
        phi: Rotation vector of the segment in the start frame, log(R0⁻¹ R1) [rad].
        width0: Gripper width at the start [m].
        dwidth: Width change over the segment [m].
        p0_xyz: Position at the start [m].
        dp_xyz: Position change over the segment [m].
        omega_dir_W_xyz: R0 φ: the world-frame rotation vector of the segment [rad].
        curve: For a curved segment, the cubic coefficients of its position p(u) = A u³ + B u²
            + C u + D, as (A, B, C, D) [m], and of the rotation's progress g(u) = a u³ + b u² +
            c u, as (a, b, c) [-]; None for a straight line with g(u) = u.
    """

    t0: float
    inv_duration: float
    law: TimeLaw | None
    q0: FloatArray
    phi: FloatArray
    width0: float
    dwidth: float
    p0_xyz: tuple[float, float, float]
    dp_xyz: tuple[float, float, float]
    omega_dir_W_xyz: tuple[float, float, float]
    curve: tuple[tuple[float, ...], ...] | None = None


class TimeLaw(Protocol):
    """A segment's path parameter over time: u(t) from 0 to 1 in ``duration``, at rest where
    its keyframes stop (e.g. :class:`pickplace.planning.timing.TabulatedLaw`, the robot's
    time-optimal
    timing)."""

    @property
    def duration(self) -> float:
        """Time the segment takes [s]."""

    def __call__(self, t: float) -> tuple[float, float]:
        """(u [-], u̇ [1/s]) at local time ``t`` [s] from the segment's start."""


class JointSegment(Protocol):
    """A segment moved in joint space: the joint path q(u), u ∈ [0, 1], and the tool pose
    and spatial velocity it gives by forward kinematics (e.g.
    :class:`pickplace.planning.cspace.JointMotion`)."""

    def sample(
        self, u: float, u_dot: float
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """(x_WG wxyz_xyz, V_WG = J q'(u) u̇ [m/s, rad/s], q [rad], q̇ [rad/s]) at ``u``."""


class PoseTrajectory:
    """Gripper pose ``X_WG(t)``, spatial velocity and gripper width through keyframes.

    Times before the first keyframe or after the last one clamp to the ends (velocity zero).
    A segment may move in joint space (a :class:`JointSegment`, planned in C-space): its pose
    and velocity are the forward kinematics of its joint path, q(u(t)), and its joint path
    itself is given to the controller (:meth:`joint_sample`).
    """

    def __init__(
        self,
        keyframes: Sequence[Keyframe],
        profile: MotionProfile | str = "sine",
        laws: Sequence[TimeLaw | None] | None = None,
        joint_segments: Sequence[JointSegment | None] | None = None,
    ) -> None:
        """Build the trajectory and precompute per-segment data.

        Args:
            keyframes: At least 2 keyframes with strictly increasing times [s].
            profile: Motion profile of the segments without a law, or its name (``PROFILES``).
            laws: Per segment, a time law that replaces the profile (its duration must be the
                segment's), or None for the profile.
            joint_segments: Per segment, a joint path it moves along instead of the Cartesian
                line or curve between its keyframes (whose poses must be the path's ends), or
                None; both keyframes of such a segment must stop.

        Raises:
            PlanError: Invalid keyframes, or laws or joint segments that do not match the
                segments.
            UnknownNameError: Unknown profile name.
        """
        validate_keyframes(keyframes)
        self._profile = profile_by_name(profile) if isinstance(profile, str) else profile
        self._keyframes = tuple(keyframes)
        n_segments = len(self._keyframes) - 1
        self._laws: tuple[TimeLaw | None, ...] = tuple(laws) if laws else (None,) * n_segments
        if len(self._laws) != n_segments:
            raise PlanError(
                f"laws must have one entry per segment ({n_segments}), got {len(self._laws)}"
            )
        for i, law in enumerate(self._laws):
            span = self._keyframes[i + 1].t - self._keyframes[i].t
            if law is not None and abs(law.duration - span) > 1e-9 * max(1.0, span):
                raise PlanError(
                    f"segment {i}'s time law lasts {law.duration!r} s, the segment {span!r} s"
                )
        self._joint: tuple[JointSegment | None, ...] = (
            tuple(joint_segments) if joint_segments else (None,) * n_segments
        )
        if len(self._joint) != n_segments:
            raise PlanError(
                f"joint_segments must have one entry per segment ({n_segments}), got "
                f"{len(self._joint)}"
            )
        for i, js in enumerate(self._joint):
            a, b = self._keyframes[i], self._keyframes[i + 1]
            if js is not None and not (a.stop and b.stop):
                raise PlanError(
                    f"segment '{a.name}' -> '{b.name}' moves in joint space: both its keyframes "
                    "must stop"
                )
        self._times = [float(k.t) for k in keyframes]
        self._segments: list[_Segment] = []
        tangents, rates = _via_tangents(self._keyframes)
        for i, (a, b) in enumerate(itertools.pairwise(self._keyframes)):
            R0 = a.X_WG.rotation()
            phi = rotation_log(R0.inverse() @ b.X_WG.rotation())
            p0 = np.array(a.X_WG.translation(), dtype=np.float64)
            dp = np.asarray(b.X_WG.translation(), dtype=np.float64) - p0
            omega_dir_W = np.asarray(R0.apply(phi), dtype=np.float64)
            self._segments.append(
                _Segment(
                    t0=float(a.t),
                    inv_duration=1.0 / (float(b.t) - float(a.t)),
                    law=self._laws[len(self._segments)],
                    q0=np.array(R0.wxyz, dtype=np.float64),
                    phi=phi,
                    width0=float(a.gripper_width),
                    dwidth=float(b.gripper_width) - float(a.gripper_width),
                    p0_xyz=_xyz(p0),
                    dp_xyz=_xyz(dp),
                    omega_dir_W_xyz=_xyz(omega_dir_W),
                    curve=_curve(a, b, tangents[i], tangents[i + 1], rates[i], b.curve),
                )
            )

    @property
    def keyframes(self) -> tuple[Keyframe, ...]:
        """The keyframes, in time order."""
        return self._keyframes

    @property
    def laws(self) -> tuple[TimeLaw | None, ...]:
        """Per segment, its time law (None: the profile)."""
        return self._laws

    @property
    def joint_segments(self) -> tuple[JointSegment | None, ...]:
        """Per segment, the joint path it moves along (None: Cartesian)."""
        return self._joint

    @property
    def has_joint_segments(self) -> bool:
        """True if a segment moves in joint space."""
        return any(js is not None for js in self._joint)

    def joint_sample(self, t: float) -> tuple[FloatArray, FloatArray] | None:
        """The joint path's (q [rad], q̇ [rad/s]) at time ``t`` [s] inside a joint-space
        segment, or None elsewhere (a knot time belongs to the segment that starts there)."""
        i = bisect.bisect_right(self._times, t) - 1
        if i < 0 or i >= len(self._segments):
            return None
        js = self._joint[i]
        if js is None:
            return None
        seg = self._segments[i]
        u, u_dot = self._progress(seg, t)
        _, _, q, q_dot = js.sample(u, u_dot)
        return q, q_dot

    def _progress(self, seg: _Segment, t: float) -> tuple[float, float]:
        """(s, ṡ [1/s]) of segment ``seg`` at time ``t`` (its law or the profile)."""
        if seg.law is not None:
            return seg.law(t - seg.t0)
        tau = min(max((t - seg.t0) * seg.inv_duration, 0.0), 1.0)
        return self._profile.s(tau), self._profile.ds(tau) * seg.inv_duration

    @property
    def profile(self) -> MotionProfile:
        """The motion profile of every segment."""
        return self._profile

    @property
    def start_time(self) -> float:
        """Time of the first keyframe [s]."""
        return self._times[0]

    @property
    def end_time(self) -> float:
        """Time of the last keyframe [s]."""
        return self._times[-1]

    @property
    def duration(self) -> float:
        """Total duration ``end_time - start_time`` [s]."""
        return self._times[-1] - self._times[0]

    def path_derivative_bounds(self) -> list[tuple[float, float, float, float]]:
        """Per segment, the largest |p'(u)|, |p''(u)| [m], |θ'(u)|, |θ''(u)| [rad] of its path
        over u ∈ [0, 1]: what a time law scales into tool speeds and accelerations.

        Exact: on a cubic Hermite p' is quadratic in u (|p'|² is largest at an end or where
        p'·p'' = 0, a cubic's root) and p'' linear (largest at an end); likewise for the
        rotation's progress g(u).
        """
        out = []
        for seg in self._segments:
            angle = float(np.linalg.norm(seg.phi))
            if seg.curve is None:
                out.append((float(np.linalg.norm(seg.dp_xyz)), 0.0, angle, 0.0))
                continue
            c3, c2, c1, _ = (np.asarray(x, dtype=np.float64) for x in seg.curve[:4])
            ga, gb, gc = seg.curve[4]
            # p'(u) = 3 c3 u² + 2 c2 u + c1; p''(u) = 6 c3 u + 2 c2.
            A, B, C = 3 * c3, 2 * c2, c1
            # d/du |p'|² / 2 = p'·p'' = 2A·A u³ + 3A·B u² + (B·B + 2A·C) u + B·C.
            roots = np.roots([2 * A @ A, 3 * A @ B, B @ B + 2 * A @ C, B @ C])
            us = [0.0, 1.0]
            us += [float(r.real) for r in roots if abs(r.imag) < 1e-12 and 0 < r.real < 1]
            speed = max(float(np.linalg.norm(A * u * u + B * u + C)) for u in us)
            accel = max(float(np.linalg.norm(2 * A * u + B)) for u in (0.0, 1.0))
            # g'(u) = 3 ga u² + 2 gb u + gc, g''(u) = 6 ga u + 2 gb.
            qa, qb = 3 * ga, 2 * gb
            gus = [0.0, 1.0] + ([-qb / (2 * qa)] if qa and 0 < -qb / (2 * qa) < 1 else [])
            rate = max(abs(qa * u * u + qb * u + gc) for u in gus)
            rate_dot = max(abs(2 * qa * u + qb) for u in (0.0, 1.0))
            out.append((speed, accel, angle * float(rate), angle * float(rate_dot)))
        return out

    def segment_index(self, t: float) -> int:
        """Index ``i`` of the segment (keyframe ``i`` → ``i + 1``) active at time ``t`` [s].

        A knot time belongs to the segment that starts there; times are clamped.
        """
        i = bisect.bisect_right(self._times, t) - 1
        return min(max(i, 0), len(self._segments) - 1)

    def active_keyframe(self, t: float) -> Keyframe:
        """Last keyframe reached at time ``t`` [s] (the first one before the start)."""
        i = bisect.bisect_right(self._times, t) - 1
        return self._keyframes[max(i, 0)]

    def next_keyframe_time(self, t: float) -> float:
        """Time [s] of the first keyframe strictly after ``t`` (the end time past the end)."""
        i = bisect.bisect_right(self._times, t)
        return self._times[min(i, len(self._times) - 1)]

    def sample(self, t: float) -> tuple[FloatArray, FloatArray, float]:
        """The plan at time ``t`` [s]: the trajectory's one evaluator.

        Position on the straight line ``p_i + s Δp`` (or the segment's curve), orientation
        ``R_i · exp(s φ_i)`` (MuJoCo's quaternion integration; ``g(s)`` for ``s`` next to a
        pass-through keyframe), spatial velocity ``ṡ [Δp; R_i φ_i]`` on a line with
        ``s = s(τ)``, ``ṡ = s'(τ) / T_i`` under the profile, or ``(s, ṡ)`` from the segment's
        time law; width ``w_i + τ Δw`` (a linear ramp in time). Times before the first keyframe
        or after the last clamp to the ends, where the velocity is zero.

        Args:
            t: Time [s].

        Returns:
            ``(x_WG, V_WG, width)``: tool pose [qw, qx, qy, qz, x, y, z] ([-], [m]), spatial
            velocity [v; ω] in world [m/s, rad/s] and finger gap [m]. The arrays are new.
        """
        times = self._times
        segments = self._segments
        i = min(max(bisect.bisect_right(times, t) - 1, 0), len(segments) - 1)
        seg = segments[i]
        tau = min(max((t - seg.t0) * seg.inv_duration, 0.0), 1.0)
        width = seg.width0 + tau * seg.dwidth
        if t >= times[-1]:
            x_WG = np.array(self._keyframes[-1].X_WG.wxyz_xyz, dtype=np.float64)
            return x_WG, np.zeros(6, dtype=np.float64), width
        js = self._joint[i]
        if js is not None and t > times[0]:
            u, u_dot = self._progress(seg, t)
            x_WG, V_WG, _, _ = js.sample(u, u_dot)
            return x_WG, V_WG, width
        law = seg.law
        if law is None:
            s = self._profile.s(tau)
        else:
            s, s_dot = law(t - seg.t0)
        if seg.curve is not None:
            s_dot_law = s_dot if law is not None else None
            return self._sample_curve(seg, seg.curve, s, s_dot_law, tau, width, t)
        quat = seg.q0.copy()
        mujoco.mju_quatIntegrate(quat, seg.phi, s)  # R0 · exp(s φ), φ in R0's frame
        # Plain float math for the 3-vectors (as exact as NumPy's, elementwise).
        p0x, p0y, p0z = seg.p0_xyz
        dpx, dpy, dpz = seg.dp_xyz
        x_WG = np.array((*quat.tolist(), p0x + s * dpx, p0y + s * dpy, p0z + s * dpz))
        if t <= times[0]:
            return x_WG, np.zeros(6, dtype=np.float64), width
        if law is None:
            s_dot = self._profile.ds(tau) * seg.inv_duration
        wx, wy, wz = seg.omega_dir_W_xyz
        V_WG = np.array((s_dot * dpx, s_dot * dpy, s_dot * dpz, s_dot * wx, s_dot * wy, s_dot * wz))
        return x_WG, V_WG, width

    def _sample_curve(
        self,
        seg: _Segment,
        curve: tuple[tuple[float, ...], ...],
        s: float,
        s_dot: float | None,
        tau: float,
        width: float,
        t: float,
    ) -> tuple[FloatArray, FloatArray, float]:
        """:meth:`sample` on a curved segment: cubic Hermite position, rotation progress g(s)."""
        (ax, ay, az), (bx, by, bz), (cx, cy, cz), (dx, dy, dz), (ga, gb, gc) = curve
        pos = (
            ((ax * s + bx) * s + cx) * s + dx,
            ((ay * s + by) * s + cy) * s + dy,
            ((az * s + bz) * s + cz) * s + dz,
        )
        s3 = 3.0 * s
        dpos = (
            (ax * s3 + 2.0 * bx) * s + cx,
            (ay * s3 + 2.0 * by) * s + cy,
            (az * s3 + 2.0 * bz) * s + cz,
        )
        g = ((ga * s + gb) * s + gc) * s
        dg = (ga * s3 + 2.0 * gb) * s + gc
        quat = seg.q0.copy()
        mujoco.mju_quatIntegrate(quat, seg.phi, g)
        x_WG = np.array((*quat.tolist(), *pos))
        if t <= self._times[0]:
            return x_WG, np.zeros(6, dtype=np.float64), width
        if s_dot is None:
            s_dot = self._profile.ds(tau) * seg.inv_duration
        w = seg.omega_dir_W_xyz
        V_WG = np.array((*(s_dot * v for v in dpos), *(s_dot * dg * w[c] for c in range(3))))
        return x_WG, V_WG, width

    def sample_path(self, n: int) -> FloatArray:
        """Positions ``p_WG`` at ``n`` equally spaced times over the trajectory, shape (n, 3) [m].

        Raises:
            PlanError: ``n`` is not an integer ≥ 2.
        """
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 2:
            raise PlanError(f"n must be an integer >= 2, got {n!r}")
        times = np.linspace(self._times[0], self._times[-1], int(n))
        return np.array([self.sample(t)[0][4:] for t in times.tolist()], dtype=np.float64)
