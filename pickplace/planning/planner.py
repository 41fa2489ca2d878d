"""Plans the robot can execute: grasp candidates ranked by cheap tests, the best few pre-flighted.

The planner makes the grasp candidates of the object's box (:func:`~pickplace.planning.candidates.
box_grasps`: both pairs of side faces, the approach vertical or tilted about the closing axis,
the pads centred or off-centre along the face, both wrist turns; the gripper opened to the
object's width plus :func:`~pickplace.robot.calibration.pad_clearance` a side), and ranks them
by tests that need no IK, in this order:

1. reach: the tool at the pick and the place within the arm's reach (the sum of its link
   lengths from the first joint's anchor);
2. the open hand's footprint: its collision geoms' convex hulls at the pick (opened to the
   grasp's width) and at the place (opened to the whole opening the release ramps to) inside
   the bin's inner walls and above its floor by the pre-flight's clearance
   (:class:`~pickplace.planning.candidates.HandFootprint`);
3. the wrist's margin: the last joint's angle at the pick and after the transfer, predicted from
   the tool's yaw changes (:meth:`PickPlacePlanner.rank`), at least
   :data:`WRIST_MARGIN` from its limits.

A candidate failing 1 or 2 is not pre-flighted; one failing 3 is ranked after those that pass.
Among the passing, those with the whole pad clearance a side first (a grasp the gripper opens
to only with less, :data:`~pickplace.robot.calibration.MIN_PAD_CLEARANCE` at least, after
them), then the smaller tilt, then the open hand's room (one clearing the bins' walls by less
than the clearance plus :data:`FOOTPRINT_MARGIN` after those with more), then the smaller
torque of the weight about the pads (:func:`~pickplace.planning.candidates.gravity_torque`),
then the shorter pendulum (the centre of mass's distance from the pad axis), then the
narrower width, then the smaller wrist travel (the nearest yaw, as every plan chose before
candidates existed). The best :data:`MAX_PREFLIGHTS` are pre-flighted with the run's own
controller (:mod:`pickplace.planning.preflight`) in that order, and the first feasible one is
taken; a candidate whose pre-flight fails after the lift, but not near a singularity (the
transfer's is C-space's to avoid, below), is tried next placing the object the other way
round (its half-turn symmetry at the goal, the tool leaning the other way:
:attr:`~pickplace.planning.candidates.GraspCandidate.other_place`), counted among the
pre-flights; after two of the same approach axis fail near a singularity, the others of that
axis are passed over (:data:`SAME_APPROACH`). If none is, the report says so, with each pre-flighted
candidate's first problem; if none passed 1 and 2, with the best-ranked candidate's cheap-test
problem.

When no grasp candidate is feasible where the object lies (beside a wall, in a corner), the
planner looks for a push that slides it to where one is (:mod:`pickplace.planning.push`: the
closed fingers behind it, the shortest push after which a grasp candidate is feasible at the
predicted pose); that push's plan, pre-flighted, is then the report's chosen candidate, and
the run plans the pick after it from where the object came to rest
(:mod:`pickplace.sim.recovery`).

A plan starts at the home posture unless given a :class:`Start` (the configuration and tool
pose where the arm stopped, when a run tries again: :mod:`pickplace.sim.recovery`); its
candidates then start at that pose, the wrist's margin is predicted from that configuration
and the pre-flight runs from it.

Every candidate's clearance via-point turns with the base swing (``via="swing"``, see
:func:`pickplace.planning.plan.plan_pick_place`).

When a candidate's path sweep collides in the transfer (after the lift, up to the pre-place),
or passes near a singularity there (the straight line and the via-point's swing can take a
wrist through one that a joint-space path between the same configurations avoids), the
transfer is planned again in joint space (:mod:`pickplace.planning.cspace`: RRT-Connect,
shortcutting, a smooth spline, collision-checked by the pre-flight's own check at its
clearance) from the IK's joint positions at the lift to those at the pre-place, both refined to
the keyframes' poses exactly; the lift and the pre-place then stop, the via-point is dropped,
and the plan is swept, timed by the robot's limits and pre-flighted again as a whole. Each
candidate records which motion came from which planner (:class:`Motion`) and the report the
time each planner took.

A brick that the grip cannot hold even at rest within the timing's slip budget (too heavy,
too little friction or grip force: :class:`~pickplace.planning.timing.GripTooWeakError`) is still
planned, timed within the friction alone or else the robot's limits alone, with a warning on
the candidate: the physics, not the planner, then shows whether it is held or dropped.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any

import mujoco
import numpy as np
from mink.lie import SE3, SO3

from pickplace.control.kinematics import ArmKinematics
from pickplace.errors import ObjectError, PlanError
from pickplace.geometry import (
    HALF_TURNS,
    FloatArray,
    pose_error_W_floats,
    require_pose,
    turned_half_extents,
    vertical_axis,
)
from pickplace.planning.candidates import (
    GRASP_HEIGHT_FRACTIONS,
    GRAVITY,
    HAND_OBJECT_MARGIN,
    TIGHT_LABEL,
    GraspCandidate,
    HandFootprint,
    HandObjectGaps,
    box_grasps,
    object_grasps,
)
from pickplace.planning.cspace import (
    CSpaceConfig,
    CSpaceResult,
    JointMotion,
    lever_arms,
    plan_joint_path,
)
from pickplace.planning.grasp import choose_place_pose, yaw_of
from pickplace.planning.plan import (
    Phases,
    Plan,
    PlanConfig,
    Waypoint,
    for_gripper,
    grasp_width,
    plan_pick_place,
    swung_pose,
    time_keyframes,
)
from pickplace.planning.preflight import (
    Preflight,
    PreflightConfig,
    PreflightResult,
    Problem,
    start_configuration,
)
from pickplace.planning.push import Pusher, PushTrajectory
from pickplace.planning.timing import (
    GripTooWeakError,
    SegmentLimits,
    TimingConfig,
    TimingStallError,
    retime,
)
from pickplace.planning.trajectory import JointSegment, PoseTrajectory
from pickplace.robot.calibration import MIN_PAD_CLEARANCE, PAD_CLEARANCE
from pickplace.signals import stop_point
from pickplace.world.scene import BinGeometry, Scene

# Clearance of the via-point above the higher bin wall: brick height hanging below the tool
# (0.025 m half-height) plus 0.1 m of air [m].
CLEARANCE_ABOVE_WALLS = 0.125
# The path sweep's spacing: at most this much tool travel [m] or turn [rad] between two
# pre-flight ticks (for the collision checks and the joint path the timing works on).
PATH_SPACING = 0.02
PATH_ANGLE = 0.1
SWEEP_SLOWDOWNS = 2
"""Times a candidate's path sweep is run again at half its speed when the IK fell behind it
held by a joint limit (the sweep's constant speed, set by its spacing, is not the robot's;
the timing comes after it)."""


def _keyframe_at(times: list[float], t: float) -> int:
    """Index of the keyframe at time ``t`` [s] (phases lie on keyframes)."""
    i = min(range(len(times)), key=lambda j: abs(times[j] - t))
    if abs(times[i] - t) > 1e-9:
        raise PlanError(f"phase time {t!r} s is not a keyframe time")
    return i


def _wrap(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped into [-π, π) [rad]."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def _at_half_speed(config: PlanConfig) -> PlanConfig:
    """``config`` with its Cartesian speed limits halved (a path the joints fell behind, swept
    or timed again at half the speed)."""
    return replace(
        config,
        max_linear_speed=0.5 * config.max_linear_speed,
        max_angular_speed=0.5 * config.max_angular_speed,
    )


MAX_PUSH_PREFLIGHTS = 6
"""Most pushes pre-flighted in one planning (:mod:`pickplace.planning.push`), shortest first:
a push whose hand meets a wall on the way down (the arm's links, not the hand, which the
push's own tests clear) is followed by its other hand poses and the next push."""

MAX_PREFLIGHTS = 8
"""Most candidates pre-flighted in one planning, best-ranked first. Eight, not four: on
uniform poses where the best four fail (the wrist at a limit, the palm or the forearm at a
wall, a singular transfer), a fifth to seventh candidate (another face pair, the wrist's
other turn) planned 3 of 12 refused panda-hand poses and 4 of 26 menagerie-panda-hand ones
(seeds 98600-98899; all 7 succeeded in the physics). Only plans whose first candidates fail
pay for it: a refusal pre-flights up to twice as many."""
SAME_APPROACH = math.radians(1.0)
"""Angle between two candidates' approach axes (the tool's z in world at the pick) within
which, once two have failed their pre-flights near a singularity, no other is pre-flighted
[rad]. The tool Jacobian at a point on the last joint's axis does not depend on the turn about
it, so grasps differing only by that turn (another closing direction of a vertical approach,
the wrist turned, the pads a few millimetres off) meet the same singularity where the arm's
other joints take the same path; a redundant arm's path may differ with the turn (a Panda's
transfer met σmin 0.016 with one wrist turn and 0.066 with the other), so one failure is not
taken for the axis', two are."""
WRIST_MARGIN = 0.3
"""Predicted distance of the last joint from its limits below which a candidate is ranked
after those above it [rad]: the prediction counts the last joint alone, and the pre-flight
measured the others sharing the turn, or the path overshooting it, by up to about 0.2 rad."""

OTHER_PLACE = ", placed the other way round"
"""What a candidate's label gains when it is tried again placing the object the other way
round (:attr:`~pickplace.planning.candidates.GraspCandidate.other_place`)."""


EXACT_TOLERANCE = 1e-9
"""Largest pose error [m, rad] of a C-space path's end refined to its keyframe's pose (the
Gauss-Newton steps reach 1e-15 where they converge)."""
FOOTPRINT_MARGIN = 0.003
"""Open-hand clearance beyond the pre-flight's below which a candidate is ranked after those
clearing the bins by more [m]: lifting the brick, the IK drifts 1.5–3 mm sideways, and the
physical arm lags its command by a few millimetres more."""


PLANNERS = ("cartesian", "c-space")

_UNREACHABLE = "unreachable"  # how a reach problem's text starts (Ranked.cheap_test)

#: Why a planning found no feasible plan, by the best candidate's first problem
#: (:attr:`PlanningReport.refusal_cause`): the two cheap tests that refuse a candidate before
#: any pre-flight, then the pre-flight's problem kinds (:class:`~pickplace.planning.preflight.
#: Problem`). A coverage sweep counts its refusals by these (``pickplace sweep``'s report).
REFUSAL_CAUSES: dict[str, str] = {
    "reach": "no candidate's tool within the arm's reach at the pick or the place",
    "footprint": "no candidate's open hand clear of the bin's walls and floor at the pick or "
    "the place",
    "collision": "the best candidate's robot or held object within the clearance of the world",
    "singularity": "the best candidate's tool Jacobian near a singularity",
    "joint-limit": "the best candidate's joint within its margin of a limit",
    "speed-limit": "the best candidate's joint commanded above its speed limit",
    "ik": "the best candidate's IK without a solution, or falling behind the plan",
}
"""Where a motion of a plan comes from: the Cartesian keyframes or the C-space planner."""


@dataclass(frozen=True)
class Motion:
    """One motion of a plan between two keyframes, and the planner it came from.

    Attributes:
        start: The keyframe it starts at.
        end: The keyframe it ends at.
        planner: ``"cartesian"`` or ``"c-space"`` (:data:`PLANNERS`).
    """

    start: str
    end: str
    planner: str

    def __post_init__(self) -> None:
        """Validate the planner's name."""
        if self.planner not in PLANNERS:
            raise PlanError(f"motion planner must be one of {', '.join(PLANNERS)}")

    def as_dict(self) -> dict[str, str]:
        """JSON form."""
        return {"from": self.start, "to": self.end, "planner": self.planner}


@dataclass(frozen=True)
class CSpaceAttempt:
    """A candidate's transfer planned in C-space (because its Cartesian transfer collided or
    met a singularity).

    Attributes:
        cartesian_problem: The Cartesian transfer's collision or singularity.
        result: What the C-space planning found (path, problem, time, checks).
    """

    cartesian_problem: Problem
    result: CSpaceResult

    def as_dict(self) -> dict[str, Any]:
        """JSON form, without the wall time: the Cartesian problem, whether a path was found,
        the C-space problem, the collision checks and the path's vertices."""
        r = self.result
        return {
            "cartesian_problem": self.cartesian_problem.as_dict(),
            "found": r.path is not None,
            "problem": r.problem,
            "checks": r.checks,
            "vertices": r.vertices,
        }


@dataclass(frozen=True)
class Candidate:
    """One plan tried, and what its pre-flight found.

    Attributes:
        label: How the candidate differs from the others, e.g. ``"across the length"``.
        plan: The plan.
        preflight: Its pre-flight result.
        warning: What the timing could not honour (the slip budget of a brick too heavy for
            the grip), or None.
        cspace: Its transfer planned in C-space, or None (every motion Cartesian).
        refused_by: The cheap test that refused it before any pre-flight (``"reach"`` or
            ``"footprint"``, see :data:`REFUSAL_CAUSES`), or None (it was pre-flighted).
    """

    label: str
    plan: Plan
    preflight: PreflightResult
    warning: str | None = None
    cspace: CSpaceAttempt | None = None
    refused_by: str | None = None

    def motions(self) -> list[Motion]:
        """Each motion of the plan (between keyframes where the tool moves) and its planner."""
        traj = self.plan.trajectory
        out = []
        for k, (a, b) in enumerate(zip(traj.keyframes, traj.keyframes[1:], strict=False)):
            moves = float(np.linalg.norm(b.X_WG.translation() - a.X_WG.translation())) > 1e-9
            if not moves and traj.joint_segments[k] is None:
                continue
            planner = "cartesian" if traj.joint_segments[k] is None else "c-space"
            out.append(Motion(a.name, b.name, planner))
        return out

    def as_dict(self) -> dict[str, Any]:
        """JSON form: label, feasible, the first problem, how far the plan was checked and the
        timing's warning; for a candidate whose transfer was planned in C-space also its
        motions with their planners and the C-space attempt."""
        p = self.preflight
        out: dict[str, Any] = {
            "label": self.label,
            "feasible": p.feasible,
            "problem": None if p.problem is None else p.problem.as_dict(),
            "checked_until_s": p.t_checked,
            "warning": self.warning,
        }
        if self.cspace is not None:
            out["motions"] = [m.as_dict() for m in self.motions()]
            out["c_space"] = self.cspace.as_dict()
        return out


@dataclass(frozen=True)
class PlanningReport:
    """The candidates tried, in order, and the one chosen.

    Attributes:
        candidates: Every candidate tried, in the planner's order.
        chosen: Index of the chosen (first feasible) candidate, or None.
        planning_time_s: Wall time spent planning and pre-flighting [s].
        config: The pre-flight's rate and thresholds.
        ranked: How many grasp candidates were ranked by the cheap tests (``candidates`` holds
            the pre-flighted ones, or the best-ranked one when none passed the cheap tests).
        planner_time_s: Wall time per planner [s]: ``"cartesian"`` (ranking, keyframes,
            pre-flights and timing) and ``"c-space"`` (the C-space plannings).
    """

    candidates: tuple[Candidate, ...]
    chosen: int | None
    planning_time_s: float
    config: PreflightConfig
    ranked: int = 0
    planner_time_s: dict[str, float] = field(default_factory=dict)

    @property
    def used_cspace(self) -> bool:
        """True if some candidate's transfer was planned in C-space."""
        return any(c.cspace is not None for c in self.candidates)

    @property
    def feasible(self) -> bool:
        """True if a candidate is feasible."""
        return self.chosen is not None

    @property
    def plan(self) -> Plan:
        """The chosen plan, or (when none is feasible) the first candidate's."""
        return self.candidates[0 if self.chosen is None else self.chosen].plan

    def refusal(self) -> str:
        """Why no plan is feasible: the best candidate's first problem (empty if feasible)."""
        if self.feasible:
            return ""
        best = self.candidates[0]
        p = best.preflight.problem
        assert p is not None  # an infeasible candidate has a problem
        return f"the best candidate, '{best.label}', at t={p.t:.2f} s: {p.text}"

    @property
    def refusal_cause(self) -> str | None:
        """Why no plan is feasible, as one key of :data:`REFUSAL_CAUSES`: the cheap test that
        refused every candidate, else the kind of the best candidate's first problem; None if
        a plan is feasible."""
        if self.feasible:
            return None
        best = self.candidates[0]
        if best.refused_by is not None:
            return best.refused_by
        assert best.preflight.problem is not None  # an infeasible candidate has a problem
        return best.preflight.problem.kind

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


@dataclass(frozen=True)
class Start:
    """Where a plan starts when not at the home posture (a replan at run time).

    Attributes:
        q: The arm's commanded configuration [rad], one angle per arm joint: the pre-flight's
            IK starts from it.
        X_WG: The tool pose there, in world: the plan's first keyframe (the pose the plan being
            replaced holds, so that the planned pose does not jump).
    """

    q: np.ndarray
    X_WG: SE3

    def __post_init__(self) -> None:
        """Check the pose (a unit quaternion, finite) and that ``q`` is finite angles, copied;
        the planner checks that there is one per arm joint.

        Raises:
            PlanError: Either is invalid.
        """
        require_pose("start X_WG", self.X_WG)
        q = np.array(self.q, dtype=np.float64).reshape(-1)
        if not np.all(np.isfinite(q)):
            raise PlanError(f"a start configuration must be finite [rad], got {q.tolist()!r}")
        object.__setattr__(self, "q", q)


@dataclass(frozen=True)
class Ranked:
    """A grasp candidate and its cheap tests (see the module docstring).

    Attributes:
        grasp: The candidate.
        problem: The first cheap test it fails (reach or footprint), or None.
        clearance: The open hand's smallest distance to the bins at the pick and the place
            [m]: exact below the pre-flight's clearance, else a lower bound (a geom's
            bounding box where that clears the bins by the clearance).
        wrist_margin: Predicted distance of the last joint from its limits [rad] (inf for a
            last joint without limits).
        wrist_travel: Predicted turn of the last joint, home to pick plus the transfer [rad].
        torque: Torque of the object's weight about the pad axis [N m].
        arm: Distance of the object's centre of mass from the pad axis [m]: the pendulum an
            acceleration of the hand swings it on (pads on a curved side touch it along a
            line, which resists no turn about that axis).
        close_to_bins: The open hand clears the bins' walls by less than the pre-flight's
            clearance plus :data:`FOOTPRINT_MARGIN` (the floor, which the pads' height sets,
            not a sideways drift, counts only for the clearance).
    """

    grasp: GraspCandidate
    problem: str | None
    clearance: float
    wrist_margin: float
    wrist_travel: float
    torque: float
    arm: float
    close_to_bins: bool = False

    @property
    def cheap_test(self) -> str | None:
        """The cheap test it fails, ``"reach"`` or ``"footprint"``, or None."""
        if self.problem is None:
            return None
        return "reach" if self.problem.startswith(_UNREACHABLE) else "footprint"

    def key(self) -> tuple[bool | float, ...]:
        """Sort key: passing first, then the order of the module docstring; failing ones
        nearest to passing first."""
        if self.problem is not None:
            return (True, -self.clearance)
        return (
            self.problem is not None,
            self.wrist_margin < WRIST_MARGIN,
            self.grasp.open_width - self.grasp.width < 2.0 * PAD_CLEARANCE - 1e-12,
            abs(self.grasp.tilt),
            self.close_to_bins,
            round(self.torque, 9),
            round(self.arm, 9),
            round(self.grasp.width, 9),
            self.wrist_travel,
            -self.clearance,
        )


@dataclass(frozen=True)
class GraspSet:
    """Grasp candidates with what the ranking computes from them, once.

    Attributes:
        grasps: The candidates, in generation order.
        R_OG: Their rotations in the object frame (n, 3, 3).
        p_OG: Their tool positions in the object frame (n, 3) [m].
        open_widths: Their open widths (n,) [m].
        arms: The centre of mass's distance from each pad axis (n,) [m]: the pendulum a held
            object swings on about it.
        siblings: For a tight twin, the index of its sibling opened with the whole clearance
            (:attr:`~pickplace.planning.candidates.GraspCandidate.tight`); -1 for the others
            (and for a twin whose sibling is not in the set).
    """

    grasps: list[GraspCandidate]
    R_OG: FloatArray
    p_OG: FloatArray
    open_widths: FloatArray
    arms: FloatArray
    siblings: np.ndarray

    @classmethod
    def of(cls, grasps: list[GraspCandidate], p_O_com: FloatArray) -> GraspSet:
        """The set of ``grasps`` of an object whose centre of mass is at ``p_O_com`` [m]."""
        R_OG = np.array([g.X_OG.rotation().as_matrix() for g in grasps])
        p_OG = np.array([g.X_OG.translation() for g in grasps])
        r_O = p_O_com - p_OG  # the centre of mass from the tool, in O
        y_O = R_OG[:, :, 1]
        along = np.einsum("ni,ni->n", r_O, y_O)[:, None] * y_O
        arms = np.linalg.norm(r_O - along, axis=1)
        open_widths = np.array([g.open_width for g in grasps])
        return cls(grasps, R_OG, p_OG, open_widths, arms, _siblings(grasps))

    def select(self, keep: np.ndarray) -> GraspSet:
        """The candidates where ``keep`` (n,) is true, in their order."""
        grasps = [g for g, k in zip(self.grasps, keep, strict=True) if k]
        return GraspSet(
            grasps,
            self.R_OG[keep],
            self.p_OG[keep],
            self.open_widths[keep],
            self.arms[keep],
            _siblings(grasps),
        )


def _siblings(grasps: list[GraspCandidate]) -> np.ndarray:
    """Per candidate, the index of a tight twin's sibling among ``grasps`` (-1 if none)."""
    index = {g.label: i for i, g in enumerate(grasps) if not g.tight}
    return np.array(
        [index.get(g.label.removesuffix(TIGHT_LABEL), -1) if g.tight else -1 for g in grasps],
        dtype=np.intp,
    )


class PickPlacePlanner:
    """Makes, ranks and pre-flights pick-and-place candidates (see the module docstring).

    Args:
        scene: The scene (bins, brick, arm, gripper).
        controller: Name of the run's controller, which the pre-flight runs.
        config: Planning limits and parameters; the open width is capped at the gripper's
            (:func:`~pickplace.planning.plan.for_gripper`), and each candidate opens only as
            wide as its object width needs.
        preflight: Pre-flight rate and thresholds.
        timing: How plans are timed by the robot's limits.
        seed: The run's seed: seeds the C-space planner's random numbers (with the attempt).
        cspace: Budget and resolution of C-space planning.
        push: Whether :meth:`plan` pushes the object where no grasp candidate is feasible
            (:mod:`pickplace.planning.push`).

    Raises:
        ObjectError: The object has no grasp the gripper opens to (wider than its opening
            less the pad clearance along every direction it could be grasped along).
    """

    def __init__(
        self,
        scene: Scene,
        controller: str,
        config: PlanConfig | None = None,
        preflight: PreflightConfig | None = None,
        timing: TimingConfig | None = None,
        seed: int = 0,
        cspace: CSpaceConfig | None = None,
        push: bool = True,
    ) -> None:
        self.scene = scene
        self.push = bool(push)
        self.seed = int(seed)
        self.cspace = cspace or CSpaceConfig()
        self._cspace_time = 0.0
        self._attempts = 0
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
        robot = scene.robot
        pads = np.concatenate(robot.pad_geom_ids)
        mu = robot.pad_friction(scene.model)
        # |a − g| the pads' friction holds on the brick: μ · 2 sides · squeeze force / mass.
        self.slip_accel = mu * 2.0 * robot.squeeze_force / scene.brick_mass
        kin = ArmKinematics(scene)
        kin.update(robot.q_home)
        self.X_WG_home = kin.X_WG()
        src, dst = scene.source_bin, scene.target_bin
        self.clearance_z = max(src.wall_top_z, dst.wall_top_z) + CLEARANCE_ABOVE_WALLS
        # Reach: the link lengths, anchor to anchor (fixed in each link), and on to the tool.
        anchors = kin.data.xanchor[: robot.n_joints]
        self.p_W_shoulder = anchors[0].copy()
        self.reach = float(
            np.linalg.norm(np.diff(anchors, axis=0), axis=1).sum()
            + np.linalg.norm(self.X_WG_home.translation() - anchors[-1])
        )
        # The last joint turns the tool's yaw by its own angle times its axis' z component.
        self.wrist_axis_z = float(kin.data.xaxis[robot.n_joints - 1][2])
        footprint = self.footprint_of
        self.hand = footprint(robot.gripper_geom_ids)
        pad_hand = footprint(pads)
        pad_corners = pad_hand.corners_G(self.config.open_width)
        pad_x, pad_z = pad_corners[..., 0], pad_corners[..., 2]
        self.pad_half_length = 0.5 * float(np.max(pad_x.max(axis=1) - pad_x.min(axis=1)))
        self.pad_half_height = 0.5 * float(np.max(pad_z.max(axis=1) - pad_z.min(axis=1)))
        self.pad_friction = mu
        self.p_O_com = scene.model.body_ipos[scene.brick_body_id].copy()
        grasps = self.grasps()
        if grasps:
            others = robot.gripper_geom_ids[~np.isin(robot.gripper_geom_ids, pads)]
            self._hand_gaps = HandObjectGaps(footprint(others), scene.object)
            height = 2.0 * float(scene.object.half_extents[2])
            self._set = self._clear_of_hand(GraspSet.of(grasps, self.p_O_com), height)
            self._grasps = self._set.grasps
            self._pusher: Pusher | None = None  # made on the first push search
        else:
            shape = scene.object
            narrowest = 2.0 * shape.min_footprint_half
            raise ObjectError(
                f"the object ({shape.kinds}) is at least {narrowest * 1000:.0f} mm across every "
                f"horizontal direction it can be grasped along; the gripper opens to "
                f"{self.config.open_width * 1000:.0f} mm; valid: an object at most "
                f"{(self.config.open_width - 2 * MIN_PAD_CLEARANCE) * 1000:.0f} mm across "
                "(the opening less the pad clearance a side)"
            )
        self._turned: dict[bytes, GraspSet] = {}
        self._bin_frames = {
            b.name: (b.X_WB.inverse().rotation().as_matrix(), b.X_WB.inverse().translation())
            for b in (src, dst)
        }
        p_home = self.X_WG_home.translation() - robot.p_W_base
        self._home_azimuth = math.atan2(p_home[1], p_home[0])
        self._home_yaw = yaw_of(self.X_WG_home.rotation())
        self._kin = kin
        # The C-space metric: each joint's lever arm over the links after it, the hand and
        # the brick (the farthest of their points from the tool).
        self.lever_arms = lever_arms(kin, robot.q_home, self._hand_reach())

    @property
    def pusher(self) -> Pusher:
        """The push planner of this planner's hand and object (:mod:`pickplace.planning.push`),
        made when first asked for: only a pose no grasp fits needs it."""
        if self._pusher is None:
            self._pusher = Pusher(
                self.scene,
                self.hand,
                HandObjectGaps(self.hand, self.scene.object),
                self.config.closed_width,
                self.preflight.config.clearance,
                self.clearance_z,
                yaw_of(self.X_WG_home.rotation()),
            )
        return self._pusher

    def footprint_of(self, geom_ids: np.ndarray) -> HandFootprint:
        """The collision boxes of the hand's geoms ``geom_ids`` on the pre-flight's model, at
        home (:class:`~pickplace.planning.candidates.HandFootprint`)."""
        scene, robot = self.scene, self.scene.robot
        return HandFootprint(
            self.preflight.model,
            geom_ids,
            [scene.geom_name(int(g)) for g in geom_ids],
            robot.tool_site_id,
            scene.gripper_qpos_adr,
            robot.qpos_for_width,
            (robot.arm_qpos_adr, robot.q_home),
        )

    def _hand_reach(self) -> float:
        """The farthest point of the hand (open) or the held brick from the tool [m]."""
        m = self.preflight.model
        d = mujoco.MjData(m)
        robot = self.scene.robot
        d.qpos[robot.arm_qpos_adr] = robot.q_home
        d.qpos[self.scene.gripper_qpos_adr] = robot.qpos_for_width(self.config.open_width)
        mujoco.mj_kinematics(m, d)
        p_tool = d.site_xpos[robot.tool_site_id]
        geoms = robot.gripper_geom_ids
        hand = np.linalg.norm(d.geom_xpos[geoms] - p_tool, axis=1) + m.geom_rbound[geoms]
        brick = self.scene.object.bounding_radius
        grasp = max(float(np.linalg.norm(p)) for p in self._set.p_OG)
        return float(max(hand.max(), grasp + brick))

    def plan(
        self,
        X_WO_pick: SE3,
        X_WO_place: SE3,
        first_feasible: bool = True,
        start: Start | None = None,
        turn: FloatArray | None = None,
        push: bool | None = None,
    ) -> PlanningReport:
        """Rank the candidates, pre-flight the best few in order; stop at the first feasible
        one (unless told not to); if none is, look for a push (module docstring).

        Args:
            X_WO_pick: Brick pose to pick, in world.
            X_WO_place: Goal pose of the brick, in world.
            first_feasible: Stop at the first feasible candidate (else pre-flight all of the
                best :data:`MAX_PREFLIGHTS`).
            start: Where the plans start (configuration and tool pose); None: at home.
            turn: For a box resting on a face its frame's z is not normal to (a brick
                standing on its end): the turn R (3, 3) of its frame O such that it lies with
                the z of ``O · R`` up (:func:`~pickplace.geometry.upright_turn`); the grasps
                are then the box's in that frame (:meth:`turned_grasps`). None: O's z is up.
            push: Whether to look for a push when no grasp is feasible (None: the planner's
                own :attr:`push`; never for a ``turn``).

        Raises:
            PlanError: ``start.q`` is not one finite angle per arm joint, or a ``turn`` for an
                object that is not a box.
        """
        t0 = time.perf_counter()
        self._cspace_time, self._attempts = 0.0, 0
        if start is not None:
            start = Start(start_configuration(self.scene, start.q), start.X_WG)
        ranked = self.rank(X_WO_pick, X_WO_place, start, turn)
        tried: list[Candidate] = []
        chosen: int | None = None
        singular: list[np.ndarray] = []  # approach axes of the candidates that met one
        R_WO = X_WO_pick.rotation().as_matrix()
        queue = [r.grasp for r in ranked if r.problem is None]
        while queue and len(tried) < MAX_PREFLIGHTS:
            grasp = queue.pop(0)
            z_W = R_WO @ grasp.X_OG.rotation().as_matrix()[:, 2]
            if sum(float(z_W @ a) > math.cos(SAME_APPROACH) for a in singular) >= 2:
                continue  # an approach that met a singularity twice
            stop_point()  # a long planning may be cut by a stop request (pickplace.signals)
            plan, result, warning, attempt = self.planned(X_WO_pick, X_WO_place, grasp, start)
            tried.append(Candidate(grasp.label, plan, result, warning, attempt))
            problem = result.problem
            if problem is not None and problem.kind == "singularity":
                singular.append(z_W)
            if result.feasible and chosen is None:
                chosen = len(tried) - 1
                if first_feasible:
                    break
            elif (
                problem is not None
                and problem.kind != "singularity"  # the transfer's is C-space's to avoid
                and not grasp.other_place
                and plan.phases is not None
                and problem.t > plan.phases.transport[0]
            ):
                other = replace(grasp, other_place=True, label=grasp.label + OTHER_PLACE)
                queue.insert(0, other)
        if not tried:  # none passed the cheap tests: the best one, with its problem
            best = ranked[0]
            plan = self.make_plan(X_WO_pick, X_WO_place, best.grasp, start=start)
            tried.append(
                Candidate(
                    best.grasp.label, plan, self._refused(plan, best), refused_by=best.cheap_test
                )
            )
        if chosen is None and (self.push if push is None else push) and turn is None:
            cspace_time = self._cspace_time
            pushed = self._push_candidate(X_WO_pick, X_WO_place, start)
            self._cspace_time = cspace_time
            if pushed is not None:
                tried.append(pushed)
                chosen = len(tried) - 1
        total = time.perf_counter() - t0
        times = {"cartesian": total - self._cspace_time, "c-space": self._cspace_time}
        return PlanningReport(
            tuple(tried), chosen, total, self.preflight.config, len(ranked), times
        )

    def _push_candidate(
        self, X_WO_pick: SE3, X_WO_place: SE3, start: Start | None
    ) -> Candidate | None:
        """A push after which some grasp candidate is feasible, as a pre-flighted candidate
        (:mod:`pickplace.planning.push`), or None (none found, or its pre-flight fails)."""
        bin_ = self.bin_at(X_WO_pick)
        if bin_ is None:
            return None

        def pickable_at(X_WO: SE3) -> bool:
            return any(r.problem is None for r in self.rank(X_WO, X_WO_place, None))

        def feasible_at(X_WO: SE3) -> bool:
            return self.plan(X_WO, X_WO_place, push=False).feasible

        X_from = self.X_WG_home if start is None else start.X_WG
        q_start = None if start is None else start.q
        failed: list[SE3] = []  # hand poses whose way down to the push's start met the world
        tried = 0
        for push in self.pusher.pushes(X_WO_pick, bin_, feasible_at, pickable_at):
            if tried >= MAX_PUSH_PREFLIGHTS:
                break
            if any(push.X_WG_start is X for X in failed):
                continue  # the same way down, only pushing further
            tried += 1
            config = self.config
            for _ in range(SWEEP_SLOWDOWNS + 1):
                plan = self.pusher.plan(push, X_from, self.config.open_width, config)
                result = self.preflight.run(plan, X_WO_pick, None, q_start=q_start)
                problem = result.problem
                if problem is None or problem.kind not in ("speed-limit", "ik"):
                    break
                config = _at_half_speed(config)
            if result.feasible:
                return Candidate(push.label, plan, result)
            traj = plan.trajectory
            assert isinstance(traj, PushTrajectory)
            if problem is not None and problem.t < traj.push_start_time:
                failed.append(push.X_WG_start)
        return None

    def observe_world(self, mocap_pos: np.ndarray, mocap_quat: np.ndarray) -> None:
        """Take the world's moving bodies' poses into the pre-flight's collision model, so that
        the next plans are checked (and C-space paths routed) around them where they are now.

        Args:
            mocap_pos: The simulation's ``data.mocap_pos`` (nmocap, 3) [m].
            mocap_quat: Its ``data.mocap_quat`` (nmocap, 4), wxyz.
        """
        self.preflight.observe_world(mocap_pos, mocap_quat)

    def plan_held(self, start: Start, X_WO_held: SE3, X_WO_place: SE3, X_OG: SE3) -> PlanningReport:
        """The rest of a pick-and-place whose brick is in the hand: from ``start`` straight on
        to the pre-place (in C-space when that collides), then the place, release and retreat
        of a plan from there, the gripper kept closed until the release.

        The plan's grasp is the one whose tool pose in the object frame is ``X_OG`` (the grasp
        the brick is held by), so the brick's pose in the hand is ``X_OG``'s; its phases start
        holding (``approach`` and ``grip_closed`` at 0, the transport from 0 to the
        pre-place), so the run's grasp monitor judges the grip at once and watches for a drop
        from there. The path is swept, timed and pre-flighted as every candidate
        (:meth:`planned`'s C-space fallback included).

        Args:
            start: The arm's commanded configuration and tool pose.
            X_WO_held: The brick's pose in world now (in the hand).
            X_WO_place: Goal pose of the brick.
            X_OG: The tool site in the object frame, as held.

        Raises:
            PlanError: ``start.q`` is not one finite angle per arm joint.
        """
        t0 = time.perf_counter()
        self._cspace_time, self._attempts = 0.0, 0
        start = Start(start_configuration(self.scene, start.q), start.X_WG)
        R, p = X_OG.rotation().as_matrix(), X_OG.translation()
        grasp = min(
            self._grasps,
            key=lambda g: float(
                np.linalg.norm(g.X_OG.translation() - p)
                + np.linalg.norm(g.X_OG.rotation().as_matrix() - R)
            ),
        )
        grasp = replace(grasp, X_OG=X_OG)
        path = self._held_path(start, X_WO_held, X_WO_place, grasp)
        swept = self.preflight.run(path, X_WO_held, X_WO_place, q_start=start.q)
        attempt: CSpaceAttempt | None = None
        problem, phases = swept.problem, path.phases
        assert phases is not None
        if swept.feasible:
            plan, result, warning = self._timed(path, swept, X_WO_held, X_WO_place, start.q)
        elif (
            problem is not None and problem.kind == "collision" and problem.t <= phases.transport[1]
        ):
            plan, result, warning, attempt = self.cspace_plan(
                X_WO_held, X_WO_place, path, swept, start
            )
        else:
            plan, result, warning = path, swept, None
        total = time.perf_counter() - t0
        times = {"cartesian": total - self._cspace_time, "c-space": self._cspace_time}
        candidate = Candidate(f"{grasp.label}, held", plan, result, warning, attempt)
        return PlanningReport(
            (candidate,), 0 if result.feasible else None, total, self.preflight.config, 1, times
        )

    def _held_path(
        self, start: Start, X_WO_held: SE3, X_WO_place: SE3, grasp: GraspCandidate
    ) -> Plan:
        """The swept path of :meth:`plan_held`: ``start``, then the keyframes from the
        pre-place on of the pick-and-place :meth:`make_plan` makes from ``start`` with the
        brick picked where it is held, timed by the path sweep's limits."""
        full = self.make_plan(X_WO_held, X_WO_place, grasp, self.sweep_config, start)
        ph = full.phases
        assert ph is not None and full.X_OG is not None
        keyframes = full.trajectory.keyframes
        times = [k.t for k in keyframes]
        i_pre = _keyframe_at(times, ph.transport[1])
        closed = keyframes[i_pre].gripper_width
        waypoints = [Waypoint("replan-start", start.X_WG, closed, 0.0, stop=True)]
        waypoints += [
            Waypoint(
                k.name,
                k.X_WG,
                k.gripper_width,
                k.hold,
                stop=k.stop or i == i_pre,
                curve=k.curve and i != i_pre,
            )
            for i, k in enumerate(keyframes)
            if i >= i_pre
        ]
        new = time_keyframes(waypoints, self.sweep_config)

        def moved(t: float) -> float:
            return new[1 + _keyframe_at(times, t) - i_pre].t

        phases = Phases(
            approach=(0.0, 0.0),
            grip_closed=0.0,
            transport=(0.0, new[1].t),
            place_reached=moved(ph.place_reached),
            release=moved(ph.release),
        )
        trajectory = PoseTrajectory(new, self.sweep_config.profile)
        return Plan(trajectory, phases, full.X_OG)

    def _refused(self, plan: Plan, ranked: Ranked) -> PreflightResult:
        """A pre-flight result for a candidate refused by a cheap test, at the pick."""
        t = plan.phases.approach[1] if plan.phases is not None else 0.0
        p = plan.trajectory.sample(t)[0][4:]  # wxyz_xyz of the tool at the pick
        point = (float(p[0]), float(p[1]), float(p[2]))
        kind = "ik" if ranked.cheap_test == "reach" else "collision"
        problem = Problem(t, kind, ranked.problem or "", point)
        nq = self.scene.robot.n_joints
        return PreflightResult(
            problem,
            0.0,
            ranked.clearance,
            ranked.wrist_margin,
            0.0,
            0.0,
            np.zeros(0),
            np.zeros((0, nq)),
        )

    def rank(
        self,
        X_WO_pick: SE3,
        X_WO_place: SE3,
        start: Start | None = None,
        turn: FloatArray | None = None,
    ) -> list[Ranked]:
        """Every grasp candidate with its cheap tests, best first (see the module docstring).

        The wrist's margin is predicted from ``start`` (its last joint's angle and tool yaw),
        by default from home; the candidates are those of a box turned by ``turn`` (see
        :meth:`plan`) when given.

        Vectorised over the candidates: the pick poses ``X_WG = X_WO X_OG``, the place poses
        (of ``X_WO_goal X_OG`` and ``X_WO_goal Rz(π) X_OG``, the one whose yaw is nearer the
        pick's carried along by the base swing, as :func:`~pickplace.planning.plan.
        plan_pick_place` chooses), the reach, the open hand in each bin, the wrist, the torque.
        """
        sc, robot = self.scene, self.scene.robot
        clearance = self.preflight.config.clearance
        candidates = self._grasp_set(turn)
        grasps, R_OG, p_OG = candidates.grasps, candidates.R_OG, candidates.p_OG
        open_widths = candidates.open_widths
        n = len(grasps)
        R_pick = np.einsum("ij,njk->nik", X_WO_pick.rotation().as_matrix(), R_OG)
        p_pick = p_OG @ X_WO_pick.rotation().as_matrix().T + X_WO_pick.translation()
        R_goal = X_WO_place.rotation().as_matrix()
        turns = (np.eye(3), HALF_TURNS[vertical_axis(X_WO_place.rotation())])
        options = [np.einsum("ij,njk->nik", R_goal @ T, R_OG) for T in turns]
        p_options = [p_OG @ (R_goal @ T).T + X_WO_place.translation() for T in turns]
        yaw_pick = np.arctan2(R_pick[:, 1, 0], R_pick[:, 0, 0])
        base = robot.p_W_base
        to_goal = X_WO_place.translation()[:2] - base[:2]
        from_pick = p_pick[:, :2] - base[:2]
        swing_goal = _wrap(np.arctan2(to_goal[1], to_goal[0]) - np.arctan2(*from_pick.T[::-1]))
        reference = yaw_pick + swing_goal
        changes = [np.abs(_wrap(np.arctan2(R[:, 1, 0], R[:, 0, 0]) - reference)) for R in options]
        second = changes[1] < changes[0]
        R_place = np.where(second[:, None, None], options[1], options[0])
        p_place = np.where(second[:, None], p_options[1], p_options[0])
        # Reach.
        far = np.maximum(
            np.linalg.norm(p_pick - self.p_W_shoulder, axis=1),
            np.linalg.norm(p_place - self.p_W_shoulder, axis=1),
        )
        # The open hand in each bin, per open width: against the walls and the floor, and
        # against the walls alone for the room beyond the clearance (FOOTPRINT_MARGIN).
        near = np.full(n, np.inf)
        near_walls = np.full(n, np.inf)

        def footprints(todo: np.ndarray) -> None:
            # The hand opens to the grasp's width at the pick, to the whole opening at the
            # release.
            for width in np.unique(open_widths[todo]):
                sel = todo & (open_widths == width)
                for R, p, bin_, w in (
                    (R_pick, p_pick, self.bin_at(X_WO_pick), width),
                    (R_place, p_place, self.bin_at(X_WO_place), self.config.open_width),
                ):
                    if bin_ is None:
                        continue  # on the ground: the pre-flight checks the hand there
                    R_BW, p_BW = self._bin_frames[bin_.name]
                    to_bin, to_walls = self.hand.clearances(
                        np.einsum("ij,njk->nik", R_BW, R[sel]),
                        p[sel] @ R_BW.T + p_BW,
                        w,
                        bin_,
                        exact_below=clearance,
                        walls_exact_below=clearance + FOOTPRINT_MARGIN,
                    )
                    near[sel] = np.minimum(near[sel], to_bin)
                    near_walls[sel] = np.minimum(near_walls[sel], to_walls)

        # A tight twin only where its sibling, opened with the whole clearance, fails the
        # footprint: elsewhere it would fail the pre-flight as its sibling does.
        sibling = candidates.siblings
        twin = sibling >= 0
        footprints(~twin)
        wanted = ~twin | (near[np.maximum(sibling, 0)] < clearance)
        footprints(twin & wanted)
        # The wrist: the tool's yaw changes, less what the base swing carries along, are the
        # last joint's turns over its axis' vertical component: from home to the pick (the
        # first motion slerps the tool's orientation the shorter way round, so its yaw turns
        # by the wrapped difference, of which the base swing to the pick carries part), then
        # over the transfer (the pick's yaw to the place's, less the swing between them: the
        # via-point turns with the swing). Without a vertical last axis, or without limits,
        # the margin is inf.
        yaw0, azimuth0, q0 = self._home_yaw, self._home_azimuth, robot.q_home
        if start is not None:
            p0 = start.X_WG.translation() - base
            yaw0, azimuth0, q0 = yaw_of(start.X_WG.rotation()), math.atan2(p0[1], p0[0]), start.q
        to_pick = _wrap(yaw_pick - yaw0) - _wrap(np.arctan2(*from_pick.T[::-1]) - azimuth0)
        p_to = p_place[:, :2] - base[:2]
        swing = _wrap(np.arctan2(*p_to.T[::-1]) - np.arctan2(*from_pick.T[::-1]))
        transfer = _wrap(np.arctan2(R_place[:, 1, 0], R_place[:, 0, 0]) - yaw_pick - swing)
        travel = np.abs(to_pick) + np.abs(transfer)
        margin = np.full(n, np.inf)
        j = robot.n_joints - 1
        if abs(self.wrist_axis_z) >= 0.5 and not robot.continuous[j]:
            q_pick = q0[j] + to_pick / self.wrist_axis_z
            q_place = q_pick + transfer / self.wrist_axis_z
            qs = np.stack([q_pick, q_place])
            margin = np.minimum(qs - robot.q_min[j], robot.q_max[j] - qs).min(axis=0)
        r = X_WO_pick.apply(self.p_O_com) - p_pick
        weight = np.array([0.0, 0.0, -sc.brick_mass * GRAVITY])
        torque = np.abs(np.einsum("ni,ni->n", R_pick[:, :, 1], np.cross(r, weight)))
        out = []
        for i, g in enumerate(grasps):
            if not wanted[i]:
                continue
            problem = None
            if far[i] > self.reach:
                problem = (
                    f"{_UNREACHABLE}: the tool is {far[i]:.3f} m from the arm's first joint, "
                    f"beyond its reach {self.reach:.3f} m (the sum of its link lengths)"
                )
            elif near[i] < clearance:
                problem = "footprint"  # worded below, for the best-ranked only
            out.append(
                Ranked(
                    g,
                    problem,
                    float(near[i]),
                    float(margin[i]),
                    float(travel[i]),
                    float(torque[i]),
                    float(candidates.arms[i]),
                    bool(near_walls[i] < clearance + FOOTPRINT_MARGIN),
                )
            )
        out.sort(key=Ranked.key)
        if out[0].problem == "footprint":
            out[0] = replace(out[0], problem=self._footprint_text(X_WO_pick, X_WO_place, out[0]))
        return out

    def bin_at(self, X_WO: SE3) -> BinGeometry | None:
        """The bin whose inner walls the brick's centre lies within (the source bin first),
        or None: a brick on the ground beside the bins (after a drop)."""
        p_WO = X_WO.translation()
        for bin_ in (self.scene.source_bin, self.scene.target_bin):
            if bin_.contains_xy(p_WO):
                return bin_
        return None

    def _footprint_text(self, X_WO_pick: SE3, X_WO_place: SE3, ranked: Ranked) -> str:
        """The cheap footprint problem of a candidate, in words."""
        g, clearance = ranked.grasp, self.preflight.config.clearance
        X_WG_pick = X_WO_pick @ g.X_OG
        base = self.scene.robot.p_W_base
        X_WG_place = choose_place_pose(
            X_WO_place, g.X_OG, swung_pose(X_WG_pick, X_WO_place.translation(), base)
        )
        for what, X, bin_ in (
            ("pick", X_WG_pick, self.bin_at(X_WO_pick)),
            ("place", X_WG_place, self.bin_at(X_WO_place)),
        ):
            if bin_ is None:
                continue
            width = g.open_width if what == "pick" else self.config.open_width
            found = self.hand.problem(X, width, bin_, clearance)
            if found is not None:
                return (
                    f"{found.geom} of the hand open to {width * 1000:.0f} mm comes within "
                    f"{found.distance * 1000:.1f} mm of {found.where} at the {what} (its "
                    f"footprint; clearance {clearance * 1000:.0f} mm)"
                )
        return "the open hand's footprint"

    def _grasp_set(self, turn: FloatArray | None) -> GraspSet:
        """The candidates (``turn`` None: the object's; else :meth:`turned_grasps`), with what
        the ranking needs of them."""
        if turn is None or np.array_equal(turn, np.eye(3)):
            return self._set
        key = np.asarray(turn, dtype=np.float64).tobytes()
        if key not in self._turned:
            self._turned[key] = self.turned_grasps(turn)
        return self._turned[key]

    def turned_grasps(self, turn: FloatArray) -> GraspSet:
        """The grasp candidates of the box with its frame O turned to ``O' = O · turn``: those
        of the box lying with O''s z up, sizes ``|turn|ᵀ h`` (:func:`~pickplace.planning.
        candidates.box_grasps`), each also with the pads raised up its side, expressed in O
        (``X_OG = turn · X_O'G``), less those where more of the hand than the pads touches it.

        Raises:
            PlanError: The object is not a box (only a box's frame is turned onto a face), or
                the gripper opens to none of its turned face pairs.
            ObjectError: More of the hand than its pads touches the box at every one of them.
        """
        box = self.scene.object.box_half_extents
        if box is None:
            raise PlanError(
                f"only a box's grasps are turned onto another face; the object is "
                f"{self.scene.object.kinds}; valid: turn=None"
            )
        R = np.asarray(turn, dtype=np.float64)
        X_OO = SE3.from_rotation(SO3.from_matrix(R))
        h = turned_half_extents(box, R)
        # Standing, the box is taller than it lies: the pads also grip up its side, the palm
        # above its top.
        turned = [
            replace(g, X_OG=X_OO @ g.X_OG)
            for g in box_grasps(
                h,
                self.config.open_width,
                self.pad_half_length,
                height_fractions=GRASP_HEIGHT_FRACTIONS,
                pad_half_height=self.pad_half_height,
            )
        ]
        if not turned:
            raise PlanError(
                f"the gripper opens to {self.config.open_width * 1000:.0f} mm, too little for "
                "any pair of the box's faces beside the one it rests on; valid: the box lying"
            )
        return self._clear_of_hand(GraspSet.of(turned, self.p_O_com), 2.0 * float(h[2]))

    def grasps(self) -> list[GraspCandidate]:
        """The object's grasp candidates, in generation order (module docstring)."""
        return list(
            object_grasps(
                self.scene.object,
                self.config.open_width,
                (self.pad_half_length, self.pad_half_height),
                self.pad_friction,
            )
        )

    def _clear_of_hand(self, candidates: GraspSet, height: float) -> GraspSet:
        """The ``candidates`` whose hand, but for the pads, keeps :data:`~pickplace.planning.
        candidates.HAND_OBJECT_MARGIN` from the object, open around it and closed on it
        (:class:`~pickplace.planning.candidates.HandObjectGaps`), in their order; ``height``
        [m]: how tall the object stands, for the refusal.

        Raises:
            ObjectError: None does: the message names the nearest geom of the best one.
        """
        gaps, grasps = self._hand_gaps, candidates.grasps
        R_OG, p_OG = candidates.R_OG, candidates.p_OG
        margin = HAND_OBJECT_MARGIN
        closed = gaps.gaps(R_OG, p_OG, np.array([g.width for g in grasps]), margin)
        opened = gaps.gaps(R_OG, p_OG, candidates.open_widths, margin)
        near = np.minimum(closed[0], opened[0])
        keep = near >= margin
        if keep.any():
            return candidates.select(keep)
        i = int(np.argmax(near))
        is_closed = bool(closed[0][i] <= opened[0][i])
        dists, geoms = closed if is_closed else opened
        dist, geom = float(dists[i]), int(geoms[i])
        shape = self.scene.object
        state = "closed on it" if is_closed else "open around it"
        raise ObjectError(
            f"the object ({shape.kinds}, {height * 1000:.0f} mm tall) is "
            f"touched by more of the hand than its pads at every grasp: at the best "
            f"({grasps[i].label}) {gaps.hand.names[geom]} with the fingers {state} comes "
            f"within {dist * 1000:.1f} mm of it; valid: an object whose sides the pads reach "
            "with the rest of the hand clear of it"
        )

    def timed_plan(
        self, X_WO_pick: SE3, X_WO_place: SE3, grasp: GraspCandidate, start: Start | None = None
    ) -> tuple[Plan, PreflightResult, str | None]:
        """One candidate: the path swept by the pre-flight, then (if it passes) timed by the
        robot's limits and pre-flighted again as timed; from ``start`` (default: home).

        Returns:
            The timed plan, its pre-flight and the timing's warning (None if the slip budget
            held); or, when the path sweep fails, the swept plan, the sweep's result (its first
            problem is on the path, whatever the timing) and None.
        """
        q_start = None if start is None else start.q
        sweep = self.sweep_config
        for slower in range(SWEEP_SLOWDOWNS + 1):
            path = self.make_plan(X_WO_pick, X_WO_place, grasp, sweep, start)
            swept = self.preflight.run(path, X_WO_pick, X_WO_place, q_start=q_start)
            problem = swept.problem
            if problem is None or not problem.lagging or slower == SWEEP_SLOWDOWNS:
                break
            # The sweep outran the joints (its speed is the pre-flight's spacing, not the
            # robot's): the same path again at half the speed, twice the ticks.
            sweep = _at_half_speed(sweep)
        if not swept.feasible:
            return path, swept, None
        return self._timed(path, swept, X_WO_pick, X_WO_place, q_start)

    def _timed(
        self,
        path: Plan,
        swept: PreflightResult,
        X_WO_pick: SE3,
        X_WO_place: SE3,
        q_start: np.ndarray | None,
    ) -> tuple[Plan, PreflightResult, str | None]:
        """The feasible swept ``path`` timed by the robot's limits and pre-flighted as timed,
        with the timing's warning; a path whose timing stalls (a stretch admits no speed
        within the limits) is the candidate's ``speed-limit`` problem, on the swept plan."""
        try:
            timed, warning = self.retimed(path, swept.times, swept.q)
        except TimingStallError as exc:  # this path has no timing: the candidate's problem
            t = exc.t if math.isfinite(exc.t) else 0.0
            p = path.trajectory.sample(t)[0][4:]
            problem = Problem(t, "speed-limit", str(exc), (float(p[0]), float(p[1]), float(p[2])))
            return path, replace(swept, problem=problem), None
        result = self.preflight.run(timed, X_WO_pick, X_WO_place, q_start=q_start)
        return timed, result, warning

    def planned(
        self, X_WO_pick: SE3, X_WO_place: SE3, grasp: GraspCandidate, start: Start | None = None
    ) -> tuple[Plan, PreflightResult, str | None, CSpaceAttempt | None]:
        """One candidate as :meth:`timed_plan` plans it (from ``start``, default home), and,
        when its path sweep collides or meets a singularity in the transfer, with the transfer
        planned in C-space instead (:meth:`cspace_plan`).

        Returns:
            The plan, its pre-flight, the timing's warning and the C-space attempt (None when
            the Cartesian plan was kept). When the C-space planning finds no path, the
            Cartesian sweep with its collision, the C-space problem added to its text.
        """
        plan, result, warning = self.timed_plan(X_WO_pick, X_WO_place, grasp, start)
        problem, phases = result.problem, plan.phases
        if (
            problem is None
            or problem.kind not in ("collision", "singularity")
            or phases is None
            or not phases.transport[0] < problem.t <= phases.transport[1]
            or any(law is not None for law in plan.trajectory.laws)  # the timed plan's
        ):
            return plan, result, warning, None
        return self.cspace_plan(X_WO_pick, X_WO_place, plan, result, start)

    def cspace_plan(
        self,
        X_WO_pick: SE3,
        X_WO_place: SE3,
        path: Plan,
        swept: PreflightResult,
        start: Start | None = None,
    ) -> tuple[Plan, PreflightResult, str | None, CSpaceAttempt]:
        """The swept Cartesian ``path`` with its transfer (lift → pre-place) planned in
        C-space, swept, timed and pre-flighted again (see the module docstring).

        Args:
            X_WO_pick: Brick pose to pick, in world.
            X_WO_place: Goal pose of the brick.
            path: The candidate's swept Cartesian plan, whose transfer collides or meets a
                singularity.
            swept: Its path sweep's pre-flight, with that problem.
            start: Where the plan starts (default: home).
        """
        q_start = None if start is None else start.q
        t0 = time.perf_counter()
        problem = swept.problem
        assert problem is not None
        sc, dt = self.scene, self.preflight.dt
        phases = path.phases
        assert phases is not None and path.X_OG is not None  # a pick-and-place plan
        keyframes = path.trajectory.keyframes
        times = [k.t for k in keyframes]
        i_lift, i_pre = (
            _keyframe_at(times, phases.transport[0]),
            _keyframe_at(times, phases.transport[1]),
        )
        # The IK's joint positions along the whole Cartesian path (through the collision: the
        # IK does not see it), at the lift and the pre-place, refined to their poses.
        full = self.preflight.run(
            path, X_WO_pick, X_WO_place, stop_at_problem=False, q_start=q_start
        )
        q_lift = self._exact(full.q[round(times[i_lift] / dt)], keyframes[i_lift].X_WG)
        q_pre = self._exact(full.q[round(times[i_pre] / dt)], keyframes[i_pre].X_WG)
        if q_lift is None or q_pre is None:
            what = "start (the lift)" if q_lift is None else "goal (the pre-place)"
            result = CSpaceResult(
                None,
                f"the c-space path's {what}: the IK's configuration there does not refine to "
                f"the keyframe's pose within the joint ranges (near a singularity)",
                time.perf_counter() - t0,
                0,
            )
        else:
            result = self._joint_path(path, X_WO_pick, X_WO_place, q_lift, q_pre)
        self._cspace_time += time.perf_counter() - t0
        attempt = CSpaceAttempt(problem, result)
        if result.path is None:
            text = f"{problem.text}; {result.problem}"
            return path, replace(swept, problem=replace(problem, text=text)), None, attempt
        motion = JointMotion(result.path, ArmKinematics(sc))
        swept_plan = self._with_joint_transfer(path, i_lift, i_pre, motion)
        swept = self.preflight.run(swept_plan, X_WO_pick, X_WO_place, q_start=q_start)
        if not swept.feasible:
            return swept_plan, swept, None, attempt
        return (*self._timed(swept_plan, swept, X_WO_pick, X_WO_place, q_start), attempt)

    def _joint_path(
        self,
        path: Plan,
        X_WO_pick: SE3,
        X_WO_place: SE3,
        q_lift: np.ndarray,
        q_pre: np.ndarray,
    ) -> CSpaceResult:
        """OMPL's joint path from ``q_lift`` to ``q_pre`` [rad] with the held brick of
        ``path``, collision-checked by the pre-flight's check at its clearance plus the
        C-space's extra clearance (:meth:`cspace_plan`)."""
        sc = self.scene
        assert path.X_OG is not None  # a pick-and-place plan
        X_GO = path.X_OG.inverse()
        width = grasp_width(path, sc)
        kinds = self.preflight.pair_kinds(X_WO_pick, X_WO_place)
        kin = ArmKinematics(sc)

        def check(q: np.ndarray) -> tuple[float, tuple[str, str, tuple[float, ...]] | None]:
            kin.update(q)
            return self.preflight.clearance(q, width, kin.X_WG() @ X_GO, kinds, True)

        robot, margin = sc.robot, 2.0 * self.preflight.config.joint_margin
        # Within the ranges less twice the joint margin, widened to take in the two ends
        # (the pre-flight keeps a joint one margin from its limit, not two); a continuous
        # joint within a turn beyond them.
        ends = np.minimum(q_lift, q_pre), np.maximum(q_lift, q_pre)
        low = np.where(
            robot.continuous, ends[0] - math.pi, np.minimum(robot.q_min + margin, ends[0])
        )
        high = np.where(
            robot.continuous, ends[1] + math.pi, np.maximum(robot.q_max - margin, ends[1])
        )
        self._attempts += 1
        return plan_joint_path(
            check,
            q_lift,
            q_pre,
            low,
            high,
            self.lever_arms,
            self.preflight.config.clearance + self.cspace.extra_clearance,
            (self.seed * 7919 + self._attempts) & 0x7FFFFFFF,
            self.cspace,
        )

    def _exact(self, q: np.ndarray, X_WG: SE3, iterations: int = 20) -> np.ndarray | None:
        """``q`` moved (least-norm Gauss-Newton steps) until the tool is at ``X_WG`` [rad];
        None when the steps do not get there (within :data:`EXACT_TOLERANCE`) inside the
        joints' ranges: near a singularity they can run off by whole turns."""
        kin, target = self._kin, X_WG.wxyz_xyz.tolist()
        q = np.array(q, dtype=np.float64)
        error = math.inf
        for _ in range(iterations + 1):
            kin.update(q)
            e = np.array(pose_error_W_floats(kin.wxyz_xyz_list(), target))
            error = float(np.abs(e).max())
            if error < 1e-12:
                break
            q = q + np.linalg.lstsq(kin.J_WG(), e, rcond=None)[0]
        robot = self.scene.robot
        inside = robot.continuous | ((q >= robot.q_min) & (q <= robot.q_max))
        if not (error < EXACT_TOLERANCE and bool(np.all(inside))):
            return None
        return q

    def _with_joint_transfer(
        self, path: Plan, i_lift: int, i_pre: int, motion: JointMotion
    ) -> Plan:
        """The swept ``path`` with the keyframes between the lift and the pre-place dropped,
        both stopping, and the segment between them moving along ``motion`` (its sweep a
        pre-flight tick every :data:`PATH_SPACING` of the path's scaled L1 length, which
        bounds every point's travel)."""
        keyframes = path.trajectory.keyframes
        dt = self.preflight.dt
        ticks = max(2, math.ceil(motion.path.scaled_l1_length() / PATH_SPACING))
        kept = [i for i in range(len(keyframes)) if not i_lift < i < i_pre]
        waypoints = []
        for i in kept:
            k = keyframes[i]
            ends = i in (i_lift, i_pre)
            hold = max(k.hold, ticks * dt) if i == i_pre else k.hold
            waypoints.append(
                Waypoint(
                    k.name,
                    k.X_WG,
                    k.gripper_width,
                    hold,
                    stop=k.stop or ends,
                    curve=k.curve and i != i_pre,
                )
            )
        new = time_keyframes(waypoints, self.sweep_config)
        index = {old: j for j, old in enumerate(kept)}
        old_times = [k.t for k in keyframes]

        def moved(t: float) -> float:
            return new[index[_keyframe_at(old_times, t)]].t

        ph = path.phases
        assert ph is not None
        phases = ph.mapped(moved)
        joints: list[JointSegment | None] = [None] * (len(new) - 1)
        joints[index[i_lift]] = motion
        trajectory = PoseTrajectory(new, self.sweep_config.profile, joint_segments=joints)
        return Plan(trajectory, phases, path.X_OG)

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
        grasp: GraspCandidate | None = None,
        config: PlanConfig | None = None,
        start: Start | None = None,
    ) -> Plan:
        """The pick-and-place plan with ``grasp`` (default: the best-ranked one), the gripper
        opened to the grasp's open width, timed by Cartesian limits (``config``, default the
        planner's), from ``start``'s tool pose (default: home's)."""
        if grasp is None:
            grasp = self.rank(X_WO_pick, X_WO_place, start)[0].grasp
        config = replace(
            config or self.config,
            open_width=grasp.open_width,
            release_width=self.config.open_width,  # the whole opening its open time spans
        )
        return plan_pick_place(
            self.X_WG_home if start is None else start.X_WG,
            X_WO_pick,
            X_WO_place,
            self.clearance_z,
            config,
            p_W_base=self.scene.robot.p_W_base,
            X_OG=grasp.X_OG,
            other_place=grasp.other_place,
        )
