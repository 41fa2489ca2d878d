"""The real CLI in a subprocess: bad input, faults, interruption, output formats (issue 6)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pickplace.scenarios import SCENARIOS
from tests.conftest import REPO, run_cli, run_cli_json

BAD_INPUTS = [
    (["--scene", "/nonexistent/scene.xml"], "does not exist"),
    (["--scene", "README.md"], "not valid MJCF"),
    (["--scenario", "nope"], "valid: fault-brick-moved"),
    (["--controller", "newton"], "valid: dls, pinv, qp"),
    (["--brick", "0.1,0.2"], "must be X,Y,YAW"),
    (["--brick", "a,b,c"], "must be X,Y,YAW"),
    (["--brick", "nan,-0.55,0"], "must be X,Y,YAW"),
    (["--brick", "inf,-0.55,0"], "must be X,Y,YAW"),
    (["--brick", "0.5,0.5,0"], "outside bin1"),
    (["--brick=0.17,-0.55,1.57"], "no feasible plan picks the brick"),
    (["--seed", "-1"], "non-negative integer"),
    (["--seed", "1.5"], "non-negative integer"),
    (["--seed", "99999999999"], "--seed: seed must be an integer in"),
    (["--record", "/nonexistent/run.rrd"], "does not exist"),
    (["--record", "run.txt"], "must end in .rrd"),
    (["--record", "/proc/run.rrd"], "not writable"),
    (["--control-rate", "5"], "--control-rate: control rate must be in"),
    (["--control-rate", "300"], "not a whole number of physics steps"),
    (["--pace", "-1"], "--pace: pace must be in"),
    (["--connect", "http://x"], "must be a Rerun viewer URL"),
    (["--scenario", "singular-reach", "--brick", "0,-0.55,0"], "does not apply"),
]


@pytest.mark.parametrize(
    ("args", "expected"), BAD_INPUTS, ids=lambda v: " ".join(v) if isinstance(v, list) else ""
)
def test_bad_input_is_one_line_exit_2_without_traceback(args: list[str], expected: str) -> None:
    proc = run_cli("run", *args)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert expected in lines[0]
    assert "Traceback" not in proc.stderr
    assert proc.stdout == ""


def test_scene_missing_a_required_name_lists_the_names_that_exist(tmp_path: Path) -> None:
    scenes = REPO / "scenes"
    (tmp_path / "wsg50.xml").write_text(
        (scenes / "wsg50.xml").read_text().replace('name="tool"', 'name="tcp"')
    )
    (tmp_path / "iiwa14.xml").write_text((scenes / "iiwa14.xml").read_text())
    (tmp_path / "scene.xml").write_text((scenes / "scene.xml").read_text())
    proc = run_cli("run", "--scene", str(tmp_path / "scene.xml"))
    assert proc.returncode == 2
    assert proc.stderr.strip() == (
        "pickplace: error: unknown site 'wsg50/tool'; valid: attachment_site, bin1_center, "
        "bin2_center, brick, wsg50/tcp"
    )


def test_unreachable_brick_is_refused(tmp_path: Path) -> None:
    """A scene whose bin 1 lies 2 m away: the brick is inside the bin but out of reach."""
    scenes = REPO / "scenes"
    for name in ("wsg50.xml", "iiwa14.xml"):
        (tmp_path / name).write_text((scenes / name).read_text())
    (tmp_path / "scene.xml").write_text(
        (scenes / "scene.xml")
        .read_text()
        .replace('<body name="bin1" pos="0 -0.55 0">', '<body name="bin1" pos="0 -2 0">')
    )
    proc = run_cli("run", "--scene", str(tmp_path / "scene.xml"), "--brick=0,-2,0")
    assert proc.returncode == 2
    assert "unreachable" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(
    ("scenario", "reason"),
    [(s.name, s.expected) for s in SCENARIOS.values() if s.expected != "success"],
)
def test_faults_end_in_exit_1_with_the_right_reason(scenario: str, reason: str) -> None:
    code, s = run_cli_json("--scenario", scenario)
    assert code == 1
    assert s["success"] is False
    assert s["failure"] == reason
    assert s["failure_tick"] is not None
    failure = [e for e in s["events"] if e["kind"] == "failure"]
    assert failure and failure[0]["tick"] == s["failure_tick"]


def test_knock_is_reported_at_the_tick_it_happened() -> None:
    _, s = run_cli_json("--scenario", "fault-knock")
    fault = next(e for e in s["events"] if e["kind"] == "fault")
    drop = next(e for e in s["events"] if e["kind"] == "drop")
    assert 0 <= drop["tick"] - fault["tick"] <= 5  # within 50 ms of the blow


def test_unreachable_target_keeps_joints_within_limits_and_finite() -> None:
    _, s = run_cli_json("--scenario", "fault-unreachable")
    assert s["failure"] == "ik-failed"
    assert s["max_joint_limit_violation_rad"] <= 1e-3
    assert s["max_joint_speed_ratio"] <= 1 + 1e-6
    assert all(v == v for v in s["brick_final_xyz"])  # no NaN


def test_json_output_has_every_documented_key() -> None:
    code, s = run_cli_json()
    assert code == 0
    keys = {
        "scenario",
        "controller",
        "seed",
        "success",
        "failure",
        "brick_start_xyz",
        "brick_final_xyz",
        "target_xyz",
        "place_error_m",
        "sim_time_s",
        "wall_time_s",
        "realtime_factor",
        "ticks",
        "min_singular_value",
        "max_condition_number",
        "max_joint_speed_ratio",
        "max_joint_limit_violation_rad",
        "max_position_error_m",
        "max_orientation_error_rad",
        "ik_status_counts",
        "ik_tick_us_median",
        "recording",
    }
    assert keys <= set(s)
    assert s["success"] is True and s["failure"] is None


def test_human_summary_and_scenarios_listing() -> None:
    proc = run_cli("run")
    assert proc.returncode == 0
    assert "pick-place / qp / seed 0: SUCCESS" in proc.stdout
    listing = run_cli("scenarios")
    names = [line.split()[0] for line in listing.stdout.splitlines()]
    assert {"pick-place", "pick-place-random", "singular-reach"} <= set(names)
    assert json.loads(run_cli("scenarios", "--json").stdout)["pick-place"]["expected"] == "success"
