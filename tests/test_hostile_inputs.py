"""A hostile or unlucky user: planted links, pathological files, huge numbers, stuck workers,
signals at awkward moments.

Every test drives the real CLI in a subprocess (the helpers of ``tests/test_robustness.py``)
and checks the exit code, that stderr is at most a few lines without a traceback, and that
files outside the output path are left as they were. Bad input is exit 2 with one line naming
the file and the field, and what would be valid.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from pickplace.errors import OutputError
from pickplace.outfile import OutputFile
from pickplace.sweep.sweep import DEFAULT_TRIAL_TIMEOUT_S
from tests.conftest import REPO
from tests.test_robustness import (
    SLOW,
    _workers,
    clean_stderr,
    complete_rrd,
    finish,
    handles,
    one_json,
    spawn,
    sweep_report,
    wait_for_run,
)

# Every test here starts the real CLI as a process (or several): the full tier.
pytestmark = pytest.mark.slow

PRECIOUS = "precious\n"


# ---------------------------------------------------------------------------- the lock file


@pytest.mark.parametrize("kind", ["symlink", "hardlink"])
def test_a_planted_lock_link_is_refused_and_what_it_points_at_is_untouched(
    tmp_path: Path, kind: str
) -> None:
    precious = tmp_path / "v.txt"
    precious.write_text(PRECIOUS)
    lock = tmp_path / ".v.rrd.lock"
    if kind == "symlink":
        lock.symlink_to("v.txt")
    else:
        os.link(precious, lock)
    code, out, err = finish(spawn("run", "--record", str(tmp_path / "v.rrd"), cwd=tmp_path), 60)
    assert code == 2
    (line,) = clean_stderr(err)
    assert "--record" in line and ".v.rrd.lock" in line
    assert ("symbolic link" if kind == "symlink" else "hard links") in line
    assert out == ""
    assert precious.read_text() == PRECIOUS
    assert sorted(p.name for p in tmp_path.iterdir()) == [".v.rrd.lock", "v.txt"]


def test_a_lock_link_planted_after_the_checks_is_not_followed(tmp_path: Path) -> None:
    precious = tmp_path / "v.txt"
    precious.write_text(PRECIOUS)
    (tmp_path / ".v.rrd.lock").symlink_to("v.txt")
    output = OutputFile(tmp_path / "v.rrd")
    with pytest.raises(OutputError, match="symbolic link"):
        output.open()
    assert precious.read_text() == PRECIOUS
    assert not (tmp_path / "v.rrd").exists()


def test_a_record_name_near_the_file_system_limit_is_written(tmp_path: Path) -> None:
    name = "a" * 240 + ".rrd"  # legal (244 bytes), but ".<name>.<pid>-<hex>.tmp" would not be
    code, out, err = finish(spawn("run", "--record", name, "--json", cwd=tmp_path), 120)
    assert code == 0, err
    assert one_json(out)["recording"] == name
    complete_rrd(tmp_path / name)
    assert [p.name for p in tmp_path.iterdir()] == [name]  # no lock or temporary file left


def test_a_record_name_beyond_the_file_system_limit_is_bad_input(tmp_path: Path) -> None:
    code, _, err = finish(spawn("run", "--record", "b" * 252 + ".rrd", cwd=tmp_path), 60)
    assert code == 2
    (line,) = clean_stderr(err)
    assert "--record" in line and "256 bytes long" in line and "at most 255" in line
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------- signals


def console(*args: str, **kw: Any) -> subprocess.Popen[str]:
    """``python -m pickplace ARGS``: the console script's entry, which installs the stop-signal
    handlers before it imports the CLI (``python -m pickplace.cli`` imports it first)."""
    kw.setdefault("stdout", subprocess.PIPE)
    kw.setdefault("stderr", subprocess.PIPE)
    return subprocess.Popen(
        [sys.executable, "-m", "pickplace", *args], cwd=kw.pop("cwd", REPO), text=True, **kw
    )


def wait_for_handlers(proc: subprocess.Popen[str]) -> None:
    """Until ``proc`` catches SIGHUP: pickplace's handlers are in, and its imports have only
    begun (MuJoCo, which takes seconds on a loaded machine, is not loaded yet)."""
    deadline = time.monotonic() + 30
    while not handles(proc.pid, signal.SIGHUP):
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.002)
    assert "mujoco" not in Path(f"/proc/{proc.pid}/maps").read_text()


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc")
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=str)
@pytest.mark.parametrize("command", ["run", "sweep"])
def test_a_stop_signal_during_the_imports_is_a_clean_stop(
    sig: signal.Signals, command: str
) -> None:
    args = ["run", "--json"] if command == "run" else ["sweep", "--trials", "2", "--json"]
    proc = console(*args)
    wait_for_handlers(proc)
    proc.send_signal(sig)  # MuJoCo, numpy and the package are still being imported
    code, out, err = finish(proc, 60)
    assert code == 128 + sig
    (line,) = clean_stderr(err)
    assert line.startswith(f"pickplace: stopped by {sig.name}")
    if command == "run":  # the run starts, and stops at its first block, with a summary
        assert one_json(out)["failure"] == "interrupted"


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc")
def test_a_hangup_of_the_whole_group_during_the_imports_leaves_no_traceback() -> None:
    proc = console("run", "--json", start_new_session=True)
    wait_for_handlers(proc)
    os.killpg(proc.pid, signal.SIGHUP)  # a closed terminal: every process of the group
    code, out, err = finish(proc, 60)
    assert code == 129
    clean_stderr(err)
    assert one_json(out)["failure"] == "interrupted"


def children_seen(proc: subprocess.Popen[str]) -> set[int]:
    """Every child process of ``proc`` seen while it runs (polled every millisecond)."""
    seen: set[int] = set()
    path = Path(f"/proc/{proc.pid}/task/{proc.pid}/children")
    while proc.poll() is None:
        with contextlib.suppress(OSError):
            seen.update(int(c) for c in path.read_text().split())
        time.sleep(0.001)
    return seen


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc")
def test_a_run_starts_no_child_process_that_a_hangup_could_break() -> None:
    # Importing MuJoCo with OpenGL probes glfw in a child Python, which a SIGHUP to the group
    # killed mid-pipe (a BrokenPipeError traceback); a run renders nothing with MuJoCo.
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    proc = console("run", "--json", env=env)
    assert children_seen(proc) == set()
    code, out, err = finish(proc)
    assert code == 0, err
    assert one_json(out)["success"] is True


def signal_until_it_exits(proc: subprocess.Popen[str], sig: signal.Signals) -> None:
    """Send ``sig`` every few milliseconds until ``proc`` has exited (at most 30 s)."""
    deadline = time.monotonic() + 30
    while proc.poll() is None and time.monotonic() < deadline:
        with contextlib.suppress(ProcessLookupError):
            proc.send_signal(sig)
        time.sleep(0.005)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=str)
def test_signals_after_the_summary_change_neither_the_output_nor_the_exit_code(
    sig: signal.Signals,
) -> None:
    proc = console("scenarios", "--json")
    assert proc.stdout is not None
    first = proc.stdout.readline()  # the whole output: the process is now only exiting
    signal_until_it_exits(proc, sig)
    code, rest, err = finish(proc, 30)
    assert code == 0, (code, err)
    assert err == ""
    one_json(first + rest)


def test_sigterm_then_repeated_ctrl_c_exits_143_as_the_message_says(tmp_path: Path) -> None:
    rrd = tmp_path / "twice.rrd"
    proc = console("run", "--record", str(rrd), "--speed", SLOW, "--pace", "3", "--json")
    wait_for_run(proc, rrd)
    proc.send_signal(signal.SIGTERM)
    # (Two signals pending at once are handled in signal-number order: leave the first alone.)
    time.sleep(0.3)
    signal_until_it_exits(proc, signal.SIGINT)  # through the finishing, the summary, the exit
    code, out, err = finish(proc, 60)
    assert code == 143
    (line,) = clean_stderr(err)
    assert line == "pickplace: stopped by SIGTERM"
    assert one_json(out)["failure"] == "interrupted"
    complete_rrd(rrd)


def test_help_and_version_to_a_reader_that_has_gone_are_exit_141_like_any_output() -> None:
    for args in (["run", "--help"], ["--version"]):
        proc = console(*args)
        assert proc.stdout is not None
        proc.stdout.close()  # the reader is gone before the output is written
        code, _, err = finish(proc)
        assert code == 141, args
        assert err == ""


# ---------------------------------------------------------------------------- long planning

# At 0.1 % of the speed limits (the lowest --speed allowed) the nominal plan lasts about an
# hour: its pre-flight runs for seconds of wall time, planning at full speed for a tenth of one.
CRAWL = "0.001"


def _wall_time(*args: str) -> float:
    t0 = time.monotonic()
    code, _, err = finish(console(*args), 120)
    assert code == 0, err
    return time.monotonic() - t0


@pytest.fixture(scope="module")
def while_planning() -> float:
    """Seconds after its start at which a crawling `plan` or `run` is surely still planning.

    Measured on this machine as it is now, not assumed: a third of the way from the wall time
    of a normal `plan` (imports, set-up, planning at full speed: by then the crawling one is
    planning) to that of the crawling one, so a faster or a busier CPU moves both ends alike,
    and the crawl would have to run 1.5 times faster than it was measured to end first.
    """
    normal = _wall_time("plan", "--json")
    crawling = _wall_time("plan", "--speed", CRAWL, "--json")
    assert crawling > normal + 1.0, (normal, crawling)
    return normal + (crawling - normal) / 3.0


@pytest.mark.parametrize(
    ("command", "sig", "message"),
    [
        ("plan", signal.SIGTERM, "pickplace: stopped by SIGTERM while planning"),
        ("run", signal.SIGINT, "pickplace: stopped by SIGINT before the run started"),
    ],
)
def test_a_stop_signal_ends_a_long_planning_promptly(
    tmp_path: Path, command: str, sig: signal.Signals, message: str, while_planning: float
) -> None:
    rrd = tmp_path / "never.rrd"
    rrd.write_text(PRECIOUS)
    extra = ["--record", str(rrd)] if command == "run" else []
    proc = console(command, "--speed", CRAWL, *extra, "--json")
    time.sleep(while_planning)  # imports done, the pre-flight of the long plan under way
    assert proc.poll() is None, proc.communicate()
    t0 = time.monotonic()
    proc.send_signal(sig)
    code, out, err = finish(proc, 60)
    took = time.monotonic() - t0
    assert code == 128 + sig
    assert took < 4.0, took  # 1 s for a normal set-up to reach the run, then at once
    assert clean_stderr(err) == [message]
    assert out == ""
    assert rrd.read_text() == PRECIOUS
    assert [p.name for p in tmp_path.iterdir()] == ["never.rrd"]


@pytest.mark.parametrize(
    "args",
    [
        ["plan", "--speed", "1e-9"],
        ["run", "--speed", "1e-4"],
        ["sweep", "--trials", "2", "--speed", "2"],
    ],
    ids=lambda a: " ".join(a),
)
def test_speed_overrides_that_would_plan_for_hours_are_bad_input(args: list[str]) -> None:
    t0 = time.monotonic()
    code, out, err = finish(spawn(*args), 60)
    assert code == 2
    assert time.monotonic() - t0 < 30.0  # refused before any planning
    (line,) = clean_stderr(err)
    assert line.startswith("pickplace: error: --speed: speed must be a number in [0.001, 1]")
    assert out == ""


def robot_with(folder: Path, **fields: str) -> Path:
    """The default robot's files in ``folder``, with ``fields`` of robot.toml replaced or
    added (``"gripper.mount_pos"`` for a gripper field), as TOML text."""
    src = REPO / "robots" / "iiwa14-wsg50"
    for name in ("arm.xml", "gripper.xml"):
        (folder / name).write_text((src / name).read_text())
    lines = (src / "robot.toml").read_text().splitlines()
    for key, value in fields.items():
        section, _, name = key.rpartition(".")
        section = section or "arm"
        lines = [line for line in lines if not line.startswith(f"{name} =")]
        at = lines.index(f"[{section}]") + 1
        lines.insert(at, f"{name} = {value}")
    (folder / "robot.toml").write_text("\n".join(lines) + "\n")
    return folder / "robot.toml"


def test_a_plan_longer_than_an_hour_is_refused_before_its_preflight(tmp_path: Path) -> None:
    # Half the default speed limits at the lowest speed override: a plan of about two hours.
    slow = "[0.74, 0.74, 0.87, 0.65, 1.13, 1.18, 1.18]"
    robot = robot_with(tmp_path, speed_limits=slow)
    t0 = time.monotonic()
    code, out, err = finish(spawn("plan", "--robot", str(robot), "--speed", "0.001"), 60)
    assert code == 2
    assert time.monotonic() - t0 < 30.0
    (line,) = clean_stderr(err)
    assert "the timed plan lasts" in line and "at most 3600 s" in line and "--speed" in line
    assert out == ""


def test_a_run_whose_tick_log_would_not_fit_in_memory_is_refused(tmp_path: Path) -> None:
    rrd = tmp_path / "huge.rrd"
    args = ["run", "--speed", "0.004", "--control-rate", "500", "--record", str(rrd)]
    code, out, err = finish(spawn(*args), 120)
    assert code == 2
    (line,) = clean_stderr(err)
    assert "its tick log" in line and "valid: at most 1 GiB" in line
    assert out == ""
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------- robot files


def bad_robot_line(robot: Path, *args: str, command: str = "plan") -> str:
    """The one error line of ``pickplace COMMAND --robot ROBOT ARGS`` (exit 2, nothing on
    stdout, no warning)."""
    code, out, err = finish(spawn(command, "--robot", str(robot), *args, cwd=robot.parent), 60)
    assert code == 2, err
    (line,) = clean_stderr(err)
    assert line.startswith(f"pickplace: error: --robot: {robot}: "), line
    assert "Warning" not in err
    assert out == ""
    assert not (robot.parent / "MUJOCO_LOG.TXT").exists()
    return line


@pytest.mark.parametrize(
    ("key", "value", "expected"),
    [
        (
            "gripper.grip_force",
            "1e300",
            "grip_force: is 1e+300; valid: a number in [0.1, 10000] [N]",
        ),
        ("gripper.mount_pos", "[1e308, 0, 0]", "[gripper] mount_pos: value 1 of 3 is 1e+308"),
        ("speed_limits", "[1e300, 1, 1, 1, 1, 1, 1]", "[arm] speed_limits: value 1 of 7"),
        ("accel_limits", "[1e-9, 1, 1, 1, 1, 1, 1]", "[arm] accel_limits: value 1 of 7"),
        ("home", "[1e300, 0, 0, 0, 0, 0, 0]", "[arm] home: value 1 of 7 is 1e+300"),
    ],
    ids=lambda v: str(v)[:30],
)
def test_robot_numbers_outside_physical_ranges_are_named_with_the_range(
    tmp_path: Path, key: str, value: str, expected: str
) -> None:
    line = bad_robot_line(robot_with(tmp_path, **{key: value}))
    assert expected in line and "valid: " in line


def test_a_huge_bad_list_is_quoted_short(tmp_path: Path) -> None:
    robot = robot_with(tmp_path, speed_limits="[" + ", ".join(["-1"] * 200_000) + "]")
    line = bad_robot_line(robot)
    assert "[arm] speed_limits: value 1 of 200000 is -1, not > 0" in line
    assert len(line) < 400


def test_a_bad_list_of_non_numbers_is_quoted_short(tmp_path: Path) -> None:
    robot = robot_with(tmp_path, speed_limits="[" + ", ".join(['"x"'] * 200_000) + "]")
    line = bad_robot_line(robot)
    assert "[arm] speed_limits: must be a list of numbers" in line and "..." in line
    assert len(line) < 400


def test_speed_limits_of_the_wrong_length_are_blamed_on_the_speed_limits(tmp_path: Path) -> None:
    line = bad_robot_line(robot_with(tmp_path, speed_limits="[1, 1, 1]"))
    assert "[arm] speed_limits: has 3 values; valid: 7 positive numbers" in line
    assert "accel_limits" not in line


def test_a_description_nested_thousands_deep_is_one_line(tmp_path: Path) -> None:
    robot = tmp_path / "robot.toml"
    robot.write_text('name = "deep"\nx = ' + "[" * 5000 + "]" * 5000 + "\n")
    line = bad_robot_line(robot)
    assert "nested thousands deep" in line


def with_arm(folder: Path, arm: str, **fields: str) -> Path:
    """:func:`robot_with`, its arm file then replaced by the text ``arm``."""
    robot = robot_with(folder, **fields)
    (folder / "arm.xml").write_text(arm)
    return robot


def default_arm(head: str = "", body: str = "") -> str:
    """The default arm file with ``head`` after its compiler and ``body`` in its worldbody."""
    text = (REPO / "robots" / "iiwa14-wsg50" / "arm.xml").read_text()
    compiler = '<compiler angle="radian" autolimits="true"/>'
    assert compiler in text and "<worldbody>" in text
    return text.replace(compiler, compiler + head, 1).replace("<worldbody>", "<worldbody>" + body)


@pytest.mark.parametrize("kind", ["directory", "FIFO", "character device"])
@pytest.mark.parametrize("role", ["mjcf", "include", "mesh"])
def test_a_folder_fifo_or_device_named_as_a_file_is_called_what_it_is(
    tmp_path: Path, kind: str, role: str
) -> None:
    if kind == "directory":
        (tmp_path / "thing").mkdir()
        target = "thing"
    elif kind == "FIFO":
        os.mkfifo(tmp_path / "thing")  # reading it would block for ever
        target = "thing"
    else:
        target = "/dev/zero"  # reading it would never end
    if role == "mjcf":
        robot = robot_with(tmp_path, mjcf=f'"{target}"')
    elif role == "include":
        robot = with_arm(tmp_path, default_arm(head=f'<include file="{target}"/>'))
    else:
        mesh = f'<asset><mesh name="m" file="{target}"/></asset>'
        robot = with_arm(tmp_path, default_arm(head=mesh))
    line = bad_robot_line(robot)
    assert f"is a {kind}" in line and "does not exist" not in line and "[arm] mjcf" in line


@pytest.mark.parametrize("case", ["includes itself", "50 MB", "500,000 bodies", "12 deep"])
def test_pathological_arm_files_are_refused_in_bounded_time(tmp_path: Path, case: str) -> None:
    if case == "includes itself":
        robot = with_arm(tmp_path, default_arm(head='<include file="arm.xml"/>'))
        expected = "includes itself ('arm.xml' -> 'arm.xml')"
    elif case == "50 MB":
        robot = with_arm(tmp_path, default_arm(head="<!-- " + "x" * 50_000_000 + " -->"))
        expected = "valid: an MJCF file of at most 16777216 bytes"
    elif case == "500,000 bodies":
        robot = with_arm(tmp_path, default_arm(body="<body/>" * 500_000))
        expected = "more than 20000 XML elements"
    else:
        for i in range(1, 13):
            (tmp_path / f"c{i}.xml").write_text(f'<mujoco><include file="c{i + 1}.xml"/></mujoco>')
        (tmp_path / "c13.xml").write_text("<mujoco/>")
        robot = with_arm(tmp_path, default_arm(head='<include file="c1.xml"/>'))
        expected = "is nested more than 8 deep; valid: at most 8 levels"
    t0 = time.monotonic()
    line = bad_robot_line(robot)
    assert time.monotonic() - t0 < 30.0  # start-up and a bounded read (was 30 s to minutes)
    assert expected in line and "[arm] mjcf" in line


@pytest.mark.parametrize("workers", ["1", "2"])
def test_a_bad_robot_is_refused_up_front_whatever_the_workers(tmp_path: Path, workers: str) -> None:
    robot = robot_with(tmp_path, **{"gripper.grip_force": "1e300"})
    args = ("--trials", "2", "--workers", workers, "--json")
    line = bad_robot_line(robot, *args, command="sweep")
    assert "[gripper] grip_force" in line


# ---------------------------------------------------------------------------- world files


def world_with(folder: Path, old: str, new: str) -> Path:
    """The default world file in ``folder`` with ``old`` replaced by ``new``."""
    text = (REPO / "scenes" / "world.xml").read_text()
    assert old in text
    (folder / "world.xml").write_text(text.replace(old, new, 1))
    return folder / "world.xml"


BRICK = '<geom name="brick" type="box" size="0.0375 0.025 0.025" mass="0.2"'


@pytest.mark.parametrize(
    ("old", "new", "expected"),
    [
        (BRICK, BRICK.replace('mass="0.2"', 'mass="0"'), "mass and inertia of moving bodies"),
        (BRICK, BRICK.replace("0.0375 0.025 0.025", "0.3 0.3 0.3"), "larger than bin 'bin1'"),
        (BRICK, BRICK.replace('type="box"', 'type="sphere"'), "brick geom 'brick' is a sphere"),
        (
            '<body name="brick" pos="0 -0.55 0.035">',
            '<body name="brick" pos="nan -0.55 0.035">',
            "contains a NaN",
        ),
        (
            "<worldbody>",
            '<asset><mesh name="junk" file="junk.stl"/></asset><worldbody>'
            '<geom type="mesh" mesh="junk" pos="2 2 0"/>',
            "junk.stl",
        ),
    ],
    ids=["brick of mass 0", "oversized brick", "sphere brick", "brick at nan", "non-mesh mesh"],
)
def test_world_file_problems_are_blamed_on_the_world_file(
    tmp_path: Path, old: str, new: str, expected: str
) -> None:
    (tmp_path / "junk.stl").write_text("not a mesh\n")
    world = world_with(tmp_path, old, new)
    code, out, err = finish(spawn("run", "--scene", str(world), "--json", cwd=tmp_path), 60)
    assert code == 2, err
    (line,) = clean_stderr(err)
    assert line.startswith(f"pickplace: error: --scene: scene file '{world}'"), line
    assert expected in line and "valid: " in line
    assert "robot.toml" not in line
    assert out == ""
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


# ---------------------------------------------------------------------------- sweeps


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc")
def test_a_stopped_worker_times_out_its_trial_and_the_sweep_goes_on() -> None:
    timeout = 10.0  # [s]: several trials' time on a loaded machine
    args = ["--trials", "6", "--workers", "2", "--seed", "7", "--trial-timeout", str(timeout)]
    proc = spawn("sweep", *args, "--json")
    deadline = time.monotonic() + 60
    while not (kids := _workers(proc.pid)):
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.01)
    os.kill(kids[0], signal.SIGSTOP)  # frozen with a trial in hand
    try:
        code, out, err = finish(proc, 120)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(kids[0], signal.SIGKILL)
    assert code == 1
    clean_stderr(err)
    report = sweep_report(out)
    assert report["completed"] == 6 and report["interrupted"] is False
    assert report["failures_by_reason"] == {"worker-timeout": 1}
    (lost,) = [t for t in report["trial_results"] if t.get("lost")]
    assert lost["seed"] in range(7, 13)
    assert lost["detail"] == f"no result within {timeout:g} s (--trial-timeout); worker killed"
    assert not Path(f"/proc/{kids[0]}").exists()  # killed, not left stopped


def test_the_trial_timeout_is_documented_and_checked() -> None:
    code, out, _ = finish(spawn("sweep", "--help"))
    assert code == 0
    assert f"(default: {DEFAULT_TRIAL_TIMEOUT_S:g} s)" in " ".join(out.split())
    for value, expected in (("0.5", "must be in [1, 86400] s"), ("5", "Ray tasks have no")):
        extra = ["--backend", "ray"] if value == "5" else []
        code, out, err = finish(spawn("sweep", "--trial-timeout", value, *extra), 60)
        assert code == 2
        (line,) = clean_stderr(err)
        assert line.startswith("pickplace: error: --trial-timeout") and expected in line
        assert out == ""


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc")
def test_a_killed_worker_says_by_which_signal() -> None:
    proc = spawn("sweep", "--trials", "6", "--workers", "2", "--json")
    deadline = time.monotonic() + 60
    while not (kids := _workers(proc.pid)):
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.01)
    os.kill(kids[0], signal.SIGKILL)
    code, out, err = finish(proc, 120)
    assert code == 1, err
    (lost,) = [t for t in sweep_report(out)["trial_results"] if t.get("lost")]
    assert lost["failure"] == "worker-died"
    assert lost["detail"] == "killed by signal 9"


@pytest.mark.parametrize("workers", ["1", "2"])
def test_a_trial_that_raises_is_a_worker_error_whatever_the_workers(
    tmp_path: Path, workers: str
) -> None:
    # Half the speed limits at the lowest speed override: every trial's plan is refused in
    # its planning (longer than an hour), after the sweep's checks passed.
    slow = "[0.74, 0.74, 0.87, 0.65, 1.13, 1.18, 1.18]"
    robot = robot_with(tmp_path, speed_limits=slow)
    args = ["--scenario", "pick-place", "--robot", str(robot), "--speed", "0.001"]
    args += ["--trials", "2", "--workers", workers]
    code, out, err = finish(spawn("sweep", *args, "--json"), 120)
    assert code == 1, err
    clean_stderr(err)
    report = sweep_report(out)
    assert report["completed"] == 2
    assert report["failures_by_reason"] == {"worker-error": 2}
    for trial in report["trial_results"]:
        assert trial["detail"].startswith("PlanError: the timed plan lasts")


@pytest.mark.parametrize("command", ["run", "sweep"])
def test_a_varied_control_rate_is_named_as_the_vary_option(command: str) -> None:
    seed = ["--seed", "1"] if command == "run" else []  # seed 1 draws the second value
    code, out, err = finish(spawn(command, *seed, "--vary", "control_rate=100,123"), 60)
    assert code == 2
    (line,) = clean_stderr(err)
    assert line.startswith("pickplace: error: --vary control_rate=123: control rate 123 Hz")
    assert "--control-rate" not in line
    assert out == ""
