"""Controllers: the fast QP equals mink.solve_ik; pinv and dls follow their formulas."""

from __future__ import annotations

import mink
import mujoco
import numpy as np
import pytest
from mink.lie import SE3, SO3

from pickplace.control.controllers import (
    DLSController,
    IKStatus,
    PinvController,
    QPController,
    make_controller,
)
from pickplace.control.kinematics import ArmKinematics
from pickplace.errors import UnknownNameError

DT = 0.01


def _targets(scene, rng: np.random.Generator, n: int):
    ctrl = QPController(scene, DT)
    ctrl.kinematics.update(scene.robot.q_home)
    X0 = ctrl.kinematics.X_WG()
    for _ in range(n):
        dR = SO3.exp(rng.normal(0.0, 0.2, 3))
        p = X0.translation() + rng.normal(0.0, 0.05, 3)
        yield SE3.from_rotation_and_translation(dR @ X0.rotation(), p), rng.normal(0, 0.3, 6)


def _step_both(a_ctrl, b_ctrl, q: np.ndarray, X, V, atol: float, same_status: bool = True):
    """One command of each controller from the same state: equal joint velocities (and
    statuses); returns the next q along the first controller's answer."""
    a, b = a_ctrl.command(q, X, V), b_ctrl.command(q, X, V)
    np.testing.assert_allclose(a.qdot, b.qdot, atol=atol)
    if same_status:
        assert a.status is b.status
    return q + a.qdot * DT


def test_fast_qp_equals_mink_solve_ik_on_the_same_problem(scene) -> None:
    fast = QPController(scene, DT, backend="fast")
    ref = QPController(scene, DT, backend="mink")
    rng = np.random.default_rng(0)
    q = scene.robot.q_home.copy()
    for X, V in _targets(scene, rng, 300):
        q = _step_both(fast, ref, q, X, V, atol=1e-8)


def test_fast_qp_matches_a_direct_mink_call(scene) -> None:
    """Independent of our wrapper: build mink's problem by hand and solve it."""
    ctrl = QPController(scene, DT)
    rng = np.random.default_rng(1)
    q = scene.robot.q_home.copy()
    X, V = next(iter(_targets(scene, rng, 1)))
    res = ctrl.command(q, X, V)
    cfg = mink.Configuration(ctrl.kinematics.model, q=q)
    v = mink.solve_ik(cfg, ctrl.tasks, DT, solver="daqp", limits=ctrl.limits)
    np.testing.assert_allclose(res.qdot, v, atol=1e-8)


def test_qp_never_exceeds_the_joint_speed_limits(scene) -> None:
    ctrl = QPController(scene, DT)
    rng = np.random.default_rng(2)
    q = scene.robot.q_home.copy()
    for X, V in _targets(scene, rng, 200):
        res = ctrl.command(q, X, 20.0 * V)  # far faster than the arm can go
        assert np.all(np.abs(res.qdot) <= scene.robot.v_max * (1 + 1e-6))
        q = q + res.qdot * DT
        assert np.all(q >= scene.robot.q_min) and np.all(q <= scene.robot.q_max)


def test_pinv_and_dls_follow_their_formulas(scene) -> None:
    pinv = PinvController(scene, DT, cutoff=1e-6)
    dls = DLSController(scene, DT, damping=0.1)
    rng = np.random.default_rng(3)
    q = scene.robot.q_home.copy()
    for X, V in _targets(scene, rng, 20):
        a = pinv.command(q, X, V)
        np.testing.assert_allclose(a.qdot, np.linalg.pinv(a.J_WG) @ a.V_cmd, atol=1e-10)
        b = dls.command(q, X, V)
        J = b.J_WG
        expected = np.linalg.solve(J.T @ J + 0.01 * np.eye(7), J.T @ b.V_cmd)
        np.testing.assert_allclose(b.qdot, expected, atol=1e-10)
        # Resolved rate: the commanded twist is feed-forward plus K times the pose error.
        np.testing.assert_allclose(b.V_cmd, V + 10.0 * b.error, atol=1e-12)


def test_near_the_stretched_singularity_pinv_explodes_and_qp_stays_limited(scene) -> None:
    """At a bent-elbow pose near full stretch (ε = 0.01, as measured in docs/physics-notes.md,
    "mink 1.3 and the controllers"), pinv asks for a huge joint speed and the QP stays limited."""
    eps = 0.01
    q = np.array([0.0, eps, 0.0, 2 * eps, 0.0, eps, 0.0])
    V = np.array([0.0, 0.0, 0.1, 0.0, 0.0, 0.0])  # 0.1 m/s along the stretched arm
    results = {}
    for name in ("pinv", "qp"):
        ctrl = make_controller(name, scene, DT)
        ctrl.kinematics.update(q)
        X = ctrl.kinematics.X_WG()
        results[name] = ctrl.command(q, X, V)
    assert np.max(np.abs(results["pinv"].qdot) / scene.robot.v_max) > 5.0
    assert np.max(np.abs(results["qp"].qdot) / scene.robot.v_max) <= 1 + 1e-6
    assert results["qp"].status is IKStatus.LIMITED


def test_unknown_controller_and_backend_list_the_valid_ones(scene) -> None:
    with pytest.raises(UnknownNameError, match="valid: dls, pinv, qp"):
        make_controller("newton", scene, DT)
    with pytest.raises(UnknownNameError, match="valid: fast, mink"):
        QPController(scene, DT, backend="osqp")


@pytest.mark.parametrize("name", ["qp", "pinv", "dls"])
def test_result_x_WG_is_the_forward_kinematics_of_q(scene, name: str) -> None:
    ctrl = make_controller(name, scene, DT)
    # On the controller's own model (qp's has its fingers moved to their gap, which moves
    # the arm's subtree centres of mass and so J's last bits).
    kin = ArmKinematics(scene, model=ctrl.kinematics.model)
    rng = np.random.default_rng(4)
    q = scene.robot.q_home.copy()
    for X, V in _targets(scene, rng, 20):
        res = ctrl.command(q, X, V)
        kin.update(q)
        np.testing.assert_array_equal(res.x_WG, kin.wxyz_xyz())
        np.testing.assert_array_equal(res.J_WG, kin.J_WG())
        X_WG = SE3(wxyz_xyz=res.x_WG)
        np.testing.assert_allclose(X_WG.translation(), kin.p_WG(), atol=1e-15)
        np.testing.assert_allclose(X_WG.rotation().as_matrix(), kin.R_WG(), atol=1e-12)
        # The error is the target pose minus this one.
        np.testing.assert_allclose(res.error[:3], X.translation() - kin.p_WG(), atol=1e-15)
        R_err = X.rotation() @ X_WG.rotation().inverse()
        np.testing.assert_allclose(res.error[3:], R_err.log(), atol=1e-12)
        q = q + res.qdot * DT


@pytest.mark.parametrize("name", ["qp", "pinv", "dls"])
def test_successive_results_do_not_alias(scene, name: str) -> None:
    ctrl = make_controller(name, scene, DT)
    rng = np.random.default_rng(5)
    (X1, V1), (X2, V2) = list(_targets(scene, rng, 2))
    q1 = scene.robot.q_home.copy()
    q2 = q1 + 0.05
    first = ctrl.command(q1, X1, V1)
    fields = ("qdot", "V_cmd", "error", "J_WG", "x_WG")
    kept = {f: getattr(first, f).copy() for f in fields}
    second = ctrl.command(q2, X2, V2)
    for f in fields:
        np.testing.assert_array_equal(getattr(first, f), kept[f], err_msg=f)
        for g in fields:
            assert not np.shares_memory(getattr(first, f), getattr(second, g)), (f, g)
    assert not np.array_equal(first.x_WG, second.x_WG)


def test_fast_qp_follows_task_costs_gains_and_targets_changed_on_the_tasks(scene) -> None:
    """The fast backend reads the tasks: changing them after construction is seen."""
    fast = QPController(scene, DT, backend="fast")
    ref = QPController(scene, DT, backend="mink")
    rng = np.random.default_rng(6)
    q = scene.robot.q_home.copy()
    changes = [
        lambda c: c.frame_task.set_position_cost(2.0),
        lambda c: c.frame_task.set_orientation_cost(np.array([0.5, 1.0, 3.0])),
        lambda c: setattr(c.frame_task, "gain", 0.7),
        lambda c: setattr(c.frame_task, "lm_damping", 0.5),
        lambda c: c.posture_task.set_cost(np.linspace(1e-3, 1e-1, 7)),
        lambda c: setattr(c.posture_task, "gain", 0.5),
        lambda c: setattr(c.posture_task, "lm_damping", 2.0),
        lambda c: c.posture_task.set_target(scene.robot.q_home + 0.2),
    ]
    targets = list(_targets(scene, rng, 5 * (len(changes) + 1)))
    for k, (X, V) in enumerate(targets):
        if k % 5 == 0 and k // 5 >= 1:
            for ctrl in (fast, ref):
                changes[k // 5 - 1](ctrl)
        q = _step_both(fast, ref, q, X, V, atol=1e-8)


def test_fast_qp_posture_through_mink_equals_the_hinge_shortcut(scene) -> None:
    """The general posture path (mink's residual, used unless all joints are hinge/slide)."""
    shortcut = QPController(scene, DT)
    general = QPController(scene, DT)
    assert shortcut._posture_is_difference
    general._posture_is_difference = False
    general._task_weights_key = ()  # recompute the constant parts for the general path
    rng = np.random.default_rng(7)
    q = scene.robot.q_home.copy()
    for X, V in _targets(scene, rng, 50):
        q = _step_both(shortcut, general, q, X, V, atol=1e-10, same_status=False)


def test_frame_target_is_one_tick_ahead_along_the_commanded_twist(scene) -> None:
    ctrl = QPController(scene, DT)
    rng = np.random.default_rng(8)
    for X, V in _targets(scene, rng, 20):
        x = X.wxyz_xyz
        ctrl.set_frame_target(x, V)
        step = np.array([1.0, 0.0, 0.0, 0.0])
        mujoco.mju_quatIntegrate(step, V[3:], DT)
        expected = np.empty(7)
        mujoco.mju_mulQuat(expected[:4], step, x[:4])
        expected[4:] = x[4:] + V[:3] * DT
        target = ctrl.frame_task.transform_target_to_world
        assert target is not None
        np.testing.assert_allclose(target.wxyz_xyz, expected, atol=1e-15)
    ctrl.set_frame_target(x, np.zeros(6))  # no rotation: the orientation is kept exactly
    np.testing.assert_array_equal(ctrl.frame_task.transform_target_to_world.wxyz_xyz, x)


def test_bounds_are_the_tighter_of_speed_and_joint_limits(scene) -> None:
    ctrl = QPController(scene, DT)
    w = ctrl.weights
    rng = np.random.default_rng(9)
    for _ in range(50):
        q = rng.uniform(scene.robot.q_min, scene.robot.q_max)
        lower, upper = ctrl.bounds(q)
        q_hi = ctrl.configuration_limit.upper
        q_lo = ctrl.configuration_limit.lower
        np.testing.assert_array_equal(
            upper, np.minimum(scene.robot.v_max * DT, w.limit_gain * (q_hi - q))
        )
        np.testing.assert_array_equal(
            lower, np.maximum(-scene.robot.v_max * DT, -w.limit_gain * (q - q_lo))
        )
