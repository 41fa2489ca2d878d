"""Time-optimal timing by the robot's limits: the TOPP solution against the toppra
package and against the limits it must respect; plans retimed without changing their path."""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
import pytest
from mink.lie import SE3

import pickplace.planning.planner as planner_module
from pickplace.errors import InvalidInputError, PlanError
from pickplace.planning.plan import PlanConfig
from pickplace.planning.planner import PickPlacePlanner
from pickplace.planning.timing import (
    GRAVITY_W,
    SegmentLimits,
    TimingConfig,
    TimingStallError,
    cycle_time_at_speed_limits,
    cycle_time_bound,
    path_derivatives,
    scaled_law,
    slip_box,
    time_optimal_law,
    time_optimal_profile,
)
from pickplace.planning.trajectory import Keyframe
from pickplace.run.runner import RunRequest, prepare
from tests.conftest import finished

V_MAX = np.array([1.48, 1.48, 1.75, 1.31, 2.27, 2.36, 2.36])
A_MAX = np.array([8.57, 8.57, 8.74, 11.36, 12.23, 15.72, 15.72])


def _path(seed: int, n: int = 40) -> np.ndarray:
    """A smooth random joint path sampled at u = k / n."""
    rng = np.random.default_rng(seed)
    u = np.linspace(0.0, 1.0, n + 1)[:, None]
    q0, dq = rng.uniform(-1, 1, 7), rng.uniform(-1.2, 1.2, 7)
    bend = rng.uniform(-0.3, 0.3, 7)
    return q0 + u * dq + np.sin(np.pi * u) * bend


@pytest.mark.parametrize("seed", range(6))
def test_duration_equals_toppra_on_the_same_path(seed: int) -> None:
    toppra = pytest.importorskip("toppra")
    import toppra.algorithm as algo
    import toppra.constraint as constraint

    q = _path(seed)
    u = np.linspace(0.0, 1.0, len(q))
    law = time_optimal_law(q, np.zeros(3), np.zeros(3), SegmentLimits(V_MAX, A_MAX))
    path = toppra.SplineInterpolator(u, q)
    instance = algo.TOPPRA(
        [constraint.JointVelocityConstraint(V_MAX), constraint.JointAccelerationConstraint(A_MAX)],
        path,
        gridpoints=u,
        parametrizer="ParametrizeConstAccel",
    )
    reference = instance.compute_trajectory(0, 0)
    # toppra differentiates a spline through the samples, we the samples: within 1 %.
    assert law.duration == pytest.approx(reference.duration, rel=0.01)


@pytest.mark.parametrize("seed", range(6))
def test_the_law_respects_every_joint_limit_and_rests_at_both_ends(seed: int) -> None:
    q = _path(seed)
    law = time_optimal_law(q, np.zeros(3), np.zeros(3), SegmentLimits(V_MAX, A_MAX))
    dq, ddq = path_derivatives(q)
    x = np.square(law.u_dot)
    w = np.asarray(law.u_ddot)
    speed = np.abs(dq) * np.sqrt(x)[:, None]
    assert np.all(speed <= V_MAX * (1 + 1e-9))
    # The acceleration on each interval, at its first grid point (TOPP-RA's discretisation).
    acc = ddq[:-1] * x[:-1, None] + dq[:-1] * w[:, None]
    assert np.all(np.abs(acc) <= A_MAX * (1 + 1e-9))
    assert law(0.0) == (0.0, 0.0) and law(law.duration) == (1.0, 0.0)
    # Some limit is active at every interval (the law is as fast as allowed, not merely
    # feasible): the speed, or the acceleration at one end of the interval.
    tight = (speed / V_MAX).max(axis=1)[:-1] > 0.999
    tight |= (np.abs(acc) / A_MAX).max(axis=1) > 0.999
    acc_end = ddq[1:] * x[1:, None] + dq[1:] * w[:, None]
    tight |= (np.abs(acc_end) / A_MAX).max(axis=1) > 0.999
    assert tight.mean() > 0.9


def test_the_law_is_continuous_and_its_speed_integrates_to_its_position() -> None:
    law = time_optimal_law(_path(3), np.zeros(3), np.zeros(3), SegmentLimits(V_MAX, A_MAX))
    t = np.linspace(0.0, law.duration, 4001)
    u, ud = np.array([law(float(x)) for x in t]).T
    assert np.all(np.diff(u) >= -1e-12) and u[0] == 0.0 and u[-1] == 1.0
    # Trapezoid integral of u̇ is u (the law is piecewise quadratic in time).
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (ud[1:] + ud[:-1]) * np.diff(t))])
    np.testing.assert_allclose(integral, u, atol=2e-4)
    assert np.max(np.abs(np.diff(u))) < 1e-2  # no jumps


def test_speed_only_timing_approaches_the_path_length_bound() -> None:
    """With (nearly) unlimited acceleration the time is ∫ max_j |q'_j| / v_j du, which is at
    least each joint's path length over its speed limit."""
    q = _path(1, n=200)
    law = time_optimal_law(q, np.zeros(3), np.zeros(3), SegmentLimits(V_MAX, np.full(7, 1e6)))
    dq, _ = path_derivatives(q)
    integrand = np.max(np.abs(dq) / V_MAX, axis=1)
    integral = float(np.sum(0.5 * (integrand[1:] + integrand[:-1])) / (len(q) - 1))
    assert law.duration == pytest.approx(integral, rel=0.02)
    per_joint = np.abs(np.diff(q, axis=0)).sum(axis=0) / V_MAX
    assert law.duration >= per_joint.max() * (1 - 1e-9)


def test_tool_and_slip_limits_bind_when_they_are_the_tightest() -> None:
    q = _path(2)
    dp = np.array([0.3, 0.0, 0.0])
    free = time_optimal_law(q, dp, np.zeros(3), SegmentLimits(V_MAX, A_MAX))
    slow = time_optimal_law(
        q, dp, np.zeros(3), SegmentLimits(V_MAX, A_MAX, tool_speed=0.05, tool_accel=0.1)
    )
    # 0.3 m at ≤ 0.05 m/s with ≤ 0.1 m/s²: at least 6 s (plus the ramps).
    assert slow.duration >= 0.3 / 0.05 and slow.duration > free.duration
    assert max(slow.u_dot) * 0.3 <= 0.05 * (1 + 1e-9)
    with pytest.raises(PlanError, match="too heavy for the grip"):
        time_optimal_law(q, dp, np.zeros(3), SegmentLimits(V_MAX, A_MAX, slip_accel=5.0))


@pytest.mark.parametrize("budget", [9.82, 12.0, 30.0, 63.0, 64.0, 400.0])
def test_the_slip_box_lies_in_the_friction_ball_and_holds_the_brick_at_rest(budget: float) -> None:
    half = slip_box(budget)
    g = np.abs(GRAVITY_W)
    assert np.linalg.norm(half) <= budget * (1 + 1e-12)  # every corner of the box in the ball
    assert np.all(half >= g) and np.all(half > 0)  # a = 0 inside: |−g_i| ≤ half_i
    if budget / np.sqrt(3) >= (budget + 9.81) / 2:  # the cube holds g with room to spare
        np.testing.assert_allclose(half, budget / np.sqrt(3))


def test_a_law_can_be_slowed_but_not_sped_up() -> None:
    law = time_optimal_law(_path(4), np.zeros(3), np.zeros(3), SegmentLimits(V_MAX, A_MAX))
    slow = scaled_law(law, 2 * law.duration)
    assert slow.duration == pytest.approx(2 * law.duration)
    for t in np.linspace(0, law.duration, 17):
        u, ud = law(float(t))
        u2, ud2 = slow(float(2 * t))
        assert u2 == pytest.approx(u) and ud2 == pytest.approx(ud / 2)
    with pytest.raises(PlanError, match="cannot be sped up"):
        scaled_law(law, 0.5 * law.duration)


def test_speed_override_is_validated() -> None:
    for bad in (0.0, -0.5, 1.5, math.nan, 1e-9):
        with pytest.raises(InvalidInputError, match=r"speed must be a number in \[0.001, 1\]"):
            TimingConfig(speed=bad)


def test_retimed_plan_keeps_its_path_and_phases_and_beats_the_cartesian_timing() -> None:
    _, task, _ = prepare(RunRequest())
    planning = task.planning
    assert planning is not None and planning.chosen is not None
    timed = task.plan
    names = [k.name for k in timed.trajectory.keyframes]
    assert names[0] == "initial" and names[-1] == "retreat"
    times = [k.t for k in timed.trajectory.keyframes]
    assert all(b > a for a, b in itertools.pairwise(times))
    phases = timed.phases
    assert phases is not None and phases.grip_closed in times and phases.release in times
    # Every keyframe pose is reached exactly; at rest where the tool stops, moving where it
    # passes through (pre-pick, lift, clearance, pre-place: the motions are not cut there).
    for k in timed.trajectory.keyframes:
        x, V, _ = timed.trajectory.sample(k.t)
        np.testing.assert_allclose(x[4:], k.X_WG.translation(), atol=1e-9)
        if k.stop:
            assert np.max(np.abs(V)) <= 1e-9
        else:
            assert np.linalg.norm(V[:3]) > 0.05
    assert timed.trajectory.end_time < 5.0  # the Cartesian timing took 13.9 s


@pytest.mark.slow
def test_quarter_speed_takes_about_four_times_as_long_and_succeeds() -> None:
    _, fast_task, _ = prepare(RunRequest())
    _, slow_task, slow = prepare(RunRequest(speed=0.25))
    c = PlanConfig()
    holds = c.settle_time + c.close_time + c.open_time  # the gripper's own times do not scale

    def motion(task) -> float:  # type: ignore[no-untyped-def]
        return task.trajectory.end_time - holds

    assert motion(slow_task) / motion(fast_task) == pytest.approx(4.0, rel=0.05)
    s = slow.run().summary()
    assert s["success"], s["failure"]
    # The plan asks for at most 0.25 · 95 % of each limit; the controller's error feedback adds
    # a little on top.
    assert s["max_joint_speed_ratio"] <= 0.3


def test_the_cycle_time_bound_is_a_lower_bound_of_the_run() -> None:
    run = finished()  # the nominal run
    sim, task, s = run.sim, run.sim.task, run.summary()
    assert s["success"]
    args = (task.trajectory.keyframes, sim.dt, sim.log.q_cmd, sim.scene.robot.v_max)
    bound, at_speed_limits = cycle_time_bound(*args), cycle_time_at_speed_limits(*args)
    assert 0 < bound <= at_speed_limits <= s["cycle_time_s"]
    assert s["cycle_time_s"] == pytest.approx(task.trajectory.end_time)


def test_at_the_speed_limits_the_tightest_joint_counts_step_by_step() -> None:
    """Joint 0 leads the first half of a motion, joint 1 the second: the bound takes the
    larger per-joint total (1.2 s), the speed-limited time each step's leader (2.0 s); an
    in-place segment counts its own duration in both."""
    X_a = SE3.from_translation(np.zeros(3))
    X_b = SE3.from_translation(np.array([0.1, 0.0, 0.0]))
    dt = 0.1
    keyframes = [
        Keyframe("start", 0.0, X_a, 0.0),
        Keyframe("end", 2.0, X_b, 0.0),
        Keyframe("hold", 2.5, X_b, 0.0),
    ]
    steps = np.array([[0.1, 0.02]] * 10 + [[0.02, 0.1]] * 10 + [[0.0, 0.0]] * 5)
    q = np.vstack([np.zeros(2), np.cumsum(steps, axis=0)])
    v_max = np.ones(2)
    assert cycle_time_bound(keyframes, dt, q, v_max) == pytest.approx(1.2 + 0.5)
    assert cycle_time_at_speed_limits(keyframes, dt, q, v_max) == pytest.approx(2.0 + 0.5)


def test_a_path_a_limit_leaves_no_speed_on_stalls_and_the_planner_refuses_that_candidate() -> None:
    """A joint moving along the path with (all but) no speed allowed leaves the middle of the
    path no speed: a TimingStallError. The planner makes it the candidate's problem (its
    motion named), never an error of the run, and goes on to the next candidate."""
    s = np.linspace(0.0, 0.2, 21)
    q = np.stack([np.sin(10.0 * s), s], axis=1)  # joint 0 moves, then turns back
    p_W = np.stack([s, np.zeros_like(s), np.zeros_like(s)], axis=1)
    limits = SegmentLimits(v_max=np.array([1e-300, 1.0]), a_max=np.array([10.0, 10.0]))
    with pytest.raises(TimingStallError, match="admits no speed"):
        time_optimal_profile(q, s, p_W, np.zeros_like(p_W), limits)
    ok = SegmentLimits(v_max=np.array([1.0, 1.0]), a_max=np.array([10.0, 10.0]))
    assert time_optimal_profile(q, s, p_W, np.zeros_like(p_W), ok).t[-1] > 0.0


def test_a_candidate_whose_path_stalls_is_refused_and_the_next_one_planned(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The planner makes a stalled timing the candidate's problem (``speed-limit``, at the
    stalled motion's start, naming it), never an error of the run, and goes on."""
    scene, task, _ = prepare(RunRequest(scenario="pick-place"))
    planner = PickPlacePlanner(scene, "qp")
    calls: list[int] = []

    def stalls_once(*args: Any, **kwargs: Any) -> Any:
        calls.append(1)
        if len(calls) == 1:
            raise TimingStallError("the timing stalls (test)", 0.25)
        return real_retime(*args, **kwargs)

    real_retime = planner_module.retime
    monkeypatch.setattr(planner_module, "retime", stalls_once)
    report = planner.plan(task.X_WO_start, task.goal.X_WO_goal)  # type: ignore[attr-defined]
    first = report.candidates[0].preflight.problem
    assert first is not None and first.kind == "speed-limit" and first.t == 0.25
    assert "stalls" in first.text
    assert report.feasible and report.chosen == 1
