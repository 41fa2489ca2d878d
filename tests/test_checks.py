"""Checks judge blocks of the tick log: each one on rows made to fail it, their precedence, and
a new check added without touching the loop."""

from __future__ import annotations

import re
from pathlib import Path

import mujoco
import numpy as np
import pytest

from pickplace.control.controllers import IK_STATUSES
from pickplace.run.runner import RunRequest, prepare
from pickplace.sim import checks
from pickplace.sim.checks import (
    PLACE_CHECKS,
    REACH_CHECKS,
    Check,
    CheckContext,
    Failure,
    FailureReason,
    NonFiniteCheck,
    PositionLimitCheck,
    QPSolutionCheck,
    SpeedLimitCheck,
    SuccessCriteria,
    TrackingCheck,
)
from pickplace.sim.ticklog import CONTROLLER_NONFINITE, STATE_NONFINITE, TickLog
from pickplace.world.scene import Scene

DT = 0.01


def _context(scene: Scene) -> CheckContext:
    _, task, _ = prepare(RunRequest())
    return CheckContext(scene, task.plan, SuccessCriteria(), DT, lambda *a, **k: None)


def _log(scene: Scene, n: int = 20) -> TickLog:
    log = TickLog(scene, n, DT)
    log.q_cmd[:] = scene.robot.q_home
    log.qpos[:] = scene.make_data().qpos
    log.derive(0, n)
    return log


def test_quiet_rows_pass_every_check(scene: Scene) -> None:
    ctx, log = _context(scene), _log(scene)
    for cls in (NonFiniteCheck, QPSolutionCheck, TrackingCheck, SpeedLimitCheck):
        assert cls(ctx).first_failure(log, 0, 20) is None
    assert PositionLimitCheck(ctx).first_failure(log, 0, 20) is None


@pytest.mark.parametrize("code", [CONTROLLER_NONFINITE, STATE_NONFINITE])
def test_non_finite_is_reported_at_its_first_tick(scene: Scene, code: int) -> None:
    ctx, log = _context(scene), _log(scene)
    log.nonfinite[[7, 12]] = code
    f = NonFiniteCheck(ctx).first_failure(log, 0, 20)
    assert f is not None and (f.tick, f.reason) == (7, FailureReason.NAN)
    assert ("controller" if code == CONTROLLER_NONFINITE else "state") in f.text
    assert NonFiniteCheck(ctx).first_failure(log, 13, 20) is None  # only its block


def test_no_qp_solution_and_lost_tracking_are_ik_failures(scene: Scene) -> None:
    ctx, log = _context(scene), _log(scene)
    log.ik_status[9] = IK_STATUSES.index("no-solution")
    f = QPSolutionCheck(ctx).first_failure(log, 0, 20)
    assert f == Failure(9, FailureReason.IK_FAILED, "the QP found no solution at t=0.100 s")
    limit = ctx.criteria.tracking_limit
    log.command_error[4] = limit  # at the limit is still tracking
    log.command_error[5] = limit * 1.01
    f = TrackingCheck(ctx).first_failure(log, 0, 20)
    assert f is not None and f.tick == 5 and f.reason is FailureReason.IK_FAILED


def test_speed_and_position_limits_name_the_joint_and_the_excess(scene: Scene) -> None:
    ctx, log = _context(scene), _log(scene)
    j = 3
    log.qdot_cmd[6, j] = 1.5 * scene.robot.v_max[j]
    log.derive(0, 20)
    f = SpeedLimitCheck(ctx).first_failure(log, 0, 20)
    assert f is not None and (f.tick, f.reason) == (6, FailureReason.LIMIT_VIOLATED)
    assert scene.robot.arm_joint_names[j] in f.text and "1.5000x" in f.text
    tol = ctx.criteria.position_limit_tolerance
    log.q_cmd[11, 0] = scene.robot.q_max[0] + 2 * tol
    log.derive(0, 20)
    f = PositionLimitCheck(ctx).first_failure(log, 0, 20)
    assert f is not None and f.tick == 11 and f"{2 * tol:.4f} rad past" in f.text


def test_the_goals_list_the_limit_checks_in_their_precedence() -> None:
    assert PLACE_CHECKS[:2] == REACH_CHECKS[:2] == (NonFiniteCheck, QPSolutionCheck)
    assert checks.GraspMonitor in PLACE_CHECKS and checks.GraspMonitor not in REACH_CHECKS
    assert TrackingCheck in PLACE_CHECKS and TrackingCheck not in REACH_CHECKS


class _FailsAt(Check):
    """A check of a test's own: fails at a fixed tick with a given reason."""

    tick = 40
    reason = FailureReason.LIMIT_VIOLATED

    def __init__(self, ctx: CheckContext) -> None:
        self.ctx = ctx

    def first_failure(self, log: TickLog, k0: int, k1: int) -> Failure | None:
        if k0 <= self.tick < k1:
            return Failure(self.tick, self.reason, "a test's own check")
        return None


class _AlsoFailsAt(_FailsAt):
    reason = FailureReason.DROPPED


def test_a_new_check_needs_only_its_place_in_the_list(monkeypatch: pytest.MonkeyPatch) -> None:
    """The loop is not edited: a check appended to the goal's list fails the run at its tick,
    and of two failures at one tick the one listed first wins."""
    monkeypatch.setattr(checks, "PLACE_CHECKS", (*PLACE_CHECKS, _FailsAt, _AlsoFailsAt))
    _, _, sim = prepare(RunRequest())
    s = sim.run().summary()
    assert (s["failure"], s["failure_tick"]) == ("limit-violated", 40)
    failures = [e for e in s["events"] if e["kind"] == "failure"]
    assert failures == [
        {
            "tick": 40,
            "t": pytest.approx(0.41),  # the end of tick 40
            "level": "error",
            "kind": "failure",
            "text": "limit-violated: a test's own check",
        }
    ]
    # The run went on for the failure's grace period, then stopped.
    assert s["ticks"] == 40 + round(SuccessCriteria().failure_grace / sim.dt)


def test_an_earlier_failure_of_a_later_check_wins(monkeypatch: pytest.MonkeyPatch) -> None:
    class Earlier(_AlsoFailsAt):
        tick = 20

    monkeypatch.setattr(checks, "PLACE_CHECKS", (*PLACE_CHECKS, _FailsAt, Earlier))
    _, _, sim = prepare(RunRequest())
    s = sim.run().summary()
    assert (s["failure"], s["failure_tick"]) == ("dropped", 20)


def test_failure_reasons_are_the_documented_strings() -> None:
    """Every FailureReason is a bullet of the failure list in docs/failures.md, and nothing
    else is."""
    doc = (Path(__file__).resolve().parent.parent / "docs" / "failures.md").read_text()
    section = doc.split("## Reasons, in order of precedence", 1)[1].split("\n## ", 1)[0]
    documented = re.findall(r"^- `([a-z-]+)`:", section, flags=re.MULTILINE)
    assert sorted(documented) == sorted(r.value for r in FailureReason)
    assert str(FailureReason.NAN) == "nan"


# ---------------------------------------------------------------------------- failure texts
# Every failure text states the measured value, the limit and what it refers to.


def test_missed_grasp_text_gives_forces_with_the_digits_their_limit_needs() -> None:
    text = checks.missed_grasp_text(0.0056, 0.025, 0.05, np.array([0.0, 2.3]), 0.3)
    assert text.startswith("the fingers closed past the brick and a pad does not press firmly")
    assert "finger gap 5.6 mm (need >= 25.0 mm, 50 % of the 50 mm brick)" in text
    assert "pad forces 0.00 / 2.30 N (need > 0.30 N each)" in text
    firm = checks.missed_grasp_text(0.049, 0.025, 0.05, np.array([3.0, 12.0]), 10.0)
    assert firm.startswith("a pad does not press firmly: ")
    assert "pad forces 3.0 / 12.0 N (need > 10.0 N each)" in firm


def test_a_tilted_brick_in_the_target_bin_is_measured_against_its_limit(scene: Scene) -> None:
    """Lying flat on any face is lying flat; 30 deg about x from a face is tilted 30 deg."""
    from pickplace.sim.checks import SuccessCriteria
    from pickplace.sim.verdict import placement_problems

    a = scene.brick_qpos_adr
    c = scene.target_bin.center_W
    half = scene.brick_half_extents

    def tilt_problems(angle_x: float) -> list[str]:
        data = scene.make_data()
        data.qpos[a : a + 3] = [c[0], c[1], scene.target_bin.floor_top_z + half[1]]
        data.qpos[a + 3 : a + 7] = [np.cos(angle_x / 2), np.sin(angle_x / 2), 0.0, 0.0]
        data.qvel[:] = 0.0
        mujoco.mj_forward(scene.model, data)
        problems = placement_problems(scene, data, scene.target_bin, SuccessCriteria(), 0.0)
        return [p for p in problems if "tilted" in p]

    assert tilt_problems(np.pi / 2) == [] and tilt_problems(np.pi) == []
    assert tilt_problems(np.pi / 6) == [
        "the brick is tilted 30 deg from lying flat (world z from its nearest face normal; "
        "limit 5 deg)"
    ]
