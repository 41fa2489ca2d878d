"""Many trials of one scenario, on this machine's processes or a Ray cluster, as one report.

Trial ``i`` runs with seed ``first_seed + i``. Its varied parameters (``--vary``,
:mod:`pickplace.sim.vary`) are drawn from that seed alone, so any trial re-runs alone with the
command the report prints for it (``pickplace run --scenario NAME --seed SEED --vary ...``),
whatever the order, the backend or the number of workers. With ``--compare KEY=A,B`` every
seed runs once per value of KEY (e.g. ``controller=qp,dls``) with the same parameters: the
runs are paired by seed (:mod:`pickplace.sweep.report` compares them).

Backends (results are ordered by seed and do not depend on the backend):

- ``process`` (default): with one worker the trials run in this process (an interrupt ends the
  running trial, which is left out of the report). With more, each worker process runs one
  trial at a time and gets the next one only when it returns a result, so nothing is queued in
  a worker: a worker that dies (the OOM killer, a crash) fails its trial with reason
  ``worker-died`` and a new worker takes the next trial; one that gives no result within the
  trial time limit (``trial_timeout_s``, ``--trial-timeout``: stopped, stuck) is killed and
  its trial failed with reason ``worker-timeout``. Ctrl-C, SIGTERM or SIGHUP (a
  KeyboardInterrupt in the calling thread) kills the workers at once and the report covers
  the trials finished so far, with ``"interrupted": true``. Workers ignore the terminal's
  Ctrl-C themselves: only this process decides. The time limit needs a worker process to
  kill: it does not apply to one worker (the trials run here) nor, yet, to Ray tasks.
- ``ray``: the trials are Ray tasks (:mod:`pickplace.sweep.ray_backend`), on a running cluster
  (``address``) or a local one started for the sweep; the same rules for dead workers and
  interrupts.

Every backend and worker count runs a trial through
:func:`~pickplace.sweep.trial.guarded_trial`: an exception in a trial is that trial's
``worker-error``, never a traceback that ends the sweep.

Each trial keeps only its compact summary (:func:`pickplace.sweep.trial.compact_summary`: no event
list, no plan), so memory grows by under a kilobyte per trial.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import signal
import sys
import time
from collections import deque
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from multiprocessing.connection import Connection, wait
from typing import Any

from pickplace.control.controllers import CONTROLLERS
from pickplace.errors import InvalidInputError, RobotError, UnknownNameError
from pickplace.robot.compose import HeldObject
from pickplace.robot.description import RobotDescription
from pickplace.robot.registry import DEFAULT_ROBOT, resolve_description
from pickplace.run.runner import (
    MAX_SEED,
    object_world,
    resolve_control_rate,
    validate_request,
    varied_rate_error,
)
from pickplace.signals import STOP_SIGNALS, ignore_in_child
from pickplace.sim.loader import load_scene
from pickplace.sim.vary import VaryPlan
from pickplace.sweep.ray_backend import check_ray, run_ray
from pickplace.sweep.report import SWEEP_WALL_TIME_FIELDS, build_report
from pickplace.sweep.trial import (
    POLL_PERIOD_S,
    TRIAL_KEYS,
    WORKER_DIED,
    WORKER_ERROR,
    WORKER_TIMEOUT,
    Add,
    Job,
    TrialSpec,
    available_cpus,
    compact_summary,
    guarded_trial,
    lost_trial,
    run_trial,
)
from pickplace.world.scene import WorldFile, read_world

MAX_TRIALS = 100_000
# A trial's time limit [s]: a worker without a result by then is killed (worker-timeout). A
# trial takes about a second (a minute for the slowest robots on a loaded machine).
DEFAULT_TRIAL_TIMEOUT_S = 600.0
TRIAL_TIMEOUT_RANGE_S = (1.0, 86_400.0)
BACKENDS = ("process", "ray")
# What --compare can vary, each a field of TrialSpec.
COMPARABLE = ("controller", "robot")
# ---------------------------------------------------------------------- what a trial is


@dataclass(frozen=True)
class Comparison:
    """``--compare KEY=A,B``: every seed runs once per value of KEY.

    Attributes:
        key: What differs between the arms (one of :data:`COMPARABLE`).
        values: Its values, at least two, all different, in the order given.
    """

    key: str
    values: tuple[str, ...]

    def __post_init__(self) -> None:
        """Check the key, and that there are two or more distinct values."""
        if self.key not in COMPARABLE:
            raise InvalidInputError(
                f"--compare {self.key}=...: can compare {', '.join(COMPARABLE)}, e.g. "
                "--compare controller=qp,dls"
            )
        values = tuple(self.values)
        if len(values) < 2 or len(set(values)) != len(values) or not all(values):
            raise InvalidInputError(
                f"--compare {self.key}= needs two or more different values, e.g. "
                f"controller=qp,dls; got '{','.join(values)}'"
            )
        if self.key == "controller":
            for v in values:
                if v not in CONTROLLERS:
                    raise UnknownNameError("controller", v, CONTROLLERS)
        object.__setattr__(self, "values", values)

    def flag(self) -> str:
        """The ``--compare`` value, e.g. ``controller=qp,dls``."""
        return f"{self.key}={','.join(self.values)}"

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {"key": self.key, "values": list(self.values)}


def given_and_compared(key: str) -> InvalidInputError:
    """The error for a trial field (one of :data:`COMPARABLE`) both given and compared."""
    return InvalidInputError(f"the {key} is given and also compared; give one of them", field=key)


def parse_compare(text: str) -> Comparison:
    """Parse ``KEY=A,B[,C...]``.

    Raises:
        InvalidInputError: Bad syntax, a key that cannot be compared, fewer than two values,
            a robot that is not bundled or whose robot.toml cannot be read.
        UnknownNameError: An unknown controller.
    """
    key, sep, rest = text.partition("=")
    if not sep or not key.strip() or not rest.strip():
        raise InvalidInputError(
            f"--compare '{text}' must be KEY=A,B with KEY one of {', '.join(COMPARABLE)}, "
            "e.g. controller=qp,dls"
        )
    return Comparison(key.strip(), tuple(v.strip() for v in rest.split(",")))


@dataclass(frozen=True)
class SweepRequest:
    """A sweep: ``trials`` seeds ``first_seed …`` of ``scenario``.

    Attributes:
        scenario: Scenario name.
        controller: Controller name (not with ``compare`` on the controller).
        trials: Number of seeds, in [1, :data:`MAX_TRIALS`].
        first_seed: Seed of the first trial.
        workers: Trials run at once: processes (default: one per available CPU, see
            :func:`available_cpus`; 1 runs them in this process), or the local Ray
            cluster's CPUs; on a Ray cluster at ``address`` the tasks in flight (default:
            the cluster's CPUs).
        vary: Varied parameters (drawn per trial from its seed).
        compare: Run every seed once per value of this (paired), or None.
        speed: Speed override in (0, 1].
        control_rate_hz: IK rate [Hz].
        backend: ``process`` or ``ray``.
        address: Address of a running Ray cluster (``ray`` only; None: start a local one).
        robot: A bundled robot's name or a ``robot.toml`` path (not with ``compare`` on the
            robot).
        trial_timeout_s: Time limit of one trial in a worker process [s] (see the module
            docstring), in :data:`TRIAL_TIMEOUT_RANGE_S`; None: :data:`DEFAULT_TRIAL_TIMEOUT_S`.
            Not with the Ray backend (its tasks have no time limit yet).
        attempts: Most attempts each run may take (``--attempts``).
        object: The object every trial picks (``--object``), None for the world's brick.
    """

    scenario: str = "pick-place-random"
    controller: str = "qp"
    trials: int = 20
    first_seed: int = 0
    workers: int | None = None
    vary: VaryPlan = field(default_factory=VaryPlan)
    compare: Comparison | None = None
    speed: float = 1.0
    control_rate_hz: float = 100.0
    backend: str = "process"
    address: str | None = None
    robot: str = DEFAULT_ROBOT
    trial_timeout_s: float | None = None
    attempts: int = 1
    object: str | None = None

    def specs(self) -> tuple[TrialSpec, ...]:
        """One trial spec per arm (one without a comparison), in the order of the values."""
        base = TrialSpec(
            self.scenario,
            self.controller,
            self.speed,
            self.control_rate_hz,
            self.vary,
            self.robot,
            self.attempts,
            object=self.object,
        )
        if self.compare is None:
            return (base,)
        key = self.compare.key  # a str field of TrialSpec (COMPARABLE)
        arms: list[dict[str, Any]] = [{key: v, "arm": f"{key}={v}"} for v in self.compare.values]
        return tuple(replace(base, **arm) for arm in arms)

    @property
    def seeds(self) -> range:
        """The trials' seeds."""
        return range(self.first_seed, self.first_seed + self.trials)

    @property
    def runs(self) -> int:
        """Runs the sweep makes: seeds × arms."""
        return self.trials * len(self.specs())

    def resolved_workers(self) -> int:
        """The number of workers when none was given: one per available CPU (a Ray
        cluster at an address: its CPUs, known once connected; this gives 0 then)."""
        if self.workers is not None:
            return self.workers
        if self.backend == "ray" and self.address is not None:
            return 0
        return available_cpus()

    def validate(self) -> ResolvedSweep:
        """Check the sweep and resolve what it names, once: every arm's robot description,
        the world's timestep for the control rates, a Ray cluster's address.

        Raises:
            InvalidInputError: An invalid field (the message names it and the valid range).
            UnknownNameError: An unknown scenario, controller or parameter.
            RobotError: A robot description cannot be used.
        """
        if self.backend not in BACKENDS:
            raise InvalidInputError(
                f"--backend must be one of {', '.join(BACKENDS)}, got '{self.backend}'"
            )
        if self.address is not None and self.backend != "ray":
            raise InvalidInputError("--address needs --backend ray (the address of its cluster)")
        if self.compare is not None:
            key = self.compare.key
            if getattr(self, key) != next(f.default for f in fields(self) if f.name == key):
                raise given_and_compared(key)
        robots: dict[str, RobotDescription] = {}
        for spec in self.specs():
            if spec.robot in robots:
                continue
            try:
                robots[spec.robot] = resolve_description(spec.robot)
            except RobotError as exc:  # unknown name or a bad robot.toml
                if self.compare is None or self.compare.key != "robot":
                    raise
                raise InvalidInputError(f"--compare robot=...: {exc}") from exc
        for spec in self.specs():
            validate_request(spec.request(self.first_seed))
        if self.trial_timeout_s is not None:
            lo, hi = TRIAL_TIMEOUT_RANGE_S
            timeout = self.trial_timeout_s
            if not (isinstance(timeout, int | float) and lo <= timeout <= hi):
                raise InvalidInputError(
                    f"--trial-timeout must be in [{lo:g}, {hi:g}] s (one trial's time limit), "
                    f"got {timeout!r}"
                )
            if self.backend == "ray":
                raise InvalidInputError(
                    "--trial-timeout applies to the process backend's worker processes; Ray "
                    "tasks have no time limit yet: leave it out with --backend ray"
                )
        if not 1 <= self.trials <= MAX_TRIALS:
            raise InvalidInputError(f"--trials must be in [1, {MAX_TRIALS}], got {self.trials}")
        if self.first_seed + self.trials - 1 > MAX_SEED:
            raise InvalidInputError(f"--seed + --trials - 1 must be <= {MAX_SEED}")
        self._validate_control_rates()
        world, held = object_world(read_world(), self.object)  # a bad --object: no trial
        if self.workers is not None:
            remote = self.backend == "ray" and self.address is not None
            cpus = available_cpus()
            top = MAX_TRIALS if remote else 4 * cpus
            if not 1 <= self.workers <= top:
                where = "" if remote else f" here ({cpus} CPUs available)"
                raise InvalidInputError(
                    f"--workers must be in [1, {top}]{where}, got {self.workers}"
                )
        if self.backend == "ray":
            check_ray(self.address)
        return ResolvedSweep(self, robots, world, held)

    def _validate_control_rates(self) -> None:
        """Every control rate the trials use is a whole number of the scene's steps."""
        rates = {self.control_rate_hz}
        varied = "control_rate" in self.vary.names
        if varied:
            rates = set(self.vary.spec("control_rate").values)
        if rates == {100.0}:
            return  # the runner's default: valid for every usable timestep
        timestep = read_world().timestep
        for rate in sorted(rates):
            try:
                resolve_control_rate(rate, timestep)
            except InvalidInputError as exc:
                if not varied:
                    raise
                raise varied_rate_error(rate, exc) from None


@dataclass(frozen=True)
class ResolvedSweep:
    """A sweep checked once (:meth:`SweepRequest.validate`), with what it resolved.

    Attributes:
        request: The sweep.
        robots: Each arm's robot as given (name or path) → its description.
        world: The world file, with the sweep's object in the brick's place.
        held: That object, as the robot's composition must know it (None: the brick).
    """

    request: SweepRequest
    robots: Mapping[str, RobotDescription]
    world: WorldFile
    held: HeldObject | None


def jobs_of(req: SweepRequest) -> list[Job]:
    """Every run of the sweep, seed by seed (all arms of a seed together)."""
    n = len(req.specs())
    return [(a, seed) for seed in req.seeds for a in range(n)]


def run_sweep(req: SweepRequest | ResolvedSweep, on_trial: Add | None = None) -> dict[str, Any]:
    """Run every trial of ``req`` and return the report (JSON-serialisable, see
    :func:`pickplace.sweep.report.sweep_report`).

    ``on_trial`` gets each trial's compact summary (or lost-trial entry) as it arrives. An
    interrupt (KeyboardInterrupt) stops the sweep and returns the partial report.
    """
    resolved = req if isinstance(req, ResolvedSweep) else req.validate()
    req = resolved.request
    specs = req.specs()
    jobs = jobs_of(req)
    wall0 = time.perf_counter()
    results: list[dict[str, Any]] = []
    workers = req.resolved_workers()

    def add(entry: dict[str, Any]) -> None:
        results.append(entry)
        if on_trial:
            on_trial(entry)

    interrupted = False
    start_s = 0.0
    try:
        # Composed and calibrated once, here: forked workers inherit the cached scenes (and a
        # bad robot file is refused before any trial).
        for desc in resolved.robots.values():
            load_scene(resolved.world, desc, held=resolved.held)
        if req.backend == "ray":
            workers, start_s = run_ray(specs, jobs, add, req.address, req.workers)
        elif workers == 1:
            for a, seed in jobs:
                summary = guarded_trial(specs[a], seed)  # the workers' guard, here too
                if summary["failure"] == "interrupted":  # a stop request, not a result
                    interrupted = True
                    break
                add(summary)
        else:
            timeout = req.trial_timeout_s or DEFAULT_TRIAL_TIMEOUT_S
            _run_parallel(specs, jobs, workers, add, timeout)
    except KeyboardInterrupt:
        interrupted = True
    wall = time.perf_counter() - wall0
    return sweep_report(
        req, results, wall, interrupted=interrupted, workers=workers, start_s=start_s
    )


def sweep_report(
    req: SweepRequest,
    results: Sequence[dict[str, Any]],
    wall: float,
    *,
    interrupted: bool = False,
    workers: int | None = None,
    start_s: float = 0.0,
) -> dict[str, Any]:
    """Aggregate trial summaries (and lost-trial entries) into the sweep report
    (:func:`pickplace.sweep.report.build_report`).

    ``completed`` counts the runs that ended (a lost trial counts, as a failure);
    ``success_rate`` is successes / completed; ``runs`` = seeds × arms were asked for.
    ``start_s`` is the part of ``wall`` spent starting the backend (a Ray cluster) [s].
    """
    compare = req.compare
    controlled = compare is not None and compare.key == "controller"
    robots = compare is not None and compare.key == "robot"
    header = {
        "scenario": req.scenario,
        "robot": None if robots else _robot_name(req.robot, results),
        "controller": None if controlled else req.controller,
        "trials": req.trials,
        "runs": req.runs,
        "interrupted": interrupted,
        "first_seed": req.first_seed,
        "backend": req.backend,
        "workers": workers if workers is not None else req.resolved_workers(),
        "speed": req.speed,
        "control_rate_hz": req.control_rate_hz,
        "attempts": req.attempts,
        "vary": req.vary.as_dict(),
        "vary_text": req.vary.describe(),
        "compare_flag": None if compare is None else compare.flag(),
    }
    return build_report(
        header,
        req.specs(),
        list(results),
        req.vary,
        wall,
        None if compare is None else compare.as_dict(),
        start_s,
    )


def _robot_name(robot: str, results: Sequence[dict[str, Any]]) -> str:
    """The robot's name as runs report it (a robot.toml path gives the name it holds)."""
    return next((str(r["robot"]) for r in results if r.get("robot")), robot)


# ---------------------------------------------------------------------- worker processes


def _context() -> Any:
    """fork on Linux (fast; the workers share the parent's imports), spawn elsewhere."""
    return mp.get_context("fork" if sys.platform.startswith("linux") else "spawn")


def _worker_main(conn: Connection, specs: Sequence[TrialSpec]) -> None:
    """A worker: jobs in, summaries out, until it gets None."""
    ignore_in_child()
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)
    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError):
            return
        if job is None:
            return
        arm, seed = job
        conn.send(guarded_trial(specs[arm], seed))


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
    def __init__(self, ctx: Any, specs: Sequence[TrialSpec], job: Job) -> None:
        self.conn, child = ctx.Pipe()
        with _stop_signals_blocked():
            self.process = ctx.Process(target=_worker_main, args=(child, specs), daemon=True)
            self.process.start()
        child.close()
        self.job: Job | None = None
        self.since = 0.0  # time.monotonic() when the job was given [s]
        self.give(job)

    def give(self, job: Job | None) -> None:
        """Hand ``job`` (None: stop) to the worker. One killed meanwhile — before its first job,
        or right after sending a result — has closed its end of the pipe: the send fails, and
        its sentinel then reports it, the job it was given a ``worker-died`` trial."""
        self.job = job
        self.since = time.monotonic()
        with contextlib.suppress(BrokenPipeError, ConnectionResetError):
            self.conn.send(job)

    def exit_text(self) -> str:
        """How the dead worker ended: ``killed by signal N`` or ``exit N``."""
        self.process.join(timeout=1.0)  # the sentinel fires before the exit code is known
        code = self.process.exitcode
        if code is None:
            return "ended, exit status unknown"
        return f"killed by signal {-code}" if code < 0 else f"exit {code}"

    def kill(self) -> None:
        with contextlib.suppress(OSError, AttributeError):
            self.process.kill()
        self.process.join(timeout=1.0)
        self.conn.close()


def _run_parallel(
    specs: Sequence[TrialSpec],
    jobs: Sequence[Job],
    workers: int,
    add: Add,
    timeout_s: float = DEFAULT_TRIAL_TIMEOUT_S,
) -> None:
    """Run ``jobs`` on ``workers`` worker processes (see the module docstring); a worker that
    holds a job longer than ``timeout_s`` [s] is killed and the job is a ``worker-timeout``."""
    ctx = _context()
    pending = deque(jobs)
    running: list[_Worker] = []
    try:
        while pending and len(running) < workers:
            running.append(_Worker(ctx, specs, pending.popleft()))
        while running:
            waitables: list[Any] = [w.conn for w in running] + [w.process.sentinel for w in running]
            ready = set(wait(waitables, timeout=POLL_PERIOD_S))
            for w in list(running):
                result = None
                if w.conn in ready or w.process.sentinel in ready:
                    with contextlib.suppress(EOFError, OSError):
                        if w.conn.poll():
                            result = w.conn.recv()
                if result is not None:
                    add(result)
                    w.give(pending.popleft() if pending else None)
                    if w.job is None:
                        w.process.join(timeout=1.0)
                        w.conn.close()
                        running.remove(w)
                elif w.process.sentinel in ready:  # died with a trial in hand
                    if w.job is not None:
                        arm, seed = w.job
                        add(lost_trial(seed, WORKER_DIED, w.exit_text(), specs[arm].arm))
                    w.kill()
                    running.remove(w)
                    if pending:
                        running.append(_Worker(ctx, specs, pending.popleft()))
            now = time.monotonic()
            for w in list(running):  # stopped or stuck: no result in time
                if w.job is not None and now - w.since > timeout_s:
                    arm, seed = w.job
                    detail = f"no result within {timeout_s:g} s (--trial-timeout); worker killed"
                    add(lost_trial(seed, WORKER_TIMEOUT, detail, specs[arm].arm))
                    w.kill()
                    running.remove(w)
                    if pending:
                        running.append(_Worker(ctx, specs, pending.popleft()))
    finally:
        for w in running:
            w.kill()


__all__ = [
    "BACKENDS",
    "COMPARABLE",
    "DEFAULT_TRIAL_TIMEOUT_S",
    "MAX_TRIALS",
    "SWEEP_WALL_TIME_FIELDS",
    "TRIAL_KEYS",
    "WORKER_DIED",
    "WORKER_ERROR",
    "WORKER_TIMEOUT",
    "Comparison",
    "SweepRequest",
    "TrialSpec",
    "available_cpus",
    "compact_summary",
    "guarded_trial",
    "jobs_of",
    "lost_trial",
    "parse_compare",
    "run_sweep",
    "run_trial",
    "sweep_report",
]
