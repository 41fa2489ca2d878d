"""Benchmark: where a run's time goes, as ratios and medians measured in one process and one run.

Targets (figures, not tests):
- qp IK tick <= 0.5x mink.solve_ik on the identical problem;
- nominal pick-and-place >= 40x real time headless, >= 30x while recording;
- sweep throughput with all workers >= 1.8x that with 1 worker (2 cores);
- planning time of the nominal pose and median over uniform bin-1 poses, the candidates ranked
  and the best pre-flighted, <= 30 ms; nominal run >= 55x real time with its planning included;
- nominal cycle time <= 1.25x its joint-speed bound (each keyframe segment's largest per-joint
  path length over speed limit, summed, plus the gripper's actions, from the run's own
  commanded joint path), with success, slip <= 3 mm, speed ratio <= 1, tracking <= 10 mm;
- composing and calibrating each bundled robot in a second process (calibration, home and
  compiled models on disk), <= 1 s; the first process's time (every cache empty) and the
  disk the compiled models take are figures;
- trials/s per worker of the Ray backend (a local cluster) within 10 % of the process
  backend's on this machine, both in steady state (from the 10th result on); speed-up with 2
  workers >= 1.8; peak RSS of a 2,000-trial sweep (its process and its largest worker) and the
  bytes a trial's record takes;
- planning with C-space paths: for every bundled robot the nominal pose behind a divider
  wall that the Cartesian transfer runs into (0.26 m), and over pick-place-obstacles cells
  (seeds 90000…) the planning time's percentiles, the C-space planner's share and how many
  of its plannings found a path (figures, no target: the C-space budget is 2 s a candidate);
- the qp collision limit's cost: the real-time factor of headless nominal runs with and
  without it and their ratio, its per-tick broad phase and rows against mink's own (figures
  without a target);
- ``pickplace --help``, ``--version``, ``scenarios`` and ``robots`` each answer in <= 0.3 s
  (median wall time of a fresh process, and its CPU time, which the machine's load does not
  inflate; ``robots`` after its first call, which measures the robots once).

Usage: python scripts/bench.py [--json] [--trials N] [--backend-trials N] [--rss-trials N]
       python scripts/bench.py --cli-only [--json]
       python scripts/bench.py --cspace-only [--json] [--cells N]
       python scripts/bench.py --collision-only [--json] [--repeats N]
       python scripts/bench.py --compose-only [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import mink
import mujoco
import numpy as np

from pickplace.cache import CACHE_ENV
from pickplace.control.controllers import QPController, make_controller
from pickplace.errors import InvalidInputError
from pickplace.geometry import pose_error_W
from pickplace.planning.planner import PickPlacePlanner
from pickplace.planning.timing import cycle_time_at_speed_limits, cycle_time_bound
from pickplace.robot.compose import clear_calibration_cache
from pickplace.robot.registry import bundled_robots
from pickplace.run.runner import RunRequest, prepare
from pickplace.sim.loader import clear_scene_cache, load_scene
from pickplace.sweep.sweep import SweepRequest, run_sweep
from pickplace.world.placements import (
    brick_on_floor,
    nominal_placement,
    target_placement,
    uniform_placement,
)

TARGETS = {
    "ik_tick_ratio_vs_mink": ("<=", 0.5),
    "realtime_factor_headless": (">=", 40.0),
    "realtime_factor_recording": (">=", 30.0),
    "sweep_speedup_all_workers": (">=", 1.8),
    "planning_time_ms_nominal": ("<=", 30.0),
    "planning_time_ms_median": ("<=", 30.0),
    **{
        f"planning_time_ms_{which}_{name}": ("<=", 30.0)
        for which in ("nominal", "median")
        for name in ("can", "ball", "jar")
    },
    "realtime_factor_headless_with_planning": (">=", 55.0),
    "cycle_time_ratio_to_bound": ("<=", 1.25),
    "nominal_max_slip_m": ("<=", 0.003),
    "nominal_max_joint_speed_ratio": ("<=", 1.0 + 1e-6),
    "nominal_max_position_error_m": ("<=", 0.010),
    "ray_vs_process_trials_per_second_per_worker": (">=", 0.9),
}

COMPOSE_TARGET_S = 1.0
CLI_TARGET_S = 0.3
CLI_COMMANDS = {
    "help": ["--help"],
    "version": ["--version"],
    "scenarios": ["scenarios"],
    "robots": ["robots"],
}

# The peak-RSS sweep runs in a process of its own, so that nothing of the benchmark's counts.
RSS_SCRIPT = """
import json, resource, sys
from pickplace.sweep.sweep import SweepRequest, run_sweep
report = run_sweep(SweepRequest("pick-place-random", "qp", int(sys.argv[1]), 0, 2))
records = report["trial_results"]
print(json.dumps({
    "completed": report["completed"],
    "self_kib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
    "largest_worker_kib": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss,
    "record_bytes": sum(len(json.dumps(t)) for t in records) / len(records),
}))
"""

# Brick poses for the planning-time median: this many seeds of pick-place-random's generator.
PLANNING_POSES = 40


def median_us(fn: Callable[[], object], repeats: int = 2000) -> float:
    """Median wall time of ``fn`` [µs] over ``repeats`` calls (after 50 warm-up calls)."""
    for _ in range(50):
        fn()
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        fn()
        samples.append(time.perf_counter_ns() - t0)
    return statistics.median(samples) * 1e-3


def ik_ticks(states: np.ndarray, targets: np.ndarray, velocities: np.ndarray) -> dict[str, Any]:
    """The qp solve vs mink.solve_ik on identical problems taken from a nominal run."""
    scene = load_scene()
    dt = 0.01
    fast = QPController(scene, dt, backend="fast")
    max_diff = 0.0
    fast_us, mink_us = [], []
    for q, x, V in zip(states, targets, velocities, strict=True):
        # Set up the problem exactly as a control tick does, then time only the QP part.
        kin = fast.kinematics
        kin.update(q)
        x_WG = kin.wxyz_xyz()
        V_cmd = V + fast._K * pose_error_W(x_WG, x)  # feed-forward plus correction
        fast.set_frame_target(x_WG, V_cmd)
        a = fast._solve_fast(q)
        b = mink.solve_ik(fast.configuration, fast.tasks, dt, solver="daqp", limits=fast.limits)
        if a is None:
            raise RuntimeError("fast QP found no solution on a nominal-run state")
        max_diff = max(max_diff, float(np.abs(a - b).max()))
        fast_us.append(median_us(partial(fast._solve_fast, q), 30))
        mink_us.append(
            median_us(
                lambda: mink.solve_ik(
                    fast.configuration, fast.tasks, dt, solver="daqp", limits=fast.limits
                ),
                30,
            )
        )
    f, m = statistics.median(fast_us), statistics.median(mink_us)
    return {
        "ik_tick_us_qp_fast": f,
        "ik_tick_us_mink_solve_ik": m,
        "ik_tick_ratio_vs_mink": f / m,
        "ik_fast_vs_mink_max_abs_diff": max_diff,
        "ik_fast_equals_mink_1e-8": max_diff <= 1e-8,
    }


def collision_limit(repeats: int) -> dict[str, Any]:
    """The qp collision limit's cost: the real-time factor of headless nominal runs with it
    (``qp``) and without it (``qp-no-collision``), interleaved so that both see the same load,
    their ratio; its per-tick cost on the run's own states (the broad phase, and the rows with
    their narrow phase and Jacobians, against mink's own ``compute_qp_inequalities`` on the
    same states) and how many pairs each tick reaches each stage."""
    rtf: dict[str, list[float]] = {"qp": [], "qp-no-collision": []}
    ik_us: dict[str, float] = {}
    sim: Any = None
    for _ in range(repeats):
        for name in rtf:
            _, _, run = prepare(RunRequest(controller=name))
            t0 = time.perf_counter()
            result = run.run()
            wall = time.perf_counter() - t0
            if not result.success:
                raise RuntimeError(f"nominal run with {name} failed: {result.failure}")
            rtf[name].append(result.sim_time_s / wall)
            ik_us[name] = float(np.median(run.log.ik_us[: run.ticks]))
            if name == "qp":
                sim = run
    ctrl = sim.controller
    collision, kin = ctrl.collision, ctrl.kinematics
    states = sim.log.q_cmd[: sim.ticks]
    broad, rows, mink_rows, survivors, active = [], [], [], [], []
    for q in states:
        kin.update(q)
        broad.append(median_us(partial(collision.candidates, kin.data), 5))
        rows.append(median_us(partial(collision.rows, kin.data), 5))
        survivors.append(collision.survivors)
        active.append(collision.active)
        mink_rows.append(
            median_us(
                lambda: [
                    limit.compute_qp_inequalities(ctrl.configuration, ctrl.dt)
                    for limit in collision.limits
                ],
                5,
            )
        )
    with_limit = statistics.median(rtf["qp"])
    without = statistics.median(rtf["qp-no-collision"])
    return {
        "realtime_factor_headless_collision_limit": with_limit,
        "realtime_factor_headless_no_collision_limit": without,
        "collision_limit_realtime_factor_ratio": with_limit / without,
        "collision_limit_ik_tick_us_in_run": ik_us["qp"],
        "collision_limit_off_ik_tick_us_in_run": ik_us["qp-no-collision"],
        "collision_limit_pairs": collision.n_pairs,
        "collision_limit_broad_phase_us": statistics.median(broad),
        "collision_limit_rows_us": statistics.median(rows),
        "collision_limit_rows_us_mink": statistics.median(mink_rows),
        "collision_limit_broad_phase_survivors_mean": float(np.mean(survivors)),
        "collision_limit_rows_mean": float(np.mean(active)),
    }


def controller_ticks(q: np.ndarray, x: np.ndarray, V: np.ndarray) -> dict[str, float]:
    """Whole controller ticks (FK, error, solve, status) of the three controllers."""
    scene = load_scene()
    out = {}
    for name in ("qp", "qp-no-collision", "pinv", "dls"):
        ctrl = make_controller(name, scene, 0.01)
        out[f"controller_tick_us_{name}"] = median_us(partial(ctrl.command, q, x, V))
    return out


def mj_step_us() -> float:
    """One physics step [µs] with the brick held between the pads (from a nominal run)."""
    _, _, sim = prepare(RunRequest())
    phases = sim.plan.phases
    if phases is None:
        raise RuntimeError("the nominal plan has no phases")
    grasp_tick = round(phases.grip_closed / sim.dt)
    sim.advance(grasp_tick + 50)
    return median_us(lambda: mujoco.mj_step(sim.model, sim.data), 3000)


def nominal_run(record: Path | None) -> tuple[float, float, float, Any]:
    """Wall time [s] of the nominal run's physics (optionally recording), its sim time [s] and
    its planning time [s] (the candidates and their pre-flights, before any physics)."""
    _, task, sim = prepare(RunRequest(record=record))
    t0 = time.perf_counter()
    result = sim.run()
    wall = time.perf_counter() - t0
    if not result.success:
        raise RuntimeError(f"nominal run failed: {result.failure}")
    planning = task.planning.planning_time_s if task.planning is not None else 0.0
    return wall, result.sim_time_s, planning, sim


def cycle_time(sim: Any) -> dict[str, float]:
    """The nominal run's cycle time against its joint-speed bound, and its quality figures."""
    log, n = sim.log, sim.ticks
    keyframes = sim.task.trajectory.keyframes
    args = (keyframes, sim.dt, log.q_cmd[:n], sim.scene.robot.v_max)
    bound, at_speed_limits = cycle_time_bound(*args), cycle_time_at_speed_limits(*args)
    slip = log.slip[:n]
    cycle = sim.task.trajectory.end_time
    return {
        "cycle_time_s": cycle,
        "cycle_time_bound_s": bound,
        "cycle_time_ratio_to_bound": cycle / bound,
        # The same joint path at the speed limits alone: cycle minus this is what the
        # acceleration limits and the speed margin cost.
        "cycle_time_at_speed_limits_s": at_speed_limits,
        "nominal_max_slip_m": float(np.nanmax(slip)),
        "nominal_max_joint_speed_ratio": float(log.speed_ratio[:n].max()),
        "nominal_max_position_error_m": float(log.position_error[:n].max()),
    }


def planning_times(name: str = "brick") -> dict[str, float]:
    """Planning time of the nominal pose and median and p90 over PLANNING_POSES poses drawn
    like pick-place-uniform's (uniform over bin 1's valid poses), feasible or not, each with
    its candidates ranked and the best pre-flighted until one is feasible [ms]; wall and CPU
    time (the CPU time is what a shared machine's load does not inflate), the mean number of
    candidates pre-flighted and the number ranked. ``name``: the bundled object picked (the
    brick's keys have no suffix, another object's end in ``_<name>``)."""
    from pickplace.run.runner import build_task

    if name == "brick":
        scene = load_scene()
    else:
        scene, _ = build_task(RunRequest(object=name), refuse_infeasible=False)
    planner = PickPlacePlanner(scene, "qp")
    X_place = brick_on_floor(scene, target_placement(scene), scene.target_bin.floor_top_z)

    floor = scene.source_bin.floor_top_z

    def timed(p: Any) -> tuple[float, float, int, bool]:
        X_pick = brick_on_floor(scene, p, floor)
        cpu = time.process_time()
        report = planner.plan(X_pick, X_place)
        cpu = time.process_time() - cpu
        pre_flighted = len(report.candidates) if report.candidates[0].preflight.q.size else 0
        return report.planning_time_s * 1e3, cpu * 1e3, pre_flighted, report.feasible

    timed(nominal_placement(scene))  # warm-up
    nominal = [timed(nominal_placement(scene)) for _ in range(5)]
    runs = [
        timed(uniform_placement(scene, np.random.default_rng(s))) for s in range(PLANNING_POSES)
    ]
    wall, cpu = [r[0] for r in runs], [r[1] for r in runs]
    suffix = "" if name == "brick" else f"_{name}"
    figures = {
        "planning_time_ms_nominal": statistics.median(r[0] for r in nominal),
        "planning_cpu_ms_nominal": statistics.median(r[1] for r in nominal),
        "planning_time_ms_median": statistics.median(wall),
        "planning_cpu_ms_median": statistics.median(cpu),
        "planning_time_ms_p90": float(np.percentile(wall, 90)),
        "planning_preflighted_mean": float(np.mean([r[2] for r in runs])),
        "planning_feasible_fraction": float(np.mean([r[3] for r in runs])),
        "planning_candidates_ranked": float(
            planner.plan(brick_on_floor(scene, nominal_placement(scene), floor), X_place).ranked
        ),
    }
    return {k + suffix: v for k, v in figures.items()}


# The pushing figures: the robot whose long palm leaves the most poses beside the walls
# without a grasp, and the uniform poses drawn (their refused ones are planned with pushes).
PUSH_ROBOT = "menagerie-panda-hand"
PUSH_POSES = 100


def push_planning_times(poses: int = PUSH_POSES) -> dict[str, Any]:
    """Planning with pushes (pickplace/planning/push.py): over ``poses`` uniform poses of
    PUSH_ROBOT, those no grasp candidate is feasible at (planned without pushes) planned again
    with them: how many, the fraction a push was found for, and that planning's p50 and max
    wall time [ms]."""
    scene = load_scene(None, PUSH_ROBOT)
    planner = PickPlacePlanner(scene, "qp")
    X_place = brick_on_floor(scene, target_placement(scene), scene.target_bin.floor_top_z)
    floor = scene.source_bin.floor_top_z
    times, found = [], 0
    for seed in range(poses):
        X_pick = brick_on_floor(scene, uniform_placement(scene, np.random.default_rng(seed)), floor)
        if planner.plan(X_pick, X_place, push=False).feasible:
            continue
        report = planner.plan(X_pick, X_place)
        times.append(report.planning_time_s * 1e3)
        found += report.feasible
    return {
        "push_refused_poses": len(times),
        "push_found_fraction": found / len(times) if times else None,
        "push_planning_ms_p50": float(np.percentile(times, 50)) if times else None,
        "push_planning_ms_max": max(times, default=None),
    }


# The divider of the C-space planning figures [m]: the Cartesian transfer's brick runs into it.
CSPACE_DIVIDER = 0.26
CSPACE_FIRST_SEED = 90000


def cspace_planning_times(cells: int) -> dict[str, Any]:
    """Planning with C-space transfers: per bundled robot the nominal pose behind a
    CSPACE_DIVIDER wall (wall time, the C-space planner's part, feasible), and over ``cells``
    pick-place-obstacles cells for the default robot the planning time's p50, p90 and max
    [ms], the C-space part's, and the fraction of plannings that used and found a C-space
    path."""
    from pickplace.sim.scenarios import obstacle_cell
    from pickplace.world.cell import ObstacleCell
    from pickplace.world.obstacles import with_obstacles

    out: dict[str, Any] = {}

    def plan(scene: Any, seed: int) -> Any:
        X_pick = brick_on_floor(scene, nominal_placement(scene), scene.source_bin.floor_top_z)
        X_place = brick_on_floor(scene, target_placement(scene), scene.target_bin.floor_top_z)
        return PickPlacePlanner(scene, "qp", seed=seed).plan(X_pick, X_place)

    for name in bundled_robots():
        scene = with_obstacles(load_scene(None, name), ObstacleCell(CSPACE_DIVIDER))
        report = plan(scene, 0)
        out[f"cspace_divider_planning_ms_{name}"] = report.planning_time_s * 1e3
        out[f"cspace_divider_cspace_ms_{name}"] = report.planner_time_s["c-space"] * 1e3
        out[f"cspace_divider_feasible_{name}"] = report.feasible
    base = load_scene()
    totals, cspace_ms, ompl_ms, checks, used, found = [], [], [], [], 0, 0
    for seed in range(CSPACE_FIRST_SEED, CSPACE_FIRST_SEED + cells):
        report = plan(with_obstacles(base, obstacle_cell(base, seed)), seed)
        totals.append(report.planning_time_s * 1e3)
        if report.used_cspace:
            used += 1
            cspace_ms.append(report.planner_time_s["c-space"] * 1e3)
            attempts = [c.cspace.result for c in report.candidates if c.cspace is not None]
            ompl_ms.append(sum(r.ompl_s for r in attempts) * 1e3)
            checks.append(sum(r.checks for r in attempts))
            found += any(c.cspace is not None and c.cspace.result.path for c in report.candidates)
    for key, values in (
        ("cells_planning", totals),
        ("cells_cspace", cspace_ms),
        ("cells_ompl", ompl_ms),
    ):
        for q in (50, 90, 100):
            label = "max" if q == 100 else f"p{q}"
            out[f"cspace_{key}_ms_{label}"] = float(np.percentile(values, q)) if values else None
    out["cspace_cells_checks_median"] = float(np.median(checks)) if checks else None
    out["cspace_us_per_check"] = float(np.sum(cspace_ms) / np.sum(checks) * 1e3) if checks else None
    out["cspace_cells"] = cells
    out["cspace_cells_used_fraction"] = used / cells
    out["cspace_cells_found_fraction"] = found / used if used else None
    return out


def tick_breakdown() -> dict[str, float]:
    """Where a headless nominal run's time goes, per control tick [µs].

    One extra run with timers around the plan sample, the IK command, the physics and the
    block assessment, i.e. every diagnostic (singular values, manipulability, errors, grip
    force, slip) and every check (each timer adds well under 1 µs); the rest is the loop's
    own work: faults, the actuator commands, the NaN check and copying state into the log.
    """
    _, _, sim = prepare(RunRequest())
    spent = {"plan_sample": 0, "ik_command": 0, "physics": 0, "diagnostics_and_checks": 0}

    def timed(fn: Callable[..., Any], key: str) -> Callable[..., Any]:
        def wrapper(*args: Any) -> Any:
            t0 = time.perf_counter_ns()
            out = fn(*args)
            spent[key] += time.perf_counter_ns() - t0
            return out

        return wrapper

    sim._sample = timed(sim._sample, "plan_sample")
    sim._command = timed(sim._command, "ik_command")
    assess = sim.assess
    sim.assess = timed(assess, "diagnostics_and_checks")  # type: ignore[method-assign]
    step = mujoco.mj_step
    mujoco.mj_step = timed(step, "physics")
    try:
        t0 = time.perf_counter_ns()
        result = sim.run()
        total = time.perf_counter_ns() - t0
    finally:
        mujoco.mj_step = step
    ticks = result.ticks
    out = {f"tick_us_{key}": ns * 1e-3 / ticks for key, ns in spent.items()}
    out["tick_us_loop_rest"] = (total - sum(spent.values())) * 1e-3 / ticks
    out["tick_us_total"] = total * 1e-3 / ticks
    return out


COMPOSE_SCRIPT = """
import sys, time
from pickplace.sim.loader import load_scene
import pickplace.robot.compose, pickplace.world.scene  # imports outside the measurement
t0 = time.perf_counter()
load_scene(robot=sys.argv[1])
print(time.perf_counter() - t0)
"""


def compose_times() -> dict[str, float]:
    """Wall time [s] of loading each bundled robot's scene — composition, gripper calibration,
    the home choice (if the description gives none) and the scene — first with every cache
    empty (``robot_compose_calibrate_s_<name>``, in this process), then in a second process
    that finds the calibration, the home and the compiled models on disk
    (``robot_compose_cached_s_<name>``, what each sweep worker pays), and the disk the
    compiled models of that robot take (``robot_compiled_models_mb_<name>`` [MB]). The disk
    cache is a temporary directory, so the user's is not touched."""
    load_scene()  # imports and first-call costs outside the measurement
    out = {}
    saved = os.environ.get(CACHE_ENV)
    with tempfile.TemporaryDirectory() as cache:
        os.environ[CACHE_ENV] = cache
        try:
            for name in bundled_robots():
                clear_scene_cache()
                clear_calibration_cache()
                t0 = time.perf_counter()
                load_scene(robot=name)
                out[f"robot_compose_calibrate_s_{name}"] = time.perf_counter() - t0
                second = subprocess.run(
                    [sys.executable, "-c", COMPOSE_SCRIPT, name],
                    capture_output=True,
                    text=True,
                    check=True,
                    env=dict(os.environ),
                )
                out[f"robot_compose_cached_s_{name}"] = float(second.stdout.split()[-1])
                models = list(Path(cache).glob("model-*.mjb"))
                out[f"robot_compiled_models_mb_{name}"] = (
                    sum(f.stat().st_size for f in models) / 1e6
                )
                for f in models:  # each robot's own
                    f.unlink()
        finally:
            if saved is None:
                os.environ.pop(CACHE_ENV, None)
            else:
                os.environ[CACHE_ENV] = saved
    return out


def cli_times(repeats: int = 7) -> dict[str, float]:
    """Median wall and CPU time [s] of ``pickplace ARGS`` in a fresh process, per command."""
    import resource

    out: dict[str, float] = {}
    cmd = [sys.executable, "-m", "pickplace.cli"]
    subprocess.run([*cmd, "robots"], capture_output=True, check=True)  # measures once
    for name, args in CLI_COMMANDS.items():
        walls, cpus = [], []
        for _ in range(repeats):
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            subprocess.run([*cmd, *args], capture_output=True, check=True)
            walls.append(time.perf_counter() - t0)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
        out[f"cli_wall_s_{name}"] = statistics.median(walls)
        out[f"cli_cpu_s_{name}"] = statistics.median(cpus)
    return out


def steady_rate(times: list[float], skip: int = 10) -> float:
    """Results per second from the ``skip``-th result to the last (start-up left out)."""
    k = min(skip, len(times) // 4)
    return (len(times) - 1 - k) / (times[-1] - times[k])


def _stamp(times: list[float], _: object) -> None:
    times.append(time.perf_counter())


def backend_rates(trials: int, workers: int = 2) -> dict[str, Any]:
    """Trials/s per worker of the process backend and of Ray (a local cluster of ``workers``
    CPUs) on the same trials, in steady state; the Ray cluster's start-up time."""
    out: dict[str, Any] = {}
    for backend in ("process", "ray"):
        times: list[float] = []
        try:
            rep = run_sweep(
                SweepRequest("pick-place-random", "qp", trials, 0, workers, backend=backend),
                on_trial=partial(_stamp, times),
            )
        except InvalidInputError as exc:  # Ray not installed
            out[f"{backend}_trials_per_second_per_worker"] = None
            out[f"{backend}_unavailable"] = str(exc)
            continue
        out[f"{backend}_trials_per_second_per_worker"] = steady_rate(times) / workers
        out[f"{backend}_trials_per_second_whole_sweep"] = rep["trials_per_second"]
        out[f"{backend}_start_s"] = rep["backend_start_s"]
    ray, proc = (out[f"{b}_trials_per_second_per_worker"] for b in ("ray", "process"))
    out["ray_vs_process_trials_per_second_per_worker"] = ray / proc if ray and proc else None
    return out


def peak_rss(trials: int) -> dict[str, Any]:
    """Peak resident memory [MiB] of a ``trials``-trial sweep (2 workers): of the sweep's own
    process, which keeps every trial's record, and of its largest worker; bytes per record."""
    proc = subprocess.run(
        [sys.executable, "-c", RSS_SCRIPT, str(trials)],
        capture_output=True,
        text=True,
        check=True,
    )
    m = json.loads(proc.stdout.strip().splitlines()[-1])
    return {
        f"sweep_{trials}_trials_peak_rss_mib": m["self_kib"] / 1024,
        f"sweep_{trials}_trials_worker_peak_rss_mib": m["largest_worker_kib"] / 1024,
        f"sweep_{trials}_trials_record_bytes": m["record_bytes"],
    }


def _at_most(report: dict[str, Any], keys: list[str], target: float) -> dict[str, Any]:
    """A target check per figure of ``report`` under ``keys``: at most ``target``."""
    return {k: {"target": f"<= {target}", "met": report[k] <= target} for k in keys}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--trials", type=int, default=64, help="trials per sweep measurement")
    parser.add_argument("--repeats", type=int, default=3, help="nominal runs per mode")
    parser.add_argument(
        "--backend-trials", type=int, default=80, help="trials per backend measurement"
    )
    parser.add_argument("--rss-trials", type=int, default=2000, help="trials of the peak-RSS sweep")
    parser.add_argument("--cli-only", action="store_true", help="only the CLI's answer times")
    parser.add_argument(
        "--cspace-only", action="store_true", help="only the planning times with C-space paths"
    )
    parser.add_argument(
        "--push-only", action="store_true", help="only the planning times with pushes"
    )
    parser.add_argument("--cells", type=int, default=30, help="obstacle cells planned")
    parser.add_argument(
        "--collision-only", action="store_true", help="only the qp collision limit's cost"
    )
    parser.add_argument(
        "--compose-only", action="store_true", help="only the robots' compose times"
    )
    args = parser.parse_args(argv)
    report: dict[str, Any] = {"machine_cpus": os.cpu_count()}
    if args.push_only:
        report.update(push_planning_times())
        print(json.dumps(report) if args.json else _table(report, {}))
        return 0
    if args.cspace_only:
        report.update(cspace_planning_times(args.cells))
        print(json.dumps(report) if args.json else _table(report, {}))
        return 0
    if args.collision_only:
        report.update(collision_limit(args.repeats))
        print(json.dumps(report) if args.json else _table(report, {}))
        return 0
    if args.compose_only:
        report.update(compose_times())
        checks = _at_most(
            report, [f"robot_compose_cached_s_{n}" for n in bundled_robots()], COMPOSE_TARGET_S
        )
        report["targets"] = checks
        print(json.dumps(report) if args.json else _table(report, checks))
        return 0
    if args.cli_only:
        report.update(cli_times())
        checks = _at_most(report, [f"cli_wall_s_{n}" for n in CLI_COMMANDS], CLI_TARGET_S)
        report["targets"] = checks
        print(json.dumps(report) if args.json else _table(report, checks))
        return 0

    # Headless nominal runs, interleaved with recording runs so that both see the same load.
    headless, with_planning, recording, sizes = [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeats):
            wall, sim_time, planning, sim = nominal_run(None)
            headless.append(sim_time / wall)
            with_planning.append(sim_time / (wall + planning))
            rrd = Path(tmp) / f"bench-{i}.rrd"
            wall, sim_time, _, _ = nominal_run(rrd)
            recording.append(sim_time / wall)
            sizes.append(rrd.stat().st_size / sim_time)
    log = sim.log
    n = sim.ticks
    picks = np.linspace(10, n - 10, 40).astype(int)
    plan = sim.task.trajectory
    targets = np.array([plan.sample(log.t[k] - sim.dt)[0] for k in picks])
    velocities = np.array([plan.sample(log.t[k] - sim.dt)[1] for k in picks])
    states = log.q_cmd[picks - 1]
    report["realtime_factor_headless"] = statistics.median(headless)
    report["realtime_factor_headless_with_planning"] = statistics.median(with_planning)
    report.update(cycle_time(sim))
    report["realtime_factor_recording"] = statistics.median(recording)
    report["recording_slowdown"] = (
        report["realtime_factor_headless"] / report["realtime_factor_recording"]
    )
    report["rrd_bytes_per_sim_second"] = statistics.median(sizes)
    report["control_tick_us_median_in_run"] = 1e6 / (report["realtime_factor_headless"] * 100.0)
    report.update(tick_breakdown())
    report.update(collision_limit(args.repeats))
    report.update(ik_ticks(states, targets, velocities))
    report.update(controller_ticks(states[20], targets[20], velocities[20]))
    report["mj_step_us_holding_brick"] = mj_step_us()
    report.update(planning_times())
    for name in ("can", "ball", "jar"):
        report.update(planning_times(name))
    report.update(push_planning_times())
    report.update(cspace_planning_times(args.cells))
    report["physics_share_of_tick"] = report["tick_us_physics"] / report["tick_us_total"]
    report.update(compose_times())

    workers = os.cpu_count() or 1
    rates = {}
    for w in sorted({1, workers}):
        rep = run_sweep(SweepRequest("pick-place-random", "qp", args.trials, 0, w))
        rates[w] = rep["trials_per_second"]
        report[f"sweep_trials_per_second_{w}_workers"] = rates[w]
    report["sweep_speedup_all_workers"] = rates[workers] / rates[1]

    report.update(backend_rates(args.backend_trials))
    report.update(peak_rss(min(args.rss_trials, 200)))
    report.update(peak_rss(args.rss_trials))

    report.update(cli_times())
    goals = dict(TARGETS)
    for name in CLI_COMMANDS:
        goals[f"cli_wall_s_{name}"] = ("<=", CLI_TARGET_S)
    for name in bundled_robots():
        goals[f"robot_compose_cached_s_{name}"] = ("<=", COMPOSE_TARGET_S)
    checks = {}
    for key, (op, target) in goals.items():
        value = report[key]
        met = None if value is None else (value <= target if op == "<=" else value >= target)
        checks[key] = {"target": f"{op} {target}", "met": met}
    report["targets"] = checks
    print(json.dumps(report) if args.json else _table(report, checks))
    return 0


def _table(report: dict[str, Any], checks: dict[str, dict[str, Any]]) -> str:
    """The report as lines of ``name value``, then each target and whether it was met."""
    lines = []
    for key, value in report.items():
        if key != "targets":
            shown = f"{value:.4g}" if isinstance(value, float) else str(value)
            lines.append(f"{key:40s} {shown}")
    for key, c in checks.items():
        verdict = "not measured" if c["met"] is None else "met" if c["met"] else "MISSED"
        lines.append(f"target {key:33s} {c['target']:>8s}  {verdict}")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
