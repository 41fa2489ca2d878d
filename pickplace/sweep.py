"""Many trials of one scenario in parallel processes, summarised as one report.

Trial ``i`` runs with seed ``first_seed + i``, so a failing trial can be re-run alone with
``pickplace run --scenario NAME --seed SEED``. Results are ordered by seed and do not depend on
the number of workers.

With more than one worker, each worker process runs one trial at a time and gets the next seed
only when it returns a result, so nothing is queued in a worker:

- A worker that dies (the OOM killer, a crash) fails its trial with reason ``worker-died``
  (its seed is listed like any other failure); a new worker takes the next seed.
- Ctrl-C, SIGTERM or SIGHUP (a KeyboardInterrupt in the calling thread) kills the workers at
  once; the report covers the trials finished so far and says ``"interrupted": true``. Workers
  ignore the terminal's Ctrl-C themselves: only this process decides.

With one worker the trials run in this process; an interrupt ends the running trial, which is
left out of the report.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
import sys
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from typing import Any

import numpy as np

from pickplace.errors import InvalidInputError
from pickplace.loader import load_scene
from pickplace.robot import DEFAULT_ROBOT, resolve_description
from pickplace.runner import MAX_SEED, RunRequest, run, validate_request
from pickplace.signals import STOP_SIGNALS, ignore_in_child

MAX_TRIALS = 100_000
WORKER_DIED = "worker-died"
WORKER_ERROR = "worker-error"
POLL_PERIOD_S = 0.2  # the main loop wakes at least this often [s]


def available_cpus() -> int:
    """CPUs this process may run on (its affinity mask, e.g. under ``taskset``), else the
    machine's count."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except (AttributeError, OSError):
        return os.cpu_count() or 1


@dataclass(frozen=True)
class SweepRequest:
    """A sweep: ``trials`` runs of ``scenario`` with seeds ``first_seed …`` on ``workers``
    processes (default: one per available CPU, see :func:`available_cpus`), with ``robot``
    (a bundled name or a robot.toml)."""

    scenario: str = "pick-place-random"
    controller: str = "qp"
    trials: int = 20
    first_seed: int = 0
    workers: int = field(default_factory=available_cpus)
    robot: str = DEFAULT_ROBOT

    def validate(self) -> None:
        """Raise InvalidInputError / UnknownNameError / RobotError for an invalid sweep."""
        validate_request(RunRequest(self.scenario, self.controller, self.first_seed))
        resolve_description(self.robot)
        if not 1 <= self.trials <= MAX_TRIALS:
            raise InvalidInputError(f"--trials must be in [1, {MAX_TRIALS}], got {self.trials}")
        if self.first_seed + self.trials - 1 > MAX_SEED:
            raise InvalidInputError(f"--seed + --trials - 1 must be <= {MAX_SEED}")
        cpus = available_cpus()
        if not 1 <= self.workers <= 4 * cpus:
            raise InvalidInputError(
                f"--workers must be in [1, {4 * cpus}] here ({cpus} CPUs available), "
                f"got {self.workers}"
            )


def run_trial(
    scenario: str, controller: str, seed: int, robot: str = DEFAULT_ROBOT
) -> dict[str, Any]:
    """Run one trial and return its summary without the event list."""
    req = RunRequest(scenario=scenario, controller=controller, seed=seed, robot=robot)
    summary = run(req).summary()
    summary.pop("events", None)
    return summary


def lost_trial(seed: int, reason: str, detail: str | None = None) -> dict[str, Any]:
    """The entry of a trial that gave no summary (``worker-died``, ``worker-error``)."""
    entry: dict[str, Any] = {"seed": seed, "success": False, "failure": reason, "lost": True}
    if detail:
        entry["detail"] = detail
    return entry


def run_sweep(
    req: SweepRequest, on_trial: Callable[[dict[str, Any]], None] | None = None
) -> dict[str, Any]:
    """Run every trial of ``req`` and return the report (JSON-serialisable).

    ``on_trial`` gets each trial's summary (or lost-trial entry) as it arrives. An interrupt
    (KeyboardInterrupt) stops the sweep and returns the partial report.
    """
    req.validate()
    seeds = [req.first_seed + i for i in range(req.trials)]
    wall0 = time.perf_counter()
    # Composed and calibrated once, here: forked workers inherit the cached scene (and a bad
    # robot file is refused before any trial).
    load_scene(robot=req.robot)
    results: list[dict[str, Any]] = []

    def add(entry: dict[str, Any]) -> None:
        results.append(entry)
        if on_trial:
            on_trial(entry)

    interrupted = False
    try:
        if req.workers == 1:
            for seed in seeds:
                summary = run_trial(req.scenario, req.controller, seed, req.robot)
                if summary["failure"] == "interrupted":  # a stop request, not a result
                    interrupted = True
                    break
                add(summary)
        else:
            _run_parallel(req, seeds, add)
    except KeyboardInterrupt:
        interrupted = True
    wall = time.perf_counter() - wall0
    return sweep_report(req, results, wall, interrupted=interrupted)


# ---------------------------------------------------------------------- worker processes


def _context() -> Any:
    """fork on Linux (fast; the workers share the parent's imports), spawn elsewhere."""
    return mp.get_context("fork" if sys.platform.startswith("linux") else "spawn")


def _worker_main(conn: Connection, scenario: str, controller: str, robot: str) -> None:
    """A worker: seeds in, summaries out, until it gets None."""
    ignore_in_child()
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)
    while True:
        try:
            seed = conn.recv()
        except (EOFError, OSError):
            return
        if seed is None:
            return
        try:
            result = run_trial(scenario, controller, seed, robot)
        except Exception as exc:  # reported as a failed trial, never as a traceback
            result = lost_trial(seed, WORKER_ERROR, f"{type(exc).__name__}: {exc}")
        conn.send(result)


@contextlib.contextmanager
def _stop_signals_blocked() -> Iterator[None]:
    """Hold stop signals while a worker is forked: it must not run this process's handler;
    one arriving meanwhile is delivered here right after."""
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


class _Worker:
    def __init__(self, ctx: Any, req: SweepRequest, seed: int) -> None:
        self.conn, child = ctx.Pipe()
        with _stop_signals_blocked():
            self.process = ctx.Process(
                target=_worker_main,
                args=(child, req.scenario, req.controller, req.robot),
                daemon=True,
            )
            self.process.start()
        child.close()
        self.seed: int | None = None
        self.give(seed)

    def give(self, seed: int | None) -> None:
        """Hand the worker its next seed (None: stop). A worker that died meanwhile cannot
        take it; its sentinel reports it, and the seed counts as its lost trial."""
        self.seed = seed
        with contextlib.suppress(BrokenPipeError, OSError):
            self.conn.send(seed)

    def kill(self) -> None:
        with contextlib.suppress(OSError, AttributeError):
            self.process.kill()
        self.process.join(timeout=1.0)
        self.conn.close()


def _run_parallel(
    req: SweepRequest, seeds: list[int], add: Callable[[dict[str, Any]], None]
) -> None:
    ctx = _context()
    pending = deque(seeds)
    workers: list[_Worker] = []
    try:
        while pending and len(workers) < req.workers:
            workers.append(_Worker(ctx, req, pending.popleft()))
        while workers:
            waitables: list[Any] = [w.conn for w in workers] + [w.process.sentinel for w in workers]
            ready = set(wait(waitables, timeout=POLL_PERIOD_S))
            for w in list(workers):
                result = None
                if w.conn in ready or w.process.sentinel in ready:
                    with contextlib.suppress(EOFError, OSError):
                        if w.conn.poll():
                            result = w.conn.recv()
                if result is not None:
                    add(result)
                    w.give(pending.popleft() if pending else None)
                    if w.seed is None:
                        w.process.join(timeout=1.0)
                        w.conn.close()
                        workers.remove(w)
                elif w.process.sentinel in ready:  # died with a trial in hand
                    code = w.process.exitcode
                    if w.seed is not None:
                        how = f"killed by signal {-code}" if code and code < 0 else f"exit {code}"
                        add(lost_trial(w.seed, WORKER_DIED, how))
                    w.kill()
                    workers.remove(w)
                    if pending:
                        workers.append(_Worker(ctx, req, pending.popleft()))
    finally:
        for w in workers:
            w.kill()


# ---------------------------------------------------------------------- report


def sweep_report(
    req: SweepRequest, results: list[dict[str, Any]], wall: float, *, interrupted: bool = False
) -> dict[str, Any]:
    """Aggregate trial summaries (and lost-trial entries) into the sweep report.

    ``completed`` counts the trials that ended (a lost trial counts, as a failure);
    ``success_rate`` is successes / completed. Metrics come from the trials with a summary.
    """
    results = sorted(results, key=lambda r: r["seed"])
    full = [r for r in results if not r.get("lost")]
    ok = [r for r in full if r["success"]]
    failed: dict[str, list[int]] = {}
    for r in results:
        if not r["success"]:
            failed.setdefault(str(r["failure"]), []).append(int(r["seed"]))
    errors = np.array([r["place_error_m"] for r in ok if r["place_error_m"] is not None])
    return {
        "scenario": req.scenario,
        "robot": next((r["robot"] for r in full), req.robot),
        "controller": req.controller,
        "trials": req.trials,
        "completed": len(results),
        "interrupted": interrupted,
        "first_seed": req.first_seed,
        "workers": req.workers,
        "successes": len(ok),
        "success_rate": len(ok) / len(results) if results else 0.0,
        "failures_by_reason": {k: len(v) for k, v in sorted(failed.items())},
        "failed_seeds": dict(sorted(failed.items())),
        "place_error_p50_m": float(np.percentile(errors, 50)) if errors.size else None,
        "place_error_p95_m": float(np.percentile(errors, 95)) if errors.size else None,
        "min_singular_value": min((r["min_singular_value"] for r in full), default=None),
        "max_joint_speed_ratio": max((r["max_joint_speed_ratio"] for r in full), default=None),
        "max_slip_m": max(((r["max_slip_m"] or 0.0) for r in full), default=None),
        "sim_time_s": float(sum(r["sim_time_s"] for r in full)),
        "wall_time_s": wall,
        "trials_per_second": len(results) / wall if wall > 0 and results else None,
    }


SWEEP_WALL_TIME_FIELDS = ("wall_time_s", "trials_per_second")
