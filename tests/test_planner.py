"""Candidate plans, the choice among them, and what happens when none is feasible."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest
from mink.lie import SE3, SO3

import pickplace.planning.planner as planner_module
from pickplace.geometry import rotation_angle
from pickplace.planning.candidates import (
    GRASP_OFFSET_FRACTIONS,
    GRASP_TILTS,
    GRAVITY,
    TIGHT_LABEL,
    gravity_torque,
)
from pickplace.planning.plan import PlanConfig, plan_pick_place
from pickplace.planning.planner import (
    FOOTPRINT_MARGIN,
    OTHER_PLACE,
    REFUSAL_CAUSES,
    SAME_APPROACH,
    WRIST_MARGIN,
    PickPlacePlanner,
)
from pickplace.planning.preflight import PreflightConfig
from pickplace.robot.calibration import MIN_PAD_CLEARANCE, PAD_CLEARANCE
from pickplace.run.runner import RunRequest, build_task, prepare
from pickplace.sim.checks import FailureReason
from pickplace.sim.loader import load_scene
from pickplace.sim.scenarios import BuildRequest
from pickplace.sim.task import World
from pickplace.world.placements import (
    BrickPlacement,
    brick_on_floor,
    nominal_placement,
    target_placement,
    uniform_placement,
)
from pickplace.world.scene import Scene
from tests.conftest import CliRun, finished, uniform_task
from tests.toy_robot import TOY_TOML, write_toy_robot

# A corner of bin 1 where no grasp fits: the brick against two walls, the WSG's 146 mm palm
# over one of them whichever way it closes.
CORNER = "--brick=-0.16,-0.67,0"


def _poses(scene: Scene, x_B: float, y_B: float, yaw: float) -> tuple[SE3, SE3]:
    p = scene.source_bin.X_WB.apply(np.array([x_B, y_B, 0.0]))
    X_pick = brick_on_floor(
        scene, BrickPlacement(float(p[0]), float(p[1]), yaw), scene.source_bin.floor_top_z
    )
    X_place = brick_on_floor(scene, target_placement(scene), scene.target_bin.floor_top_z)
    return X_pick, X_place


def test_candidates_are_antipodal_opened_by_the_clearance_and_keep_the_pads_on_the_faces(
    scene: Scene,
) -> None:
    """Every candidate closes along a box axis through the box's centre plane, approaches
    perpendicular to it within the largest tilt of vertical, opens to the width plus
    PAD_CLEARANCE a side (and, its tight twin, plus MIN_PAD_CLEARANCE), and keeps the pad on
    the face; each comes with its wrist twin."""
    planner = PickPlacePlanner(scene, "qp")
    half = scene.brick_half_extents
    grasps = planner.grasps()
    # 2 face pairs (the iiwa's WSG opens 100 mm) x 5 tilts x 3 offsets x 2 turns x 2 openings.
    assert len(grasps) == 2 * (2 * len(GRASP_TILTS) - 1) * len(GRASP_OFFSET_FRACTIONS) * 2 * 2
    assert grasps[0].label == "across the width"
    tight = f", opened {MIN_PAD_CLEARANCE * 1000:.0f} mm a side"
    by_label = {g.label: g for g in grasps}
    for g in grasps:
        R = g.X_OG.rotation().as_matrix()
        y_O, z_O, x_O = R[:, 1], R[:, 2], R[:, 0]
        axis = int(np.argmax(np.abs(y_O)))
        assert abs(abs(y_O[axis]) - 1.0) < 1e-12  # closing along a box axis: antipodal faces
        assert axis in (0, 1)
        assert g.width == pytest.approx(2.0 * half[axis], abs=1e-12)
        if g.label.endswith(tight):
            assert g.open_width == pytest.approx(g.width + 2.0 * MIN_PAD_CLEARANCE, abs=1e-12)
            full = by_label[g.label.removesuffix(tight)]  # the same pads, opened wider
            assert full.X_OG is g.X_OG or np.allclose(full.X_OG.wxyz_xyz, g.X_OG.wxyz_xyz)
        else:
            assert g.open_width == pytest.approx(g.width + 2.0 * PAD_CLEARANCE, abs=1e-12)
        p = g.X_OG.translation()
        assert abs(p[axis]) < 1e-12 and abs(p[2]) < 1e-12  # midway between the faces
        assert math.acos(float(np.clip(-z_O[2], -1.0, 1.0))) == pytest.approx(abs(g.tilt))
        assert abs(x_O[2]) == pytest.approx(math.sin(abs(g.tilt)), abs=1e-12)
        along = 1 - axis  # the offset runs along the face, horizontally
        assert abs(p[along]) + planner.pad_half_length <= half[along] + 1e-12
        assert abs(p[along]) == pytest.approx(abs(g.offset), abs=1e-12)
    for g in grasps:
        if g.turned:
            twin = by_label[g.label.replace(", turned 180°", "")]
            np.testing.assert_allclose(g.X_OG.translation(), twin.X_OG.translation(), atol=1e-15)
            R, R_twin = g.X_OG.rotation(), twin.X_OG.rotation()
            assert rotation_angle(R, R_twin) == pytest.approx(math.pi)


def test_the_weight_s_torque_about_the_pads_is_weight_times_offset(scene: Scene) -> None:
    """Whatever the tilt (a turn about the pad axis itself), m g times the offset."""
    planner = PickPlacePlanner(scene, "qp")
    X_pick, _ = _poses(scene, 0.0, 0.0, 0.7)
    m = scene.brick_mass
    for g in planner.grasps():
        tau = gravity_torque(X_pick, g.X_OG, np.zeros(3), m)
        assert tau == pytest.approx(m * GRAVITY * abs(g.offset), abs=1e-12)


@pytest.mark.parametrize(
    ("open_width", "length_clearance"),
    [(0.088, PAD_CLEARANCE), (0.08, 0.0025), (0.0789, None), (0.0785, None)],
)
def test_a_narrow_gripper_closes_across_the_length_with_what_it_opens_beyond_it(
    scene: Scene, open_width: float, length_clearance: float | None
) -> None:
    """Closing across the 75 mm length: 6 mm a side where the fingers open to 87 mm, what
    they open beyond it a side down to MIN_PAD_CLEARANCE (80 mm: 2.5 mm), none below 79 mm;
    across the 50 mm width always 6 mm. Where a side has more than MIN_PAD_CLEARANCE, its
    tight twin opens only that a side as well."""
    planner = PickPlacePlanner(scene, "qp", PlanConfig(open_width=open_width))
    length = 2.0 * float(scene.brick_half_extents[0])
    by_name: dict[str, set[float]] = {}
    for g in planner.grasps():
        by_name.setdefault(g.label.split(",")[0], set()).add(round(g.open_width - g.width, 12))
    both = {round(2.0 * PAD_CLEARANCE, 12), round(2.0 * MIN_PAD_CLEARANCE, 12)}
    assert by_name["across the width"] == both
    if length_clearance is None:
        assert "across the length" not in by_name
        assert length + 2.0 * MIN_PAD_CLEARANCE > open_width
    else:
        tight = round(2.0 * MIN_PAD_CLEARANCE, 12)
        assert by_name["across the length"] == {round(2.0 * length_clearance, 12), tight}


def test_the_open_hand_s_footprint_is_the_distance_of_its_hulls_to_the_walls(
    scene: Scene,
) -> None:
    """The hand straight down over bin 1's centre: its smallest distance to the walls is the
    inner half width less the largest extent along that axis of each hull's part below the
    walls' top (computed here from every pair of a hull's vertices, not from its edges); moved
    towards the +y wall by d, the distance falls by d."""
    planner = PickPlacePlanner(scene, "qp")
    hand, width = planner.hand, 0.062
    bin_ = scene.source_bin
    floor_z = float(bin_.to_bin_frame(bin_.center_W)[2])
    R_BG = np.diag([1.0, -1.0, -1.0])  # pointing down
    p = np.array([0.0, 0.0, floor_z + 0.025])

    def distance(shift: float) -> float:
        d, _, _ = hand.distances(R_BG[None], (p + np.array([0.0, shift, 0.0]))[None], width, bin_)
        return float(d[0])

    P = hand.hull_G(width) @ R_BG.T + p
    top = floor_z + bin_.wall_top_z - bin_.floor_top_z
    low = []
    for k in range(len(hand.geom_ids)):
        V = P[hand.hull_geom == k]
        below, above = V[V[:, 2] < top], V[V[:, 2] >= top]
        low.append(below)
        for a in below:  # where the segment to each vertex above crosses the top
            t = (top - a[2]) / (above[:, 2] - a[2])
            low.append(a + t[:, None] * (above - a))
    pts = np.concatenate(low)
    expected = min(
        float(bin_.inner_half_extents[0] - np.abs(pts[:, 0]).max()),
        float(bin_.inner_half_extents[1] - np.abs(pts[:, 1]).max()),
        float(P[:, 2].min() - floor_z),
    )
    assert distance(0.0) == pytest.approx(expected, abs=1e-12)
    y_extent = float(pts[:, 1].max())
    shift = float(bin_.inner_half_extents[1]) - y_extent - 0.001  # 1 mm from the +y wall
    assert distance(shift) == pytest.approx(0.001, abs=1e-12)
    X_WG = SE3.from_rotation_and_translation(
        SO3.from_matrix(bin_.X_WB.rotation().as_matrix() @ R_BG),
        bin_.X_WB.apply(p + np.array([0.0, shift, 0.0])),
    )
    found = hand.problem(X_WG, width, bin_, 0.005)
    assert found is not None and found.where == "bin1's +y wall"
    assert found.distance == pytest.approx(0.001, abs=1e-12)


@pytest.mark.parametrize("robot", ["iiwa14-wsg50", "panda-hand"])
def test_a_hand_close_to_the_walls_ranks_after_those_with_room(robot: str) -> None:
    """Near bin 1's -y wall, the candidates passing the cheap tests are ranked with those whose
    open hand clears the walls by less than the clearance plus FOOTPRINT_MARGIN after the
    others of the same wrist class, pad clearance and tilt; the flag agrees with the exact
    hull distance at the pick."""
    scene = load_scene(robot=robot)
    planner = PickPlacePlanner(scene, "qp")
    clearance = planner.preflight.config.clearance
    for y_B in (-0.05, -0.06, -0.07, -0.08, -0.09):  # the first with both kinds
        X_pick, X_place = _poses(scene, 0.0, y_B, 0.0)
        passing = [r for r in planner.rank(X_pick, X_place) if r.problem is None]
        if any(r.close_to_bins for r in passing) and any(not r.close_to_bins for r in passing):
            break
    else:
        pytest.fail("no pose 50-90 mm off bin 1's centre has passing candidates of both kinds")
    classes = [
        (
            r.wrist_margin < WRIST_MARGIN,
            r.grasp.open_width - r.grasp.width < 2.0 * PAD_CLEARANCE - 1e-12,
            round(abs(r.grasp.tilt), 9),
            r.close_to_bins,
        )
        for r in passing
    ]
    assert classes == sorted(classes)
    for r in passing:
        X_WG = X_pick @ r.grasp.X_OG
        bin_ = scene.source_bin
        R_BG = bin_.X_WB.inverse().rotation().as_matrix() @ X_WG.rotation().as_matrix()
        p_BG = bin_.to_bin_frame(X_WG.translation())
        _, walls = planner.hand.clearances(
            R_BG[None], p_BG[None], r.grasp.open_width, bin_, math.inf, math.inf
        )
        if walls[0] < clearance + FOOTPRINT_MARGIN:  # close at the pick (maybe at the place)
            assert r.close_to_bins
        assert r.clearance >= clearance


def test_after_a_singularity_the_same_approach_is_not_pre_flighted_again() -> None:
    """The Menagerie UR5e reaching for the jar at bin 1's far side: the vertical approach meets
    a singularity with both wrist turns, and the next candidate pre-flighted approaches along
    another axis (every closing direction of the vertical approach would meet it again), which
    is feasible."""
    scene, _ = build_task(
        RunRequest(scenario="pick-place-uniform", robot="menagerie-ur5e-2f85", object="jar"),
        refuse_infeasible=False,
    )
    placement = uniform_placement(scene, np.random.default_rng(98054))
    X_pick = brick_on_floor(scene, placement, scene.source_bin.floor_top_z)
    X_place = brick_on_floor(scene, target_placement(scene), scene.target_bin.floor_top_z)
    planner = BuildRequest(scene, "pick-place-uniform", 98054).planner()
    report = planner.plan(X_pick, X_place)
    by_label = {g.label: g for g in planner.grasps()}
    axes = [
        X_pick.rotation().as_matrix()
        @ by_label[c.label.removesuffix(OTHER_PLACE)].X_OG.rotation().as_matrix()[:, 2]
        for c in report.candidates
    ]
    kinds = [
        None if c.preflight.problem is None else c.preflight.problem.kind for c in report.candidates
    ]
    assert kinds.count("singularity") >= 2
    for i in range(len(axes)):
        same = [
            j
            for j in range(i)
            if kinds[j] == "singularity" and float(axes[j] @ axes[i]) > math.cos(SAME_APPROACH)
        ]
        assert len(same) < 2  # never a third try of an axis that met a singularity twice
    assert report.feasible


def test_a_candidate_that_fails_after_the_lift_is_tried_placed_the_other_way_round() -> None:
    """iiwa14-wsg50, a uniform pose near its base (seed 98746): the best candidate's transfer
    to the place the wrist's yaw prefers takes joint 4 to its limit; the same grasp placing
    the brick the other way round (its half-turn symmetry, the tool leaning the other way) is
    pre-flighted next and is feasible. Only a failure after the lift makes such a twin: a
    failure at the pick would be met again."""
    _, planner, X_pick, X_place = uniform_task("iiwa14-wsg50", 98746)
    report = planner.plan(X_pick, X_place, first_feasible=False)
    suffix = OTHER_PLACE
    labels = [c.label for c in report.candidates]
    for i, c in enumerate(report.candidates):
        if c.label.endswith(suffix):
            twin = report.candidates[i - 1]
            assert twin.label == c.label.removesuffix(suffix)
            problem, phases = twin.preflight.problem, twin.plan.phases
            assert problem is not None and phases is not None
            assert problem.t > phases.transport[0]
        else:
            problem, phases = c.preflight.problem, c.plan.phases
            failed_late = (
                problem is not None
                and problem.kind != "singularity"
                and problem.t > phases.transport[0]
            )
            twin_tried = i + 1 < len(labels) and labels[i + 1] == c.label + suffix
            assert twin_tried == failed_late or i + 1 == len(labels)
    first, second = report.candidates[:2]
    assert first.preflight.problem is not None and first.preflight.problem.kind == "joint-limit"
    assert second.label == first.label + suffix and second.preflight.feasible
    assert report.chosen == 1
    # The same pick; the places put the brick at the goal, turned by half a turn.
    X_WG = [c.plan.trajectory.keyframes[i].X_WG for c in (first, second) for i in (2, -2)]
    assert np.allclose(X_WG[0].wxyz_xyz, X_WG[2].wxyz_xyz, atol=1e-12)
    X_OG = np.linalg.inv(X_pick.as_matrix()) @ X_WG[0].as_matrix()
    placed = [X_WG[k].as_matrix() @ np.linalg.inv(X_OG) for k in (1, 3)]
    assert np.allclose(placed[0][:3, 3], X_place.translation(), atol=1e-12)
    assert np.allclose(placed[1][:3, 3], X_place.translation(), atol=1e-12)
    assert np.allclose(
        placed[0][:3, :3] @ np.diag([-1.0, -1.0, 1.0]), placed[1][:3, :3], atol=1e-12
    )


def test_near_a_wall_the_length_grasp_is_chosen(scene: Scene) -> None:
    """60 mm from the far wall, closing across the width puts the palm over the wall, which the
    footprint sees without a pre-flight; closing across the length does not
    (docs/physics-notes.md, class W)."""
    X_pick, X_place = _poses(scene, 0.0, -0.09, 0.0)
    planner = PickPlacePlanner(scene, "qp")
    ranked = planner.rank(X_pick, X_place)
    width = [r for r in ranked if r.grasp.label.startswith("across the width") and not r.grasp.tilt]
    assert width and all(r.problem is not None for r in width)
    report = planner.plan(X_pick, X_place)
    assert report.feasible
    chosen = report.candidates[report.chosen or 0]
    assert chosen.label.startswith("across the length")
    assert not any(c.label.startswith("across the width") for c in report.candidates)


def test_a_brick_resting_against_a_wall_is_picked(scene: Scene) -> None:
    """3 mm from bin 1's -y wall, within the 5 mm clearance where it lies: that pair counts in
    the transport only, not as it leaves straight up, and the brick is picked."""
    half = scene.source_bin.inner_half_extents
    X_pick, X_place = _poses(scene, 0.0, -(float(half[1]) - 0.025 - 0.003), 0.0)
    planner = PickPlacePlanner(scene, "qp")
    kinds = planner.preflight.pair_kinds(X_pick, X_place)
    assert kinds[scene.brick_geom_id, scene.model.geom("bin1_wall_ny").id] == 4
    assert kinds[scene.brick_geom_id, scene.model.geom("bin1_wall_py").id] == 2
    report = planner.plan(X_pick, X_place)
    assert report.feasible, report.problems()


def test_a_tight_twin_is_ranked_only_where_its_sibling_fails_the_footprint() -> None:
    """ur5e-2f85, a uniform pose along bin 1's wall (seed 98680): every grasp opened 6 mm a
    side puts a finger within the clearance of the wall; the same grasp opened 2 mm a side
    fits and plans. No tight twin is ranked whose sibling passes the cheap tests."""
    _, planner, X_pick, X_place = uniform_task("ur5e-2f85", 98680)
    ranked = planner.rank(X_pick, X_place)
    by_label = {r.grasp.label: r for r in ranked}
    assert all(r.problem is not None for r in ranked if not r.grasp.tight)
    tight = [r for r in ranked if r.grasp.tight]
    assert tight and tight[0].problem is None
    for r in tight:
        sibling = by_label[r.grasp.label.removesuffix(TIGHT_LABEL)]
        assert sibling.problem is not None and sibling.cheap_test == "footprint"
        assert r.grasp.open_width == pytest.approx(r.grasp.width + 2.0 * MIN_PAD_CLEARANCE)
        assert sibling.grasp.X_OG is r.grasp.X_OG or np.allclose(
            sibling.grasp.X_OG.wxyz_xyz, r.grasp.X_OG.wxyz_xyz
        )
        if r.problem is None:  # opened less, the hand keeps more room from the walls
            assert r.clearance > sibling.clearance
    report = planner.plan(X_pick, X_place)
    assert report.feasible
    assert report.candidates[report.chosen or 0].label.endswith(TIGHT_LABEL)


@pytest.mark.slow
def test_a_brick_along_a_wall_is_picked_with_the_tight_twin() -> None:
    """The pose above, in the physics: the pads opened 2 mm a side come down beside the
    brick, close on it and place it."""
    result = finished("pick-place-uniform", seed=98680, robot="ur5e-2f85").result
    s = result.summary()
    assert s["success"], s.get("failure_text")
    assert s["max_robot_world_contact_force_n"] == 0.0


def test_swing_via_point_equals_the_shortest_arc_under_a_half_turn(scene: Scene) -> None:
    """The via-point turns with the base swing; when the total turn is under π that is the
    shortest arc, and when it is over π it goes the long way, with the swing."""
    planner = PickPlacePlanner(scene, "qp")

    def via(plan: Any) -> SE3:
        return next(k.X_WG for k in plan.trajectory.keyframes if k.name == "clearance")

    for yaw, same in ((0.0, True), (-0.212, False)):
        X_pick, X_place = _poses(scene, -0.121, 0.002, yaw)
        plans = [
            plan_pick_place(
                planner.X_WG_home,
                X_pick,
                X_place,
                planner.clearance_z,
                PlanConfig(),
                p_W_base=scene.robot.p_W_base,
                via=v,
            )
            for v in ("swing", "shortest")
        ]
        angle = rotation_angle(via(plans[0]).rotation(), via(plans[1]).rotation())
        if same:
            assert angle <= 1e-12
        else:
            assert angle == pytest.approx(math.pi, abs=1e-9)  # halfway the other way round


def test_no_feasible_plan_ends_the_run_before_any_physics(scene: Scene) -> None:
    X_pick, X_place = _poses(scene, -0.16, -0.12, 0.0)
    report = PickPlacePlanner(scene, "qp").plan(X_pick, X_place)
    assert not report.feasible and len(report.candidates) == 1
    _, task, sim = prepare(RunRequest())
    task.planning = report
    task.plan = report.plan
    result = sim.run()
    s = result.summary()
    assert result.failure is FailureReason.NO_FEASIBLE_PLAN
    assert report.refusal_cause == s["refusal"] == "footprint"  # the cheap test refused all
    assert (s["ticks"], s["failure_tick"], s["success"]) == (0, 0, False)
    rejected = [e for e in s["events"] if e["kind"] == "plan"]
    assert len(rejected) == 1
    assert s["plan"]["feasible"] is False
    failure = next(e for e in s["events"] if e["kind"] == "failure")
    assert report.refusal() in failure["text"] and "palm" in failure["text"]


def test_corner_brick_is_refused_by_run_and_reported_by_plan(cli: Callable[..., CliRun]) -> None:
    proc = cli("run", CORNER)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr
    assert "no feasible plan" in lines[0] and "move it inwards or turn it" in lines[0]
    proc = cli("plan", CORNER, "--json")
    assert proc.returncode == 1
    report = json.loads(proc.stdout)
    assert report["feasible"] is False and report["chosen"] is None
    assert report["refusal"] == "footprint"
    assert "refusal" not in json.loads(cli("plan", "--json").stdout)  # feasible
    assert len(report["candidates"]) == 1  # the best; none passed the footprint
    for c in report["candidates"]:
        assert c["feasible"] is False
        assert c["problem"]["kind"] == "collision" and "footprint" in c["problem"]["text"]
        assert len(c["problem"]["point"]) == 3


def test_plan_json_and_run_json_carry_the_same_plan(cli: Callable[..., CliRun]) -> None:
    proc = cli("plan", "--json")
    assert proc.returncode == 0, proc.stderr
    planned = json.loads(proc.stdout)
    assert planned["feasible"] and planned["chosen"] == "across the width"
    assert set(planned["margins"]) == {
        "min_clearance_m",
        "min_joint_margin_rad",
        "peak_speed_ratio",
        "min_singular_value",
    }
    assert planned["planning_time_s"] > 0
    names = [k["name"] for k in planned["keyframes"]]
    assert names[0] == "initial" and names[-1] == "retreat"
    # What `pickplace run --json` prints is the run's summary (tests/test_cli.py): the shared
    # nominal run's.
    ran = json.loads(json.dumps(finished().summary()))
    keys = set(planned) - {"scenario", "robot", "controller", "seed", "planning_time_s"}
    keys -= {"planner_time_s"}  # wall clock per planner, in a run summary only with C-space
    assert planned["robot"] == ran["robot"] == "iiwa14-wsg50"
    assert {k: ran["plan"][k] for k in keys} == {k: planned[k] for k in keys}


class _WallMoved:
    """After planning, bin 1's far (−y) wall moves 90 mm inwards, into the open hand's way."""

    name = "wall-moved"

    def __init__(self, scene: Scene) -> None:
        self.wall = scene.model.geom("bin1_wall_ny").id

    def apply(self, world: World, tick: int) -> str | None:
        if tick != 0:
            return None
        world.model.geom_pos[self.wall, 1] += 0.09
        mujoco.mj_forward(world.model, world.data)
        return "bin 1's far wall moved 90 mm inwards"


def test_a_scrape_after_planning_is_a_collision_not_a_success() -> None:
    _, task, sim = prepare(RunRequest())
    task.faults = (_WallMoved(sim.scene),)
    s = sim.run().summary()
    assert s["success"] is False
    assert s["failure"] == "collision"
    assert s["max_robot_world_contact_force_n"] > 0
    failure = next(e for e in s["events"] if e["kind"] == "failure")
    assert "bin1_wall_ny" in failure["text"] and " N at t=" in failure["text"]


@pytest.mark.parametrize("speed_limit", [0.6, 0.4])
def test_a_sweep_that_outruns_slow_joints_is_swept_again_slower(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, speed_limit: float
) -> None:
    """The path sweep's constant speed (its tick spacing) is not the robot's: on an arm whose
    joints turn at most ``speed_limit`` rad/s the IK falls behind it held by the limits; swept
    again slower, the same candidate is feasible, and the timed plan keeps every joint within
    its limit."""
    toml = TOY_TOML.replace(
        "speed_limits = [2.0, 2.0, 2.5, 3.0, 3.0, 3.0]", f"speed_limits = {[speed_limit] * 6}"
    )
    scene = load_scene(robot=write_toy_robot(tmp_path, toml=toml))
    X_WO_pick = brick_on_floor(scene, nominal_placement(scene), scene.source_bin.floor_top_z)
    X_WO_place = brick_on_floor(scene, target_placement(scene), scene.target_bin.floor_top_z)
    monkeypatch.setattr(planner_module, "SWEEP_SLOWDOWNS", 0)
    once = PickPlacePlanner(scene, "qp").plan(X_WO_pick, X_WO_place)
    problem = once.candidates[0].preflight.problem
    assert not once.feasible and problem is not None and problem.lagging, problem
    monkeypatch.undo()
    again = PickPlacePlanner(scene, "qp").plan(X_WO_pick, X_WO_place)
    assert again.feasible and again.chosen == 0
    assert again.candidates[0].preflight.peak_speed_ratio <= 1.0


def test_a_refusal_names_its_cause_from_the_cheap_tests_or_the_pre_flight(scene: Scene) -> None:
    """``refusal_cause``: ``reach`` when every candidate's tool lies beyond the arm's reach,
    else the best candidate's first pre-flight problem; none for a feasible plan, and a run
    summary has the key only when it was refused."""
    X_pick, X_place = _poses(scene, 0.0, 0.0, 0.0)
    planner = PickPlacePlanner(scene, "qp")
    assert planner.plan(X_pick, X_place).refusal_cause is None
    assert "refusal" not in finished().summary()
    far = SE3.from_rotation_and_translation(X_place.rotation(), np.array([3.0, 0.0, 0.035]))
    report = planner.plan(X_pick, far)
    assert report.refusal_cause == "reach" and report.candidates[0].refused_by == "reach"
    assert report.candidates[0].preflight.problem.kind == "ik"
    # Every tool pose "near a singularity": the candidates pass the cheap tests and the
    # pre-flight refuses them for it.
    strict = PickPlacePlanner(scene, "qp", preflight=PreflightConfig(min_singular_value=10.0))
    report = strict.plan(X_pick, X_place)
    assert report.candidates[0].refused_by is None
    assert report.refusal_cause == "singularity" == report.candidates[0].preflight.problem.kind
    kinds = {"ik", "joint-limit", "speed-limit", "singularity", "collision"}  # Problem.kind
    assert set(REFUSAL_CAUSES) == {"reach", "footprint", *kinds}
