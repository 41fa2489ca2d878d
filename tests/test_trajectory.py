"""Facts about motion profiles and PoseTrajectory."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from mink.lie import SE3, SO3
from scipy.spatial.transform import Rotation, Slerp

from pickplace.errors import PlanError, UnknownNameError
from pickplace.geometry import rotation_log, slerp, top_down_rotation
from pickplace.planning.plan import PlanConfig, plan_pick_place
from pickplace.planning.trajectory import (
    PROFILES,
    Keyframe,
    LinearProfile,
    MinimumJerkProfile,
    MotionProfile,
    PoseTrajectory,
    SineProfile,
    profile_by_name,
)
from pickplace.world.placements import brick_pose


def pose_at(traj: PoseTrajectory, t: float) -> SE3:
    """The trajectory's pose at ``t`` as an SE3 (from its one evaluator, ``sample``)."""
    return SE3(wxyz_xyz=traj.sample(t)[0])


def velocity_at(traj: PoseTrajectory, t: float) -> np.ndarray:
    """The trajectory's spatial velocity [v; ω] at ``t``."""
    return traj.sample(t)[1]


def width_at(traj: PoseTrajectory, t: float) -> float:
    """The trajectory's gripper width at ``t``."""
    return traj.sample(t)[2]


def quat_angle(q_a: np.ndarray, q_b: np.ndarray) -> float:
    """Angle of the rotation between two wxyz quaternions, accurate for small angles [rad]."""
    q = SO3(wxyz=np.asarray(q_a)).inverse() @ SO3(wxyz=np.asarray(q_b))
    return 2.0 * math.atan2(float(np.linalg.norm(q.wxyz[1:])), abs(float(q.wxyz[0])))


def pose(R: SO3, p: tuple[float, float, float]) -> SE3:
    return SE3.from_rotation_and_translation(R, np.array(p, dtype=np.float64))


def pick_place_keyframes(config: PlanConfig) -> list[Keyframe]:
    X_WG_initial = pose(top_down_rotation(0.4) @ SO3.from_y_radians(0.3), (0.35, 0.05, 0.55))
    plan = plan_pick_place(
        X_WG_initial,
        brick_pose(0.55, -0.30, 0.045, 2.5),
        brick_pose(0.55, 0.30, 0.045, -0.7),
        clearance_z=0.35,
        config=config,
    )
    return list(plan.trajectory.keyframes)


def random_keyframes(rng: np.random.Generator, n: int) -> list[Keyframe]:
    keyframes = []
    t = 0.0
    for i in range(n):
        wxyz = rng.normal(size=4)
        wxyz /= np.linalg.norm(wxyz)
        keyframes.append(
            Keyframe(f"k{i}", t, SE3(np.concatenate([wxyz, rng.uniform(-1, 1, 3)])), 0.05)
        )
        t += float(rng.uniform(0.5, 2.0))
    return keyframes


def trajectories() -> list[PoseTrajectory]:
    rng = np.random.default_rng(7)
    out = [PoseTrajectory(random_keyframes(rng, 6), name) for name in PROFILES]
    for name in ("sine", "minimum-jerk"):
        out.append(PoseTrajectory(pick_place_keyframes(PlanConfig(profile=name)), name))
    return out


TRAJECTORIES = trajectories()


@pytest.mark.parametrize("traj", TRAJECTORIES)
def test_pose_at_keyframe_times_equals_keyframe(traj: PoseTrajectory) -> None:
    for k in traj.keyframes:
        X = pose_at(traj, k.t)
        assert np.max(np.abs(X.translation() - k.X_WG.translation())) <= 1e-12
        assert quat_angle(X.rotation().wxyz, k.X_WG.rotation().wxyz) <= 1e-12


@pytest.mark.parametrize("traj", TRAJECTORIES)
def test_orientation_is_unit_quaternion_everywhere(traj: PoseTrajectory) -> None:
    for t in np.linspace(-0.5, traj.end_time + 0.5, 2001):
        assert abs(np.linalg.norm(pose_at(traj, float(t)).rotation().wxyz) - 1.0) <= 1e-12


def _sign_flip_endpoints() -> list[tuple[SO3, SO3]]:
    """Endpoint pairs whose quaternions are in opposite hemispheres (w_a > 0, w_b < 0)."""
    R_a = SO3.from_rpy_radians(0.1, -0.2, 0.3)
    pairs = []
    for angle in (0.4, 2.0, 3.0):
        R_b = R_a @ SO3.exp(angle * np.array([0.6, 0.0, 0.8]))
        wxyz = R_b.wxyz if R_b.wxyz[0] < 0 else -R_b.wxyz
        pairs.append((R_a, SO3(wxyz=np.array(wxyz))))
    return pairs


@pytest.mark.parametrize(("R_a", "R_b"), _sign_flip_endpoints())
@pytest.mark.parametrize("profile", ["sine", "linear"])
def test_slerp_never_takes_the_long_way_round(R_a: SO3, R_b: SO3, profile: str) -> None:
    assert R_a.wxyz[0] > 0 and R_b.wxyz[0] < 0
    total = quat_angle(R_a.wxyz, R_b.wxyz)
    traj = PoseTrajectory(
        [
            Keyframe("a", 0.0, pose(R_a, (0, 0, 0)), 0.0),
            Keyframe("b", 2.0, pose(R_b, (0, 0, 0)), 0.0),
        ],
        profile,
    )
    quats = [pose_at(traj, float(t)).rotation().wxyz for t in np.linspace(0.0, 2.0, 501)]
    steps = [quat_angle(q0, q1) for q0, q1 in itertools.pairwise(quats)]
    assert max(steps) <= total
    # The path length equals the shortest angle: no detour.
    assert sum(steps) == pytest.approx(total, abs=1e-9)
    for q in quats:
        assert abs(np.linalg.norm(q) - 1.0) <= 1e-12
        assert quat_angle(R_a.wxyz, q) <= total + 1e-12


def test_half_turn_with_zero_w_is_interpolated() -> None:
    """A rotation by exactly π (w == 0) is where mink's log returns zero; ours does not."""
    R_b = SO3(wxyz=np.array([0.0, 0.0, 0.6, 0.8]))
    assert np.linalg.norm(rotation_log(R_b)) == pytest.approx(math.pi, abs=1e-15)
    mid = slerp(SO3.identity(), R_b, 0.5)
    assert quat_angle(SO3.identity().wxyz, mid.wxyz) == pytest.approx(math.pi / 2, abs=1e-12)
    traj = PoseTrajectory(
        [
            Keyframe("a", 0.0, SE3.identity(), 0.0),
            Keyframe("b", 1.0, pose(R_b, (0, 0, 0)), 0.0),
        ],
        "linear",
    )
    omega = velocity_at(traj, 0.3)[3:]
    assert np.linalg.norm(omega) == pytest.approx(math.pi, abs=1e-12)


def _world_rotation_log(R_plus: SO3, R_minus: SO3) -> np.ndarray:
    return rotation_log(R_plus @ R_minus.inverse())


@pytest.mark.parametrize("traj", TRAJECTORIES)
def test_spatial_velocity_matches_central_finite_difference(traj: PoseTrajectory) -> None:
    rng = np.random.default_rng(1234)
    h = 1e-6
    knots = np.array([k.t for k in traj.keyframes])
    times = rng.uniform(traj.start_time, traj.end_time, 1000)
    times = times[np.min(np.abs(knots[None, :] - times[:, None]), axis=1) >= 2 * h]
    assert len(times) >= 990
    errors = []
    for t in times:
        X_plus, X_minus = pose_at(traj, t + h), pose_at(traj, t - h)
        v_fd = (X_plus.translation() - X_minus.translation()) / (2 * h)
        w_fd = _world_rotation_log(X_plus.rotation(), X_minus.rotation()) / (2 * h)
        errors.append(velocity_at(traj, float(t)) - np.concatenate([v_fd, w_fd]))
    assert np.max(np.abs(errors)) <= 1e-6


@pytest.mark.parametrize("traj", [t for t in TRAJECTORIES if t.profile.name != "linear"])
def test_spatial_velocity_is_zero_at_keyframes_and_outside(traj: PoseTrajectory) -> None:
    for k in traj.keyframes:
        assert np.max(np.abs(velocity_at(traj, k.t))) <= 1e-12
    assert not np.any(velocity_at(traj, traj.start_time - 1.0))
    assert not np.any(velocity_at(traj, traj.end_time + 1.0))


@pytest.mark.parametrize("profile", ["sine", "minimum-jerk", "linear"])
def test_planned_velocity_respects_speed_limits(profile: str) -> None:
    config = PlanConfig(profile=profile)
    traj = PoseTrajectory(pick_place_keyframes(config), profile)
    knots = [k.t for k in traj.keyframes]
    times = list(np.linspace(0.0, traj.end_time, 5001))
    times += [0.5 * (a + b) for a, b in itertools.pairwise(knots)]  # sine peaks
    v_max = w_max = 0.0
    for t in times:
        V = velocity_at(traj, float(t))
        v_max = max(v_max, float(np.linalg.norm(V[:3])))
        w_max = max(w_max, float(np.linalg.norm(V[3:])))
    assert v_max <= config.max_linear_speed * (1 + 1e-9)
    assert w_max <= config.max_angular_speed * (1 + 1e-9)
    assert v_max > 0.5 * config.max_linear_speed  # the limits are used, not just respected


def test_pure_rotation_with_linear_profile_has_constant_angular_velocity() -> None:
    R_a = SO3.from_rpy_radians(0.3, 0.2, -1.0)
    R_b = R_a @ SO3.exp(np.array([0.5, -1.0, 0.7]))
    traj = PoseTrajectory(
        [
            Keyframe("a", 0.0, pose(R_a, (0.1, 0.2, 0.3)), 0.0),
            Keyframe("b", 1.5, pose(R_b, (0.1, 0.2, 0.3)), 0.0),
        ],
        "linear",
    )
    omegas = np.array([velocity_at(traj, float(t))[3:] for t in np.linspace(0.01, 1.49, 200)])
    norms = np.linalg.norm(omegas, axis=1)
    assert np.max(np.abs(norms - norms[0])) <= 1e-12
    assert np.max(np.abs(omegas / norms[:, None] - omegas[0] / norms[0])) <= 1e-12
    assert norms[0] == pytest.approx(quat_angle(R_a.wxyz, R_b.wxyz) / 1.5, abs=1e-12)
    # The constant-rate claim also holds for the finite difference of the poses.
    h = 1e-4
    for t in (0.2, 0.7, 1.3):
        w_fd = _world_rotation_log(pose_at(traj, t + h).rotation(), pose_at(traj, t - h).rotation())
        np.testing.assert_allclose(w_fd / (2 * h), omegas[0], rtol=0, atol=1e-9)


@pytest.mark.parametrize("profile", list(PROFILES))
def test_pure_translation_stays_on_the_straight_line(profile: str) -> None:
    R = SO3.from_rpy_radians(0.5, -0.4, 2.0)
    p_a, p_b = np.array([0.3, -0.2, 0.4]), np.array([-0.25, 0.6, 0.1])
    traj = PoseTrajectory(
        [
            Keyframe("a", 0.0, pose(R, tuple(p_a)), 0.0),
            Keyframe("b", 2.0, pose(R, tuple(p_b)), 0.0),
        ],
        profile,
    )
    u = (p_b - p_a) / np.linalg.norm(p_b - p_a)
    for p in traj.sample_path(500):
        assert np.linalg.norm(np.cross(p - p_a, u)) < 1e-12
        assert -1e-12 <= float(np.dot(p - p_a, u)) <= np.linalg.norm(p_b - p_a) + 1e-12


def test_orientation_matches_scipy_slerp_for_linear_profile() -> None:
    rng = np.random.default_rng(99)
    keyframes = random_keyframes(rng, 8)
    traj = PoseTrajectory(keyframes, "linear")
    times = np.array([k.t for k in keyframes])
    xyzw = np.array([np.roll(k.X_WG.rotation().wxyz, -1) for k in keyframes])
    reference = Slerp(times, Rotation.from_quat(xyzw))
    samples = rng.uniform(times[0], times[-1], 500)
    expected = reference(samples).as_quat()
    for t, q_xyzw in zip(samples, expected, strict=True):
        q_wxyz = np.roll(q_xyzw, 1)
        assert quat_angle(pose_at(traj, float(t)).rotation().wxyz, q_wxyz) <= 1e-9


def test_gripper_width_ramps_linearly_across_segments() -> None:
    X = SE3.identity()
    traj = PoseTrajectory(
        [Keyframe("a", 0.0, X, 0.10), Keyframe("b", 1.0, X, 0.10), Keyframe("c", 3.0, X, 0.0)]
    )
    assert width_at(traj, 0.5) == 0.10
    assert width_at(traj, 2.0) == pytest.approx(0.05, abs=1e-15)
    assert width_at(traj, 3.0) == 0.0
    assert width_at(traj, -1.0) == 0.10
    assert width_at(traj, 10.0) == 0.0


def test_segment_index_active_keyframe_and_clamping() -> None:
    X_a = SE3.identity()
    X_b = pose(SO3.identity(), (0.1, 0.0, 0.0))
    traj = PoseTrajectory(
        [Keyframe("a", 0.0, X_a, 0.0), Keyframe("b", 1.0, X_b, 0.0), Keyframe("c", 2.5, X_a, 0.0)]
    )
    assert traj.duration == 2.5
    assert [traj.segment_index(t) for t in (-1.0, 0.0, 0.99, 1.0, 2.5, 9.0)] == [0, 0, 0, 1, 1, 1]
    names = [traj.active_keyframe(t).name for t in (-1.0, 0.0, 0.99, 1.0, 2.49, 2.5, 9.0)]
    assert names == ["a", "a", "a", "b", "b", "c", "c"]
    assert pose_at(traj, -3.0) == X_a
    assert pose_at(traj, 7.0) == X_a
    assert traj.sample_path(7).shape == (7, 3)


@pytest.mark.parametrize(
    "profile", [SineProfile(), MinimumJerkProfile(), LinearProfile()], ids=lambda p: p.name
)
def test_profile_factors_match_the_curves(profile: MotionProfile) -> None:
    taus = np.linspace(0.0, 1.0, 200001)
    ds = np.array([profile.ds(float(t)) for t in taus])
    s = np.array([profile.s(float(t)) for t in taus])
    assert profile.s(0.0) == 0.0 and profile.s(1.0) == pytest.approx(1.0, abs=1e-15)
    np.testing.assert_allclose(np.gradient(s, taus), ds, rtol=0, atol=1e-4)
    assert ds.max() == pytest.approx(profile.peak_speed_factor, rel=1e-9)
    dds = np.abs(np.gradient(ds, taus))
    if math.isfinite(profile.peak_accel_factor):
        assert dds.max() == pytest.approx(profile.peak_accel_factor, rel=1e-6)


def test_profile_by_name() -> None:
    assert isinstance(profile_by_name("minimum-jerk"), MinimumJerkProfile)
    with pytest.raises(UnknownNameError, match=r"profile 'cubic'.*linear, minimum-jerk, sine"):
        profile_by_name("cubic")


def _two(t0: float = 0.0, t1: float = 1.0, w1: float = 0.0) -> list[Keyframe]:
    return [Keyframe("a", t0, SE3.identity(), 0.0), Keyframe("b", t1, SE3.identity(), w1)]


def test_invalid_trajectory_inputs_are_rejected() -> None:
    with pytest.raises(PlanError, match=r"keyframe 'b' time t=0\.5 s must be greater"):
        PoseTrajectory(_two(1.0, 0.5))
    with pytest.raises(PlanError, match=r"keyframe 'b' time t=0\.0 s must be greater"):
        PoseTrajectory(_two(0.0, 0.0))
    with pytest.raises(PlanError, match="keyframes must contain at least 2"):
        PoseTrajectory(_two()[:1])
    with pytest.raises(UnknownNameError, match="unknown profile 'cubic'"):
        PoseTrajectory(_two(), "cubic")
    with pytest.raises(PlanError, match="n must be an integer >= 2"):
        PoseTrajectory(_two()).sample_path(1)


def test_invalid_keyframes_are_rejected() -> None:
    bad_quat = SE3(np.array([1.0, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0]))
    with pytest.raises(PlanError, match=r"keyframe 'x' X_WG quaternion norm .* must be 1"):
        Keyframe("x", 0.0, bad_quat, 0.0)
    with pytest.raises(PlanError, match=r"keyframe 'x' gripper_width \[m\] must be >= 0"):
        Keyframe("x", 0.0, SE3.identity(), -0.01)
    with pytest.raises(PlanError, match=r"keyframe 'x' time t \[s\] must be a finite"):
        Keyframe("x", math.nan, SE3.identity(), 0.0)
    with pytest.raises(PlanError, match="keyframe name must be a non-empty string"):
        Keyframe("", 0.0, SE3.identity(), 0.0)
    with pytest.raises(PlanError, match="keyframe 'x' X_WG must be finite"):
        Keyframe("x", 0.0, SE3(np.array([1.0, 0, 0, 0, math.inf, 0, 0])), 0.0)


def test_sample_is_the_straight_line_and_slerp_of_the_lecture() -> None:
    """sample (MuJoCo quaternion integration, float math) equals p_i + s Δp and
    R_i · exp(s φ_i) computed independently with mink, and ṡ [Δp; R_i φ_i] for the velocity."""
    X0 = SE3.from_rotation_and_translation(
        SO3.from_rpy_radians(np.pi, 0.1, 2.0), np.array([0.4, -0.4, 0.3])
    )
    plan = plan_pick_place(
        X0,
        brick_pose(0.05, -0.55, 0.035, 2.5),
        brick_pose(0.55, 0.0, 0.035, -0.3),
        0.26,
        PlanConfig(pass_through=False),
        p_W_base=np.zeros(3),
    )
    traj = plan.trajectory
    keyframes, profile = traj.keyframes, traj.profile
    for t in np.linspace(-1.0, traj.end_time + 1.0, 997):
        t = float(t)
        i = min(max(traj.segment_index(t), 0), len(keyframes) - 2)
        a, b = keyframes[i], keyframes[i + 1]
        T = b.t - a.t
        tau = min(max((t - a.t) / T, 0.0), 1.0)
        s_ = profile.s(tau)
        phi = rotation_log(a.X_WG.rotation().inverse() @ b.X_WG.rotation())
        R = a.X_WG.rotation() @ SO3.exp(s_ * phi)
        p = a.X_WG.translation() + s_ * (b.X_WG.translation() - a.X_WG.translation())
        x, V, _ = traj.sample(t)
        sign = 1.0 if R.wxyz @ x[:4] >= 0 else -1.0
        np.testing.assert_allclose(x[:4] * sign, R.wxyz, atol=1e-12)
        np.testing.assert_allclose(x[4:], p, atol=1e-12)
        if traj.start_time < t < traj.end_time:
            s_dot = profile.ds(tau) / T
            dp = b.X_WG.translation() - a.X_WG.translation()
            np.testing.assert_allclose(V[:3], s_dot * dp, atol=1e-12)
            np.testing.assert_allclose(V[3:], s_dot * a.X_WG.rotation().apply(phi), atol=1e-12)
        else:
            assert not np.any(V)


def test_sample_returns_new_arrays() -> None:
    traj = TRAJECTORIES[0]
    t = 0.5 * (traj.start_time + traj.end_time)
    a, b = traj.sample(t), traj.sample(t)
    assert not np.shares_memory(a[0], b[0]) and not np.shares_memory(a[1], b[1])
    a[0][:] = 0.0
    a[1][:] = 0.0
    np.testing.assert_array_equal(traj.sample(t)[0], b[0])
    np.testing.assert_array_equal(traj.sample(t)[1], b[1])


def _curved_plan(profile: str = "sine") -> PoseTrajectory:
    X0 = SE3.from_rotation_and_translation(
        SO3.from_rpy_radians(np.pi, 0.1, 2.0), np.array([0.4, -0.4, 0.3])
    )
    return plan_pick_place(
        X0,
        brick_pose(0.05, -0.55, 0.035, 2.5),
        brick_pose(0.55, 0.0, 0.035, -0.3),
        0.26,
        PlanConfig(profile=profile),
        p_W_base=np.zeros(3),
    ).trajectory


def test_pass_through_keyframes_are_on_a_c1_path_whose_velocity_is_its_derivative() -> None:
    """The approach and the transfer are curves through the via points: positions are hit,
    the path's tangent is continuous there, the straight moves (descent, lift, place) stay
    straight, and the velocity is the central difference of the pose."""
    traj = _curved_plan("linear")  # constant parameter speed: the tangent shows in V
    kf = {k.name: k for k in traj.keyframes}
    assert not kf["pre-pick"].stop and not kf["lift"].stop and not kf["clearance"].stop
    for k in traj.keyframes:
        np.testing.assert_allclose(
            pose_at(traj, k.t).translation(), k.X_WG.translation(), atol=1e-12
        )
    for name in ("pre-pick", "lift", "clearance", "pre-place"):
        t = kf[name].t
        before, after = velocity_at(traj, t - 1e-9)[:3], velocity_at(traj, t + 1e-9)[:3]
        cos = before @ after / (np.linalg.norm(before) * np.linalg.norm(after))
        assert cos == pytest.approx(1.0, abs=1e-6), name
    # Straight vertical moves stay straight: the descent from pre-pick to pick.
    t0, t1 = kf["pre-pick"].t, kf["pick"].t
    for t in np.linspace(t0, t1, 11):
        p = pose_at(traj, float(t)).translation()
        np.testing.assert_allclose(p[:2], kf["pick"].X_WG.translation()[:2], atol=1e-12)
    # The velocity is the derivative of the pose.
    h = 1e-6
    for t in np.linspace(0.05, traj.end_time - 0.05, 97):
        t = float(t)
        i = traj.segment_index(t)
        if abs(t - traj.keyframes[i].t) < 2 * h or abs(t - traj.keyframes[i + 1].t) < 2 * h:
            continue
        X_plus, X_minus = pose_at(traj, t + h), pose_at(traj, t - h)
        v_fd = (X_plus.translation() - X_minus.translation()) / (2 * h)
        w_fd = rotation_log(X_plus.rotation() @ X_minus.rotation().inverse()) / (2 * h)
        np.testing.assert_allclose(velocity_at(traj, t), np.concatenate([v_fd, w_fd]), atol=2e-5)


def test_curves_are_timed_within_the_cartesian_limits() -> None:
    """A curve is longer than its chord: its own derivatives set its duration."""
    config = PlanConfig()
    traj = _curved_plan(config.profile)
    speeds = [
        np.linalg.norm(velocity_at(traj, float(t))[:3]) for t in np.linspace(0, traj.end_time, 4001)
    ]
    assert max(speeds) <= config.max_linear_speed * (1 + 1e-6)
    assert max(speeds) > 0.5 * config.max_linear_speed


def test_a_corner_between_two_lines_cannot_be_passed_through() -> None:
    a = Keyframe("a", 0.0, pose(SO3.identity(), (0.0, 0.0, 0.0)), 0.0)
    b = Keyframe("b", 1.0, pose(SO3.identity(), (0.1, 0.0, 0.0)), 0.0, stop=False)
    c = Keyframe("c", 2.0, pose(SO3.identity(), (0.1, 0.1, 0.0)), 0.0)
    with pytest.raises(PlanError, match="corner between two straight segments"):
        PoseTrajectory([a, b, c])
    with pytest.raises(PlanError, match="must stop"):
        PoseTrajectory([a, Keyframe("z", 1.0, a.X_WG, 0.0, stop=False)])
