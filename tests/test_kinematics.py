"""Jacobians, manipulability and Jᵀ statics checked against independent computations."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from mink.lie import SO3

from pickplace.control.diagnostics import Manipulability, holding_torques, jacobian_health
from pickplace.control.kinematics import ArmKinematics


def _random_q(scene, rng: np.random.Generator) -> np.ndarray:
    return rng.uniform(0.8 * scene.robot.q_min, 0.8 * scene.robot.q_max)


def test_tool_jacobian_equals_finite_differences_of_the_tool_pose(scene) -> None:
    kin = ArmKinematics(scene)
    rng = np.random.default_rng(0)
    h = 1e-6
    for _ in range(20):
        q = _random_q(scene, rng)
        kin.update(q)
        J = kin.J_WG()
        J_fd = np.zeros_like(J)
        for i in range(7):
            dq = np.zeros(7)
            dq[i] = h
            kin.update(q + dq)
            p_plus, R_plus = kin.p_WG(), SO3.from_matrix(kin.R_WG())
            kin.update(q - dq)
            p_minus, R_minus = kin.p_WG(), SO3.from_matrix(kin.R_WG())
            J_fd[:3, i] = (p_plus - p_minus) / (2 * h)
            J_fd[3:, i] = (R_plus @ R_minus.inverse()).log() / (2 * h)
        np.testing.assert_allclose(J, J_fd, atol=1e-6)


def test_arm_model_matches_the_simulation_kinematics(scene) -> None:
    kin = ArmKinematics(scene)
    data = mujoco.MjData(scene.model)
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = _random_q(scene, rng)
        data.qpos[scene.robot.arm_qpos_adr] = q
        mujoco.mj_kinematics(scene.model, data)
        kin.update(q)
        np.testing.assert_allclose(kin.p_WG(), data.site_xpos[scene.robot.tool_site_id], atol=1e-12)


def test_manipulability_measures_agree_with_their_definitions(scene) -> None:
    kin = ArmKinematics(scene)
    rng = np.random.default_rng(2)
    for _ in range(10):
        kin.update(_random_q(scene, rng))
        J = kin.J_WG()
        health = jacobian_health(J)
        m = health.full
        assert m.w1 == pytest.approx(np.sqrt(np.linalg.det(J @ J.T)), rel=1e-9)
        assert m.w2 == pytest.approx(1.0 / np.linalg.cond(J), rel=1e-9)
        assert m.w3 == pytest.approx(m.singular_values.min(), rel=1e-12)
        assert m.w4 == pytest.approx(np.prod(m.singular_values) ** (1 / 6), rel=1e-9)
        assert m.condition == pytest.approx(np.linalg.cond(J), rel=1e-9)
        # The ellipsoid axes: J_v J_vᵀ u = σ² u.
        Jv = J[:3]
        for k in range(3):
            u = health.U_translational[:, k]
            s = health.translational.singular_values[k]
            np.testing.assert_allclose(Jv @ Jv.T @ u, s**2 * u, atol=1e-10)


def test_singular_jacobian_has_infinite_condition() -> None:
    m = Manipulability.from_singular_values(np.array([2.0, 1.0, 0.0]))
    assert m.condition == float("inf")
    assert m.w1 == 0.0 and m.w2 == 0.0 and m.w3 == 0.0


def test_holding_torques_equal_mujocos_generalized_force_of_the_weight(scene) -> None:
    """Jᵀ statics: τ = Jᵥᵀ(−m g) equals −(generalized force of the load's weight)."""
    model = scene.model
    data = mujoco.MjData(model)
    rng = np.random.default_rng(3)
    mass = 0.2
    for _ in range(5):
        q = _random_q(scene, rng)
        data.qpos[scene.robot.arm_qpos_adr] = q
        mujoco.mj_forward(model, data)
        qfrc = np.zeros(model.nv)
        weight = np.array([0.0, 0.0, -9.81 * mass])
        body = model.site_bodyid[scene.robot.tool_site_id]
        mujoco.mj_applyFT(
            model, data, weight, np.zeros(3), data.site_xpos[scene.robot.tool_site_id], body, qfrc
        )
        jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
        mujoco.mj_jacSite(model, data, jacp, jacr, scene.robot.tool_site_id)
        J = np.vstack([jacp, jacr])[:, scene.robot.arm_dof_adr]
        np.testing.assert_allclose(
            holding_torques(J, mass), -qfrc[scene.robot.arm_dof_adr], atol=1e-10
        )


def test_logged_ellipsoid_axes_diagonalise_the_translational_velocity_ellipsoid() -> None:
    """Per tick the loop stores U_t (columns = axes) and its quaternion: one proper rotation
    with J_v J_vᵀ = U_t diag(σ_t²) U_tᵀ."""
    from pickplace.run.runner import RunRequest, prepare

    _, _, sim = prepare(RunRequest())
    sim.advance(300)
    log, kin = sim.log, sim.controller.kinematics
    for k in range(0, 300, 37):
        U = log.U_t[k]
        R = np.empty(9)
        mujoco.mju_quat2Mat(R, log.quat_t[k])
        np.testing.assert_allclose(R.reshape(3, 3), U, atol=1e-9)
        assert np.linalg.det(U) == pytest.approx(1.0, abs=1e-9)
        kin.update(log.q_cmd[k - 1] if k else sim.scene.robot.q_home)
        Jv = kin.J_WG()[:3]
        np.testing.assert_allclose(U @ np.diag(log.sigma_t[k] ** 2) @ U.T, Jv @ Jv.T, atol=1e-9)


def test_pose_and_jacobian_are_new_arrays(scene) -> None:
    kin = ArmKinematics(scene)
    kin.update(scene.robot.q_home)
    J, x = kin.J_WG(), kin.wxyz_xyz()
    kin.update(scene.robot.q_home + 0.3)
    J2, x2 = kin.J_WG(), kin.wxyz_xyz()
    assert not np.shares_memory(J, J2) and not np.shares_memory(x, x2)
    assert not np.allclose(J, J2) and not np.allclose(x, x2)
    assert kin.wxyz_xyz_list() == x2.tolist()
