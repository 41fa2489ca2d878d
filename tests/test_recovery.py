"""Trying again after a missed grasp or a drop (pickplace/sim/recovery.py), the loop's plan
replacement, the planner's start configuration and --attempts, against what they promise."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest
from mink.lie import SE3, SO3

from pickplace.control.kinematics import ArmKinematics
from pickplace.errors import InvalidInputError, PlanError
from pickplace.geometry import AXIS_ROTATIONS, box_corners, transform_points
from pickplace.planning.planner import PickPlacePlanner, Start
from pickplace.planning.preflight import Preflight
from pickplace.run.runner import RunRequest, prepare
from pickplace.sim.checks import (
    CheckContext,
    Failure,
    FailureReason,
    GraspMonitor,
    SuccessCriteria,
)
from pickplace.sim.events import EventKind
from pickplace.sim.loop import Simulation
from pickplace.sim.recovery import (
    RECOVERABLE,
    CommandedDrift,
    Reattempt,
    StopTrajectory,
    check_attempts,
    limit_held,
    standing_goal,
)
from pickplace.sim.ticklog import TickLog
from pickplace.sim.verdict import WALL_TIME_FIELDS, RunResult, brick_pose, placement_problems
from pickplace.world.scene import Scene
from tests.conftest import CliRun


def _run(scenario: str, attempts: int, **kw: Any) -> tuple[Simulation, RunResult]:
    _, _, sim = prepare(RunRequest(scenario=scenario, attempts=attempts, **kw))
    return sim, sim.run()


def _without_wall_time(summary: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in summary.items() if k not in WALL_TIME_FIELDS}


# ------------------------------------------------------------------ one attempt: as before


def test_one_attempt_is_the_run_without_a_recovery() -> None:
    """--attempts 1 takes nothing up: the same summary, tick for tick, as the task without
    any recovery at all."""
    _, result = _run("fault-brick-moved", 1)
    _, task, bare = prepare(RunRequest(scenario="fault-brick-moved"))
    bare.task = dataclasses.replace(task, recovery=None)
    plain = bare.run()
    assert result.failure is FailureReason.MISSED_GRASP
    assert _without_wall_time(result.summary()) == _without_wall_time(plain.summary())
    assert [a["attempt"] for a in result.summary()["attempts"]] == [1]
    assert result.summary()["replans"] == []


def test_a_run_without_faults_takes_one_attempt_and_keeps_its_summary() -> None:
    """Allowing 3 attempts changes nothing for a run that succeeds (the grasp is judged at a
    block's end, and block lengths never change a run)."""
    _, three = _run("pick-place", 3)
    _, one = _run("pick-place", 1)
    assert three.success and len(three.summary()["attempts"]) == 1
    assert _without_wall_time(three.summary()) == _without_wall_time(one.summary())


# ------------------------------------------------------------------ a missed grasp recovered


@pytest.fixture(scope="module")
def recovered() -> tuple[Simulation, RunResult]:
    return _run("fault-brick-moved", 3)


def test_a_missed_grasp_is_recovered_and_the_brick_rests_in_bin_2(
    recovered: tuple[Simulation, RunResult],
) -> None:
    sim, result = recovered
    assert result.success, result.failure_text
    # The same verdict as any run, from the simulated end state.
    plan = sim.plan
    assert plan.X_OG is not None
    width = float(np.ptp([k.gripper_width for k in plan.trajectory.keyframes]))
    assert placement_problems(sim.scene, sim.data, sim.scene.target_bin, sim.criteria, 0.0) == []
    assert width > 0.0
    s = result.summary()
    first, second = s["attempts"]
    assert first["failure"] == "missed-grasp" and first["failure_text"].startswith("missed-grasp: ")
    assert second["success"] and second["failure"] is None
    (replan,) = s["replans"]
    assert replan["after"] == "missed-grasp" and replan["failure_text"] == first["failure_text"]
    assert replan["tick"] == second["start_tick"] and replan["candidate"] == second["candidate"]
    assert s["failure"] is None and s["cycle_time_s"] > second["start_time_s"]


def test_each_replan_starts_at_its_tick_and_its_plan_is_sampled_from_there(
    recovered: tuple[Simulation, RunResult],
) -> None:
    """The stop starts at the tick after the failure's block, the new plan at its event's
    tick, sampled at t - t_start: the log's planned pose there is the plan's first pose."""
    sim, result = recovered
    first, second = result.attempts or []
    replans = [e for e in result.events if e.kind is EventKind.REPLAN]
    assert [e.tick for e in replans] == [first.stop_tick, second.start_tick]
    assert first.failure_tick is not None and first.stop_tick is not None
    assert first.failure_tick < first.stop_tick < second.start_tick
    # The failure was judged right after the grip closed: the stop begins one tick later.
    assert first.stop_tick == first.failure_tick + 1
    assert sim.plan_start == pytest.approx(second.start_tick * sim.dt)
    x0 = sim.plan.trajectory.sample(0.0)[0]
    np.testing.assert_allclose(sim.log.x_WG_plan[second.start_tick], x0, atol=1e-12)
    # Keyframe events of each attempt: the new plan's pick is reached after it started.
    picks = [e for e in result.events if e.kind is EventKind.KEYFRAME and "'pick'" in e.text]
    assert len(picks) == 2 and picks[1].tick > second.start_tick


def test_the_stop_has_no_velocity_step_and_stays_within_the_acceleration_limits() -> None:
    """A drop mid-transport (the arm near its speed limits): over the stop the commanded
    joint accelerations stay within the robot's limits and the speeds fall to zero."""
    sim, result = _run("fault-heavy-brick", 2)
    first = (result.attempts or [])[0]
    assert first.failure is FailureReason.DROPPED and first.stop_tick is not None
    k = first.stop_tick
    a_max = sim.scene.robot.a_max
    assert a_max is not None
    qdot = sim.log.qdot_cmd
    accel = np.abs(np.diff(qdot[k - 1 : k + 80], axis=0)) / sim.dt / a_max
    assert accel.max() <= 1.0
    assert np.abs(qdot[k - 1]).max() > 0.5  # it was moving fast
    # At rest (but for the IK's sub-mm corrections) when the next plan starts from there.
    second = (result.attempts or [])[1]
    assert np.abs(qdot[second.start_tick - 1]).max() < 1e-3


def test_a_fault_that_persists_ends_with_its_reason_after_the_last_attempt() -> None:
    """The disabled gripper misses every time: three attempts, then missed-grasp exactly as
    a one-attempt run words it."""
    _, result = _run("fault-gripper-disabled", 3)
    _, once = _run("fault-gripper-disabled", 1)
    assert result.failure is FailureReason.MISSED_GRASP
    attempts = result.summary()["attempts"]
    assert [a["failure"] for a in attempts] == ["missed-grasp"] * 3
    assert attempts[-1]["failure_tick"] == result.failure_tick
    words = [w for w in (result.failure_text or "").split() if not w[0].isdigit()]
    assert words == [w for w in (once.failure_text or "").split() if not w[0].isdigit()]


def test_a_brick_knocked_upside_down_is_picked_again_as_it_lies() -> None:
    """The knock throws the brick out of the grip and it lands in bin 1 on another face: the
    same box with its frame turned, planned for that frame and placed; with one attempt the
    run ends dropped at the drop's tick, with the same text up to the recovery's."""
    _, result = _run("fault-knock", 3)
    _, once = _run("fault-knock", 1)
    assert once.failure is FailureReason.DROPPED
    assert result.success, result.failure_text
    first, second = result.summary()["attempts"]
    assert first["failure"] == "dropped" and first["failure_tick"] == once.failure_tick
    assert first["failure_text"] == once.failure_text and second["success"]


class _StoodOnEnd:
    """After planning, the brick stands on a 50 x 50 mm end 80 mm along world x from where it
    was planned for: the fingers close on nothing (a test's fault, like fault-brick-moved)."""

    name = "stood-on-end"

    def __init__(self, scene: Scene) -> None:
        self.adr, self.half = scene.brick_qpos_adr, scene.brick_half_extents

    def apply(self, world: Any, tick: int) -> str | None:
        if tick != 0:
            return None
        q = world.data.qpos
        q[self.adr] += 0.08
        q[self.adr + 2] += float(self.half[0] - self.half[2])
        R = SO3(q[self.adr + 3 : self.adr + 7].copy()) @ SO3.from_y_radians(0.5 * np.pi)
        q[self.adr + 3 : self.adr + 7] = R.wxyz  # its 75 mm axis up
        mujoco.mj_forward(world.model, world.data)
        return "the brick stood on its end 80 mm along x after planning"


@pytest.mark.slow
@pytest.mark.parametrize("robot", ["iiwa14-wsg50", "menagerie-panda-hand"])
def test_a_brick_standing_on_its_end_is_picked_standing_and_placed_standing(robot: str) -> None:
    """A brick standing on a 50 x 50 mm end (a face no turn of its lying frame puts down) is
    planned as the box lying in a turned frame, 75 mm tall, grasped across 50 mm, and placed
    on the same end in bin 2, resting there flat within the verdict's tilt."""
    _, _, sim = prepare(RunRequest(scenario="pick-place", robot=robot, attempts=3))
    sim.task.faults = (_StoodOnEnd(sim.scene),)
    result = sim.run()
    assert result.success, result.failure_text
    first, second = result.summary()["attempts"]
    assert first["failure"] == "missed-grasp" and second["success"]
    texts = [e.text for e in result.events if "standing" in e.text]
    assert texts and "standing 75 mm tall" in texts[0], texts
    X_WO = brick_pose(sim.scene, sim.data)
    M = X_WO.rotation().as_matrix()
    half = sim.scene.brick_half_extents
    axis = int(np.argmax(np.abs(M[2, :])))
    assert half[axis] == pytest.approx(float(half.max()))  # its long axis vertical
    bottom = X_WO.translation()[2] - half[axis]
    assert bottom == pytest.approx(sim.scene.target_bin.floor_top_z, abs=1e-3)
    assert placement_problems(sim.scene, sim.data, sim.scene.target_bin, sim.criteria, 0.0) == []


def test_standing_goal_rests_the_turned_box_on_the_goal_s_floor_about_its_yaw() -> None:
    """The goal of a box standing on its end: the turned frame has the goal's rotation, and
    the box's lowest point lies on the floor the lying goal rests on."""
    half = np.array([0.0375, 0.025, 0.025])
    X_goal = SE3.from_rotation_and_translation(SO3.from_z_radians(0.4), np.array([0.5, 0, 0.035]))
    floor = 0.035 - half[2]
    for R in AXIS_ROTATIONS:
        X = standing_goal(X_goal, half, R)
        X_p = X @ SE3.from_rotation(SO3.from_matrix(R))
        np.testing.assert_allclose(
            X_p.rotation().as_matrix(), X_goal.rotation().as_matrix(), atol=1e-12
        )
        low = transform_points(X, box_corners(half))[:, 2].min()
        assert low == pytest.approx(floor, abs=1e-12)
        np.testing.assert_allclose(X.translation()[:2], X_goal.translation()[:2], atol=1e-15)


def test_only_grasp_failures_are_recoverable() -> None:
    assert {FailureReason.MISSED_GRASP, FailureReason.DROPPED} == RECOVERABLE


# ------------------------------------------------------------------ the parts


def test_the_stop_trajectory_starts_at_the_plan_s_velocity_and_ends_at_rest(scene: Scene) -> None:
    _, task, _ = prepare(RunRequest())
    path = task.plan.trajectory
    phases = task.plan.phases
    assert phases is not None
    t0 = 0.5 * (phases.transport[0] + phases.transport[1])
    stop = StopTrajectory(path, t0, 0.4, 0.05, 0.3, 1.0, 0.0, 0.08)
    x, V, w = stop.sample(1e-9)
    x_plan, V_plan, _ = path.sample(t0)
    np.testing.assert_allclose(x, x_plan, atol=1e-6)
    np.testing.assert_allclose(V, V_plan, atol=1e-6)
    assert np.linalg.norm(V_plan[:3]) > 0.1 and w == pytest.approx(0.0, abs=1e-6)
    # At T: at rest on the plan's path, half the stop time's worth of it further on.
    x_T, V_T, w_T = stop.sample(0.4 - 1e-9)
    np.testing.assert_allclose(x_T, path.sample(t0 + 0.2)[0], atol=1e-6)
    assert np.abs(V_T).max() < 1e-6 and w_T == pytest.approx(0.08, abs=1e-6)
    # Then straight up by the rise, at rest at its end, and held.
    x_up = stop.sample(0.7)[0]
    np.testing.assert_allclose(
        x_up[4:], path.sample(t0 + 0.2)[0][4:] + np.array([0, 0, 0.05]), atol=1e-9
    )
    assert np.abs(stop.sample(0.7)[1]).max() == 0.0
    np.testing.assert_allclose(stop.X_WG_rest.wxyz_xyz, x_up)


def test_the_tick_log_grows_keeping_its_rows(scene: Scene) -> None:
    log = TickLog(scene, 4, 0.01)
    log.q_cmd[:] = 1.0
    log.slip[:] = 0.5
    log.x_WG_plan[:, 4:] = 2.0
    log.grow(10)
    assert log.capacity == 10 and log.q_cmd.shape[0] == 10
    assert (log.q_cmd[:4] == 1.0).all() and (log.q_cmd[4:] == 0.0).all()
    assert (log.slip[:4] == 0.5).all() and np.isnan(log.slip[4:]).all()
    log.p_WG_plan[9] = 3.0  # the views follow the new arrays
    assert (log.x_WG_plan[9, 4:] == 3.0).all()
    log.arm_ctrl[9] = 4.0
    assert (log.ctrl[9, : scene.robot.n_joints] == 4.0).all()


def test_the_grasp_monitor_judges_nothing_on_a_plan_that_carries_nothing(scene: Scene) -> None:
    _, task, _ = prepare(RunRequest())
    stop = StopTrajectory(task.plan.trajectory, 1.0, 0.2, 0.0, 0.2, 1.0, 0.0, 0.05)
    from pickplace.planning.plan import Plan

    ctx = CheckContext(scene, Plan(stop), SuccessCriteria(), 0.01, lambda *a, **k: None)
    log = TickLog(scene, 50, 0.01)
    log.derive(0, 50)
    assert GraspMonitor(ctx).first_failure(log, 0, 50) is None


def test_replace_plan_refuses_a_plan_that_starts_in_the_future() -> None:
    _, task, sim = prepare(RunRequest())
    sim.advance(10)
    with pytest.raises(InvalidInputError, match=r"at most at the next tick's time 0\.1000 s"):
        sim.replace_plan(task.plan, 0.2, "test")


def test_the_pre_flight_from_home_given_as_a_start_is_the_default(scene: Scene) -> None:
    _, task, _ = prepare(RunRequest())
    pre = Preflight(scene, "qp")
    a = pre.run(task.plan, task.X_WO_start, task.goal.X_WO_goal)
    b = pre.run(task.plan, task.X_WO_start, task.goal.X_WO_goal, q_start=scene.robot.q_home)
    np.testing.assert_array_equal(a.q, b.q)
    with pytest.raises(PlanError, match="7 finite joint angles"):
        pre.run(task.plan, task.X_WO_start, None, q_start=np.zeros(3))


def test_the_planner_starts_its_plans_where_it_is_told(scene: Scene) -> None:
    """From home given as a start: the default's plan; from elsewhere: a plan whose first
    keyframe is the start pose and whose pre-flight starts at the start configuration."""
    _, task, _ = prepare(RunRequest())
    planner = PickPlacePlanner(scene, "qp")
    X_WO_goal = task.goal.X_WO_goal
    assert X_WO_goal is not None
    default = planner.plan(task.X_WO_start, X_WO_goal)
    home = planner.plan(
        task.X_WO_start, X_WO_goal, start=Start(scene.robot.q_home, planner.X_WG_home)
    )
    assert default.as_dict() == home.as_dict()
    # From a configuration on the nominal plan's joint path, above bin 1.
    chosen = default.candidates[default.chosen or 0].preflight
    i = len(chosen.q) // 6
    q = chosen.q[i]
    from pickplace.control.kinematics import ArmKinematics

    kin = ArmKinematics(scene)
    kin.update(q)
    X_WG = kin.X_WG()
    report = planner.plan(task.X_WO_start, X_WO_goal, start=Start(q, X_WG))
    assert report.feasible
    chosen2 = report.candidates[report.chosen or 0]
    np.testing.assert_allclose(chosen2.plan.trajectory.keyframes[0].X_WG.wxyz_xyz, X_WG.wxyz_xyz)
    np.testing.assert_array_equal(chosen2.preflight.q[0], q)


def test_attempts_are_checked() -> None:
    assert check_attempts(3) == 3
    for bad in (0, 11, 2.0, True, "3"):
        with pytest.raises(InvalidInputError, match=r"attempts must be an integer in \[1, 10\]"):
            check_attempts(bad)
    _, task, _ = prepare(RunRequest())
    assert isinstance(task.recovery, Reattempt) and task.recovery.max_attempts == 1


@pytest.mark.parametrize("value", ["0", "11", "x"])
def test_bad_attempts_on_the_command_line_is_one_line_and_exit_2(
    value: str, cli: Callable[..., CliRun]
) -> None:
    for command in ("run", "sweep"):
        done = cli(command, "--attempts", value)
        assert done.returncode == 2 and done.stdout == ""
        assert len(done.stderr.strip().splitlines()) == 1 and "--attempts" in done.stderr


def test_a_recording_shows_each_plan_from_the_moment_it_replaced_the_last(
    tmp_path: Path,
) -> None:
    from tests.test_recording import read_entities

    path = tmp_path / "replan.rrd"
    _, result = _run("fault-brick-moved", 3, record=path)
    assert result.success
    ents = read_entities(path)
    replans = [e for e in result.events if e.kind is EventKind.REPLAN]
    for n, event in enumerate(replans, 1):
        entity = ents[f"world/plan/replans/{n}/path"]
        assert entity.rows["tick"] == [event.tick]


def test_attempts_can_be_varied_as_a_grid_of_whole_numbers() -> None:
    from pickplace.sim.vary import parse_vary

    plan = parse_vary(["attempts=1,3"])
    draws = [plan.draw(seed) for seed in (0, 1)]
    assert [RunRequest(seed=i, parameters=d).run_attempts for i, d in enumerate(draws)] == [1, 3]
    _, task, _ = prepare(RunRequest(scenario="fault-brick-moved", seed=1, parameters=draws[1]))
    assert isinstance(task.recovery, Reattempt) and task.recovery.max_attempts == 3
    with pytest.raises(InvalidInputError, match="whole numbers in"):
        parse_vary(["attempts=1,2.5"])
    with pytest.raises(InvalidInputError, match="grid of values only"):
        parse_vary(["attempts=1:3"])
    with pytest.raises(InvalidInputError, match="given and also varied"):
        prepare(RunRequest(seed=1, parameters=draws[1], attempts=2))


def test_the_verdict_panel_names_the_final_outcome_and_each_replan() -> None:
    from pickplace.record.recording import run_verdict

    sim, result = _run("fault-gripper-disabled", 2)
    verdict = run_verdict(result, sim.dt)
    assert verdict.reason == "missed-grasp" and verdict.tick == result.failure_tick
    (replan,) = result.summary()["replans"]
    assert f"Replanned at t={replan['t']:.2f} s after missed-grasp: attempt 2." in verdict.text


def test_a_start_is_checked_when_made(scene: Scene) -> None:
    from mink.lie import SE3

    X = SE3.identity()
    assert Start([0.1] * 7, X).q.dtype == np.float64
    with pytest.raises(PlanError, match="finite"):
        Start(np.array([np.nan] * 7), X)
    with pytest.raises(PlanError):
        Start(np.zeros(7), SE3(wxyz_xyz=np.array([2.0, 0, 0, 0, 0, 0, 0])))


def test_a_sweep_counts_the_trials_that_replanned() -> None:
    from pickplace.sim.vary import VaryPlan
    from pickplace.sweep.report import outcome_report

    trials = [
        {"seed": 0, "success": True, "attempts": 2, "failure": None},
        {"seed": 1, "success": False, "attempts": 3, "failure": "missed-grasp"},
        {"seed": 2, "success": True, "attempts": 1, "failure": None},
        {"seed": 3, "success": False, "failure": "worker-died", "lost": True},
    ]
    report = outcome_report(trials, {}, VaryPlan())
    assert report["replanned"] == {"trials": 2, "successes": 1}


# ------------------------------------------------------------ held back by the collision limit


class _Run:
    """The parts of a run :func:`limit_held` reads."""

    def __init__(self, log: TickLog, ticks: int) -> None:
        self.log, self.ticks, self.criteria = log, ticks, SuccessCriteria()


def test_only_an_ik_failed_at_a_tick_the_collision_limit_held_is_limit_held(scene: Scene) -> None:
    log = TickLog(scene, 10, 0.01)
    log.command_error[5] = 0.025  # behind the plan, beyond the 20 mm tracking limit
    run = _Run(log, 10)
    behind = Failure(5, FailureReason.IK_FAILED, "behind")
    assert not limit_held(run, behind)  # the limit's rows were not met there
    log.collision_held[5] = 1
    assert limit_held(run, behind)
    assert not limit_held(run, Failure(5, FailureReason.COLLISION, "touched"))
    log.command_error[4], log.collision_held[4] = 0.0, 1
    # A QP without solution at a held tick is not the limit's doing.
    assert not limit_held(run, Failure(4, FailureReason.IK_FAILED, "no solution"))
    assert not limit_held(_Run(log, 5), behind)  # a tick not yet run


@pytest.mark.slow
def test_an_ik_failed_the_collision_limit_did_not_cause_is_not_taken_up() -> None:
    """fault-unreachable's place target lies out of reach: ik-failed with the limit idle, so
    3 attempts end as one does."""
    _, three = _run("fault-unreachable", 3)
    _, one = _run("fault-unreachable", 1)
    assert three.failure is FailureReason.IK_FAILED
    assert _without_wall_time(three.summary()) == _without_wall_time(one.summary())


@pytest.mark.slow
@pytest.mark.parametrize(
    "robot", ["iiwa14-wsg50", "panda-hand", "menagerie-iiwa14-2f85", "ur5e-2f85"]
)
def test_an_obstacle_in_the_transfer_is_planned_around_with_the_brick_in_hand(robot: str) -> None:
    """fault-obstacle with 3 attempts: the limit holds the arm off the box (ik-failed), the
    recovery stops it there and carries the brick on around the box; no robot–world contact,
    the box never touched, the brick never let go between the attempts."""
    sim, result = _run("fault-obstacle", 3, robot=robot)
    summary = result.summary()
    assert result.success, result.failure_text
    first, second = summary["attempts"]
    assert first["failure"] == "ik-failed" and second["success"]
    assert second["candidate"].endswith(", held")
    assert len(summary["replans"]) == 1
    assert summary["max_robot_world_contact_force_n"] == 0.0
    log, ticks = sim.log, sim.ticks
    assert log.collision_held[first["failure_tick"]] == 1
    assert (log.robot_world_contacts[:ticks] == 0).all()
    # Still held when the new plan starts: both pads push on the brick.
    assert (log.pad_force[second["start_tick"] - 1] > 1.0).all()
    _, once = _run("fault-obstacle", 1, robot=robot)
    assert once.failure is FailureReason.IK_FAILED
    assert once.failure_text == first["failure_text"]


def test_the_held_stop_follows_the_commanded_joints_on(scene: Scene) -> None:
    """CommandedDrift: at 0 the commanded tool pose, moving at J q̇; later the forward
    kinematics of q + q̇ t."""
    kin = ArmKinematics(scene)
    q0 = scene.robot.q_home.copy()
    qdot = np.linspace(-0.2, 0.3, len(q0))
    drift = CommandedDrift(ArmKinematics(scene), q0, qdot, 0.03)
    kin.update(q0)
    x, V, w = drift.sample(0.0)
    np.testing.assert_allclose(x, kin.X_WG().wxyz_xyz, atol=1e-12)
    np.testing.assert_allclose(V, kin.J_WG().dot(qdot), atol=1e-12)
    assert w == 0.03
    kin.update(q0 + 0.4 * qdot)
    np.testing.assert_allclose(drift.sample(0.4)[0], kin.X_WG().wxyz_xyz, atol=1e-12)
    # Slowed to rest by a StopTrajectory along it, as the recovery does.
    stop = StopTrajectory(drift, 0.0, 0.15, 0.0, 0.15, 1.0, 0.03, 0.03)
    assert np.abs(stop.sample(0.15)[1]).max() < 1e-9
    V0 = drift.sample(0.0)[1]
    np.testing.assert_allclose(stop.sample(1e-9)[1], V0, atol=1e-6)
    assert np.linalg.norm(V0) > 0.01


def test_the_pre_flight_sees_a_mocap_obstacle_where_the_simulation_has_it(scene: Scene) -> None:
    preflight = Preflight(scene, "qp")
    obstacle = int(mujoco.mj_name2id(scene.model, mujoco.mjtObj.mjOBJ_BODY, "obstacle"))
    mocap = int(scene.model.body_mocapid[obstacle])
    kin = ArmKinematics(scene)
    kin.update(scene.robot.q_home)
    data = mujoco.MjData(scene.model)
    mujoco.mj_forward(scene.model, data)
    X_WO = brick_pose(scene, data)
    kinds = preflight.pair_kinds(X_WO, X_WO)
    parked, _ = preflight.clearance(scene.robot.q_home, 0.0, X_WO, kinds, False)
    pos, quat = data.mocap_pos.copy(), data.mocap_quat.copy()
    pos[mocap] = kin.X_WG().translation() + np.array([0.0, 0.0, 0.1])  # over the tool
    preflight.observe_world(pos, quat)
    near, contact = preflight.clearance(scene.robot.q_home, 0.0, X_WO, kinds, False)
    assert near < parked and contact is not None and "obstacle" in contact[1]
