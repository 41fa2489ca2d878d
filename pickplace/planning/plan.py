"""Keyframes of a gripper motion and their first, Cartesian timing.

:func:`time_keyframes` gives each segment between consecutive keyframes the shortest duration
for which the motion profile (see :mod:`pickplace.planning.trajectory`) respects the linear and
angular speed and acceleration limits of :class:`PlanConfig`; under a profile the tool comes to
rest at every keyframe. Plans executed as made keep this timing (``singular-reach``'s line, a
plan run without the pre-flight). The planner uses it, with speeds of its own, only to sweep a
candidate's path; its plans are then timed by the robot's limits
(:func:`pickplace.planning.timing.retime`), under which the tool stops only where the gripper
acts and at the ends, and passes through the other keyframes.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from mink.lie import SE3, SO3

from pickplace.errors import PlanError, require_finite, require_non_negative, require_positive
from pickplace.geometry import require_pose, rotation_angle, rotation_log, slerp, wrap_angle
from pickplace.planning.grasp import choose_grasp, choose_place_pose
from pickplace.planning.trajectory import Keyframe, MotionProfile, PoseTrajectory, profile_by_name
from pickplace.robot.calibration import GRASP_OPEN_WIDTH
from pickplace.world.scene import Scene

if TYPE_CHECKING:
    from pickplace.robot.calibration import GripperCalibration


@dataclass(frozen=True)
class PlanConfig:
    """Limits and parameters of pick-and-place planning.

    Attributes:
        max_linear_speed: Linear speed of G's origin that the Cartesian timing
            (:func:`time_keyframes`) allows [m/s]. It bounds only plans executed as timed here
            (``singular-reach``, a plan run without the pre-flight): the planner replaces both
            speeds to space its path sweep and times its plans by the robot's joint limits
            (:class:`~pickplace.planning.timing.TimingConfig`, whose optional ``tool_speed``
            and ``tool_accel`` are the tool limits of those plans).
        max_angular_speed: Angular speed of G that the Cartesian timing allows [rad/s]; likewise.
        max_linear_accel: Linear acceleration that the Cartesian timing allows [m/s²]; likewise
            (the planner's path sweep, at constant speed, does not use it).
        max_angular_accel: Angular acceleration that the Cartesian timing allows [rad/s²];
            likewise.
        approach_distance: Offset of pre-pick, pre-place and retreat from the grasp, backwards
            along the approach axis (G's -z, world up for a top grasp) [m].
        lift_height: Height the brick is lifted straight up after closing [m].
        close_time: Duration of closing the gripper, at rest [s], at least: the command
            ramps from open to closed over it, and the planner takes the gripper's calibrated
            close time when longer (:func:`for_gripper`; the grip is steady for its last 30 ms,
            :mod:`pickplace.robot.calibration`).
        open_time: Duration of opening the gripper, at rest [s], at least; likewise the
            gripper's calibrated open time (the pads clear the brick 30 ms before its end).
        settle_time: Rest at the pick pose before closing [s]; 0 omits the "settle" keyframe.
            The arm arrives within 3 mm of the pick pose (measured at full speed) and settles
            in about 50 ms.
        open_width: Commanded finger gap when open [m], at most: the planner opens a
            gripper that opens less as wide as it opens (:func:`for_gripper`).
        closed_width: Commanded finger gap when closed [m]; the brick stops the fingers.
        release_width: Commanded finger gap at the release and the retreat [m]; 0 means
            ``open_width``. The planner releases to the gripper's whole opening, over which its
            open time is calibrated (the pads clear the brick by 5 mm a side before the
            release ends: :mod:`pickplace.robot.calibration`), while it opens only as wide as
            the object needs for the pick.
        min_segment_duration: Lower bound of every segment duration [s].
        time_quantum: When > 0, every segment duration is rounded up to a whole number of
            these [s] (the pre-flight's path sweep puts its ticks on the keyframes with it).
        pass_through: The tool passes through the via points (pre-pick, lift, clearance,
            pre-place) without stopping, the approach and the transfer being smooth curves;
            False: straight lines with a stop at every keyframe. (Under a motion profile it
            comes to rest at every keyframe either way; the robot's timing does not.)
        profile: Motion profile name: "sine", "minimum-jerk" or "linear" (tests only).
    """

    max_linear_speed: float = 0.25
    max_angular_speed: float = 1.0
    max_linear_accel: float = 0.5
    max_angular_accel: float = 2.0
    approach_distance: float = 0.10
    lift_height: float = 0.15
    close_time: float = 0.05
    open_time: float = 0.05
    settle_time: float = 0.05
    open_width: float = GRASP_OPEN_WIDTH
    closed_width: float = 0.0
    release_width: float = 0.0
    min_segment_duration: float = 0.05
    time_quantum: float = 0.0
    pass_through: bool = True
    profile: str = "sine"

    def __post_init__(self) -> None:
        """Validate every field; raise PlanError (UnknownNameError for ``profile``)."""
        for f in fields(self):
            if f.name in ("profile", "pass_through"):
                continue
            value = getattr(self, f.name)
            if f.name in ("settle_time", "closed_width", "time_quantum", "release_width"):
                checked = require_non_negative(f.name, value, PlanError)
            else:
                checked = require_positive(f.name, value, PlanError)
            object.__setattr__(self, f.name, checked)
        if self.open_width <= self.closed_width:
            raise PlanError(
                f"open_width={self.open_width!r} m must be greater than "
                f"closed_width={self.closed_width!r} m"
            )
        profile_by_name(self.profile)

    @property
    def motion_profile(self) -> MotionProfile:
        """The motion profile named by ``profile``."""
        return profile_by_name(self.profile)


DEFAULT_PLAN_CONFIG = PlanConfig()


def for_gripper(config: PlanConfig, gripper: GripperCalibration) -> PlanConfig:
    """``config`` fitted to a calibrated gripper: the open width capped at what it opens to
    [m], the close and open times at least its own [s].

    Raises:
        PlanError: The gripper does not open wider than ``config.closed_width``.
    """
    return dataclasses.replace(
        config,
        open_width=min(config.open_width, gripper.open_width),
        close_time=max(config.close_time, gripper.close_time),
        open_time=max(config.open_time, gripper.open_time),
    )


@dataclass(frozen=True)
class Phases:
    """When the steps of a pick-and-place happen, on the plan's clock [s].

    These times are what the run's checks, faults and validation need from a plan; none of them
    reads keyframe names.

    Attributes:
        approach: (start, end) of the straight descent onto the grasp: the tool reaches the
            pre-grasp pose at the start and the grasp pose at the end.
        grip_closed: The grip must hold the brick from here on.
        transport: (start, end) of the carry through the air: the brick has been lifted at the
            start and is above its goal at the end.
        place_reached: The brick is at its goal pose, still gripped.
        release: The gripper has opened: the brick is let go.
    """

    approach: tuple[float, float]
    grip_closed: float
    transport: tuple[float, float]
    place_reached: float
    release: float

    def __post_init__(self) -> None:
        """Check that the phases follow each other; raise PlanError otherwise."""
        order = [
            ("approach start", self.approach[0]),
            ("approach end", self.approach[1]),
            ("grip_closed", self.grip_closed),
            ("transport start", self.transport[0]),
            ("transport end", self.transport[1]),
            ("place_reached", self.place_reached),
            ("release", self.release),
        ]
        for (name_a, a), (name_b, b) in itertools.pairwise(order):
            if not (math.isfinite(a) and math.isfinite(b) and a <= b):
                raise PlanError(f"phase {name_b} (t={b!r} s) must not precede {name_a} (t={a!r} s)")

    def mapped(self, moved: Callable[[float], float]) -> Phases:
        """These phases on another clock: every time t becomes ``moved(t)`` [s] (a plan
        retimed, or motions replaced, keyframe by keyframe)."""
        return Phases(
            approach=(moved(self.approach[0]), moved(self.approach[1])),
            grip_closed=moved(self.grip_closed),
            transport=(moved(self.transport[0]), moved(self.transport[1])),
            place_reached=moved(self.place_reached),
            release=moved(self.release),
        )


@dataclass(frozen=True)
class Plan:
    """What a run executes: the tool trajectory, and the phases of the task it carries out.

    Attributes:
        trajectory: Tool pose, spatial velocity and gripper width over time.
        phases: When the brick is grasped, carried and released; None for a motion that
            carries nothing (e.g. the singular reach).
        X_OG: The grasp (tool frame in the brick frame) the plan uses, if it picks.
    """

    trajectory: PoseTrajectory
    phases: Phases | None = None
    X_OG: SE3 | None = None


@dataclass(frozen=True)
class Waypoint:
    """An untimed keyframe: input of :func:`time_keyframes`.

    Attributes:
        name: Keyframe name.
        X_WG: Pose of the tool site in world.
        gripper_width: Commanded finger gap [m].
        min_duration: Lower bound of the duration of the segment that ends here [s]
            (e.g. the closing time of an in-place gripper action); ignored for the first.
        stop: The tool comes to rest here (else it passes through: see :class:`Keyframe`).
        curve: The segment that ends here is a smooth curve, not a straight line.
    """

    name: str
    X_WG: SE3
    gripper_width: float
    min_duration: float = 0.0
    stop: bool = True
    curve: bool = False

    def __post_init__(self) -> None:
        """Validate the pose and ``min_duration`` (the name and width are checked by the
        Keyframe that :func:`time_keyframes` makes of it)."""
        require_pose(f"waypoint '{self.name}' X_WG", self.X_WG)
        label = f"waypoint '{self.name}' min_duration [s]"
        object.__setattr__(
            self, "min_duration", require_non_negative(label, self.min_duration, PlanError)
        )


def segment_duration(X_a: SE3, X_b: SE3, config: PlanConfig = DEFAULT_PLAN_CONFIG) -> float:
    """Shortest duration of a motion from ``X_a`` to ``X_b`` within the limits [s].

    The distance ``d = |p_b - p_a|`` [m] and angle ``θ`` of ``R_a⁻¹ R_b`` [rad] are timed
    separately with the profile's peak-speed and peak-acceleration factors; the result is the
    largest of both and ``config.min_segment_duration``.
    """
    profile = config.motion_profile
    d = float(np.linalg.norm(X_b.translation() - X_a.translation()))
    theta = rotation_angle(X_a.rotation(), X_b.rotation())
    return max(
        profile.min_duration(d, config.max_linear_speed, config.max_linear_accel),
        profile.min_duration(theta, config.max_angular_speed, config.max_angular_accel),
        config.min_segment_duration,
    )


def time_keyframes(
    waypoints: Sequence[Waypoint], config: PlanConfig = DEFAULT_PLAN_CONFIG
) -> list[Keyframe]:
    """Give waypoints times: the first at 0 s, each next one a segment duration later.

    The segment ending at waypoint ``k`` lasts
    ``max(segment_duration(X_{k-1}, X_k, config), waypoints[k].min_duration)`` — for a curve
    at least what its own path's largest derivatives need under the profile — rounded up to
    whole ``config.time_quantum`` when that is set.

    Raises:
        PlanError: Fewer than 2 waypoints or an invalid waypoint.
    """
    if len(waypoints) < 2:
        raise PlanError(f"waypoints must contain at least 2 entries, got {len(waypoints)}")
    durations = [segment_duration(a.X_WG, b.X_WG, config) for a, b in itertools.pairwise(waypoints)]
    if any(w.curve for w in waypoints):
        # A curve is longer than its chord and bends: time it by its own path's largest
        # derivatives (the geometry does not depend on the times).
        draft = PoseTrajectory(_keyframes(waypoints, durations), config.profile)
        profile = config.motion_profile
        c_v, c_a = profile.peak_speed_factor, profile.peak_accel_factor
        for i, (d1, d2, a1, a2) in enumerate(draft.path_derivative_bounds()):
            need = [c_v * d1 / config.max_linear_speed, c_v * a1 / config.max_angular_speed]
            if math.isfinite(c_a):
                need.append(math.sqrt((d2 * c_v**2 + d1 * c_a) / config.max_linear_accel))
                need.append(math.sqrt((a2 * c_v**2 + a1 * c_a) / config.max_angular_accel))
            durations[i] = max(durations[i], *need)
    quantum = config.time_quantum
    for i, w in enumerate(waypoints[1:]):
        durations[i] = max(durations[i], w.min_duration)
        if quantum > 0.0:
            durations[i] = math.ceil(durations[i] / quantum - 1e-9) * quantum
    return _keyframes(waypoints, durations)


def _keyframes(waypoints: Sequence[Waypoint], durations: Sequence[float]) -> list[Keyframe]:
    """Keyframes of the waypoints, the first at 0 s and each next one a duration later."""
    t = 0.0
    out = []
    for i, w in enumerate(waypoints):
        if i:
            t += durations[i - 1]
        out.append(Keyframe(w.name, t, w.X_WG, w.gripper_width, w.stop, w.curve, w.min_duration))
    return out


def _backed_off(X_WG: SE3, distance: float) -> SE3:
    """``X_WG`` moved by ``distance`` [m] backwards along G's approach axis (-z_G)."""
    z_G = X_WG.rotation().apply(np.array([0.0, 0.0, 1.0]))
    return SE3.from_rotation_and_translation(X_WG.rotation(), X_WG.translation() - distance * z_G)


def _raised(X_WG: SE3, height: float) -> SE3:
    """``X_WG`` moved up by ``height`` [m] along world z."""
    return SE3.from_rotation_and_translation(
        X_WG.rotation(), X_WG.translation() + np.array([0.0, 0.0, height])
    )


def swung_pose(X_WG: SE3, p_W_to: np.ndarray, p_W_base: np.ndarray | None) -> SE3:
    """``X_WG`` rotated about the vertical base axis until it faces ``p_W_to``.

    The result is the tool pose the arm would carry along if only its base joint turned, the
    yaw reference for choosing among symmetric grasps. Without a base, ``X_WG`` itself.
    """
    if p_W_base is None:
        return X_WG
    swing = base_swing(X_WG.translation(), p_W_to, p_W_base)
    return SE3.from_rotation(SO3.from_z_radians(swing)) @ X_WG


VIA_ORIENTATIONS = ("swing", "shortest")
"""How the clearance via-point's orientation is chosen (see :func:`plan_pick_place`)."""

# A relative rotation whose axis is this close to world z is a turn about z [-].
_VERTICAL_AXIS_TOL = 1e-9


def base_swing(p_W_from: np.ndarray, p_W_to: np.ndarray, p_W_base: np.ndarray) -> float:
    """Azimuth change about the base's vertical axis from one point to another [rad]."""
    a, b = p_W_from[:2] - p_W_base[:2], np.asarray(p_W_to)[:2] - p_W_base[:2]
    return wrap_angle(math.atan2(b[1], b[0]) - math.atan2(a[1], a[0]))


def _swing_halfway(R_a: SO3, R_b: SO3, swing: float) -> SO3:
    """Halfway from ``R_a`` to ``R_b`` turning about world z in the base swing's direction.

    When ``R_b R_aᵀ`` is a turn by δ about world z, the total turn taken is
    Δ = swing + wrap(δ − swing): the base's swing plus the wrist's own change, which can exceed
    π; the result is Rz(Δ/2) R_a. Otherwise (not a pure turn about z) the shortest-arc slerp.
    """
    phi = rotation_log(R_b @ R_a.inverse())  # world-frame rotation vector from R_a to R_b
    if float(np.linalg.norm(phi[:2])) > _VERTICAL_AXIS_TOL:
        return slerp(R_a, R_b, 0.5)
    delta = float(phi[2])
    total = swing + wrap_angle(delta - swing)
    return SO3.from_z_radians(0.5 * total) @ R_a


def plan_pick_place(
    X_WG_initial: SE3,
    X_WO_pick: SE3,
    X_WO_place: SE3,
    clearance_z: float,
    config: PlanConfig = DEFAULT_PLAN_CONFIG,
    grasp_height: float = 0.0,
    p_W_base: npt.ArrayLike | None = None,
    X_OG: SE3 | None = None,
    via: str = "swing",
    other_place: bool = False,
) -> Plan:
    """A plan that picks the brick at ``X_WO_pick`` and places it at ``X_WO_place``.

    Keyframes, in order: ``initial``, ``pre-pick`` (pick backed off by ``approach_distance``
    along the approach axis, i.e. up), ``pick``, ``settle`` (same pose, ``settle_time`` later;
    omitted if ``settle_time`` is 0), ``grip-closed`` (same pose, ``close_time`` later),
    ``lift`` (pick raised by ``lift_height``), ``clearance`` (xy midway between lift and
    pre-place, z = ``clearance_z``, orientation halfway, see ``via``), ``pre-place``, ``place``,
    ``release`` (same pose, ``open_time`` later) and ``retreat`` (place backed off by
    ``approach_distance``). Widths are open up to ``settle``, closed from ``grip-closed`` to
    ``place``, open at ``release`` and ``retreat``; the gripper closes across the
    settle → grip-closed segment and opens across place → release.

    Args:
        X_WG_initial: Current tool pose; also picks which symmetric grasp to use.
        X_WO_pick: Pose of the brick to pick, in world.
        X_WO_place: Goal pose of the brick, in world.
        clearance_z: Absolute world height of the transfer via-point [m].
        config: Limits and parameters.
        grasp_height: Height of G above the brick centre along the brick's z [m].
        p_W_base: Position of the arm's base axis in world [m]. When given, the transfer
            follows the base's swing: the clearance via-point lies at the mean azimuth and
            mean radius of lift and pre-place around the base (not on the chord, which passes
            close to the base and folds the elbow), and the grasp and place yaws are chosen
            relative to the tool yaw carried along by the base rotation, so the wrist does not
            wind up.
        X_OG: The grasp to use; by default the top-down grasp (of the brick's two symmetric
            ones) whose yaw is nearest the tool's, carried along by the base swing.
        via: Orientation of the clearance via-point: ``"swing"`` (default) turns the tool
            about world z with the base swing plus the wrist's own yaw change, halfway; it
            equals the shortest arc whenever that total turn is under π, and goes the long
            way round with the swing otherwise. ``"shortest"``: halfway along the shortest
            arc (slerp), which can turn the wrist against the base swing.
        other_place: Place the brick at its goal turned by half a turn the other way from the
            yaw-nearest choice (:func:`~pickplace.planning.grasp.choose_place_pose`).

    Returns:
        The trajectory through the timed keyframes, the phases (approach: pre-pick → pick;
        grip closed; transport: lift → pre-place; place reached; release) and the grasp X_OG.

    Raises:
        PlanError: Invalid input.
    """
    require_pose("X_WG_initial", X_WG_initial)
    require_pose("X_WO_pick", X_WO_pick)
    require_pose("X_WO_place", X_WO_place)
    clearance_z = require_finite("clearance_z [m]", clearance_z, PlanError)

    if via not in VIA_ORIENTATIONS:
        raise PlanError(f"via must be one of {', '.join(VIA_ORIENTATIONS)}, got {via!r}")
    base = None if p_W_base is None else np.asarray(p_W_base, dtype=np.float64)
    if X_OG is None:
        X_OG = choose_grasp(
            X_WO_pick, swung_pose(X_WG_initial, X_WO_pick.translation(), base), grasp_height
        )
    require_pose("X_OG", X_OG)
    X_WG_pick = X_WO_pick @ X_OG
    X_WG_place = choose_place_pose(
        X_WO_place, X_OG, swung_pose(X_WG_pick, X_WO_place.translation(), base), other_place
    )
    X_WG_lift = _raised(X_WG_pick, config.lift_height)
    X_WG_pre_place = _backed_off(X_WG_place, config.approach_distance)
    p_lift, p_pre_place = X_WG_lift.translation(), X_WG_pre_place.translation()
    if base is None:
        p_clearance = 0.5 * (p_lift + p_pre_place)
    else:
        a, b = p_lift[:2] - base[:2], p_pre_place[:2] - base[:2]
        azimuth_a = math.atan2(a[1], a[0])
        azimuth = azimuth_a + 0.5 * wrap_angle(math.atan2(b[1], b[0]) - azimuth_a)
        radius = 0.5 * (float(np.hypot(*a)) + float(np.hypot(*b)))
        p_clearance = np.array(
            [base[0] + radius * math.cos(azimuth), base[1] + radius * math.sin(azimuth), 0.0]
        )
    p_clearance[2] = clearance_z
    R_lift, R_pre_place = X_WG_lift.rotation(), X_WG_pre_place.rotation()
    R_clearance = slerp(R_lift, R_pre_place, 0.5)
    if via == "swing" and base is not None:
        R_clearance = _swing_halfway(R_lift, R_pre_place, base_swing(p_lift, p_pre_place, base))
    X_WG_clearance = SE3.from_rotation_and_translation(R_clearance, p_clearance)

    w_open, w_closed = config.open_width, config.closed_width
    w_release = config.release_width or w_open
    # The tool stops where the gripper acts and at the ends; it passes through pre-pick, lift,
    # clearance and pre-place: the approach and the transfer are curves that leave and reach
    # the straight vertical moves (descent, lift, place) along them.
    passing = config.pass_through
    waypoints = [
        Waypoint("initial", X_WG_initial, w_open),
        Waypoint(
            "pre-pick",
            _backed_off(X_WG_pick, config.approach_distance),
            w_open,
            stop=not passing,
            curve=passing,
        ),
        Waypoint("pick", X_WG_pick, w_open),
    ]
    if config.settle_time > 0.0:
        waypoints.append(Waypoint("settle", X_WG_pick, w_open, config.settle_time))
    waypoints += [
        Waypoint("grip-closed", X_WG_pick, w_closed, config.close_time),
        Waypoint("lift", X_WG_lift, w_closed, stop=not passing),
        Waypoint("clearance", X_WG_clearance, w_closed, stop=not passing, curve=passing),
        Waypoint("pre-place", X_WG_pre_place, w_closed, stop=not passing, curve=passing),
        Waypoint("place", X_WG_place, w_closed),
        Waypoint("release", X_WG_place, w_release, config.open_time),
        Waypoint("retreat", _backed_off(X_WG_place, config.approach_distance), w_release),
    ]
    keyframes = time_keyframes(waypoints, config)
    t = {k.name: k.t for k in keyframes}  # the names this function itself just gave
    phases = Phases(
        approach=(t["pre-pick"], t["pick"]),
        grip_closed=t["grip-closed"],
        transport=(t["lift"], t["pre-place"]),
        place_reached=t["place"],
        release=t["release"],
    )
    return Plan(PoseTrajectory(keyframes, config.profile), phases, X_OG)


def grasp_width(plan: Plan, scene: Scene) -> float:
    """Width of the brick between the fingers under the plan's grasp [m] (the brick's width
    across its y axis when the plan grasps nothing)."""
    if plan.X_OG is None:
        return scene.brick_width
    return scene.object.width_across(plan.X_OG)
