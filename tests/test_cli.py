"""The CLI: bad input, faults, output formats.

Bad input runs ``main()`` in this process (the ``cli`` fixture: exit code, stdout and stderr as
a process would give them); one run goes through a real ``pickplace`` subprocess. The faults'
outcomes are judged on the runs the tests share (``tests.conftest.finished``: the CLI's JSON is
that run's summary), and one failed run is checked for its exit code.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest

from pickplace.robot.registry import bundled_robots
from pickplace.sim.scenarios import SCENARIOS
from tests.conftest import REPO, CliRun, finished, one_json, run_cli_json, without_wall_time
from tests.toy_robot import BAD_CASES, TOY_TOO_FAR, write_toy_robot

Cli = Callable[..., CliRun]

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
    (["--brick=-0.16,-0.67,0"], "no feasible plan picks the brick"),  # against two walls
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
def test_bad_input_is_one_line_exit_2_without_traceback(
    cli: Cli, args: list[str], expected: str
) -> None:
    proc = cli("run", *args)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert expected in lines[0]
    assert "Traceback" not in proc.stderr
    assert proc.stdout == ""


def test_world_missing_a_required_name_lists_the_names_that_exist(cli: Cli, tmp_path: Path) -> None:
    world = (REPO / "scenes" / "world.xml").read_text()
    (tmp_path / "world.xml").write_text(world.replace('name="bin2_floor"', 'name="bin2_base"'))
    proc = cli("run", "--scene", str(tmp_path / "world.xml"))
    assert proc.returncode == 2
    line = proc.stderr.strip()
    assert len(line.splitlines()) == 1 and "Traceback" not in proc.stderr
    assert line.startswith("pickplace: error: unknown geom 'bin2_floor'; valid: ")
    assert "bin2_base" in line and "bin1_floor" in line


def test_unreachable_brick_is_refused(cli: Cli, tmp_path: Path) -> None:
    """A world whose bin 1 lies 2 m away: the brick is inside the bin but out of reach."""
    world = (REPO / "scenes" / "world.xml").read_text()
    (tmp_path / "world.xml").write_text(
        world.replace('<body name="bin1" pos="0 -0.55 0">', '<body name="bin1" pos="0 -2 0">')
    )
    proc = cli("run", "--scene", str(tmp_path / "world.xml"), "--brick=0,-2,0")
    assert proc.returncode == 2
    assert "unreachable" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


FAULTS = [(s.name, s.expected) for s in SCENARIOS.values() if s.expected != "success"]


@pytest.mark.slow
@pytest.mark.parametrize(("scenario", "reason"), FAULTS)
def test_faults_end_with_the_right_reason_at_their_failure_tick(scenario: str, reason: str) -> None:
    s = finished(scenario).summary()
    assert s["success"] is False
    assert s["failure"] == reason
    assert s["failure_tick"] is not None
    failure = [e for e in s["events"] if e["kind"] == "failure"]
    assert failure and failure[0]["tick"] == s["failure_tick"]


@pytest.mark.slow
def test_a_failed_run_is_exit_1_and_its_json_says_why(cli: Cli) -> None:
    proc = cli("run", "--scenario", "fault-gripper-disabled", "--json")
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr == ""
    s = one_json(proc.stdout)
    assert s["success"] is False and s["failure"] == "missed-grasp"
    # The JSON is the run's summary: the faults above are judged on the shared runs.
    shared = finished("fault-gripper-disabled").summary()
    assert without_wall_time(s) == json.loads(json.dumps(without_wall_time(shared)))


@pytest.mark.slow
def test_knock_is_reported_at_the_tick_it_happened() -> None:
    s = finished("fault-knock").summary()
    fault = next(e for e in s["events"] if e["kind"] == "fault")
    drop = next(e for e in s["events"] if e["kind"] == "drop")
    assert 0 <= drop["tick"] - fault["tick"] <= 5  # within 50 ms of the blow


@pytest.mark.slow
def test_unreachable_target_keeps_joints_within_limits_and_finite() -> None:
    s = finished("fault-unreachable").summary()
    assert s["failure"] == "ik-failed"
    assert s["max_joint_limit_violation_rad"] <= 1e-3
    assert s["max_joint_speed_ratio"] <= 1 + 1e-6
    assert all(v == v for v in s["brick_final_xyz"])  # no NaN


def test_json_output_has_every_documented_key() -> None:
    """The real command in a subprocess, as a user runs it (the default tier's only one)."""
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


@pytest.mark.slow
def test_human_summary(cli: Cli) -> None:
    proc = cli("run")
    assert proc.returncode == 0
    assert "pick-place / iiwa14-wsg50 / qp / seed 0: SUCCESS" in proc.stdout


def test_scenarios_listing(cli: Cli) -> None:
    listing = cli("scenarios")
    assert listing.returncode == 0
    names = [line.split()[0] for line in listing.stdout.splitlines()]
    assert {"pick-place", "pick-place-random", "singular-reach"} <= set(names)
    assert json.loads(cli("scenarios", "--json").stdout)["pick-place"]["expected"] == "success"


# The brief's bad robot files, through the CLI (tests/toy_robot.py writes each one).
CLI_BAD_ROBOTS = [
    "missing arm file",
    "mesh does not load",
    "speed limits of the wrong length",
    "speed limits not positive",
    "no chain from the root to the flange",
    "no pads found",
    "gripper that cannot open wider than the brick",
]


@pytest.mark.parametrize("case", CLI_BAD_ROBOTS)
def test_a_bad_robot_file_is_one_line_naming_file_and_field_exit_2(
    cli: Cli, case: str, tmp_path: Path
) -> None:
    changes, field, fragments = BAD_CASES[case]
    path = write_toy_robot(tmp_path, **changes)
    proc = cli("run", "--robot", str(path))
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    line = lines[0]
    assert line.startswith(f"pickplace: error: --robot: {path.resolve()}: "), line
    assert field in line and "valid" in line, line
    for fragment in fragments:
        assert fragment in line, line
    assert proc.stdout == ""


@pytest.mark.parametrize("command", ["run", "plan", "sweep"])
def test_an_unknown_robot_lists_the_bundled_ones(cli: Cli, command: str, tmp_path: Path) -> None:
    proc = cli(command, "--robot", "no-such-robot")
    assert proc.returncode == 2
    assert proc.stderr.strip() == (
        f"pickplace: error: --robot: unknown robot 'no-such-robot'; valid: "
        f"{', '.join(bundled_robots())}, a robot.toml path or a folder holding one"
    )
    assert "iiwa14-wsg50, " in proc.stderr
    missing = tmp_path / "robot.toml"
    proc = cli(command, "--robot", str(missing))
    assert proc.returncode == 2
    assert f"{missing}: robot description does not exist" in proc.stderr


@pytest.mark.slow  # composes every robot, or starts CLI processes
def test_robots_are_listed_with_joints_gripper_width_force_and_file(cli: Cli) -> None:
    proc = cli("robots", "--json")
    assert proc.returncode == 0, proc.stderr
    rows = {r["name"]: r for r in json.loads(proc.stdout)["robots"]}
    assert set(rows) == set(bundled_robots())
    assert {n: rows[n]["joints"] for n in ("iiwa14-wsg50", "panda-hand", "ur5e-2f85")} == {
        "iiwa14-wsg50": 7,
        "panda-hand": 7,
        "ur5e-2f85": 6,
    }
    assert "coupled by the loader" in rows["panda-hand"]["gripper"]
    assert rows["ur5e-2f85"]["gripper"].startswith("linkage")
    for name, r in rows.items():
        # Absolute: right from any folder, so a user can find a bundled robot to copy.
        assert r["description"] == str((REPO / "robots" / name / "robot.toml").resolve())
        assert Path(r["description"]).is_absolute() and Path(r["description"]).is_file()
        assert r["open_width_m"] > 0.05  # wider than the brick
        assert r["squeeze_force_n"] > 10.0
    text = cli("robots")
    assert text.returncode == 0 and len(text.stdout.strip().splitlines()) == len(rows)


@pytest.mark.slow
def test_run_plan_and_sweep_take_a_robot(cli: Cli) -> None:
    proc = cli("run", "--robot", "ur5e-2f85", "--json")
    s = one_json(proc.stdout)
    assert proc.returncode == 0 and s["robot"] == "ur5e-2f85" and s["success"]
    plan = cli("plan", "--robot", "panda-hand", "--json")
    assert plan.returncode == 0 and json.loads(plan.stdout)["robot"] == "panda-hand"
    sweep = cli("sweep", "--robot", "panda-hand", "--trials", "2", "--workers", "1", "--json")
    assert sweep.returncode == 0, sweep.stderr
    report = json.loads(sweep.stdout)
    assert report["robot"] == "panda-hand" and report["successes"] == 2


@pytest.mark.slow  # the refused composition measures the reach by IK: 4 s
def test_an_arm_that_cannot_reach_both_bins_is_refused_in_one_line(
    cli: Cli, tmp_path: Path
) -> None:
    path = write_toy_robot(tmp_path, toml=TOY_TOO_FAR)
    proc = cli("run", "--robot", str(path))
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert lines[0].startswith(f"pickplace: error: --robot: {path.resolve()}: [arm]: "), lines
    for fragment in ("cannot reach both bins", "it lacks", "valid:", "base_pos"):
        assert fragment in lines[0], lines[0]
    assert proc.stdout == ""
