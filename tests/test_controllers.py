"""Controllers: the fast QP equals mink.solve_ik; pinv and dls follow their formulas."""

from __future__ import annotations

import mink
import numpy as np
import pytest
from mink.lie import SE3, SO3

from pickplace.controllers import (
    DLSController,
    IKStatus,
    PinvController,
    QPController,
    make_controller,
)
from pickplace.errors import UnknownNameError

DT = 0.01


def _targets(scene, rng: np.random.Generator, n: int):
    ctrl = QPController(scene, DT)
    ctrl.kinematics.update(scene.q_home)
    X0 = ctrl.kinematics.X_WG()
    for _ in range(n):
        dR = SO3.exp(rng.normal(0.0, 0.2, 3))
        p = X0.translation() + rng.normal(0.0, 0.05, 3)
        yield SE3.from_rotation_and_translation(dR @ X0.rotation(), p), rng.normal(0, 0.3, 6)


def test_fast_qp_equals_mink_solve_ik_on_the_same_problem(scene) -> None:
    fast = QPController(scene, DT, backend="fast")
    ref = QPController(scene, DT, backend="mink")
    rng = np.random.default_rng(0)
    q = scene.q_home.copy()
    for X, V in _targets(scene, rng, 300):
        a, b = fast.command(q, X, V), ref.command(q, X, V)
        np.testing.assert_allclose(a.qdot, b.qdot, atol=1e-8)
        assert a.status is b.status
        q = q + a.qdot * DT


def test_fast_qp_matches_a_direct_mink_call(scene) -> None:
    """Independent of our wrapper: build mink's problem by hand and solve it."""
    ctrl = QPController(scene, DT)
    rng = np.random.default_rng(1)
    q = scene.q_home.copy()
    X, V = next(iter(_targets(scene, rng, 1)))
    res = ctrl.command(q, X, V)
    cfg = mink.Configuration(ctrl.kinematics.model, q=q)
    v = mink.solve_ik(cfg, ctrl.tasks, DT, solver="daqp", limits=ctrl.limits)
    np.testing.assert_allclose(res.qdot, v, atol=1e-8)


def test_qp_never_exceeds_the_joint_speed_limits(scene) -> None:
    ctrl = QPController(scene, DT)
    rng = np.random.default_rng(2)
    q = scene.q_home.copy()
    for X, V in _targets(scene, rng, 200):
        res = ctrl.command(q, X, 20.0 * V)  # far faster than the arm can go
        assert np.all(np.abs(res.qdot) <= scene.v_max * (1 + 1e-6))
        q = q + res.qdot * DT
        assert np.all(q >= scene.q_min) and np.all(q <= scene.q_max)


def test_pinv_and_dls_follow_their_formulas(scene) -> None:
    pinv = PinvController(scene, DT, cutoff=1e-6)
    dls = DLSController(scene, DT, damping=0.1)
    rng = np.random.default_rng(3)
    q = scene.q_home.copy()
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
    """Seed 000's lesson at a bent-elbow pose near full stretch (mink notes: ε = 0.01)."""
    eps = 0.01
    q = np.array([0.0, eps, 0.0, 2 * eps, 0.0, eps, 0.0])
    V = np.array([0.0, 0.0, 0.1, 0.0, 0.0, 0.0])  # 0.1 m/s along the stretched arm
    results = {}
    for name in ("pinv", "qp"):
        ctrl = make_controller(name, scene, DT)
        ctrl.kinematics.update(q)
        X = ctrl.kinematics.X_WG()
        results[name] = ctrl.command(q, X, V)
    assert np.max(np.abs(results["pinv"].qdot) / scene.v_max) > 5.0
    assert np.max(np.abs(results["qp"].qdot) / scene.v_max) <= 1 + 1e-6
    assert results["qp"].status is IKStatus.LIMITED


def test_unknown_controller_and_backend_list_the_valid_ones(scene) -> None:
    with pytest.raises(UnknownNameError, match="valid: dls, pinv, qp"):
        make_controller("newton", scene, DT)
    with pytest.raises(UnknownNameError, match="valid: fast, mink"):
        QPController(scene, DT, backend="osqp")
