"""pickplace: an arm with a gripper, described in a robot file, picks a red brick from one bin
and places it in another.

The public API, importable from here (``from pickplace import RunRequest, run``); each name is
imported from its module on first use, so that ``import pickplace`` (and the CLI's ``--help``)
loads nothing heavy. The layers below it are documented in ``docs/architecture.md``.
``pickplace.run`` is the package of one run's request; the function that runs one is
:func:`pickplace.run.runner.run` (or :func:`execute`, exported here, with its outputs).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

_API: dict[str, str] = {
    # errors
    "PickPlaceError": "pickplace.errors",
    "InvalidInputError": "pickplace.errors",
    "UnknownNameError": "pickplace.errors",
    "RobotError": "pickplace.errors",
    "SceneError": "pickplace.errors",
    "OutputError": "pickplace.errors",
    # the robot
    "RobotDescription": "pickplace.robot.description",
    "Robot": "pickplace.robot.model",
    "load_robot": "pickplace.robot.compose",
    "bundled_robots": "pickplace.robot.registry",
    "resolve_description": "pickplace.robot.registry",
    "DEFAULT_ROBOT": "pickplace.robot.registry",
    "DEFAULT_WORLD": "pickplace.robot.registry",
    # the world
    "Scene": "pickplace.world.scene",
    "WorldNames": "pickplace.world.scene",
    "read_world": "pickplace.world.scene",
    "BrickPlacement": "pickplace.world.placements",
    # control
    "CONTROLLERS": "pickplace.control.controllers",
    "make_controller": "pickplace.control.controllers",
    # planning
    "PickPlacePlanner": "pickplace.planning.planner",
    "PlanningReport": "pickplace.planning.planner",
    "Plan": "pickplace.planning.plan",
    "PlanConfig": "pickplace.planning.plan",
    "TimingConfig": "pickplace.planning.timing",
    "Preflight": "pickplace.planning.preflight",
    # one task simulated
    "load_scene": "pickplace.sim.loader",
    "SCENARIOS": "pickplace.sim.scenarios",
    "get_scenario": "pickplace.sim.scenarios",
    "Simulation": "pickplace.sim.loop",
    "SimConfig": "pickplace.sim.loop",
    "Task": "pickplace.sim.task",
    "RunResult": "pickplace.sim.verdict",
    "Event": "pickplace.sim.events",
    "EventKind": "pickplace.sim.events",
    "FailureReason": "pickplace.sim.checks",
    "FAILURE_REASONS": "pickplace.sim.checks",
    "SuccessCriteria": "pickplace.sim.checks",
    "parse_vary": "pickplace.sim.vary",
    # recording
    "Recorder": "pickplace.record.recording",
    # one run
    "RunRequest": "pickplace.run.runner",
    "ResolvedRun": "pickplace.run.runner",
    "resolve_request": "pickplace.run.runner",
    "execute": "pickplace.run.runner",
    "plan_report": "pickplace.run.runner",
    # sweeps
    "SweepRequest": "pickplace.sweep.sweep",
    "run_sweep": "pickplace.sweep.sweep",
    "report_text": "pickplace.sweep.report",
}

__all__ = [
    "CONTROLLERS",
    "DEFAULT_ROBOT",
    "DEFAULT_WORLD",
    "FAILURE_REASONS",
    "SCENARIOS",
    "BrickPlacement",
    "Event",
    "EventKind",
    "FailureReason",
    "InvalidInputError",
    "OutputError",
    "PickPlaceError",
    "PickPlacePlanner",
    "Plan",
    "PlanConfig",
    "PlanningReport",
    "Preflight",
    "Recorder",
    "ResolvedRun",
    "Robot",
    "RobotDescription",
    "RobotError",
    "RunRequest",
    "RunResult",
    "Scene",
    "SceneError",
    "SimConfig",
    "Simulation",
    "SuccessCriteria",
    "SweepRequest",
    "Task",
    "TimingConfig",
    "UnknownNameError",
    "WorldNames",
    "__version__",
    "bundled_robots",
    "execute",
    "get_scenario",
    "load_robot",
    "load_scene",
    "make_controller",
    "parse_vary",
    "plan_report",
    "read_world",
    "report_text",
    "resolve_description",
    "resolve_request",
    "run_sweep",
]


def __getattr__(name: str) -> Any:
    """Import a public name from its module on first use (PEP 562)."""
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'pickplace' has no attribute '{name}'")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)


if TYPE_CHECKING:  # what type checkers and editors see
    from pickplace.control.controllers import CONTROLLERS, make_controller
    from pickplace.errors import (
        InvalidInputError,
        OutputError,
        PickPlaceError,
        RobotError,
        SceneError,
        UnknownNameError,
    )
    from pickplace.planning.plan import Plan, PlanConfig
    from pickplace.planning.planner import PickPlacePlanner, PlanningReport
    from pickplace.planning.preflight import Preflight
    from pickplace.planning.timing import TimingConfig
    from pickplace.record.recording import Recorder
    from pickplace.robot.compose import load_robot
    from pickplace.robot.description import RobotDescription
    from pickplace.robot.model import Robot
    from pickplace.robot.registry import (
        DEFAULT_ROBOT,
        DEFAULT_WORLD,
        bundled_robots,
        resolve_description,
    )
    from pickplace.run.runner import (
        ResolvedRun,
        RunRequest,
        execute,
        plan_report,
        resolve_request,
    )
    from pickplace.sim.checks import FAILURE_REASONS, FailureReason, SuccessCriteria
    from pickplace.sim.events import Event, EventKind
    from pickplace.sim.loader import load_scene
    from pickplace.sim.loop import SimConfig, Simulation
    from pickplace.sim.scenarios import SCENARIOS, get_scenario
    from pickplace.sim.task import Task
    from pickplace.sim.vary import parse_vary
    from pickplace.sim.verdict import RunResult
    from pickplace.sweep.report import report_text
    from pickplace.sweep.sweep import SweepRequest, run_sweep
    from pickplace.world.placements import BrickPlacement
    from pickplace.world.scene import Scene, WorldNames, read_world
