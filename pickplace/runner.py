"""One validated run: request → scene, task, controller, observers → :class:`RunResult`.

The CLI, the sweep, the benchmark and the tests all run through :func:`run`, so they validate
inputs the same way and produce the same summaries.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from pickplace.controllers import CONTROLLERS, make_controller
from pickplace.errors import InvalidInputError, UnknownNameError
from pickplace.loader import load_scene
from pickplace.planner import Candidate, PlanningReport
from pickplace.preflight import Preflight, PreflightConfig
from pickplace.robot import DEFAULT_ROBOT
from pickplace.scenarios import (
    BrickPlacement,
    BuildRequest,
    Scenario,
    check_brick_in_source_bin,
    get_scenario,
)
from pickplace.scene import Scene
from pickplace.sim import SimConfig, Simulation, TickObserver
from pickplace.task import Task
from pickplace.verdict import RunResult

CONTROL_RATE_RANGE_HZ = (100.0, 1000.0)
PACE_RANGE = (0.01, 1000.0)
MAX_SEED = 2**32 - 1


@dataclass(frozen=True)
class RunRequest:
    """Everything that defines one run.

    Attributes:
        scenario: Scenario name.
        controller: Controller name.
        seed: Seed of randomised scenarios (≥ 0).
        brick: Brick start pose override (x, y [m], yaw [rad]) in bin 1.
        scene_path: World file (bins, brick, floor, lights, cameras, physics options) the
            robot is composed into; default ``scenes/world.xml``.
        robot: A bundled robot's name or a ``robot.toml`` path.
        record: ``.rrd`` file to write.
        spawn: Stream to a newly spawned Rerun viewer.
        connect: Stream to a running Rerun viewer at this URL.
        control_rate_hz: IK rate [Hz].
        pace: Run at most this many times faster than real time (None: as fast as possible).
    """

    scenario: str = "pick-place"
    controller: str = "qp"
    seed: int = 0
    brick: BrickPlacement | None = None
    scene_path: Path | None = None
    robot: str = DEFAULT_ROBOT
    record: Path | None = None
    spawn: bool = False
    connect: str | None = None
    control_rate_hz: float = 100.0
    pace: float | None = None
    observers: Sequence[TickObserver] = field(default=(), compare=False)

    @property
    def recording_id(self) -> str:
        """Recording id naming scenario, controller and seed."""
        return f"{self.scenario}/{self.controller}/seed-{self.seed}"


def validate_record_path(path: Path) -> Path:
    """Check that ``path`` can be written as a recording.

    Raises:
        InvalidInputError: Wrong suffix, missing or read-only folder, or a directory.
    """
    if path.suffix != ".rrd":
        raise InvalidInputError(f"--record '{path}' must end in .rrd (e.g. run.rrd)")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InvalidInputError(f"--record '{path}': folder '{parent}' does not exist")
    if path.is_dir():
        raise InvalidInputError(f"--record '{path}' is a directory; give a file name ending .rrd")
    existed = path.exists()
    try:  # os.access says yes to root even on read-only file systems: try it.
        with open(path, "ab"):
            pass
    except OSError as exc:
        raise InvalidInputError(
            f"--record '{path}': folder '{parent}' is not writable ({exc.strerror})"
        ) from None
    if not existed:
        path.unlink()
    return path


def validate_request(req: RunRequest) -> Scenario:
    """Check every field that does not need the scene; return the scenario.

    Raises:
        InvalidInputError: A value is out of range.
        UnknownNameError: Unknown scenario or controller.
    """
    scenario = get_scenario(req.scenario)
    if req.controller not in CONTROLLERS:
        raise UnknownNameError("controller", req.controller, CONTROLLERS)
    if isinstance(req.seed, bool) or not isinstance(req.seed, int) or not 0 <= req.seed <= MAX_SEED:
        raise InvalidInputError(f"--seed must be an integer in [0, {MAX_SEED}], got {req.seed!r}")
    lo, hi = CONTROL_RATE_RANGE_HZ
    if not (math.isfinite(req.control_rate_hz) and lo <= req.control_rate_hz <= hi):
        raise InvalidInputError(
            f"--control-rate must be in [{lo:g}, {hi:g}] Hz, got {req.control_rate_hz!r}"
        )
    if req.pace is not None:
        lo, hi = PACE_RANGE
        if not (math.isfinite(req.pace) and lo <= req.pace <= hi):
            raise InvalidInputError(f"--pace must be in [{lo:g}, {hi:g}], got {req.pace!r}")
    if req.brick is not None and not scenario.uses_brick:
        raise InvalidInputError(
            f"--brick does not apply to scenario '{scenario.name}' (it does not move the brick)"
        )
    if req.record is not None:
        validate_record_path(req.record)
    if req.connect is not None and not req.connect.startswith(("rerun://", "rerun+http://")):
        raise InvalidInputError(
            f"--connect '{req.connect}' must be a Rerun URL such as "
            "rerun+http://127.0.0.1:9876/proxy"
        )
    return scenario


def build_task(req: RunRequest, refuse_infeasible: bool = True) -> tuple[Scene, Task]:
    """Validate ``req``, load the scene and build the scenario's task (planning included).

    Raises:
        PickPlaceError: Any invalid input (see :func:`validate_request`), a bad world file or
            robot description (:class:`~pickplace.errors.RobotError`: the file, the field and
            what would be valid);
            a ``--brick`` pose outside bin 1, or one for which no candidate plan is feasible
            (field ``brick``: the message gives the first candidate's problem and what would
            help).
    """
    scenario = validate_request(req)
    scene = load_scene(req.scene_path, req.robot)
    if req.brick is not None:
        check_brick_in_source_bin(scene, req.brick)
    task = scenario.build(
        BuildRequest(scene, scenario.name, req.seed, req.brick, controller=req.controller)
    )
    planning = task.planning
    infeasible = planning is not None and not planning.feasible
    if refuse_infeasible and req.brick is not None and planning is not None and infeasible:
        first = planning.candidates[0]
        problem = first.preflight.problem
        why = f"at t={problem.t:.2f} s {problem.text}" if problem else "infeasible"
        b = req.brick
        raise InvalidInputError(
            f"no feasible plan picks the brick at x={b.x:g} m, y={b.y:g} m, yaw={b.yaw:g} rad: "
            f"{len(planning.candidates)} candidates tried, the first ({first.label}) {why}; "
            f"move it inwards or turn it (pickplace plan --brick={b.x:g},{b.y:g},{b.yaw:g} "
            "lists every candidate)",
            field="brick",
        )
    return scene, task


def plan_report(req: RunRequest) -> PlanningReport:
    """The planning of ``req``'s scenario without physics (``pickplace plan``): its candidates
    and their pre-flights. A scenario that executes its plan without a pre-flight gets one
    here, as a single candidate, so that every plan can be asked whether it is feasible.

    Raises:
        PickPlaceError: Invalid input (an infeasible ``--brick`` pose is reported, not refused).
    """
    scene, task = build_task(req, refuse_infeasible=False)
    if task.planning is not None:
        return task.planning
    t0 = time.perf_counter()
    result = Preflight(scene, req.controller).run(task.plan, task.X_WO_start, task.goal.X_WO_goal)
    candidate = Candidate("the scenario's plan (executed without a pre-flight)", task.plan, result)
    chosen = 0 if result.feasible else None
    return PlanningReport((candidate,), chosen, time.perf_counter() - t0, PreflightConfig())


def prepare(req: RunRequest) -> tuple[Scene, Task, Simulation]:
    """Validate ``req`` and build the simulation (nothing stepped yet).

    Raises:
        PickPlaceError: Any invalid input (see :func:`build_task`).
    """
    scene, task = build_task(req)
    config = SimConfig(control_rate_hz=req.control_rate_hz)
    dt = 1.0 / req.control_rate_hz
    controller = make_controller(req.controller, scene, dt)
    observers: list[TickObserver] = list(req.observers)
    if req.pace is not None:
        observers.append(Pacer(req.pace))
    if req.record is not None or req.spawn or req.connect is not None:
        from pickplace.recording import Recorder  # rerun is imported only when recording

        observers.append(
            Recorder(
                req.record, recording_id=req.recording_id, spawn=req.spawn, connect=req.connect
            )
        )
    sim = Simulation(scene, task, controller, config, observers)
    return scene, task, sim


def run(req: RunRequest) -> RunResult:
    """Validate, build and run one simulation."""
    _, _, sim = prepare(req)
    result = sim.run()
    if req.record is not None:
        result.recording = str(req.record)
    return result


class Pacer:
    """Observer that sleeps so the run goes at most ``factor`` times faster than real time."""

    def __init__(self, factor: float) -> None:
        self.factor = factor
        self._wall0 = 0.0

    def on_start(self, run: Simulation) -> None:
        self._wall0 = time.perf_counter()

    def on_ticks(self, run: Simulation, start: int, end: int) -> None:
        due = self._wall0 + end * run.dt / self.factor
        delay = due - time.perf_counter()
        if delay > 0:
            time.sleep(delay)

    def on_event(self, run: Simulation, event: object) -> None:
        return None

    def on_finish(self, run: Simulation, result: RunResult) -> None:
        return None


__all__ = ["RunRequest", "build_task", "plan_report", "prepare", "run"]
