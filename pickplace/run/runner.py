"""One validated run: request → scene, task, controller, observers → :class:`RunResult`.

The CLI, the sweep, the benchmark and the tests all run through :func:`run` (or
:func:`execute`, which also reports what happened to the outputs), so they validate inputs the
same way and produce the same summaries. Everything is validated before any output is opened:
a refused run never creates, truncates or deletes a file.
"""

from __future__ import annotations

import contextlib
import math
import os
import stat
import tempfile
import time
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from pickplace.control.controllers import CONTROLLERS, make_controller
from pickplace.errors import InvalidInputError, ObjectError, SceneError, UnknownNameError
from pickplace.outfile import lock_path, lock_problem, name_max
from pickplace.planning.planner import Candidate, PlanningReport
from pickplace.planning.preflight import Preflight, PreflightConfig
from pickplace.planning.timing import TimingConfig, check_speed
from pickplace.record.viewer import parse_viewer_url
from pickplace.robot.compose import HeldObject
from pickplace.robot.description import RobotDescription
from pickplace.robot.registry import DEFAULT_ROBOT, resolve_description
from pickplace.sim.events import EventKind
from pickplace.sim.loader import load_scene
from pickplace.sim.loop import SimConfig, Simulation, TickObserver
from pickplace.sim.recovery import check_attempts
from pickplace.sim.scenarios import BuildRequest, Scenario, get_scenario
from pickplace.sim.task import Task
from pickplace.sim.variation import apply_to_task, apply_world
from pickplace.sim.vary import ParameterDraw
from pickplace.sim.verdict import RunResult
from pickplace.world.objects import object_file, with_object
from pickplace.world.placements import BrickPlacement, check_brick_in_source_bin
from pickplace.world.scene import Scene, WorldFile, WorldNames, read_world

if TYPE_CHECKING:
    from pickplace.record.recording import Recorder

CONTROL_RATE_RANGE_HZ = (100.0, 1000.0)
# The physics timestep of a scene: at most one control period at the lowest rate, and not so
# small that a run takes millions of MuJoCo steps per simulated second [s].
MIN_TIMESTEP_S = 1e-5
# A rate within this relative distance of an allowed one (e.g. 166.667 for 500/3 Hz) means it.
RATE_TOLERANCE = 1e-5
BRICK_YAW_LIMIT_RAD = 2.0 * math.pi
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
        speed: Speed override in (0, 1]: the planner scales every speed limit by it and every
            acceleration limit by its square.
        parameters: Varied parameters drawn for this run's seed (:mod:`pickplace.sim.vary`),
            applied by :mod:`pickplace.sim.variation`; a drawn ``speed`` or ``control_rate``
            takes the place of :attr:`speed` or :attr:`control_rate_hz` (which must then be
            left at their defaults). Recorded as the summary's ``parameters``.
        object: The object to pick instead of the world's brick: a bundled object's name
            (:data:`~pickplace.world.objects.BUNDLED_OBJECTS`) or an MJCF file with one free
            body (``--object``), put where the brick lies (:func:`~pickplace.world.objects.
            with_object`); None or ``brick``: the world's own brick.
        attempts: Most attempts the run may take (1 to
            :data:`~pickplace.sim.recovery.MAX_ATTEMPTS`): after a missed grasp or a drop it
            stops the arm, waits for the brick to rest and plans again from there
            (:mod:`pickplace.sim.recovery`); 1 (the default): the first failure ends the run.
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
    speed: float = 1.0
    parameters: ParameterDraw | None = None
    attempts: int = 1
    object: str | None = None
    observers: Sequence[TickObserver] = field(default=(), compare=False)

    def recording_id(self, robot_name: str) -> str:
        """Recording id naming scenario, robot, controller and seed (a viewer merges the data
        of recordings with one id: runs that differ in any of these must not share one)."""
        return f"{self.scenario}/{robot_name}/{self.controller}/seed-{self.seed}"

    @property
    def run_speed(self) -> float:
        """The speed override the run uses: the drawn ``speed``, else :attr:`speed`."""
        drawn = self.parameters.get("speed") if self.parameters is not None else None
        return self.speed if drawn is None else drawn

    @property
    def run_attempts(self) -> int:
        """The most attempts the run takes: the drawn ``attempts``, else :attr:`attempts`."""
        drawn = self.parameters.get("attempts") if self.parameters is not None else None
        return self.attempts if drawn is None else int(drawn)

    @property
    def run_control_rate_hz(self) -> float:
        """The control rate [Hz] asked for: the drawn ``control_rate``, else
        :attr:`control_rate_hz`."""
        drawn = self.parameters.get("control_rate") if self.parameters is not None else None
        return self.control_rate_hz if drawn is None else drawn


_FILE_KINDS = {
    stat.S_IFIFO: "a FIFO",
    stat.S_IFCHR: "a character device",
    stat.S_IFBLK: "a block device",
    stat.S_IFSOCK: "a socket",
}


def validate_record_path(path: Path) -> Path:
    """Check that ``path`` can be written as a recording, without opening or creating it.

    A symbolic link is followed (the file it points at will be replaced). The folder is tried
    with an anonymous temporary file, because ``os.access`` says yes to root even on a
    read-only file system.

    Raises:
        InvalidInputError: Empty name, wrong suffix, a name longer than the file system allows,
            a directory, a FIFO or device, a read-only file, a missing or read-only folder, a
            symlink into a missing folder, or a lock file beside it that is a link or not a
            plain file (:func:`pickplace.outfile.lock_problem`).
    """
    name = path.name
    if name in ("", ".", ".."):
        raise InvalidInputError(
            f"recording file '{path}' names no file; give one ending in .rrd", field="record"
        )
    if name.lower() == ".rrd":
        raise InvalidInputError(
            f"recording file '{path}' has no name before .rrd; give e.g. run.rrd", field="record"
        )
    if path.suffix != ".rrd":
        raise InvalidInputError(
            f"recording file '{path}' must end in .rrd (e.g. run.rrd)", field="record"
        )
    limit = name_max(path.parent)
    if len(os.fsencode(name)) > limit:
        raise InvalidInputError(
            f"recording file name '{name[:40]}…' is {len(os.fsencode(name))} bytes long; this "
            f"file system allows at most {limit}",
            field="record",
        )
    target = path
    if path.is_symlink():
        target = Path(os.path.realpath(path))
        if not target.parent.is_dir():
            raise InvalidInputError(
                f"recording file '{path}' is a symbolic link to '{target}', whose folder does not "
                "exist; remove the link or give another file",
                field="record",
            )
    parent = target.parent
    if not parent.is_dir():
        raise InvalidInputError(
            f"recording file '{path}': folder '{parent}' does not exist", field="record"
        )
    problem = lock_problem(lock_path(target))
    if problem is not None:
        raise InvalidInputError(f"recording file '{path}': {problem}", field="record")
    if target.is_dir():
        raise InvalidInputError(
            f"recording file '{path}' is a directory; give a file name ending .rrd", field="record"
        )
    try:
        mode = target.stat().st_mode
    except OSError:
        mode = None
    if mode is not None and not stat.S_ISREG(mode):
        kind = _FILE_KINDS.get(stat.S_IFMT(mode), "not a regular file")
        raise InvalidInputError(
            f"recording file '{path}' is {kind}; give a regular file ending .rrd", field="record"
        )
    if mode is not None and not os.access(target, os.W_OK):
        raise InvalidInputError(
            f"recording file '{path}' is read-only; make it writable or give another file",
            field="record",
        )
    try:
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as exc:
        raise InvalidInputError(
            f"recording file '{path}': folder '{parent}' is not writable ({exc.strerror})",
            field="record",
        ) from None
    return path


def valid_control_rates(timestep_s: float) -> list[float]:
    """Control rates [Hz] in :data:`CONTROL_RATE_RANGE_HZ` that are a whole number of physics
    steps of ``timestep_s`` [s]: 1 / (n · timestep) for n = 1, 2, …, fastest first."""
    lo, hi = CONTROL_RATE_RANGE_HZ
    n = max(1, math.ceil(1.0 / (hi * timestep_s) - 1e-9))
    rates = []
    while (rate := 1.0 / (n * timestep_s)) >= lo * (1 - 1e-12):
        if rate <= hi * (1 + 1e-12):
            rates.append(rate)
        n += 1
    return rates


def check_timestep(scene_path: Path | None, timestep_s: float) -> None:
    """Raise InvalidInputError unless the scene's physics timestep is usable.

    It must be finite, at least :data:`MIN_TIMESTEP_S` and at most one control period at the
    lowest rate (1 / 100 Hz = 0.01 s).
    """
    lo_rate = CONTROL_RATE_RANGE_HZ[0]
    hi = 1.0 / lo_rate
    if not (math.isfinite(timestep_s) and MIN_TIMESTEP_S <= timestep_s <= hi):
        where = f"scene '{scene_path}'" if scene_path is not None else "the scene"
        raise InvalidInputError(
            f"{where} has physics timestep {timestep_s:g} s; it must be in "
            f"[{MIN_TIMESTEP_S:g}, {hi:g}] s (<option timestep=...>), so that a control tick "
            f"at {lo_rate:g} Hz is a whole number of steps"
        )


def resolve_control_rate(rate_hz: float, timestep_s: float) -> float:
    """The allowed rate [Hz] that ``rate_hz`` means for this timestep (exactly 1 / (n · dt)).

    Raises:
        InvalidInputError: No whole number of physics steps gives ``rate_hz``; the message lists
            the rates that do.
    """
    rates = valid_control_rates(timestep_s)
    for rate in rates:
        if abs(rate_hz - rate) <= RATE_TOLERANCE * rate:
            return rate
    lo, hi = CONTROL_RATE_RANGE_HZ
    if not rates:
        raise InvalidInputError(
            f"this scene's physics timestep {timestep_s:g} s allows no control rate in "
            f"[{lo:g}, {hi:g}] Hz",
            field="control_rate_hz",
        )
    shown = ", ".join(f"{r:.6g}" for r in rates[:8]) + (", …" if len(rates) > 8 else "")
    raise InvalidInputError(
        f"control rate {rate_hz:g} Hz is not a whole number of physics steps of "
        f"{timestep_s:g} s; valid rates in [{lo:g}, {hi:g}] Hz are {1 / timestep_s:.6g} Hz / n: "
        f"{shown}",
        field="control_rate_hz",
    )


@contextlib.contextmanager
def mujoco_warnings() -> Iterator[list[str]]:
    """Collect MuJoCo's warnings (C and Python) instead of printing them and writing
    ``MUJOCO_LOG.TXT`` in the working directory. Yields the list, filled on exit (distinct
    messages, in order; a C message is dropped when a Python one says the same and more)."""
    collected: list[str] = []
    c_messages: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(c_messages.append)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            yield collected
    finally:
        mujoco.set_mju_user_warning(previous)
    c_texts = [" ".join(m.split()) for m in c_messages]
    messages = []
    for w in caught:
        text = " ".join(str(w.message).split())
        if any(text.startswith(c) for c in c_texts):  # the bindings' copy of a C warning
            messages.append(text)
        else:  # not MuJoCo's: shown as it would have been
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)
    for m in messages + c_texts:
        if m and m not in collected and not any(c.startswith(m) for c in collected):
            collected.append(m)


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
        raise InvalidInputError(
            f"seed must be an integer in [0, {MAX_SEED}], got {req.seed!r}", field="seed"
        )
    check_speed(req.speed)
    check_attempts(req.attempts)
    lo, hi = CONTROL_RATE_RANGE_HZ
    if not (
        isinstance(req.control_rate_hz, int | float)
        and math.isfinite(req.control_rate_hz)
        and lo <= req.control_rate_hz <= hi
    ):
        raise InvalidInputError(
            f"control rate must be in [{lo:g}, {hi:g}] Hz, got {req.control_rate_hz!r}",
            field="control_rate_hz",
        )
    if req.pace is not None:
        lo, hi = PACE_RANGE
        if not (math.isfinite(req.pace) and lo <= req.pace <= hi):
            raise InvalidInputError(
                f"pace must be in [{lo:g}, {hi:g}] times real time, got {req.pace!r}",
                field="pace",
            )
    if req.brick is not None and not scenario.uses_brick:
        raise InvalidInputError(
            f"a brick pose does not apply to scenario '{scenario.name}' (it does not move the "
            "brick)",
            field="brick",
        )
    if req.brick is not None and not abs(req.brick.yaw) <= BRICK_YAW_LIMIT_RAD:
        raise InvalidInputError(
            f"brick yaw must be in [-2π, 2π] = [{-BRICK_YAW_LIMIT_RAD:.4f}, "
            f"{BRICK_YAW_LIMIT_RAD:.4f}] rad, got {req.brick.yaw:g}",
            field="brick",
        )
    if req.object is not None:
        object_file(req.object)
    if req.parameters is not None:
        _validate_parameters(req, req.parameters)
    if req.record is not None:
        validate_record_path(req.record)
    if req.connect is not None:
        parse_viewer_url(req.connect)
    return scenario


def _validate_parameters(req: RunRequest, draw: ParameterDraw) -> None:
    """The draw belongs to the run's seed, and sets speed or control rate only once."""
    if not isinstance(draw, ParameterDraw):
        raise InvalidInputError(f"parameters must be a ParameterDraw, got {type(draw).__name__}")
    if draw.seed != req.seed:
        raise InvalidInputError(
            f"the varied parameters were drawn for seed {draw.seed}, the run has seed "
            f"{req.seed}: draw them for the run's seed (VaryPlan.draw(seed))"
        )
    if "speed" in draw.values and req.speed != 1.0:
        raise InvalidInputError(
            "the speed is given and also varied; give one of them", field="speed"
        )
    if "attempts" in draw.values and req.attempts != 1:
        raise InvalidInputError(
            "the attempts are given and also varied; give one of them", field="attempts"
        )
    if "control_rate" in draw.values and req.control_rate_hz != 100.0:
        raise InvalidInputError(
            "the control rate is given and also varied; give one of them",
            field="control_rate_hz",
        )


def build_task(req: RunRequest | ResolvedRun, refuse_infeasible: bool = True) -> tuple[Scene, Task]:
    """Validate ``req``, load the scene and build the scenario's task (planning included).

    Raises:
        PickPlaceError: Any invalid input (see :func:`validate_request`), a bad world file or
            robot description (:class:`~pickplace.errors.RobotError`: the file, the field and
            what would be valid);
            a ``--brick`` pose outside bin 1, or one for which no candidate plan is feasible
            (field ``brick``: the message gives the first candidate's problem and what would
            help).
    """
    resolved = req if isinstance(req, ResolvedRun) else resolve_request(req)
    with mujoco_warnings() as scene_warnings:
        scene, task = _scene_and_task(resolved, refuse_infeasible)
    del scene_warnings  # (only a run reports them, as events)
    return scene, task


@dataclass(frozen=True)
class ResolvedRun:
    """A run request resolved once, at the edge, and passed down: nothing below parses a
    file or looks a name up again.

    Attributes:
        request: The request as given.
        scenario: Its scenario.
        world: The world file, read and parsed.
        robot: The robot's description, read and validated.
        control_rate_hz: The control rate [Hz]: a whole number of the world's physics steps.
        held: The object in the brick's place (:func:`object_world`), None for the brick.
    """

    request: RunRequest
    scenario: Scenario
    world: WorldFile
    robot: RobotDescription
    control_rate_hz: float
    held: HeldObject | None = None


def resolve_request(req: RunRequest) -> ResolvedRun:
    """Validate ``req`` and resolve what it names: the scenario, the world file (its
    timestep checked), the control rate against that timestep, and the robot's description.

    Raises:
        PickPlaceError: Any invalid input (see :func:`validate_request`), a bad world file or
            timestep, a control rate that is not a whole number of physics steps, or a bad
            robot description.
    """
    scenario = validate_request(req)
    # The world's timestep first: the robot is composed and calibrated at it.
    world = read_world(req.scene_path)
    check_timestep(req.scene_path, world.timestep)
    world, held = object_world(world, req.object)
    drawn = req.parameters is not None and req.parameters.get("control_rate") is not None
    try:
        rate = resolve_control_rate(req.run_control_rate_hz, world.timestep)
    except InvalidInputError as exc:
        if not drawn:
            raise
        raise varied_rate_error(req.run_control_rate_hz, exc) from None
    return ResolvedRun(req, scenario, world, resolve_description(req.robot), rate, held)


def object_world(world: WorldFile, name: str | None) -> tuple[WorldFile, HeldObject | None]:
    """The world with the object ``name`` (``--object``: a bundled name or an MJCF file) in
    its brick's place, and what the robot's composition must know of it; ``world`` itself
    and None for no object or ``brick``. The gripper stays calibrated on the world's brick
    box; the world file's content, extended by the object file's, keys the scene cache.

    Raises:
        ObjectError: The object file is missing, unreadable, not one free body with
            collision geoms (the message says what would be valid).
        UnknownNameError: The world has no brick geom to calibrate the gripper on.
    """
    path = object_file(name) if name is not None else None
    if path is None:
        return world, None
    names = WorldNames()
    brick = world.spec.geom(names.brick_geom)
    if brick is None:  # the gripper is calibrated on the brick's size
        geoms = [g.name for g in world.spec.geoms if g.name]
        raise UnknownNameError("geom", names.brick_geom, geoms)
    held = HeldObject(
        names.brick_body,
        np.array(brick.size, dtype=np.float64),
        np.array(brick.friction, dtype=np.float64),
    )
    spec = with_object(world.spec, names.brick_body, path)
    content = world.content + b"\0--object\0" + str(path).encode() + b"\0" + path.read_bytes()
    return WorldFile(world.path, content, spec), held


def varied_rate_error(rate_hz: float, exc: InvalidInputError) -> InvalidInputError:
    """``exc`` (:func:`resolve_control_rate`'s) about a control rate that ``--vary`` gave:
    named as that option, not as the control rate's own."""
    return InvalidInputError(f"--vary control_rate={rate_hz:g}: {exc}")


def _scene_and_task(run: ResolvedRun, refuse_infeasible: bool) -> tuple[Scene, Task]:
    """The scene and the scenario's task of a resolved request; see :func:`build_task`."""
    try:
        return _scene_and_task_of(run, refuse_infeasible)
    except ObjectError as exc:
        if run.held is not None:
            raise
        # The world's own brick (no --object): the world file's problem.
        raise SceneError(f"scene file '{run.world.path}': {exc}") from None


def _scene_and_task_of(run: ResolvedRun, refuse_infeasible: bool) -> tuple[Scene, Task]:
    req, scenario = run.request, run.scenario
    scene = load_scene(run.world, run.robot, held=run.held)
    # Before planning: the planner must know the obstacles and the brick.
    cell = scenario.world(scene, req.seed) if scenario.world is not None else None
    if req.parameters is not None or cell is not None:
        scene = apply_world(scene, req.parameters, cell)
    if req.brick is not None:
        check_brick_in_source_bin(scene, req.brick)
    task = scenario.build(
        BuildRequest(
            scene,
            scenario.name,
            req.seed,
            req.brick,
            controller=req.controller,
            timing=TimingConfig(speed=req.run_speed),
            attempts=req.run_attempts,
        )
    )
    if req.parameters is not None:  # after planning: what the plan must not know
        task = apply_to_task(scene, task, req.parameters)
    planning = task.planning
    infeasible = planning is not None and not planning.feasible
    if refuse_infeasible and req.brick is not None and planning is not None and infeasible:
        first = planning.candidates[0]
        problem = first.preflight.problem
        why = f"at t={problem.t:.2f} s {problem.text}" if problem else "infeasible"
        b = req.brick
        raise InvalidInputError(
            f"no feasible plan picks the brick at x={b.x:g} m, y={b.y:g} m, yaw={b.yaw:g} rad: "
            f"{len(planning.candidates)} of {planning.ranked} candidates pre-flighted, the best "
            f"({first.label}) {why}, and no push frees it from the walls; "
            f"move it inwards or turn it (pickplace plan --brick={b.x:g},{b.y:g},{b.yaw:g} "
            "lists every candidate)",
            field="brick",
        )
    return scene, task


def plan_report(req: RunRequest | ResolvedRun) -> PlanningReport:
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
    controller = req.request.controller if isinstance(req, ResolvedRun) else req.controller
    result = Preflight(scene, controller).run(task.plan, task.X_WO_start, task.goal.X_WO_goal)
    candidate = Candidate("the scenario's plan (executed without a pre-flight)", task.plan, result)
    chosen = 0 if result.feasible else None
    return PlanningReport((candidate,), chosen, time.perf_counter() - t0, PreflightConfig())


def prepare(req: RunRequest) -> tuple[Scene, Task, Simulation]:
    """Validate ``req`` and build the simulation (nothing stepped yet, no output opened: a
    recorder among the observers opens its outputs when the run starts).

    MuJoCo's warnings while composing and compiling the scene become ``mujoco-warning``
    events at tick 0 instead of lines on stderr.

    Raises:
        PickPlaceError: Any invalid input (see :func:`validate_request`), a bad scene file or
            timestep, a control rate that is not a whole number of physics steps, or an
            unreachable brick pose.
    """
    scene, task, sim, _ = _build(req)
    return scene, task, sim


def _build(req: RunRequest) -> tuple[Scene, Task, Simulation, Recorder | None]:
    """:func:`prepare`, also returning the recorder it added (or None)."""
    resolved = resolve_request(req)
    rate = resolved.control_rate_hz
    with mujoco_warnings() as scene_warnings:
        scene, task = _scene_and_task(resolved, refuse_infeasible=True)
        config = SimConfig(control_rate_hz=rate)
        controller = make_controller(req.controller, scene, 1.0 / rate)
    observers: list[TickObserver] = list(req.observers)
    if req.pace is not None:
        observers.append(Pacer(req.pace))
    recorder = None
    if req.record is not None or req.spawn or req.connect is not None:
        from pickplace.record.recording import Recorder  # rerun is imported only when recording

        recorder = Recorder(
            req.record,
            recording_id=req.recording_id(scene.robot.name),
            spawn=req.spawn,
            connect=req.connect,
        )
        observers.append(recorder)
    sim = Simulation(scene, task, controller, config, observers)
    for text in scene_warnings:
        sim.emit(EventKind.MUJOCO_WARNING, f"MuJoCo: {text}", level="warn", tick=0)
    return scene, task, sim, recorder


@dataclass
class RunOutcome:
    """A finished run and what happened to its outputs.

    Attributes:
        result: The run's result; ``result.recording`` is the file written, or None.
        output_error: Why the recording file could not be written (an older file at the path
            is unchanged), or None. The CLI exits with code 3 when it is set.
        warnings: Viewer problems; the run went on (e.g. a viewer that stopped answering).
    """

    result: RunResult
    output_error: str | None = None
    warnings: list[str] = field(default_factory=list)


def execute(req: RunRequest) -> RunOutcome:
    """Validate, build and run one simulation; report its outputs.

    Raises:
        PickPlaceError: Invalid input (nothing was opened or written).
        OutputError: The recording path is being written by another run, or a viewer did not
            answer (nothing was written).
    """
    _, _, sim, recorder = _build(req)
    try:
        if recorder is not None:
            recorder.open()
        result = sim.run()
    finally:
        if recorder is not None:
            recorder.close()  # after a finished run: nothing to do; else nothing is kept
    result.recording = None
    if recorder is None:
        return RunOutcome(result)
    if recorder.written is not None:
        result.recording = str(recorder.written)
    return RunOutcome(result, recorder.file_error, list(recorder.warnings))


def run(req: RunRequest) -> RunResult:
    """Validate, build and run one simulation (see :func:`execute` for the outputs)."""
    return execute(req).result


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


__all__ = [
    "ResolvedRun",
    "RunOutcome",
    "RunRequest",
    "build_task",
    "execute",
    "plan_report",
    "prepare",
    "resolve_control_rate",
    "resolve_request",
    "run",
    "valid_control_rates",
    "validate_record_path",
    "varied_rate_error",
]
