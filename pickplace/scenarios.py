"""Named scenarios: each builds a :class:`~pickplace.task.Task` from a scene and a seed.

``pickplace scenarios`` lists them; ``pickplace run --scenario NAME`` runs one; the pytest suite
runs every scenario and checks its documented outcome (:attr:`Scenario.expected`).

To add a scenario: a builder function here and a :class:`Scenario` row in :data:`SCENARIOS`
(with its expected outcome per controller), and the README's scenario table row; the
parametrised test picks it up.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from mink.lie import SE3

from pickplace import faults
from pickplace.errors import InvalidInputError, UnknownNameError
from pickplace.geometry import box_corners, transform_points
from pickplace.goals import PlaceGoal, ReachGoal
from pickplace.grasp import brick_pose, top_down_rotation, yaw_of
from pickplace.kinematics import ArmKinematics
from pickplace.plan import Plan, PlanConfig, Waypoint, plan_pick_place, time_keyframes
from pickplace.scene import Scene
from pickplace.task import Fault, Task
from pickplace.trajectory import PoseTrajectory

# Margin kept between the brick's centre and bin 1's inner walls when drawing random poses [m]:
# the brick's half-diagonal (0.045 m) plus the open fingers' reach beyond the brick
# (0.10 m opening − 0.05 m width) / 2 = 0.025 m, so that open fingers clear the walls.
RANDOM_WALL_MARGIN = 0.07
# Clearance of the via-point above the higher bin wall: brick height hanging below the tool
# (0.025 m half-height) plus 0.1 m of air.
CLEARANCE_ABOVE_WALLS = 0.125
# Reach scenario: how far beyond the arm's reach the straight line's far end lies [m].
REACH_OVERSHOOT = 0.03
# Reach scenario: time spent pulling at the unreachable far end before coming back [s].
REACH_HOLD = 1.0


@dataclass(frozen=True)
class BrickPlacement:
    """Brick pose on a bin floor: x, y [m] in world and yaw [rad]."""

    x: float
    y: float
    yaw: float


def brick_on_floor(scene: Scene, p: BrickPlacement, bin_floor_z: float) -> SE3:
    """Pose X_WO of the brick resting flat on a floor at height ``bin_floor_z`` [m]."""
    return brick_pose(p.x, p.y, bin_floor_z + float(scene.brick_half_extents[2]), p.yaw)


def check_brick_in_source_bin(
    scene: Scene, p: BrickPlacement, open_width: float | None = None
) -> None:
    """Raise InvalidInputError unless the brick at ``p`` lies in bin 1 and can be grasped.

    The brick's footprint must be inside bin 1's inner walls, and so must the open fingers
    around it: they reach ``open_width / 2 + scene.finger_outer_offset`` from the brick's
    centre along its y axis (the closing axis), over the pads' width along its x axis.
    """
    open_width = PlanConfig().open_width if open_width is None else open_width
    values = (p.x, p.y, p.yaw)
    where = f"brick pose x={p.x:g} m, y={p.y:g} m, yaw={p.yaw:g} rad"
    if not all(math.isfinite(v) for v in values):
        raise InvalidInputError(f"{where}: the values must be finite numbers", field="brick")
    bin_ = scene.source_bin
    X_WO = brick_on_floor(scene, p, bin_.floor_top_z)
    half = scene.brick_half_extents
    if not bin_.contains_xy(transform_points(X_WO, box_corners([half[0], half[1], 0.0]))):
        c = bin_.center_W
        h = bin_.inner_half_extents
        raise InvalidInputError(
            f"{where} puts the brick outside {bin_.name}: its footprint must lie within the "
            f"inner walls, centre x in [{c[0] - h[0]:.2f}, {c[0] + h[0]:.2f}] and y in "
            f"[{c[1] - h[1]:.2f}, {c[1] + h[1]:.2f}] m minus the brick's half-size",
            field="brick",
        )
    reach = open_width / 2 + scene.finger_outer_offset
    if not bin_.contains_xy(transform_points(X_WO, box_corners([0.01, reach, 0.0]))):
        raise InvalidInputError(
            f"{where} is too close to {bin_.name}'s walls to grasp: the open fingers reach "
            f"{reach * 1000:.0f} mm from the brick's centre across its width; move it inwards "
            "or turn it so that its long side faces the wall",
            field="brick",
        )


def home_tool_pose(scene: Scene) -> SE3:
    """Tool pose X_WG at the home keyframe."""
    kin = ArmKinematics(scene)
    kin.update(scene.q_home)
    return kin.X_WG()


def pick_place_task(
    scene: Scene,
    name: str,
    seed: int,
    placement: BrickPlacement,
    goal: BrickPlacement | None = None,
    plan: PlanConfig | None = None,
    fault_list: Sequence[Fault] = (),
) -> Task:
    """Plan a pick from ``placement`` in bin 1 and a place at ``goal`` (default: bin 2 centre)."""
    plan = plan or PlanConfig()
    src, dst = scene.source_bin, scene.target_bin
    X_WO_pick = brick_on_floor(scene, placement, src.floor_top_z)
    if goal is None:
        c = dst.center_W
        goal = BrickPlacement(float(c[0]), float(c[1]), 0.0)
    X_WO_place = brick_on_floor(scene, goal, dst.floor_top_z)
    clearance_z = max(src.wall_top_z, dst.wall_top_z) + CLEARANCE_ABOVE_WALLS
    return Task(
        scenario=name,
        seed=seed,
        goal=PlaceGoal(X_WO_place, dst),
        plan=plan_pick_place(
            home_tool_pose(scene),
            X_WO_pick,
            X_WO_place,
            clearance_z,
            plan,
            p_W_base=scene.p_W_base,
        ),
        X_WO_start=X_WO_pick,
        faults=tuple(fault_list),
    )


def singular_reach_task(scene: Scene, name: str, seed: int, plan: PlanConfig | None = None) -> Task:
    """A straight radial line that pulls the tool past full stretch and back (seed 000).

    The line runs along +y (away from both bins) at a height of 0.30 m with the tool pointing
    down. Its far end lies ``REACH_OVERSHOOT`` beyond the arm's reach, computed from the
    kinematics: the wrist centre (joint 6) sits above the tool by the flange-to-tool length
    and can be at most upper arm + forearm (0.42 + 0.40 m) from the shoulder (joint 2).
    """
    plan = plan or PlanConfig()
    kin = ArmKinematics(scene)
    kin.update(scene.q_home)
    X_home = kin.X_WG()
    kin.update(np.zeros(7))
    data, model = kin.data, kin.model
    p_shoulder = data.xpos[model.body("link2").id].copy()
    p_wrist = data.xpos[model.body("link6").id].copy()
    p_elbow = data.xpos[model.body("link4").id].copy()
    wrist_to_tool = float(np.linalg.norm(kin.p_WG() - p_wrist))
    reach = float(np.linalg.norm(p_elbow - p_shoulder) + np.linalg.norm(p_wrist - p_elbow))
    z_tool = 0.30
    dz = z_tool + wrist_to_tool - p_shoulder[2]
    r_far = math.sqrt(reach**2 - dz**2) + REACH_OVERSHOOT
    # Keep the tool's yaw relative to the base as at home, so joint 7 does not wind up while
    # joint 1 swings from the home direction to the line's direction (+y).
    p_home = X_home.translation()
    swing = math.pi / 2 - math.atan2(p_home[1], p_home[0])
    R = top_down_rotation(yaw_of(X_home.rotation()) + swing)
    via = SE3.from_rotation_and_translation(R, np.array([0.35, 0.35, z_tool]))
    near = SE3.from_rotation_and_translation(R, np.array([0.0, 0.45, z_tool]))
    far = SE3.from_rotation_and_translation(R, np.array([0.0, r_far, z_tool]))
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
        scenario=name,
        seed=seed,
        goal=ReachGoal(),
        plan=Plan(PoseTrajectory(keyframes, plan.profile)),
        X_WO_start=X_WO,
    )


def random_placement(scene: Scene, rng: np.random.Generator) -> BrickPlacement:
    """Uniform x, y over bin 1's floor, ``RANDOM_WALL_MARGIN`` inside the walls; any yaw."""
    bin_ = scene.source_bin
    half = bin_.inner_half_extents - RANDOM_WALL_MARGIN
    u = rng.uniform(-half, half)
    p_W = bin_.X_WB.apply(np.array([u[0], u[1], 0.0]))
    return BrickPlacement(float(p_W[0]), float(p_W[1]), float(rng.uniform(-math.pi, math.pi)))


def nominal_placement(scene: Scene) -> BrickPlacement:
    """Bin 1's floor centre, yaw 0."""
    c = scene.source_bin.center_W
    return BrickPlacement(float(c[0]), float(c[1]), 0.0)


Builder = Callable[[Scene, str, int, "BrickPlacement | None"], Task]


@dataclass(frozen=True)
class Scenario:
    """A named scenario.

    Attributes:
        name: Registry key.
        summary: One line shown by ``pickplace scenarios``.
        build: Builds the task from scene, name, seed and an optional brick placement.
        expected: ``"success"`` or the failure reason the scenario is designed to produce
            with the default controller (``qp``).
        expected_with: Documented outcomes with other controllers, where they differ or are
            the point of the scenario (e.g. ``{"pinv": "limit-violated"}``).
        uses_brick: Whether ``--brick`` applies.
        random: Whether the seed changes the task.
    """

    name: str
    summary: str
    build: Builder
    expected: str = "success"
    expected_with: Mapping[str, str] = field(default_factory=dict)
    uses_brick: bool = True
    random: bool = False

    def outcomes(self) -> dict[str, str]:
        """Documented outcome per controller: ``qp`` and every one in ``expected_with``."""
        return {"qp": self.expected, **self.expected_with}


def _nominal(scene: Scene, name: str, seed: int, p: BrickPlacement | None) -> Task:
    return pick_place_task(scene, name, seed, p or nominal_placement(scene))


def _random(scene: Scene, name: str, seed: int, p: BrickPlacement | None) -> Task:
    placement = p or random_placement(scene, np.random.default_rng(seed))
    return pick_place_task(scene, name, seed, placement)


def _reach(scene: Scene, name: str, seed: int, p: BrickPlacement | None) -> Task:
    return singular_reach_task(scene, name, seed)


def _with_fault(fault: Callable[[Scene], Fault]) -> Builder:
    def build(scene: Scene, name: str, seed: int, p: BrickPlacement | None) -> Task:
        return pick_place_task(
            scene, name, seed, p or nominal_placement(scene), fault_list=[fault(scene)]
        )

    return build


def _unreachable(scene: Scene, name: str, seed: int, p: BrickPlacement | None) -> Task:
    # A place target 1.6 m out along +x: well beyond the arm's 1.3 m reach.
    goal = BrickPlacement(1.6, 0.0, 0.0)
    return pick_place_task(scene, name, seed, p or nominal_placement(scene), goal=goal)


SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        Scenario(
            "pick-place", "nominal pick from bin 1's centre, place at bin 2's centre", _nominal
        ),
        Scenario(
            "pick-place-random",
            "brick x, y, yaw drawn from the seed over bin 1's floor",
            _random,
            random=True,
        ),
        Scenario(
            "singular-reach",
            "tool pulled along a straight line past full arm stretch "
            "and back (qp stays within limits, pinv does not)",
            _reach,
            expected_with={"pinv": "limit-violated", "dls": "limit-violated"},
            uses_brick=False,
        ),
        Scenario(
            "fault-gripper-disabled",
            "the gripper actuator never closes -> missed-grasp",
            _with_fault(faults.GripperDisabled),
            expected="missed-grasp",
        ),
        Scenario(
            "fault-brick-moved",
            "the brick is moved 8 cm after planning -> missed-grasp",
            _with_fault(faults.BrickMoved),
            expected="missed-grasp",
        ),
        Scenario(
            "fault-heavy-brick",
            "the brick weighs 30 kg, beyond the 40 N grip -> dropped",
            _with_fault(faults.HeavyBrick),
            expected="dropped",
        ),
        Scenario(
            "fault-knock",
            "an impulse knocks the brick out of the gripper mid-transport -> dropped",
            _with_fault(faults.Knock),
            expected="dropped",
        ),
        Scenario(
            "fault-unreachable",
            "place target 1.6 m away, outside the arm's reach -> ik-failed",
            _unreachable,
            expected="ik-failed",
        ),
        Scenario(
            "fault-nan",
            "a NaN is injected into the brick's velocity mid-run -> nan",
            _with_fault(faults.InjectNaN),
            expected="nan",
        ),
    )
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
    "BrickPlacement",
    "Scenario",
    "check_brick_in_source_bin",
    "get_scenario",
]
