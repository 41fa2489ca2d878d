"""A task: what one run must do (the plan, the brick's start, the goal) and the faults it meets.

Scenarios (:mod:`pickplace.sim.scenarios`) build tasks; the loop (:mod:`pickplace.sim.loop`) runs
them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import mujoco
from mink.lie import SE3

from pickplace.planning.plan import Plan
from pickplace.planning.planner import PlanningReport
from pickplace.planning.trajectory import PoseTrajectory
from pickplace.sim.goals import Goal


class World(Protocol):
    """The simulated world as a fault sees it: the model and data it may change, the control
    period and the plan being executed (to time its act by the plan's phases)."""

    @property
    def model(self) -> mujoco.MjModel:
        """The compiled model (a fault may change it, e.g. a mass)."""

    @property
    def data(self) -> mujoco.MjData:
        """The simulation state (a fault may change it, e.g. move the brick)."""

    @property
    def dt(self) -> float:
        """Control period [s]."""

    @property
    def plan(self) -> Plan:
        """The plan being executed."""


class Fault(Protocol):
    """A disturbance injected by a scenario (see :mod:`pickplace.sim.faults`).

    A fault acts on the simulated world, never on the controller: the commands of a block of
    ticks are computed before its physics.
    """

    name: str

    def apply(self, world: World, tick: int) -> str | None:
        """Act on the world before the physics of tick ``tick``; return an event text when it
        acted."""


@dataclass
class Task:
    """What one run must do.

    Attributes:
        scenario: Scenario name.
        seed: Seed the task was drawn with.
        goal: What must be achieved (:class:`~pickplace.sim.goals.PlaceGoal` or
            :class:`~pickplace.sim.goals.ReachGoal`).
        plan: The plan to execute (trajectory and phases).
        X_WO_start: Brick pose at the start (the plan's belief about the world).
        faults: Disturbances injected during the run.
        planning: The candidates the planner pre-flighted and the one chosen (``plan`` is
            that one); None for a plan executed without a pre-flight. When no candidate is
            feasible the run ends before any physics (failure ``no-feasible-plan``).
        parameters: The varied parameters the task was built with (JSON form, see
            :mod:`pickplace.sim.variation`), reported in the run's summary; None when nothing
            was varied.
    """

    scenario: str
    seed: int
    goal: Goal
    plan: Plan
    X_WO_start: SE3
    faults: Sequence[Fault] = ()
    planning: PlanningReport | None = None
    parameters: dict[str, Any] | None = None

    @property
    def trajectory(self) -> PoseTrajectory:
        """The plan's tool trajectory."""
        return self.plan.trajectory
