"""Only the pads touch what a grasp holds (:class:`pickplace.planning.candidates.
HandObjectGaps`): checked against MuJoCo's own distance between each of the hand's geoms and
the object placed by the grasp through the full kinematics (brute force)."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from mink.lie import SE3, SO3

from pickplace.planning.candidates import HAND_OBJECT_MARGIN, GraspCandidate
from pickplace.planning.planner import PickPlacePlanner
from pickplace.robot.registry import bundled_robots
from pickplace.run.runner import RunRequest, build_task
from pickplace.world.scene import Scene

RNG_SEED = 23


def _planner(robot: str, name: str) -> tuple[Scene, PickPlacePlanner]:
    scene, _ = build_task(RunRequest(robot=robot, object=name), refuse_infeasible=False)
    return scene, PickPlacePlanner(scene, "qp")


def _distances(
    scene: Scene, planner: PickPlacePlanner, g: GraspCandidate, width: float
) -> np.ndarray:
    """MuJoCo's distance [m] of each of the hand's geoms but the pads from the object, the
    object posed by the grasp (its free joint) and the fingers at ``width``, (k,)."""
    m = planner.preflight.model
    d = mujoco.MjData(m)
    robot = scene.robot
    d.qpos[robot.arm_qpos_adr] = robot.q_home
    d.qpos[scene.gripper_qpos_adr] = robot.qpos_for_width(width)
    mujoco.mj_kinematics(m, d)
    X_WG = SE3.from_rotation_and_translation(
        SO3.from_matrix(d.site_xmat[robot.tool_site_id].reshape(3, 3)),
        d.site_xpos[robot.tool_site_id].copy(),
    )
    scene.set_brick_pose(d, X_WG @ g.X_OG.inverse())
    mujoco.mj_kinematics(m, d)
    pads = np.concatenate(robot.pad_geom_ids)
    hand = [int(h) for h in robot.gripper_geom_ids if h not in pads]
    return np.array(
        [
            min(mujoco.mj_geomDistance(m, d, h, int(o), 1.0, None) for o in scene.object.geom_ids)
            for h in hand
        ]
    )


@pytest.mark.parametrize("robot", ["ur5e-2f85", "panda-hand", "iiwa14-wsg50"])
def test_the_kept_can_grasps_touch_the_can_with_the_pads_only_and_the_dropped_ones_do_not(
    robot: str,
) -> None:
    scene, planner = _planner(robot, "can")
    kept = {g.label for g in planner._grasps}
    every = planner.grasps()
    assert 0 < len(kept) < len(every)  # a 100 mm can: the centred grasps put more on it
    rng = np.random.default_rng(RNG_SEED)
    for i in rng.choice(len(every), size=40, replace=False):
        g = every[int(i)]
        nearest = min(_distances(scene, planner, g, w).min() for w in (g.width, g.open_width))
        if g.label in kept:
            assert nearest >= HAND_OBJECT_MARGIN - 1e-9, g.label
        else:
            assert nearest < HAND_OBJECT_MARGIN + 1e-9, g.label


@pytest.mark.parametrize("name", ["can", "jar"])
def test_the_lower_bound_never_exceeds_mujoco_s_distance(name: str) -> None:
    from pickplace.planning.candidates import HandObjectGaps

    scene, planner = _planner("ur5e-2f85", name)
    robot = scene.robot
    pads = np.concatenate(robot.pad_geom_ids)
    others = robot.gripper_geom_ids[~np.isin(robot.gripper_geom_ids, pads)]
    gaps = HandObjectGaps(planner.footprint_of(others), scene.object)
    every = planner.grasps()
    rng = np.random.default_rng(RNG_SEED + 1)
    for i in rng.choice(len(every), size=20, replace=False):
        g = every[int(i)]
        R = g.X_OG.rotation().as_matrix()[None]
        p = g.X_OG.translation()[None]
        bound = gaps._lower_bounds(R, p, g.width)[0]
        exact = _distances(scene, planner, g, g.width)
        assert np.all(bound <= exact + 1e-6), (g.label, bound, exact)
        # MuJoCo's distance below the margin, at least the margin above it.
        margin = 0.01
        found, _ = gaps.gaps(R, p, np.array([g.width]), margin)
        if exact.min() < margin:
            assert found[0] == pytest.approx(exact.min(), abs=1e-6)
        else:
            assert found[0] >= margin - 1e-9


@pytest.mark.parametrize("robot", bundled_robots())
def test_the_brick_keeps_every_grasp_candidate_tilted_up_to_30_degrees(robot: str) -> None:
    """The brick's candidates tilted 30° or less touch it with the pads only on every bundled
    robot (its plans are those it had before the hand was checked against the object); of
    those tilted further, the check keeps some (the palm leaning clear of the brick's top)."""
    _, planner = _planner(robot, "brick")
    kept = {g.label for g in planner._grasps}
    steep = math.radians(30.0) + 1e-9
    for g in planner.grasps():
        if abs(g.tilt) <= steep:
            assert g.label in kept, g.label
    assert any(abs(g.tilt) > steep for g in planner._grasps)


@pytest.mark.parametrize("robot", ["panda-hand", "ur5e-2f85", "menagerie-panda-hand"])
def test_the_can_is_held_nearest_its_centre_of_mass_the_hand_allows(robot: str) -> None:
    """Pads on a cylinder's side touch it along a line, which does not stop it swinging about
    the pad axis: the plan's grasp is the vertical one, of those the hand leaves, whose pad
    axis passes nearest the can's centre of mass (its middle: the lowest such grasp)."""
    scene, task = build_task(RunRequest(robot=robot, object="can"))
    planner = PickPlacePlanner(scene, "qp")
    assert task.planning is not None and task.planning.chosen is not None
    chosen = task.planning.candidates[task.planning.chosen].label
    grasp = next(g for g in planner._grasps if g.label == chosen)
    vertical = [g for g in planner._grasps if g.tilt == 0.0]
    assert grasp.tilt == 0.0
    com_z = float(scene.model.body_ipos[scene.brick_body_id][2])
    heights = [abs(float(g.X_OG.translation()[2]) - com_z) for g in vertical]
    assert abs(float(grasp.X_OG.translation()[2]) - com_z) == pytest.approx(min(heights))
    assert min(heights) > 0.0  # the middle itself puts more of the hand on the can
