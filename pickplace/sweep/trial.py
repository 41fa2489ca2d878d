"""One trial of a sweep: what it runs (:class:`TrialSpec`), and what is kept of it.

A trial is a run request without its seed, plus the seed. What a sweep keeps of its run is the
compact summary (:func:`compact_summary`: the keys in :data:`TRIAL_KEYS`, the failure's text,
the number of attempts, the drawn parameters), about 0.6 kB; a trial that gave no summary (its
worker died or raised) is a lost-trial entry (:func:`lost_trial`). Both backends
(:mod:`pickplace.sweep.sweep`, :mod:`pickplace.sweep.ray_driver`) run :func:`guarded_trial`.
"""

from __future__ import annotations

import math
import os
import shlex
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from pickplace.robot.registry import DEFAULT_ROBOT
from pickplace.run.runner import RunRequest, run
from pickplace.sim.vary import VaryPlan
from pickplace.sim.verdict import RunResult

WORKER_DIED = "worker-died"
WORKER_ERROR = "worker-error"
WORKER_TIMEOUT = "worker-timeout"
POLL_PERIOD_S = 0.2  # a backend's main loop wakes at least this often [s]
# Summary keys a trial keeps (plus ``failure_text``, ``parameters`` and ``arm``): everything
# the report and the recording use, nothing that measures the wall clock.
TRIAL_KEYS = (
    "scenario",
    "robot",
    "controller",
    "seed",
    "success",
    "failure",
    "failure_tick",
    "failure_time_s",
    "brick_start_xyz",
    "place_error_m",
    "max_slip_m",
    "cycle_time_s",
    "min_singular_value",
    "max_joint_speed_ratio",
    "max_position_error_m",
    "max_robot_world_contact_force_n",
    "sim_time_s",
    "refusal",
)


def available_cpus() -> int:
    """CPUs this process may run on (its affinity mask, e.g. under ``taskset``), else the
    machine's count."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except (AttributeError, OSError):
        return os.cpu_count() or 1


@dataclass(frozen=True)
class TrialSpec:
    """Everything one trial's run request holds but the seed (one arm of a comparison).

    Attributes:
        scenario: Scenario name.
        controller: Controller name.
        speed: Speed override in (0, 1] (unless ``speed`` is varied).
        control_rate_hz: IK rate [Hz] (unless ``control_rate`` is varied).
        vary: The varied parameters, drawn per trial from its seed.
        robot: A bundled robot's name or a ``robot.toml`` path.
        attempts: Most attempts each run may take (``--attempts``, see
            :mod:`pickplace.sim.recovery`).
        arm: Label of the arm in a comparison, e.g. ``controller=dls`` ("" without one).
        object: The object to pick (``--object``), None for the world's brick.
    """

    scenario: str = "pick-place-random"
    controller: str = "qp"
    speed: float = 1.0
    control_rate_hz: float = 100.0
    vary: VaryPlan = field(default_factory=VaryPlan)
    robot: str = DEFAULT_ROBOT
    attempts: int = 1
    arm: str = ""
    object: str | None = None

    def request(self, seed: int) -> RunRequest:
        """The run request of the trial with ``seed``."""
        return RunRequest(
            scenario=self.scenario,
            controller=self.controller,
            seed=seed,
            robot=self.robot,
            control_rate_hz=self.control_rate_hz,
            speed=self.speed,
            parameters=self.vary.draw(seed) if self.vary.specs else None,
            attempts=self.attempts,
            object=self.object,
        )

    def rerun_command(self, seed: int) -> str:
        """The ``pickplace run`` command that re-runs the trial with ``seed`` alone."""
        args = ["pickplace", "run", "--scenario", self.scenario]
        if self.robot != DEFAULT_ROBOT:
            args += ["--robot", self.robot]
        args += ["--controller", self.controller, "--seed", str(seed)]
        if self.speed != 1.0:
            args += ["--speed", repr(self.speed)]
        if self.control_rate_hz != 100.0:
            args += ["--control-rate", repr(self.control_rate_hz)]
        if self.attempts != 1:
            args += ["--attempts", str(self.attempts)]
        if self.object is not None:
            args += ["--object", self.object]
        for spec in self.vary.specs:
            args += ["--vary", spec.flag()]
        return shlex.join(args)


def compact_summary(result: RunResult, arm: str = "") -> dict[str, Any]:
    """The part of a run a sweep keeps: the summary's :data:`TRIAL_KEYS`, the result's
    ``failure_text`` (:attr:`~pickplace.sim.verdict.RunResult.failure_text`), ``parameters``
    (when varied), ``arm`` (in a comparison), the number of ``attempts`` and of ``pushes``
    (over all attempts). A non-finite number becomes None (JSON has
    no NaN)."""
    summary = result.summary()
    out = {k: _finite_or_none(summary.get(k)) for k in TRIAL_KEYS}
    out["failure_text"] = result.failure_text
    out["attempts"] = len(summary["attempts"])
    out["pushes"] = sum(a["pushes"] for a in summary["attempts"])
    if result.parameters is not None:
        out["parameters"] = result.parameters
    if arm:
        out["arm"] = arm
    return out


def _finite_or_none(value: Any) -> Any:
    """None for a non-finite float (e.g. σmin of a run that took no step): valid JSON."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def run_trial(spec: TrialSpec, seed: int) -> dict[str, Any]:
    """Run one trial and return its compact summary (:func:`compact_summary`)."""
    return compact_summary(run(spec.request(seed)), spec.arm)


def lost_trial(seed: int, reason: str, detail: str | None = None, arm: str = "") -> dict[str, Any]:
    """The entry of a trial that gave no summary (``worker-died``, ``worker-error``,
    ``worker-timeout``)."""
    entry: dict[str, Any] = {"seed": seed, "success": False, "failure": reason, "lost": True}
    if detail:
        entry["detail"] = detail
    if arm:
        entry["arm"] = arm
    return entry


def guarded_trial(spec: TrialSpec, seed: int) -> dict[str, Any]:
    """:func:`run_trial`, with an exception reported as a ``worker-error`` trial (never as a
    traceback): what every backend runs, for any number of workers."""
    try:
        return run_trial(spec, seed)
    except Exception as exc:
        return lost_trial(seed, WORKER_ERROR, f"{type(exc).__name__}: {exc}", spec.arm)


Job = tuple[int, int]
"""(index of the trial spec, seed)."""

Add = Callable[[dict[str, Any]], None]


__all__ = [
    "POLL_PERIOD_S",
    "TRIAL_KEYS",
    "WORKER_DIED",
    "WORKER_ERROR",
    "WORKER_TIMEOUT",
    "Add",
    "Job",
    "TrialSpec",
    "available_cpus",
    "compact_summary",
    "guarded_trial",
    "lost_trial",
    "run_trial",
]
