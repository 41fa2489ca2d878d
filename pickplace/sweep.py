"""Many trials of one scenario in parallel processes, summarised as one report.

Trial ``i`` runs with seed ``first_seed + i``, so a failing trial can be re-run alone with
``pickplace run --scenario NAME --seed SEED``. Results are ordered by seed and do not depend on
the number of workers.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pickplace.errors import InvalidInputError
from pickplace.robot import DEFAULT_ROBOT, resolve_description
from pickplace.runner import MAX_SEED, RunRequest, run, validate_request

MAX_TRIALS = 100_000


@dataclass(frozen=True)
class SweepRequest:
    """A sweep: ``trials`` runs of ``scenario`` with seeds ``first_seed …`` on ``workers``
    processes (default: one per CPU), with ``robot`` (a bundled name or a robot.toml)."""

    scenario: str = "pick-place-random"
    controller: str = "qp"
    trials: int = 20
    first_seed: int = 0
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    robot: str = DEFAULT_ROBOT

    def validate(self) -> None:
        """Raise InvalidInputError / UnknownNameError / RobotError for an invalid sweep."""
        validate_request(RunRequest(self.scenario, self.controller, self.first_seed))
        resolve_description(self.robot)
        if not 1 <= self.trials <= MAX_TRIALS:
            raise InvalidInputError(f"--trials must be in [1, {MAX_TRIALS}], got {self.trials}")
        if self.first_seed + self.trials - 1 > MAX_SEED:
            raise InvalidInputError(f"--seed + --trials - 1 must be <= {MAX_SEED}")
        cpus = os.cpu_count() or 1
        if not 1 <= self.workers <= 4 * cpus:
            raise InvalidInputError(
                f"--workers must be in [1, {4 * cpus}] on this machine ({cpus} CPUs), "
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


def _trial(args: tuple[str, str, int, str]) -> dict[str, Any]:
    return run_trial(*args)


def run_sweep(
    req: SweepRequest, on_trial: Callable[[dict[str, Any]], None] | None = None
) -> dict[str, Any]:
    """Run every trial of ``req`` and return the report (JSON-serialisable)."""
    req.validate()
    jobs = [
        (req.scenario, req.controller, req.first_seed + i, req.robot) for i in range(req.trials)
    ]
    wall0 = time.perf_counter()
    results: list[dict[str, Any]] = []
    if req.workers == 1:
        for job in jobs:
            results.append(_trial(job))
            if on_trial:
                on_trial(results[-1])
    else:
        with ProcessPoolExecutor(max_workers=req.workers) as pool:
            for summary in pool.map(_trial, jobs, chunksize=1):
                results.append(summary)
                if on_trial:
                    on_trial(summary)
    wall = time.perf_counter() - wall0
    return sweep_report(req, results, wall)


def sweep_report(req: SweepRequest, results: list[dict[str, Any]], wall: float) -> dict[str, Any]:
    """Aggregate trial summaries into the sweep report."""
    results = sorted(results, key=lambda r: r["seed"])
    ok = [r for r in results if r["success"]]
    failed: dict[str, list[int]] = {}
    for r in results:
        if not r["success"]:
            failed.setdefault(str(r["failure"]), []).append(int(r["seed"]))
    errors = np.array([r["place_error_m"] for r in ok if r["place_error_m"] is not None])
    return {
        "scenario": req.scenario,
        "robot": results[0]["robot"] if results else None,
        "controller": req.controller,
        "trials": req.trials,
        "first_seed": req.first_seed,
        "workers": req.workers,
        "successes": len(ok),
        "success_rate": len(ok) / len(results) if results else 0.0,
        "failures_by_reason": {k: len(v) for k, v in sorted(failed.items())},
        "failed_seeds": dict(sorted(failed.items())),
        "place_error_p50_m": float(np.percentile(errors, 50)) if errors.size else None,
        "place_error_p95_m": float(np.percentile(errors, 95)) if errors.size else None,
        "min_singular_value": min(r["min_singular_value"] for r in results),
        "max_joint_speed_ratio": max(r["max_joint_speed_ratio"] for r in results),
        "max_slip_m": max((r["max_slip_m"] or 0.0) for r in results),
        "sim_time_s": float(sum(r["sim_time_s"] for r in results)),
        "wall_time_s": wall,
        "trials_per_second": len(results) / wall if wall > 0 else None,
    }


SWEEP_WALL_TIME_FIELDS = ("wall_time_s", "trials_per_second")
