"""Pushing the object away from a wall where no grasp fits (pickplace/planning/push.py), the
planner's push candidate and the run that picks after it (pickplace/sim/recovery.py)."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from mink.lie import SE3

from pickplace.planning.planner import PickPlacePlanner
from pickplace.planning.push import (
    PUSH_FLOOR_GAP,
    PUSH_OVERSHOOT,
    Push,
    PushTrajectory,
    push_directions,
)
from pickplace.run.runner import RunRequest, object_world, prepare
from pickplace.sim.loader import load_scene
from pickplace.sim.recovery import Reattempt
from pickplace.sim.scenarios import BuildRequest, get_scenario
from pickplace.world.placements import (
    BrickPlacement,
    brick_on_floor,
    footprint_inside,
    random_placement,
    target_placement,
    uniform_placement,
    yaw_of_bin,
)
from pickplace.world.scene import Scene, read_world

# The hands whose long palms leave the most poses beside the walls without a grasp.
PUSHING_ROBOTS = ("panda-hand", "menagerie-panda-hand")
DRAW_SEED = 7_140  # the test's own draw of uniform poses, not a sweep's
DRAWS = 150


@cache
def _refused(robot: str) -> tuple[Scene, PickPlacePlanner, list[tuple[BrickPlacement, SE3]]]:
    """The scene, a planner, and the poses of a uniform draw over bin 1 where no grasp
    candidate is feasible (planned without pushes)."""
    scene = load_scene(robot=robot)
    planner = PickPlacePlanner(scene, "qp")
    rng = np.random.default_rng(DRAW_SEED)
    X_place = _place(scene)
    out = []
    for _ in range(DRAWS):
        p = uniform_placement(scene, rng)
        X = brick_on_floor(scene, p, scene.source_bin.floor_top_z)
        if not planner.plan(X, X_place, push=False).feasible:
            out.append((p, X))
    return scene, planner, out


def _place(scene: Scene) -> SE3:
    return brick_on_floor(scene, target_placement(scene), scene.target_bin.floor_top_z)


def test_a_box_is_pushed_along_its_face_normals_and_a_ball_not_at_all() -> None:
    """The brick's four push directions are its side faces' normals (horizontal, unit, in
    opposite pairs, the pairs at right angles); a can (not a box) gets the bin's axes and
    diagonals; a ball, which rolls, none."""
    scene = load_scene()
    bin_ = scene.source_bin
    X = brick_on_floor(scene, BrickPlacement(0.03, -0.52, 0.4), bin_.floor_top_z)
    dirs = np.array([d for d, _ in push_directions(scene, X, bin_)])
    assert dirs.shape == (4, 3)
    np.testing.assert_allclose(dirs[:, 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(dirs[0], -dirs[1], atol=1e-12)
    np.testing.assert_allclose(dirs[0] @ dirs[2], 0.0, atol=1e-12)
    R = X.rotation().as_matrix()
    np.testing.assert_allclose(np.abs(dirs[0] @ R[:, 0]), 1.0, atol=1e-12)
    can = _with_object("can")
    assert len(push_directions(can, X, bin_)) == 8
    ball = _with_object("ball")
    assert push_directions(ball, X, bin_) == []


def _with_object(name: str) -> Scene:
    world, held = object_world(read_world(), name)
    return load_scene(world, held=held)


@pytest.mark.slow
@pytest.mark.parametrize("robot", PUSHING_ROBOTS)
def test_every_push_starts_clear_low_and_ends_where_a_grasp_is_feasible(robot: str) -> None:
    """Over the refused poses of a uniform draw, every push the planner chooses: its closed
    hand at the start clear of the bin by the pre-flight's clearance and the object's by it to
    within 1 mm over, the hand's lowest point PUSH_FLOOR_GAP above the floor, touching the
    object after its ``touch`` travel (nearer than 0.5 mm); the predicted pose inside the bin
    by the clearance, and a grasp feasible there; the plan pre-flighted, carrying nothing."""
    scene, planner, refused = _refused(robot)
    assert refused, "the draw has no pose beside a wall: nothing tested"
    pusher, clearance = planner.pusher, planner.preflight.config.clearance
    bin_, X_place = scene.source_bin, _place(scene)
    pushed = 0
    for _, X in refused:
        report = planner.plan(X, X_place)
        if not report.feasible:
            continue
        chosen = report.candidates[report.chosen]
        traj = chosen.plan.trajectory
        assert isinstance(traj, PushTrajectory) and chosen.plan.phases is None
        assert chosen.preflight.feasible
        push: Push = traj.push
        X_WG = push.X_WG_start
        assert pusher.hand.problem(X_WG, pusher.width, bin_, clearance) is None
        lowest = (pusher.hull @ X_WG.rotation().as_matrix().T)[:, 2].min() + X_WG.translation()[2]
        assert lowest == pytest.approx(bin_.floor_top_z + PUSH_FLOOR_GAP, abs=1e-9)
        R_WO = X.rotation().as_matrix()

        def gap(X_WG: SE3, X_WO: SE3 = X, R_WO: np.ndarray = R_WO) -> float:
            R_OG = (R_WO.T @ X_WG.rotation().as_matrix())[None]
            p_OG = (R_WO.T @ (X_WG.translation() - X_WO.translation()))[None]
            return float(pusher.gaps.gaps(R_OG, p_OG, np.array([pusher.width]), 1.0)[0][0])

        assert clearance <= gap(X_WG) <= clearance + 1e-3
        touched = SE3.from_rotation_and_translation(
            X_WG.rotation(), X_WG.translation() + push.touch * push.d_W
        )
        assert abs(gap(touched)) < 5e-4
        assert footprint_inside(scene, push.X_WO_after, bin_, clearance)
        np.testing.assert_allclose(
            push.X_WO_after.translation() - X.translation(), push.distance * push.d_W, atol=1e-12
        )
        assert planner.plan(push.X_WO_after, X_place, push=False).feasible
        pushed += 1
    assert pushed, f"no refused pose of the draw ({len(refused)}) was pushed"


def _beside_the_wall(scene: Scene, gap: float) -> SE3:
    """The brick lying along bin 1's +y wall (its long side parallel to it, ``gap`` [m]
    from it), halfway between the bin's centre and its +x wall."""
    bin_ = scene.source_bin
    half = scene.object.box_half_extents
    assert half is not None
    inner = bin_.inner_half_extents
    p_B = np.array([0.5 * inner[0], inner[1] - gap - half[1], 0.0])
    p_W = bin_.X_WB.apply(p_B)
    yaw = yaw_of_bin(bin_.X_WB)
    placement = BrickPlacement(float(p_W[0]), float(p_W[1]), yaw)
    return brick_on_floor(scene, placement, bin_.floor_top_z)


@pytest.mark.parametrize("gap", [0.045, 0.06])
def test_the_hand_behind_a_brick_beside_a_wall_is_clear_low_and_touches_it(gap: float) -> None:
    """For a brick lying along a wall: every start the pusher keeps for the push away from
    that wall has the closed hand clear of the bin by the pre-flight's clearance, the
    object's by it to within 1 mm over, its lowest point PUSH_FLOOR_GAP above the floor;
    moved by its ``touch`` along the push it touches the brick (nearer than 0.5 mm); a twin
    turned half a turn about the approach follows the first (the same place, the wrist the
    other way round)."""
    scene = load_scene()
    planner = PickPlacePlanner(scene, "qp")
    pusher, clearance, bin_ = planner.pusher, planner.preflight.config.clearance, scene.source_bin
    X = _beside_the_wall(scene, gap)
    away = -bin_.X_WB.rotation().as_matrix()[:, 1]  # from the +y wall towards the centre
    (d,) = [d for d, wall in push_directions(scene, X, bin_) if d @ away > 0.99]
    starts = pusher._starts(X, d, bin_)
    assert len(starts) >= 2
    R_WO = X.rotation().as_matrix()

    def gap_to(X_WG: SE3) -> float:
        R_OG = (R_WO.T @ X_WG.rotation().as_matrix())[None]
        p_OG = (R_WO.T @ (X_WG.translation() - X.translation()))[None]
        return float(pusher.gaps.gaps(R_OG, p_OG, np.array([pusher.width]), 1.0)[0][0])

    for X_WG, touch in starts:
        assert pusher.hand.problem(X_WG, pusher.width, bin_, clearance) is None
        R = X_WG.rotation().as_matrix()
        lowest = (pusher.hull @ R.T)[:, 2].min() + X_WG.translation()[2]
        assert lowest == pytest.approx(bin_.floor_top_z + PUSH_FLOOR_GAP, abs=1e-9)
        assert clearance <= gap_to(X_WG) <= clearance + 1e-3
        touched = SE3.from_rotation_and_translation(X_WG.rotation(), X_WG.translation() + touch * d)
        assert abs(gap_to(touched)) < 5e-4
    first, twin = starts[0][0], starts[1][0]
    np.testing.assert_allclose(first.translation()[:2], twin.translation()[:2], atol=2e-3)
    np.testing.assert_allclose(
        first.rotation().as_matrix()[:, 2], twin.rotation().as_matrix()[:, 2], atol=1e-9
    )
    np.testing.assert_allclose(
        first.rotation().as_matrix()[:, 0], -twin.rotation().as_matrix()[:, 0], atol=1e-9
    )


def test_without_pushes_the_planner_never_chooses_one() -> None:
    """A brick lying 15 mm from a wall that no Panda hand's grasp clears: refused with
    ``push=False`` (the planner's or the call's), none of its candidates a push; planned with
    pushes, the chosen candidate is one, carrying nothing, pre-flighted."""
    scene = load_scene(robot="menagerie-panda-hand")
    X, X_place = _beside_the_wall(scene, 0.015), _place(scene)
    for report in (
        PickPlacePlanner(scene, "qp", push=False).plan(X, X_place),
        PickPlacePlanner(scene, "qp").plan(X, X_place, push=False),
    ):
        assert not report.feasible
        assert not any(isinstance(c.plan.trajectory, PushTrajectory) for c in report.candidates)
    pushed = PickPlacePlanner(scene, "qp").plan(X, X_place)
    assert pushed.feasible, pushed.refusal()
    chosen = pushed.candidates[pushed.chosen]
    assert isinstance(chosen.plan.trajectory, PushTrajectory)
    assert chosen.plan.phases is None and chosen.preflight.feasible
    assert chosen.label == chosen.plan.trajectory.push.label


@pytest.mark.slow
@pytest.mark.parametrize("robot", PUSHING_ROBOTS)
def test_a_pushed_brick_is_picked_where_it_came_to_rest_and_placed(robot: str) -> None:
    """The first two refused poses of the draw that get a push, simulated: the run succeeds in
    one attempt whose candidate names the push and then the grasp, the pick planned from where
    the physics left the brick (the replan event), nearer the push's prediction than the
    overshoot the push is planned with (PUSH_OVERSHOOT)."""
    scene, planner, refused = _refused(robot)
    runs = 0
    for p, X in refused:
        report = planner.plan(X, _place(scene))
        if not report.feasible:
            continue
        push = report.candidates[report.chosen].plan.trajectory.push
        _, _, sim = prepare(RunRequest(scenario="pick-place-uniform", robot=robot, brick=p))
        result = sim.run()
        assert result.success, result.failure_text
        (attempt,) = result.attempts
        assert attempt.candidate is not None
        assert attempt.candidate.startswith(push.label + ", then ")
        replans = [e for e in result.events if e.kind.value == "replan"]
        assert len(replans) == 1 and "after the push" in replans[0].text
        rested = sim.log.body_pos[replans[0].tick - 1, scene.brick_body_id]
        # Within the overshoot the push is planned with beyond the shortest feasible push.
        assert np.linalg.norm(rested[:2] - push.X_WO_after.translation()[:2]) < PUSH_OVERSHOOT
        runs += 1
        if runs == 2:
            break
    assert runs, "no refused pose of the draw was pushed"


def test_pick_place_random_draws_again_without_pushing_and_its_replans_may_push() -> None:
    """pick-place-random's draws plan without pushes: a first draw no grasp fits (found among
    the seeds of this test's scan) is drawn again, not pushed; the task's recovery, planning
    with the same planner, may push."""
    scene = load_scene(robot="menagerie-panda-hand")
    off = PickPlacePlanner(scene, "qp", push=False)
    X_place = _place(scene)
    for seed in range(DRAW_SEED, DRAW_SEED + 200):
        first = random_placement(scene, np.random.default_rng(seed))
        X = brick_on_floor(scene, first, scene.source_bin.floor_top_z)
        if not off.plan(X, X_place).feasible:
            break
    else:
        pytest.fail("no first draw of the scan is refused: nothing tested")
    task = get_scenario("pick-place-random").build(
        BuildRequest(scene, "pick-place-random", seed, attempts=3)
    )
    assert task.planning is not None and task.planning.feasible
    assert not isinstance(task.plan.trajectory, PushTrajectory)
    assert not np.allclose(task.X_WO_start.translation(), X.translation())
    assert isinstance(task.recovery, Reattempt) and task.recovery.planner.push
