"""The loop's block-wise assessment and its grip-force sensors, against their definitions."""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
import pytest

from pickplace.control.controllers import make_controller
from pickplace.errors import InvalidInputError
from pickplace.run.runner import RunRequest, prepare
from pickplace.sim.loader import load_scene
from pickplace.sim.loop import Simulation
from pickplace.sim.scenarios import BuildRequest, get_scenario
from tests.conftest import finished, without_wall_time


def _summary(sim: Simulation) -> dict[str, Any]:
    return without_wall_time(sim.run().summary())


@pytest.mark.slow
@pytest.mark.parametrize(
    ("scenario", "controller"),
    [
        ("pick-place", "qp"),
        ("fault-knock", "qp"),
        ("fault-gripper-disabled", "qp"),
        ("fault-obstacle", "qp"),  # the moved obstacle reaches the IK at the same tick
        ("singular-reach", "pinv"),
    ],
)
def test_assessing_in_blocks_equals_assessing_every_tick(scenario: str, controller: str) -> None:
    """Same verdict, failure tick, events and metrics with blocks of 1 tick and the default
    (the shared run)."""
    shared = finished(scenario, controller)
    blocked = shared.sim
    _, _, per_tick = prepare(RunRequest(scenario=scenario, controller=controller))
    per_tick.block_ticks = 1
    assert blocked.block_ticks > 1
    a, b = without_wall_time(shared.summary()), _summary(per_tick)
    assert a == b
    n = blocked.ticks
    for name in ("sigma", "manipulability_t", "orientation_error", "slip", "holding_torque"):
        np.testing.assert_array_equal(
            getattr(blocked.log, name)[:n], getattr(per_tick.log, name)[:n]
        )


def _contact_forces(sim: Simulation) -> np.ndarray:
    """Normal force on each pad from MuJoCo's contact list (mj_contactForce)."""
    m, d = sim.model, sim.data
    out = np.zeros(2)
    f6 = np.zeros(6)
    for i in range(d.ncon):
        pair = {int(d.contact.geom1[i]), int(d.contact.geom2[i])}
        for side, pads in enumerate(sim.scene.robot.pad_geom_ids):
            for pad in pads.tolist():
                if pair == {pad, sim.scene.brick_geom_id}:
                    mujoco.mj_contactForce(m, d, i, f6)
                    out[side] += f6[0]
    return out


def _grasp_tick(sim: Simulation) -> int:
    phases = sim.plan.phases
    assert phases is not None
    return round(phases.grip_closed / sim.dt)


def test_pad_sensors_equal_the_contact_forces_and_the_log_keeps_them() -> None:
    _, _, sim = prepare(RunRequest())
    sim.advance(_grasp_tick(sim) - 30)
    seen = []
    for _ in range(80):  # closing, squeezing and lifting
        sim.advance(1)
        expected = _contact_forces(sim)
        np.testing.assert_allclose(sim.pad_forces(), expected, rtol=1e-12, atol=1e-9)
        np.testing.assert_array_equal(sim.log.pad_force[sim.ticks - 1], sim.pad_forces())
        seen.append(expected.min())
    # The squeeze measured in calibration (the WSG-like gripper's 40 N force limit) is what
    # squeezes once the pads touch.
    assert max(seen) == pytest.approx(sim.scene.robot.squeeze_force, rel=0.05)
    assert sim.scene.robot.squeeze_force == pytest.approx(40.0, rel=1e-3)


def test_too_few_sensor_slots_are_reported() -> None:
    """A pad sensor with 2 slots misses 2 of the 4 contact points: the loop says so."""
    scene = load_scene(pad_slots=2)
    task = get_scenario("pick-place").build(BuildRequest(scene, "pick-place", 0))
    sim = Simulation(scene, task, make_controller("qp", scene, 0.01))
    assert sim.scene.robot.pad_force_slots == 2
    sim.advance(_grasp_tick(sim) + 20)
    warnings = [e for e in sim.events if e.kind == "sensor"]
    assert len(warnings) == 1
    assert "touched the brick in 4 points but its sensor reports 2" in warnings[0].text
    assert sim.pad_forces().min() < 0.75 * _contact_forces(sim).min()


def test_advancing_in_pieces_equals_one_call() -> None:
    """The commands of a block are computed before its physics; stopping mid-way and going
    on must give the same run as going through at once."""
    _, _, whole = prepare(RunRequest())
    _, _, pieces = prepare(RunRequest())
    whole.advance(130)
    for n in (1, 2, 7, 50, 70):
        pieces.advance(n)
    assert whole.ticks == pieces.ticks == 130
    for name in ("q_cmd", "qpos", "J_WG", "sigma", "pad_force"):
        np.testing.assert_array_equal(
            getattr(whole.log, name)[:130], getattr(pieces.log, name)[:130]
        )
    np.testing.assert_array_equal(whole.q_cmd, pieces.q_cmd)


def test_advance_refuses_a_negative_count() -> None:
    _, _, sim = prepare(RunRequest())
    with pytest.raises(InvalidInputError, match="ticks must be >= 0"):
        sim.advance(-1)
