"""Goals: what a run must achieve, as the checks that judge it and a final verdict.

A goal owns its list of checks (:mod:`pickplace.sim.checks`; the order is their precedence within a
tick) and judges the end state. The loop knows neither grasps nor bins: it asks the goal.

- :class:`PlaceGoal`: put the brick at a goal pose inside a bin. Judged by the limit checks, the
  grasp monitor and, at the end, the brick's placement in the bin.
- :class:`ReachGoal`: track the tool path within the joint limits (nothing is carried; the tool
  may fall behind a path it cannot follow, e.g. beyond the arm's reach).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import mujoco
from mink.lie import SE3

from pickplace.planning.plan import grasp_width
from pickplace.sim import checks as _checks
from pickplace.sim.checks import Check, CheckContext, Failure, FailureReason, SuccessCriteria
from pickplace.sim.verdict import brick_at_rest, placement_problems
from pickplace.world.scene import BinGeometry, Scene


class Goal(ABC):
    """What a run must achieve; see the module docstring."""

    name: ClassVar[str]

    @abstractmethod
    def checks(self, ctx: CheckContext) -> list[Check]:
        """New checks for one run, in order of precedence."""

    @property
    def X_WO_goal(self) -> SE3 | None:
        """Goal pose of the brick, if the goal places it."""
        return None

    def settled(self, scene: Scene, data: mujoco.MjData, criteria: SuccessCriteria) -> bool:
        """After the plan has ended: is there nothing left to wait for? (The brick at rest.)"""
        return brick_at_rest(scene, data, criteria)

    def final_failure(self, ctx: CheckContext, data: mujoco.MjData, tick: int) -> Failure | None:
        """The verdict on the end state at ``tick``, when no check failed during the run."""
        return None


class PlaceGoal(Goal):
    """Bring the brick to ``X_WO_goal`` and leave it resting inside ``bin_``.

    Args:
        X_WO_goal: Goal pose of the brick in world.
        bin_: The bin it must end in (its inner walls and floor judge the placement).
    """

    name = "place"

    def __init__(self, X_WO_goal: SE3, bin_: BinGeometry) -> None:
        self._X_WO_goal = X_WO_goal
        self.bin = bin_

    @property
    def X_WO_goal(self) -> SE3:
        """Goal pose of the brick in world."""
        return self._X_WO_goal

    def checks(self, ctx: CheckContext) -> list[Check]:
        """:data:`~pickplace.sim.checks.PLACE_CHECKS`: non-finite state, no QP solution, tracking,
        speed and position limits, the grasp monitor."""
        return [check(ctx) for check in _checks.PLACE_CHECKS]

    def final_failure(self, ctx: CheckContext, data: mujoco.MjData, tick: int) -> Failure | None:
        """not-in-target-bin, listing every placement problem, unless the brick rests there."""
        width = grasp_width(ctx.plan, ctx.scene)
        problems = placement_problems(ctx.scene, data, self.bin, ctx.criteria, width)
        if not problems:
            return None
        return Failure(tick, FailureReason.NOT_IN_TARGET_BIN, "; ".join(problems))


class ReachGoal(Goal):
    """Follow the tool path within the joints' position and speed limits."""

    name = "reach"

    def checks(self, ctx: CheckContext) -> list[Check]:
        """:data:`~pickplace.sim.checks.REACH_CHECKS`: non-finite state, no QP solution, speed and
        position limits."""
        return [check(ctx) for check in _checks.REACH_CHECKS]
