"""Facts about keyframe planning and timing."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from mink.lie import SE3, SO3

from pickplace.errors import PlanError, UnknownNameError
from pickplace.geometry import rotation_angle, top_down_rotation
from pickplace.planning.grasp import choose_grasp
from pickplace.planning.plan import (
    Phases,
    PlanConfig,
    Waypoint,
    plan_pick_place,
    segment_duration,
    time_keyframes,
)
from pickplace.planning.trajectory import Keyframe
from pickplace.world.placements import brick_pose

NAMES = [
    "initial",
    "pre-pick",
    "pick",
    "settle",
    "grip-closed",
    "lift",
    "clearance",
    "pre-place",
    "place",
    "release",
    "retreat",
]
UP = np.array([0.0, 0.0, 1.0])
X_WG_INITIAL = SE3.from_rotation_and_translation(
    top_down_rotation(0.4) @ SO3.from_y_radians(0.2), np.array([0.35, 0.05, 0.55])
)
X_WO_PICK = brick_pose(0.55, -0.30, 0.045, 2.5)
X_WO_PLACE = brick_pose(0.55, 0.30, 0.045, -1.5)


def plan(config: PlanConfig | None = None, **kwargs: float) -> dict[str, Keyframe]:
    p = plan_pick_place(X_WG_INITIAL, X_WO_PICK, X_WO_PLACE, 0.35, config or PlanConfig(), **kwargs)
    return {k.name: k for k in p.trajectory.keyframes}


def test_keyframe_names_times_and_widths() -> None:
    config = PlanConfig()
    keyframes = plan_pick_place(
        X_WG_INITIAL, X_WO_PICK, X_WO_PLACE, 0.35, config
    ).trajectory.keyframes
    assert [k.name for k in keyframes] == NAMES
    times = [k.t for k in keyframes]
    assert times[0] == 0.0
    assert all(b > a for a, b in itertools.pairwise(times))
    widths = {k.name: k.gripper_width for k in keyframes}
    for name in ("initial", "pre-pick", "pick", "settle", "release", "retreat"):
        assert widths[name] == config.open_width
    for name in ("grip-closed", "lift", "clearance", "pre-place", "place"):
        assert widths[name] == config.closed_width
    k = {kf.name: kf for kf in keyframes}
    assert k["settle"].t - k["pick"].t == pytest.approx(config.settle_time, abs=1e-12)
    assert k["grip-closed"].t - k["settle"].t == pytest.approx(config.close_time, abs=1e-12)
    assert k["release"].t - k["place"].t == pytest.approx(config.open_time, abs=1e-12)


def test_zero_settle_time_omits_the_settle_keyframe() -> None:
    k = plan(PlanConfig(settle_time=0.0))
    assert list(k) == [n for n in NAMES if n != "settle"]
    assert k["grip-closed"].t - k["pick"].t == pytest.approx(PlanConfig().close_time, abs=1e-12)


def test_keyframe_geometry() -> None:
    config = PlanConfig()
    k = plan(config)

    def p(name: str) -> np.ndarray:
        return k[name].X_WG.translation()

    def same_rotation(a: str, b: str) -> bool:
        return rotation_angle(k[a].X_WG.rotation(), k[b].X_WG.rotation()) <= 1e-12

    np.testing.assert_allclose(p("pre-pick"), p("pick") + config.approach_distance * UP, atol=1e-15)
    np.testing.assert_allclose(p("lift"), p("pick") + config.lift_height * UP, atol=1e-15)
    np.testing.assert_allclose(
        p("pre-place"), p("place") + config.approach_distance * UP, atol=1e-15
    )
    np.testing.assert_allclose(p("retreat"), p("place") + config.approach_distance * UP, atol=1e-15)
    for a, b in [("pre-pick", "pick"), ("pick", "lift"), ("pre-place", "place")]:
        assert same_rotation(a, b)
    for name in ("settle", "grip-closed"):
        assert k[name].X_WG == k["pick"].X_WG
    assert k["release"].X_WG == k["place"].X_WG
    # Clearance via-point: xy midway, absolute z, orientation halfway.
    np.testing.assert_allclose(
        p("clearance")[:2], 0.5 * (p("lift")[:2] + p("pre-place")[:2]), atol=1e-15
    )
    assert p("clearance")[2] == 0.35
    R_lift, R_mid, R_pre = (k[n].X_WG.rotation() for n in ("lift", "clearance", "pre-place"))
    total = rotation_angle(R_lift, R_pre)
    assert total > 0.1
    assert rotation_angle(R_lift, R_mid) == pytest.approx(total / 2, abs=1e-12)
    assert rotation_angle(R_mid, R_pre) == pytest.approx(total / 2, abs=1e-12)


@pytest.mark.parametrize("brick_yaw", np.linspace(-math.pi, math.pi, 25))
def test_pick_keyframe_is_the_chosen_grasp(brick_yaw: float) -> None:
    X_WO_pick = brick_pose(0.5, -0.3, 0.045, float(brick_yaw))
    keyframes = plan_pick_place(
        X_WG_INITIAL, X_WO_pick, X_WO_PLACE, 0.35, grasp_height=0.01
    ).trajectory.keyframes
    X_WG_pick = next(k.X_WG for k in keyframes if k.name == "pick")
    X_OG = choose_grasp(X_WO_pick, X_WG_INITIAL, grasp_height=0.01)
    X_OG_planned = X_WO_pick.inverse() @ X_WG_pick
    np.testing.assert_allclose(X_OG_planned.translation(), X_OG.translation(), atol=1e-12)
    assert rotation_angle(X_OG_planned.rotation(), X_OG.rotation()) <= 1e-12
    # The brick is placed where asked, with the same grasp (up to its π symmetry).
    X_WG_place = next(k.X_WG for k in keyframes if k.name == "place")
    X_WO_placed = X_WG_place @ X_OG.inverse()
    np.testing.assert_allclose(X_WO_placed.translation(), X_WO_PLACE.translation(), atol=1e-12)
    angle = rotation_angle(X_WO_placed.rotation(), X_WO_PLACE.rotation())
    assert min(angle, abs(angle - math.pi)) <= 1e-9


def test_segment_duration_formulas() -> None:
    config = PlanConfig()
    start = SE3.identity()
    long_move = SE3.from_translation(np.array([1.0, 0.0, 0.0]))  # speed-limited
    short_move = SE3.from_translation(np.array([0.0, 0.01, 0.0]))  # accel-limited
    turn = SE3.from_rotation(SO3.from_z_radians(1.5))  # angular speed-limited
    assert segment_duration(start, long_move, config) == pytest.approx(math.pi / (2 * 0.25))
    assert segment_duration(start, short_move, config) == pytest.approx(
        math.pi * math.sqrt(0.01 / (2 * 0.5))
    )
    assert segment_duration(start, turn, config) == pytest.approx(math.pi * 1.5 / 2.0)
    assert segment_duration(start, start, config) == config.min_segment_duration
    mj = PlanConfig(profile="minimum-jerk")
    assert segment_duration(start, long_move, mj) == pytest.approx(1.875 / 0.25)
    assert segment_duration(start, short_move, mj) == pytest.approx(
        math.sqrt(10 / math.sqrt(3) * 0.01 / 0.5)
    )
    linear = PlanConfig(profile="linear")
    assert segment_duration(start, long_move, linear) == pytest.approx(1.0 / 0.25)
    assert segment_duration(start, short_move, linear) == config.min_segment_duration


def test_time_keyframes_for_a_reach_plan() -> None:
    R = top_down_rotation(math.pi / 2)
    X_start = SE3.from_rotation_and_translation(R, np.array([0.0, 0.45, 0.3]))
    X_far = SE3.from_rotation_and_translation(R, np.array([0.0, 0.85, 0.3]))
    keyframes = time_keyframes(
        [
            Waypoint("start", X_start, 0.1),
            Waypoint("far", X_far, 0.1),
            Waypoint("back", X_start, 0.1, min_duration=5.0),
        ]
    )
    assert [k.name for k in keyframes] == ["start", "far", "back"]
    assert keyframes[1].t == pytest.approx(math.pi * 0.4 / (2 * 0.25))
    assert keyframes[2].t - keyframes[1].t == 5.0


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("max_linear_speed", 0.0, "max_linear_speed must be a finite number > 0, got 0.0"),
        ("max_angular_speed", -1.0, "max_angular_speed must be a finite number > 0"),
        ("max_linear_accel", math.inf, "max_linear_accel must be a finite number > 0"),
        ("max_angular_accel", math.nan, "max_angular_accel must be a finite number > 0"),
        ("approach_distance", 0.0, "approach_distance must be"),
        ("lift_height", -0.1, "lift_height must be"),
        ("close_time", 0.0, "close_time must be"),
        ("open_time", 0.0, "open_time must be"),
        ("settle_time", -0.1, "settle_time must be >= 0"),
        ("closed_width", -0.01, "closed_width must be >= 0"),
        ("open_width", 0.0, "open_width must be"),
        ("min_segment_duration", 0.0, "min_segment_duration must be"),
    ],
)
def test_invalid_plan_config_is_rejected(field: str, value: float, message: str) -> None:
    with pytest.raises(PlanError, match=message):
        PlanConfig(**{field: value})  # type: ignore[arg-type]


def test_invalid_plan_inputs_are_rejected() -> None:
    with pytest.raises(PlanError, match=r"open_width=0\.02 m must be greater than closed_width"):
        PlanConfig(open_width=0.02, closed_width=0.03)
    with pytest.raises(UnknownNameError, match="unknown profile 'cubic'"):
        PlanConfig(profile="cubic")
    with pytest.raises(PlanError, match=r"clearance_z \[m\] must be a finite number"):
        plan_pick_place(X_WG_INITIAL, X_WO_PICK, X_WO_PLACE, math.nan)
    bad = SE3(np.array([1.0, 0.2, 0.0, 0.0, 0.5, 0.0, 0.05]))
    with pytest.raises(PlanError, match="X_WO_place quaternion norm"):
        plan_pick_place(X_WG_INITIAL, X_WO_PICK, bad, 0.35)
    with pytest.raises(PlanError, match="waypoints must contain at least 2"):
        time_keyframes([Waypoint("a", SE3.identity(), 0.0)])
    with pytest.raises(PlanError, match=r"waypoint 'a' min_duration \[s\] must be >= 0"):
        Waypoint("a", SE3.identity(), 0.0, min_duration=-1.0)
    with pytest.raises(PlanError, match=r"keyframe 'b' gripper_width \[m\] must be >= 0"):
        time_keyframes([Waypoint("a", SE3.identity(), 0.0), Waypoint("b", SE3.identity(), -1.0)])


def test_phases_are_the_plan_s_own_keyframe_times() -> None:
    """The run reads phases, not names: they must be the times of the keyframes they stand
    for, in order (descent, grip, carry, place, release)."""
    p = plan_pick_place(X_WG_INITIAL, X_WO_PICK, X_WO_PLACE, 0.35, PlanConfig())
    k = {kf.name: kf.t for kf in p.trajectory.keyframes}
    assert p.phases == Phases(
        approach=(k["pre-pick"], k["pick"]),
        grip_closed=k["grip-closed"],
        transport=(k["lift"], k["pre-place"]),
        place_reached=k["place"],
        release=k["release"],
    )
    assert p.X_OG is not None
    X_WG_pick = SE3(p.trajectory.sample(p.phases.approach[1])[0])
    np.testing.assert_allclose((X_WO_PICK @ p.X_OG).wxyz_xyz, X_WG_pick.wxyz_xyz, atol=1e-12)
    assert p.trajectory.next_keyframe_time(p.phases.transport[0]) == k["clearance"]


def test_phases_out_of_order_are_rejected() -> None:
    with pytest.raises(PlanError, match=r"phase grip_closed .* must not precede approach end"):
        Phases(approach=(1.0, 2.0), grip_closed=1.5, transport=(3, 4), place_reached=5, release=6)
