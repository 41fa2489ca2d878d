"""The qp controller's collision limit: it keeps its distance, equals mink's, and sees the world."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from mink.lie import SE3

from pickplace.control.collision import Clearance, GripperBodies, collision_geoms
from pickplace.control.controllers import ControllerError, IKStatus, QPController, QPWeights
from pickplace.robot.registry import DEFAULT_ROBOT, bundled_robots
from pickplace.run.runner import RunRequest, execute
from pickplace.sim.checks import FailureReason
from pickplace.world.scene import Scene

DT = 0.01
# How far below d_min a tool pushed on for 3 s creeps [m]: mink's bound below d_min is 0, not a
# push back, so the second-order motion of the tool turning and sliding under the frame
# task's push closes about 1 mm (measured: 2.0 → 0.99 mm at the bin floor).
CREEP = 1.5e-3


def _min_distance(ctrl: QPController, scene: Scene, world: list[int]) -> float:
    """Smallest distance [m] between the robot's moving collision geoms and ``world`` in the
    controller's own model at its loaded q (capped at 1 m)."""
    m, d = ctrl.kinematics.model, ctrl.kinematics.data
    robot = collision_geoms(scene, m)[0]
    fromto = np.empty(6)
    return min(mujoco.mj_geomDistance(m, d, a, b, 1.0, fromto) for a in robot for b in world)


def _drive_down(ctrl: QPController, scene: Scene, speed: float, ticks: int):
    """Command the tool straight down at ``speed`` [m/s] from above bin 1's centre, through
    its floor; yields the controller after each tick."""
    q = scene.robot.q_home.copy()
    ctrl.set_gripper_width(scene.brick_width)
    ctrl.kinematics.update(q)
    X0 = ctrl.kinematics.X_WG()
    start = scene.source_bin.center_W + np.array([0.0, 0.0, 0.12])
    # First bring the tool over the bin's centre, pointing as it does at home.
    for k in range(ticks):
        p = start + np.array([0.0, 0.0, -speed * DT * max(0, k - 100)])
        target = SE3.from_rotation_and_translation(X0.rotation(), p)
        V = np.zeros(6) if k < 100 else np.array([0.0, 0.0, -speed, 0.0, 0.0, 0.0])
        res = ctrl.command(q, target, V)
        q = q + res.qdot * DT
        ctrl.kinematics.update(q)
        yield ctrl, res


def _bin_floor(scene: Scene, model: mujoco.MjModel) -> list[int]:
    return [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{scene.source_bin.name}_floor")]


def test_a_tool_driven_into_the_bin_floor_stops_at_the_minimum_distance(scene: Scene) -> None:
    """With the limit the fingers stop at d_min above bin 1's floor (the IK limited there) and
    stay within CREEP of it while pushed down for 3 s; without it the commanded fingers go
    through the floor."""
    weights = QPWeights()
    with_limit = QPController(scene, DT, weights)
    floor = _bin_floor(scene, with_limit.kinematics.model)
    seen = [
        (_min_distance(c, scene, floor), res.status)
        for c, res in _drive_down(with_limit, scene, 0.3, 400)
    ]
    distances = np.array([d for d, _ in seen])
    assert distances.min() >= weights.collision_min_distance - CREEP
    assert distances[-1] < weights.collision_min_distance + 1e-3  # it got there, and stayed
    assert seen[-1][1] is IKStatus.LIMITED
    free = QPController(scene, DT, QPWeights(collision_limit=False))
    last = 0.0
    for c, _ in _drive_down(free, scene, 0.3, 400):
        # (its model's fingers sit at the joints' zero: measure in the limited one's model)
        with_limit.kinematics.update(c.kinematics.q)
        last = _min_distance(with_limit, scene, floor)
    assert last < -0.02


def test_the_fast_backend_equals_mink_where_collision_rows_are_active(scene: Scene) -> None:
    fast = QPController(scene, DT, backend="fast")
    ref = QPController(scene, DT, backend="mink")
    active = 0
    for (a_ctrl, a), (_, b) in zip(
        _drive_down(fast, scene, 0.3, 300), _drive_down(ref, scene, 0.3, 300), strict=True
    ):
        np.testing.assert_allclose(a.qdot, b.qdot, atol=1e-8)
        assert a.status is b.status
        active += a_ctrl.collision is not None and a_ctrl.collision.active > 0
    assert active > 50


def test_the_rows_are_the_finite_rows_of_mink_along_a_descent(scene: Scene) -> None:
    ctrl = QPController(scene, DT)
    assert ctrl.collision is not None
    for c, _ in _drive_down(ctrl, scene, 0.3, 300):
        G, h = ctrl.collision.rows(c.kinematics.data)
        mink_G, mink_h = [], []
        for limit in ctrl.collision.limits:
            con = limit.compute_qp_inequalities(c.configuration, DT)
            finite = np.isfinite(con.h)
            mink_G.append(con.G[finite])
            mink_h.append(con.h[finite])
        order = np.lexsort(np.column_stack([G, h]).T)
        ref = np.column_stack([np.concatenate(mink_G), np.concatenate(mink_h)])
        ref = ref[np.lexsort(ref.T)]
        np.testing.assert_allclose(np.column_stack([G, h])[order], ref, atol=1e-12)


def test_an_obstacle_handed_to_the_controller_is_kept_at_its_distance(scene: Scene) -> None:
    """The mocap obstacle moved under the descending tool (in the controller's own data, as
    the loop hands it over) holds the tool at the moving bodies' minimum distance."""
    weights = QPWeights()
    ctrl = QPController(scene, DT, weights)
    m = ctrl.kinematics.model
    body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "obstacle")
    obstacle = [g for g in range(m.ngeom) if m.geom_bodyid[g] == body]
    pos = np.zeros((m.nmocap, 3))
    pos[m.body_mocapid[body]] = scene.source_bin.center_W + np.array([0.0, 0.0, 0.0])
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (m.nmocap, 1))
    ctrl.observe_world(pos, quat)
    distances = [_min_distance(c, scene, obstacle) for c, _ in _drive_down(ctrl, scene, 0.3, 400)]
    assert min(distances) >= weights.moving_min_distance - CREEP
    assert distances[-1] < weights.moving_min_distance + 1e-3


def test_the_ik_models_fingers_sit_where_the_full_models_joints_put_them(scene: Scene) -> None:
    ctrl = QPController(scene, DT)
    gripper = GripperBodies(scene, ctrl.kinematics.model)
    full, d = scene.model, mujoco.MjData(scene.model)
    q = scene.robot.q_home
    for width in (0.0, scene.brick_width, scene.robot.calibration.sweep_gap.max()):
        gripper.set_width(width)
        ctrl.kinematics.update(q)
        d.qpos[scene.robot.arm_qpos_adr] = q
        d.qpos[scene.gripper_qpos_adr] = scene.robot.qpos_for_width(width)
        mujoco.mj_kinematics(full, d)
        for b in gripper.bodies:
            np.testing.assert_allclose(ctrl.kinematics.data.xpos[b], d.xpos[b], atol=1e-12)
            np.testing.assert_allclose(ctrl.kinematics.data.xquat[b], d.xquat[b], atol=1e-12)
    assert scene.robot.gap(d) == pytest.approx(scene.robot.calibration.sweep_gap.max(), abs=2e-3)


def test_pairs_leave_out_the_base_and_the_brick_and_bad_settings_are_refused(
    scene: Scene,
) -> None:
    ctrl = QPController(scene, DT)
    assert ctrl.collision is not None
    m = ctrl.kinematics.model
    bodies = {int(m.geom_bodyid[g]) for pair in ctrl.collision.pair_list for g in pair}
    assert scene.brick_body_id not in bodies
    assert all(m.body_weldid[b] != 0 or not scene.robot_body_mask[b] for b in bodies)
    assert QPController(scene, DT, QPWeights(collision_limit=False)).collision is None
    with pytest.raises(ControllerError, match="valid: 0 <= minimum < detection"):
        QPWeights(collision_min_distance=0.05)
    with pytest.raises(ControllerError, match="valid: 0 <= minimum < detection"):
        Clearance(-0.001, 0.01)
    with pytest.raises(ControllerError, match=r"valid: \(0, 1\]"):
        QPWeights(collision_gain=1.5)


@pytest.mark.slow
@pytest.mark.parametrize("robot", bundled_robots())
def test_fault_obstacle_with_qp_never_touches_the_box(robot: str) -> None:
    """Every bundled robot: the box moved into the transfer path is never touched with qp
    (the tool falls behind the plan instead); without the limit the arm hits it."""
    with_limit = execute(RunRequest(scenario="fault-obstacle", robot=robot)).result
    assert with_limit.failure is FailureReason.IK_FAILED
    assert with_limit.metrics["max_robot_world_contact_force_n"] == 0.0
    if robot == DEFAULT_ROBOT:
        free = execute(
            RunRequest(scenario="fault-obstacle", robot=robot, controller="qp-no-collision")
        ).result
        assert free.failure is FailureReason.COLLISION
