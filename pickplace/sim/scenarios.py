"""Named scenarios: each builds a :class:`~pickplace.sim.task.Task` from a scene and a seed.

``pickplace scenarios`` lists them; ``pickplace run --scenario NAME`` runs one; the pytest suite
runs every scenario and checks its documented outcome (:attr:`Scenario.expected`).

To add a scenario: a row in :data:`~pickplace.sim.catalog.CATALOG` (its summary and expected
outcome per controller), a builder function here in :data:`BUILDERS`, and its row in the
scenario tables of README.md and docs/scenarios.md (``tests/test_docs.py`` checks that both
state its outcomes); the parametrised test picks it up.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields

import numpy as np
from mink.lie import SE3, SO3

from pickplace.control.kinematics import ArmKinematics
from pickplace.errors import UnknownNameError
from pickplace.geometry import top_down_rotation
from pickplace.planning.grasp import yaw_of
from pickplace.planning.plan import Plan, PlanConfig, Waypoint, for_gripper, time_keyframes
from pickplace.planning.planner import PickPlacePlanner
from pickplace.planning.timing import TimingConfig
from pickplace.planning.trajectory import PoseTrajectory
from pickplace.robot.reach import ReachIK, farthest_reachable
from pickplace.sim import faults
from pickplace.sim.catalog import CATALOG, ScenarioInfo
from pickplace.sim.goals import PlaceGoal, ReachGoal
from pickplace.sim.recovery import Reattempt
from pickplace.sim.task import Fault, Task
from pickplace.world.cell import ObstacleCell
from pickplace.world.obstacles import draw_boxes
from pickplace.world.placements import (
    BrickPlacement,
    brick_on_floor,
    nominal_placement,
    random_placement,
    target_placement,
    uniform_placement,
)
from pickplace.world.scene import Scene

# Most brick poses pick-place-random draws before it gives up finding a feasible one.
MAX_RANDOM_DRAWS = 100
# Reach scenario: how far beyond the arm's reach the straight line's far end lies [m].
REACH_OVERSHOOT = 0.03
# Reach scenario: time spent pulling at the unreachable far end before coming back [s].
REACH_HOLD = 1.0


@dataclass(frozen=True)
class BuildRequest:
    """What a scenario's builder gets.

    Attributes:
        scene: The loaded scene.
        scenario: Scenario name.
        seed: Seed of randomised scenarios.
        brick: Brick start pose override, or None.
        controller: The run's controller (the planner's pre-flight runs it).
        timing: How the planner times plans by the robot (``--speed`` is its ``speed``).
        attempts: Most attempts a pick-and-place run may take (``--attempts``): after a
            missed grasp or a drop it plans again from where the brick rests
            (:mod:`pickplace.sim.recovery`); 1: the first failure ends the run.
    """

    scene: Scene
    scenario: str
    seed: int
    brick: BrickPlacement | None = None
    controller: str = "qp"
    timing: TimingConfig = field(default_factory=TimingConfig)
    attempts: int = 1

    def planner(self, push: bool = True) -> PickPlacePlanner:
        """A planner for this request's scene, controller and timing; with ``push`` it
        pushes the brick from a wall where no grasp fits (:mod:`pickplace.planning.push`)."""
        return PickPlacePlanner(
            self.scene, self.controller, timing=self.timing, seed=self.seed, push=push
        )


def pick_place_task(
    req: BuildRequest,
    placement: BrickPlacement,
    goal: BrickPlacement | None = None,
    fault_list: Sequence[Fault] = (),
    preflight: bool = True,
    planner: PickPlacePlanner | None = None,
) -> Task:
    """Plan a pick from ``placement`` in bin 1 and a place at ``goal`` (default: bin 2 centre).

    With ``preflight`` the planner's candidates are pre-flighted and the first feasible one is
    the task's plan (the task records them all; none feasible: the run ends before any
    physics). Without it, the first candidate is executed unchecked. The task's recovery
    (:class:`~pickplace.sim.recovery.Reattempt`) plans again with the same planner, up to
    ``req.attempts`` attempts.
    """
    scene = req.scene
    X_WO_pick = brick_on_floor(scene, placement, scene.source_bin.floor_top_z)
    X_WO_place = brick_on_floor(
        scene, goal or target_placement(scene), scene.target_bin.floor_top_z
    )
    planner = planner or req.planner()
    report = planner.plan(X_WO_pick, X_WO_place) if preflight else None
    chosen = None if report is None or report.chosen is None else report.candidates[report.chosen]
    return Task(
        scenario=req.scenario,
        seed=req.seed,
        goal=PlaceGoal(X_WO_place, scene.target_bin),
        plan=report.plan if report else planner.make_plan(X_WO_pick, X_WO_place),
        X_WO_start=X_WO_pick,
        faults=tuple(fault_list),
        planning=report,
        recovery=Reattempt(
            planner, X_WO_place, req.attempts, None if chosen is None else chosen.label
        ),
    )


# Reach scenario: the line's near end, this far from the base axis along +y [m].
LINE_START = 0.45
# Reach scenario: the line's height, the tool pointing down [m].
LINE_HEIGHT = 0.30


def _reach_rotation(scene: Scene) -> SO3:
    """The tool's orientation along the reach line: pointing down, its yaw relative to the base
    as at home, so the last joint does not wind up while the base swings from the home
    direction to the line's direction (+y)."""
    kin = ArmKinematics(scene)
    kin.update(scene.robot.q_home)
    X_home = kin.X_WG()
    p_home = X_home.translation() - scene.robot.p_W_base
    swing = math.pi / 2 - math.atan2(p_home[1], p_home[0])
    return top_down_rotation(yaw_of(X_home.rotation()) + swing)


def reach_line(scene: Scene, z_tool: float = LINE_HEIGHT) -> Callable[[float], SE3]:
    """The reach line's tool pose at distance r [m] from the base axis along +y."""
    R = _reach_rotation(scene)
    base = scene.robot.p_W_base

    def at(r: float) -> SE3:
        return SE3.from_rotation_and_translation(R, np.array([base[0], base[1] + r, z_tool]))

    return at


def full_stretch_distance(scene: Scene, z_tool: float) -> float:
    """Farthest distance from the base axis along +y at which the tool, pointing down at
    height ``z_tool`` [m] with its yaw as along the reach line, is reachable within the joint
    limits [m] (to 0.1 mm).

    Found by IK (:func:`pickplace.robot.reach.farthest_reachable`) between the line's near
    end and a bound no arm exceeds: the joint anchors' distances link to link plus the last
    anchor's to the tool.

    Raises:
        PlanError: The line's near end (``LINE_START``) is out of reach at that height.
    """
    robot = scene.robot
    kin = ArmKinematics(scene)
    kin.update(robot.q_home)
    anchors = kin.data.xanchor[: robot.n_joints]
    bound = float(
        np.linalg.norm(np.diff(anchors, axis=0), axis=1).sum()
        + np.linalg.norm(kin.p_WG() - anchors[-1])
    )
    ik = ReachIK(scene.arm_model, kin.tool_site_id, robot.q_min, robot.q_max)
    return farthest_reachable(ik, reach_line(scene, z_tool), robot.q_home, LINE_START, bound)


def singular_reach_task(req: BuildRequest, plan: PlanConfig | None = None) -> Task:
    """A straight radial line that pulls the tool past full stretch and back (where a
    pseudo-inverse asks for joint speeds above the limits and the QP does not).

    The line runs along +y from the base axis (away from both bins) at a height of
    ``LINE_HEIGHT`` with the tool pointing down (:func:`reach_line`). Its far end lies
    ``REACH_OVERSHOOT`` beyond the arm's reach there, found by IK
    (:func:`full_stretch_distance`).
    """
    scene = req.scene
    plan = for_gripper(plan or PlanConfig(), scene.robot.calibration)
    kin = ArmKinematics(scene)
    kin.update(scene.robot.q_home)
    X_home = kin.X_WG()
    line = reach_line(scene, LINE_HEIGHT)
    r_far = full_stretch_distance(scene, LINE_HEIGHT) + REACH_OVERSHOOT
    near, far = line(LINE_START), line(r_far)
    # The via point: 0.35 m along x and y from the base axis, between home and the line.
    base = scene.robot.p_W_base
    via = SE3.from_rotation_and_translation(
        near.rotation(), np.array([base[0] + 0.35, base[1] + 0.35, LINE_HEIGHT])
    )
    w = plan.open_width
    waypoints = [
        Waypoint("initial", X_home, w),
        Waypoint("via", via, w),
        Waypoint("line-start", near, w),
        Waypoint("stretched", far, w),
        Waypoint("hold", far, w, min_duration=REACH_HOLD),
        Waypoint("line-end", near, w),
    ]
    keyframes = time_keyframes(waypoints, plan)
    X_WO = brick_on_floor(scene, nominal_placement(scene), scene.source_bin.floor_top_z)
    return Task(
        scenario=req.scenario,
        seed=req.seed,
        goal=ReachGoal(),
        plan=Plan(PoseTrajectory(keyframes, plan.profile)),
        X_WO_start=X_WO,
    )


Builder = Callable[[BuildRequest], Task]
WorldBuilder = Callable[[Scene, int], ObstacleCell]
"""The obstacle cell of a scenario's world, from the loaded scene and the run's seed."""


@dataclass(frozen=True)
class Scenario(ScenarioInfo):
    """A named scenario: its row of the catalogue (:class:`~pickplace.sim.catalog.ScenarioInfo`:
    name, summary, documented outcomes) and the builder of its task.

    Attributes:
        build: Builds the task (see :class:`BuildRequest`).
        world: The obstacle cell the scenario adds to the world before planning (the runner
            adds it, :func:`pickplace.sim.variation.apply_world`), or None.
    """

    build: Builder = field(kw_only=True)
    world: WorldBuilder | None = field(default=None, kw_only=True)


# pick-place-obstacles: the divider's height [m], the chance of a shelf and its height [m],
# the most boxes; drawn from their own stream of the seed ("cell" in ASCII).
CELL_DIVIDER_HEIGHT = (0.22, 0.28)
CELL_SHELF_CHANCE = 0.5
CELL_SHELF_HEIGHT = (0.8, 0.95)
CELL_MAX_BOXES = 3
_CELL_STREAM = 0x63656C6C


def obstacle_cell(scene: Scene, seed: int) -> ObstacleCell:
    """``pick-place-obstacles``' cell for ``seed``: a divider of height uniform in
    :data:`CELL_DIVIDER_HEIGHT`, with chance :data:`CELL_SHELF_CHANCE` a shelf at a height
    uniform in :data:`CELL_SHELF_HEIGHT`, and 0 to :data:`CELL_MAX_BOXES` boxes
    (:func:`~pickplace.world.obstacles.draw_boxes`), all from the seed's own stream."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(_CELL_STREAM,)))
    divider = float(rng.uniform(*CELL_DIVIDER_HEIGHT))
    shelf = float(rng.uniform(*CELL_SHELF_HEIGHT))
    if rng.uniform() >= CELL_SHELF_CHANCE:
        shelf = 0.0
    count = int(rng.integers(0, CELL_MAX_BOXES + 1))
    return ObstacleCell(divider, shelf, draw_boxes(scene, rng, count))


def _nominal(req: BuildRequest) -> Task:
    return pick_place_task(req, req.brick or nominal_placement(req.scene))


def _random(req: BuildRequest) -> Task:
    """A brick pose drawn from the seed, drawn again (same generator) until the planner finds
    a feasible plan, at most :data:`MAX_RANDOM_DRAWS` times (a robot that finds none ends
    ``no-feasible-plan`` with the last draw's problems); a given ``--brick`` is planned as is.
    The draws are planned without pushes (:mod:`pickplace.planning.push`): a pose no grasp
    fits is drawn again, as it always was, so that a seed's pose is the same as before pushes
    existed; the recovery's replans after a miss or a drop may push.

    A brick too heavy for the grip is planned all the same (with the timing's warning, see
    :mod:`pickplace.planning.planner`): whether it is held is the physics' to show.
    """
    if req.brick is not None:
        return pick_place_task(req, req.brick)
    rng = np.random.default_rng(req.seed)
    planner = req.planner(push=False)
    for _ in range(MAX_RANDOM_DRAWS):
        task = pick_place_task(req, random_placement(req.scene, rng), planner=planner)
        if task.planning is not None and task.planning.feasible:
            break
    # The draw is made; the recovery's replans (the same planner) may push the brick.
    planner.push = True
    return task  # or none of the draws: the last one's no-feasible-plan says why


def _uniform(req: BuildRequest) -> Task:
    """A brick pose drawn from the seed uniformly over bin 1's valid poses
    (:func:`~pickplace.world.placements.uniform_placement`) and planned as drawn, never drawn
    again: where no candidate is feasible the run ends ``no-feasible-plan`` before any physics,
    naming the best candidate's first problem. A given ``--brick`` is planned as is.
    """
    rng = np.random.default_rng(req.seed)
    return pick_place_task(req, req.brick or uniform_placement(req.scene, rng))


def _reach(req: BuildRequest) -> Task:
    return singular_reach_task(req)


def _with_fault(fault: Callable[[Scene], Fault]) -> Builder:
    def build(req: BuildRequest) -> Task:
        placement = req.brick or nominal_placement(req.scene)
        return pick_place_task(req, placement, fault_list=[fault(req.scene)])

    return build


def _unreachable(req: BuildRequest) -> Task:
    # A place target 1.6 m out along +x: beyond the reach of every bundled arm (the iiwa's is
    # 1.3 m); executed without the pre-flight, which would refuse it (``pickplace plan
    # --scenario fault-unreachable``).
    goal = BrickPlacement(1.6, 0.0, 0.0)
    placement = req.brick or nominal_placement(req.scene)
    return pick_place_task(req, placement, goal=goal, preflight=False)


# The builder of each scenario of the catalogue (pickplace.sim.catalog), by name.
BUILDERS: dict[str, Builder] = {
    "pick-place": _nominal,
    "pick-place-random": _random,
    "pick-place-uniform": _uniform,
    "pick-place-obstacles": _nominal,
    "singular-reach": _reach,
    "fault-gripper-disabled": _with_fault(faults.GripperDisabled),
    "fault-brick-moved": _with_fault(faults.BrickMoved),
    "fault-heavy-brick": _with_fault(faults.HeavyBrick),
    "fault-knock": _with_fault(faults.Knock),
    "fault-unreachable": _unreachable,
    "fault-nan": _with_fault(faults.InjectNaN),
    "fault-obstacle": _with_fault(faults.Obstacle),
}

# The obstacle cell of each scenario that brings one, by name.
WORLDS: dict[str, WorldBuilder] = {"pick-place-obstacles": obstacle_cell}

SCENARIOS: dict[str, Scenario] = {
    name: Scenario(
        **{f.name: getattr(info, f.name) for f in fields(ScenarioInfo)},
        build=BUILDERS[name],
        world=WORLDS.get(name),
    )
    for name, info in CATALOG.items()
}


def get_scenario(name: str) -> Scenario:
    """Return the scenario called ``name``.

    Raises:
        UnknownNameError: No such scenario; the message lists the valid ones.
    """
    try:
        return SCENARIOS[name]
    except KeyError:
        raise UnknownNameError("scenario", name, SCENARIOS) from None


__all__ = [
    "SCENARIOS",
    "BuildRequest",
    "Scenario",
    "get_scenario",
]
