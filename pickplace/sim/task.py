"""A task: what one run must do (the plan, the brick's start, the goal), the faults it meets and
what it does after a failure (its recovery).

Scenarios (:mod:`pickplace.sim.scenarios`) build tasks; the loop (:mod:`pickplace.sim.loop`) runs
them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import mujoco
import numpy as np
from mink.lie import SE3

from pickplace.planning.plan import Plan
from pickplace.planning.planner import PlanningReport
from pickplace.planning.trajectory import PoseTrajectory
from pickplace.sim.checks import Failure, SuccessCriteria
from pickplace.sim.events import EventKind
from pickplace.sim.goals import Goal
from pickplace.world.scene import Scene

if TYPE_CHECKING:
    from pickplace.sim.ticklog import TickLog
    from pickplace.sim.verdict import Attempt


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


class RunControl(World, Protocol):
    """The run as a recovery sees it: the world, the log up to the last assessed tick, the
    commanded configuration, and the one thing it may do: replace the plan being executed."""

    @property
    def scene(self) -> Scene:
        """The scene being simulated."""

    @property
    def log(self) -> TickLog:
        """The run's tick log (rows up to :attr:`ticks` are complete)."""

    @property
    def ticks(self) -> int:
        """Ticks simulated and assessed so far; the next one to be commanded."""

    @property
    def criteria(self) -> SuccessCriteria:
        """Thresholds of the verdict (e.g. when the brick is at rest)."""

    @property
    def q_cmd(self) -> np.ndarray:
        """The arm's commanded configuration after the last simulated tick [rad]."""

    @property
    def plan_start(self) -> float:
        """Run time at which the plan being executed started [s] (its clock reads 0)."""

    def replace_plan(self, plan: Plan, t_start: float, text: str) -> None:
        """Execute ``plan`` from the next tick on, its clock reading 0 at run time
        ``t_start`` [s] (see :meth:`pickplace.sim.loop.Simulation.replace_plan`)."""

    def emit(
        self, kind: EventKind, text: str, level: str = "info", tick: int | None = None
    ) -> None:
        """Record an event (default: at the next tick)."""


class Recovery(Protocol):
    """What a task does about the failures its goal's checks find: let them end the run, or
    take them up and try again on a new plan (:mod:`pickplace.sim.recovery`).

    The loop asks it after every assessed block, and it alone decides when to replan; the loop
    only executes the plans it puts in place (:meth:`RunControl.replace_plan`). With no
    recovery, or one that takes nothing up, a run is the same as without.
    """

    def take_up(self, run: RunControl, failures: Sequence[Failure]) -> bool:
        """The block's failures (each check's first, earliest first): True if the recovery
        takes them up (they are not the run's; the run goes on, on a plan the recovery has put
        in place), False if the first of them ends the run as usual."""

    def next_decision_time(self, run: RunControl) -> float | None:
        """The next run time [s] after whose tick the recovery wants the block to end, so that
        it can act at once (e.g. when the grasp is judged), or None."""

    def after_block(self, run: RunControl) -> Failure | None:
        """After every assessed block while no failure ended the run: may replace the plan;
        returns a failure that ends the run now (e.g. a failure taken up that cannot be
        recovered after all), or None."""

    def attempts(self) -> list[Attempt]:
        """The run's attempts so far, in order (the summary's ``attempts``)."""


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
        recovery: What the run does after a failure (e.g. plan again from where the brick
            lies, :class:`~pickplace.sim.recovery.Reattempt`); None: every failure ends it.
    """

    scenario: str
    seed: int
    goal: Goal
    plan: Plan
    X_WO_start: SE3
    faults: Sequence[Fault] = ()
    planning: PlanningReport | None = None
    parameters: dict[str, Any] | None = None
    recovery: Recovery | None = None

    @property
    def trajectory(self) -> PoseTrajectory:
        """The plan's tool trajectory."""
        return self.plan.trajectory
