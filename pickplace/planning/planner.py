"""Plans the robot can execute: pick-and-place candidates, each pre-flighted, in a stated order.

The planner makes the candidates of a pick from ``X_WO_pick`` and a place at ``X_WO_place`` and
pre-flights each one with the run's own controller (:mod:`pickplace.planning.preflight`), in this
order,
taking the first that is feasible:

1. "across the width": the top-down grasp closing across the brick's width whose yaw is
   nearest the tool's (carried along by the base swing) — the grasp every plan used before
   candidates existed;
2. "across the width, turned 180°": its symmetric twin about the brick's vertical axis;
3. "across the length": turned 90°, closing across the brick's length, the nearer yaw of the
   two — only when the open fingers clear the brick's length by the pre-flight clearance on
   each side;
4. "across the length, turned 180°".

Every candidate's clearance via-point turns with the base swing (``via="swing"``, see
:func:`pickplace.planning.plan.plan_pick_place`). Measured on bin 1 (``planning-failures.md``): the
180° twin rescues only wrist cases, the 90° grasp every wall case; the swing via-point every
wrist case. If none is feasible the report says so, with each candidate's first problem.

A brick that the grip cannot hold even at rest within the timing's slip budget (too heavy,
too little friction or grip force: :class:`~pickplace.planning.timing.GripTooWeakError`) is still
planned, timed within the friction alone or else the robot's limits alone, with a warning on
the candidate: the physics, not the planner, then shows whether it is held or dropped.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from mink.lie import SE3, SO3

from pickplace.control.kinematics import ArmKinematics
from pickplace.planning.grasp import brick_width_across, top_down_grasps, yaw_of
from pickplace.planning.plan import Plan, PlanConfig, for_gripper, plan_pick_place, swung_pose
from pickplace.planning.preflight import Preflight, PreflightConfig, PreflightResult
from pickplace.planning.timing import GripTooWeakError, SegmentLimits, TimingConfig, retime
from pickplace.signals import stop_point
from pickplace.world.scene import Scene

# Clearance of the via-point above the higher bin wall: brick height hanging below the tool
# (0.025 m half-height) plus 0.1 m of air [m].
CLEARANCE_ABOVE_WALLS = 0.125
# The path sweep's spacing: at most this much tool travel [m] or turn [rad] between two
# pre-flight ticks (for the collision checks and the joint path the timing works on).
PATH_SPACING = 0.02
PATH_ANGLE = 0.1


@dataclass(frozen=True)
class Candidate:
    """One plan tried, and what its pre-flight found.

    Attributes:
        label: How the candidate differs from the others, e.g. ``"across the length"``.
        plan: The plan.
        preflight: Its pre-flight result.
        warning: What the timing could not honour (the slip budget of a brick too heavy for
            the grip), or None.
    """

    label: str
    plan: Plan
    preflight: PreflightResult
    warning: str | None = None

    def as_dict(self) -> dict[str, Any]:
        """JSON form: label, feasible, the first problem, how far the plan was checked and the
        timing's warning."""
        p = self.preflight
        return {
            "label": self.label,
            "feasible": p.feasible,
            "problem": None if p.problem is None else p.problem.as_dict(),
            "checked_until_s": p.t_checked,
            "warning": self.warning,
        }


@dataclass(frozen=True)
class PlanningReport:
    """The candidates tried, in order, and the one chosen.

    Attributes:
        candidates: Every candidate tried, in the planner's order.
        chosen: Index of the chosen (first feasible) candidate, or None.
        planning_time_s: Wall time spent planning and pre-flighting [s].
        config: The pre-flight's rate and thresholds.
    """

    candidates: tuple[Candidate, ...]
    chosen: int | None
    planning_time_s: float
    config: PreflightConfig

    @property
    def feasible(self) -> bool:
        """True if a candidate is feasible."""
        return self.chosen is not None

    @property
    def plan(self) -> Plan:
        """The chosen plan, or (when none is feasible) the first candidate's."""
        return self.candidates[0 if self.chosen is None else self.chosen].plan

    def problems(self) -> str:
        """Each candidate's first problem, one clause each."""
        return "; ".join(
            f"{c.label}: t={c.preflight.problem.t:.2f} s {c.preflight.problem.text}"
            for c in self.candidates
            if c.preflight.problem is not None
        )

    def as_dict(self) -> dict[str, Any]:
        """JSON form (everything but the planning time, which measures the wall clock)."""
        chosen = None if self.chosen is None else self.candidates[self.chosen]
        cfg = self.config
        return {
            "feasible": self.feasible,
            "chosen": None if chosen is None else chosen.label,
            "candidates": [c.as_dict() for c in self.candidates],
            "margins": None if chosen is None else chosen.preflight.margins(),
            "keyframes": [
                {
                    "name": k.name,
                    "t": k.t,
                    "position": k.X_WG.translation().tolist(),
                    "quaternion_wxyz": k.X_WG.rotation().wxyz.tolist(),
                    "gripper_width": k.gripper_width,
                }
                for k in self.plan.trajectory.keyframes
            ],
            "preflight": {
                "rate_hz": cfg.rate_hz,
                "clearance_m": cfg.clearance,
                "joint_margin_rad": cfg.joint_margin,
                "tracking_tolerance_m": cfg.tracking_tolerance,
                "min_singular_value": cfg.min_singular_value,
            },
        }


class PickPlacePlanner:
    """Makes and pre-flights pick-and-place candidates (see the module docstring).

    Args:
        scene: The scene (bins, brick, arm, gripper).
        controller: Name of the run's controller, which the pre-flight runs.
        config: Planning limits and parameters; the open width is capped at the gripper's
            (:func:`~pickplace.planning.plan.for_gripper`).
        preflight: Pre-flight rate and thresholds.
    """

    def __init__(
        self,
        scene: Scene,
        controller: str,
        config: PlanConfig | None = None,
        preflight: PreflightConfig | None = None,
        timing: TimingConfig | None = None,
    ) -> None:
        self.scene = scene
        self.config = for_gripper(config or PlanConfig(), scene.robot.calibration)
        self.timing = timing or TimingConfig()
        self.preflight = Preflight(scene, controller, preflight)
        dt = self.preflight.dt
        # The path sweep: the same waypoints at constant speed, a pre-flight tick every
        # PATH_SPACING of tool travel (or PATH_ANGLE of turn), every keyframe on a tick.
        self.sweep_config = replace(
            self.config,
            profile="linear",
            max_linear_speed=PATH_SPACING / dt,
            max_angular_speed=PATH_ANGLE / dt,
            min_segment_duration=2 * dt,
            time_quantum=dt,
        )
        pads = np.concatenate(scene.robot.pad_geom_ids)
        mu = float(scene.model.geom_friction[pads, 0].min())  # the pads have contact priority
        # |a − g| the pads' friction holds on the brick: μ · 2 sides · squeeze force / mass.
        self.slip_accel = mu * 2.0 * scene.robot.squeeze_force / scene.brick_mass
        kin = ArmKinematics(scene)
        kin.update(scene.robot.q_home)
        self.X_WG_home = kin.X_WG()
        src, dst = scene.source_bin, scene.target_bin
        self.clearance_z = max(src.wall_top_z, dst.wall_top_z) + CLEARANCE_ABOVE_WALLS

    def plan(self, X_WO_pick: SE3, X_WO_place: SE3, first_feasible: bool = True) -> PlanningReport:
        """Try the candidates in order; stop at the first feasible one (unless told not to).

        Args:
            X_WO_pick: Brick pose to pick, in world.
            X_WO_place: Goal pose of the brick, in world.
            first_feasible: Stop at the first feasible candidate (else try them all).
        """
        t0 = time.perf_counter()
        tried: list[Candidate] = []
        chosen: int | None = None
        for label, X_OG in self.grasps(X_WO_pick):
            stop_point()  # a long planning may be cut by a stop request (pickplace.signals)
            plan, result, warning = self.timed_plan(X_WO_pick, X_WO_place, X_OG)
            tried.append(Candidate(label, plan, result, warning))
            if result.feasible and chosen is None:
                chosen = len(tried) - 1
                if first_feasible:
                    break
        return PlanningReport(tuple(tried), chosen, time.perf_counter() - t0, self.preflight.config)

    def timed_plan(
        self, X_WO_pick: SE3, X_WO_place: SE3, X_OG: SE3
    ) -> tuple[Plan, PreflightResult, str | None]:
        """One candidate: the path swept by the pre-flight, then (if it passes) timed by the
        robot's limits and pre-flighted again as timed.

        Returns:
            The timed plan, its pre-flight and the timing's warning (None if the slip budget
            held); or, when the path sweep fails, the swept plan, the sweep's result (its first
            problem is on the path, whatever the timing) and None.
        """
        path = self.make_plan(X_WO_pick, X_WO_place, X_OG, self.sweep_config)
        swept = self.preflight.run(path, X_WO_pick, X_WO_place)
        if not swept.feasible:
            return path, swept, None
        timed, warning = self.retimed(path, swept.times, swept.q)
        result = self.preflight.run(timed, X_WO_pick, X_WO_place)
        return timed, result, warning

    def retimed(self, path: Plan, times: np.ndarray, q: np.ndarray) -> tuple[Plan, str | None]:
        """The swept path timed by the robot's limits and, while carrying, the slip budget.

        A brick the budget cannot hold even at rest (too heavy, too little friction or grip:
        :class:`~pickplace.planning.timing.GripTooWeakError`) is still carried, so that the physics
        shows what happens: first within the friction itself (no safety factor), and if even
        that cannot hold it, within the robot's limits alone. The warning says which.
        """

        def timed_within(timing: TimingConfig, slip: float | None) -> Plan:
            def limits(carried: bool) -> SegmentLimits:
                return timing.limits(
                    self.scene.robot.v_max, self.scene.robot.a_max, slip if carried else None
                )

            return retime(path, times, q, limits)

        try:
            return timed_within(self.timing, self.slip_accel), None
        except GripTooWeakError as exc:
            problem = str(exc)
        try:
            timed = timed_within(replace(self.timing, slip_safety_factor=1.0), self.slip_accel)
            how = "within the friction itself, without the slip safety factor"
        except GripTooWeakError:
            timed = timed_within(self.timing, None)
            how = "within the robot's limits alone: expect the brick to slip or drop"
        return timed, f"{problem}; the plan is timed {how}"

    def make_plan(
        self,
        X_WO_pick: SE3,
        X_WO_place: SE3,
        X_OG: SE3 | None = None,
        config: PlanConfig | None = None,
    ) -> Plan:
        """The pick-and-place plan with grasp ``X_OG`` (default: the nearest-yaw grasp), timed
        by Cartesian limits (``config``, default the planner's)."""
        return plan_pick_place(
            self.X_WG_home,
            X_WO_pick,
            X_WO_place,
            self.clearance_z,
            config or self.config,
            p_W_base=self.scene.robot.p_W_base,
            X_OG=X_OG,
        )

    def grasps(self, X_WO_pick: SE3) -> Iterator[tuple[str, SE3]]:
        """The candidate grasps X_OG in the planner's order, labelled by their turn."""
        reference = swung_pose(self.X_WG_home, X_WO_pick.translation(), self.scene.robot.p_W_base)
        yaw = yaw_of(reference.rotation())

        def yaw_change(X_OG: SE3) -> float:
            return abs(math.remainder(yaw_of((X_WO_pick @ X_OG).rotation()) - yaw, 2 * math.pi))

        first, twin = top_down_grasps()
        if yaw_change(twin) < yaw_change(first):
            first, twin = twin, first
        yield "across the width", first
        yield "across the width, turned 180°", twin
        quarter = SE3.from_rotation(SO3.from_z_radians(0.5 * math.pi))
        turned, turned_twin = quarter @ first, quarter.inverse() @ first
        if yaw_change(turned_twin) < yaw_change(turned):
            turned, turned_twin = turned_twin, turned
        width = brick_width_across(turned, self.scene.brick_half_extents)
        if self.config.open_width >= width + 2.0 * self.preflight.config.clearance:
            yield "across the length", turned
            yield "across the length, turned 180°", turned_twin
