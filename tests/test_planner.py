"""Candidate plans, the choice among them, and what happens when none is feasible (issue 12)."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from typing import Any

import mujoco
import numpy as np
import pytest
from mink.lie import SE3

from pickplace.geometry import rotation_angle
from pickplace.planning.grasp import brick_width_across, yaw_of
from pickplace.planning.plan import PlanConfig, plan_pick_place, swung_pose
from pickplace.planning.planner import PickPlacePlanner
from pickplace.run.runner import RunRequest, prepare
from pickplace.sim.checks import FailureReason
from pickplace.sim.task import World
from pickplace.world.placements import BrickPlacement, brick_on_floor, target_placement
from pickplace.world.scene import Scene
from tests.conftest import CliRun, finished

# A corner of bin 1 where no grasp fits: 60 mm from two walls, turned 45°.
CORNER = "--brick=-0.14,-0.64,0.785"


def _poses(scene: Scene, x_B: float, y_B: float, yaw: float) -> tuple[SE3, SE3]:
    p = scene.source_bin.X_WB.apply(np.array([x_B, y_B, 0.0]))
    X_pick = brick_on_floor(
        scene, BrickPlacement(float(p[0]), float(p[1]), yaw), scene.source_bin.floor_top_z
    )
    X_place = brick_on_floor(scene, target_placement(scene), scene.target_bin.floor_top_z)
    return X_pick, X_place


def test_candidates_are_the_brick_s_grasp_symmetries_in_the_stated_order(scene: Scene) -> None:
    planner = PickPlacePlanner(scene, "qp")
    X_pick, _ = _poses(scene, 0.0, 0.0, 0.3)
    grasps = list(planner.grasps(X_pick))
    labels = [label for label, _ in grasps]
    assert labels == [
        "across the width",
        "across the width, turned 180°",
        "across the length",
        "across the length, turned 180°",
    ]
    half = scene.brick_half_extents
    widths = [brick_width_across(X_OG, half) for _, X_OG in grasps]
    np.testing.assert_allclose(widths, [0.05, 0.05, 0.075, 0.075], atol=1e-12)
    # Each is a top-down grasp at the brick's centre, a quarter turn apart about its z.
    R = [X_OG.rotation() for _, X_OG in grasps]
    assert rotation_angle(R[0], R[1]) == pytest.approx(math.pi)
    assert rotation_angle(R[0], R[2]) == pytest.approx(math.pi / 2)
    assert rotation_angle(R[2], R[3]) == pytest.approx(math.pi)
    for _, X_OG in grasps:
        np.testing.assert_allclose(X_OG.translation(), 0.0, atol=1e-15)
    # Of each pair, the first needs the smaller wrist turn from the home yaw carried along by
    # the base swing.
    reference = swung_pose(planner.X_WG_home, X_pick.translation(), scene.robot.p_W_base)
    yaw = yaw_of(reference.rotation())

    def turn(X_OG: SE3) -> float:
        return abs(math.remainder(yaw_of((X_pick @ X_OG).rotation()) - yaw, 2 * math.pi))

    assert turn(grasps[0][1]) <= turn(grasps[1][1])
    assert turn(grasps[2][1]) <= turn(grasps[3][1])


def test_a_narrow_gripper_gets_no_length_grasp(scene: Scene) -> None:
    """Closing across the 75 mm length needs the open fingers to clear it on both sides."""
    planner = PickPlacePlanner(scene, "qp", PlanConfig(open_width=0.08))
    X_pick, _ = _poses(scene, 0.0, 0.0, 0.0)
    assert [label for label, _ in planner.grasps(X_pick)] == [
        "across the width",
        "across the width, turned 180°",
    ]


def test_near_a_wall_the_length_grasp_is_chosen(scene: Scene) -> None:
    """60 mm from the far wall, closing across the width puts the palm over the wall; closing
    across the length does not (planning-failures.md, class W)."""
    X_pick, X_place = _poses(scene, 0.0, -0.09, 0.0)
    report = PickPlacePlanner(scene, "qp").plan(X_pick, X_place)
    assert report.feasible
    chosen = report.candidates[report.chosen or 0]
    assert chosen.label == "across the length"
    rejected = [c for c in report.candidates if c.preflight.problem is not None]
    assert len(rejected) == 2 and all(c.preflight.problem.kind == "collision" for c in rejected)


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
    X_pick, X_place = _poses(scene, -0.14, -0.09, 0.785)
    report = PickPlacePlanner(scene, "qp").plan(X_pick, X_place)
    assert not report.feasible and len(report.candidates) == 4
    _, task, sim = prepare(RunRequest())
    task.planning = report
    task.plan = report.plan
    result = sim.run()
    s = result.summary()
    assert result.failure is FailureReason.NO_FEASIBLE_PLAN
    assert (s["ticks"], s["failure_tick"], s["success"]) == (0, 0, False)
    rejected = [e for e in s["events"] if e["kind"] == "plan"]
    assert len(rejected) == 4
    assert s["plan"]["feasible"] is False


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
    assert len(report["candidates"]) == 4
    for c in report["candidates"]:
        assert c["feasible"] is False
        assert c["problem"]["kind"] in {"collision", "joint-limit", "ik"}
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
