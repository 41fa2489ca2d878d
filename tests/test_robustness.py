"""Where a run meets the outside world: viewers, signals, full disks, closed pipes.

Every test drives the CLI and checks the exit code, that stderr has at most three lines and no
traceback, and that a ``.rrd`` left at the target path is complete (``RrdReader(path).store()``
works and holds the summary) or is the older file, untouched. Bad input, refused before
anything runs, goes through ``main()`` in this process (the ``cli`` fixture); everything else
(viewers, signals, full disks, closed pipes, other users) through the real CLI in a
subprocess, in the full tier (``slow``).

Waits are for something to happen (a lock file, a handler, a worker, CPU time spent), never a
fixed sleep that a loaded machine could outlast; the bounds on how fast a stop takes effect
are the documented ones with a margin.
"""

from __future__ import annotations

import contextlib
import json
import os
import resource
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import pytest

from pickplace.record.viewer import (
    CONNECT_TIMEOUT_S,
    HEALTH_FAILURES,
    HEALTH_PERIOD_S,
    PROBE_TIMEOUT_S,
    ViewerAddress,
    viewer_problem,
)
from pickplace.run.runner import valid_control_rates
from tests.conftest import REPO, CliRun

Cli = Callable[..., CliRun]

OLD = b"an older recording that must survive\n"
STARTUP_S = 15.0  # generous bound on scene set-up (loading, planning) [s]


# ---------------------------------------------------------------------------- helpers


def spawn(*args: str, **kw: Any) -> subprocess.Popen[str]:
    kw.setdefault("stdout", subprocess.PIPE)
    kw.setdefault("stderr", subprocess.PIPE)
    return subprocess.Popen(
        [sys.executable, "-m", "pickplace.cli", *args], cwd=kw.pop("cwd", REPO), text=True, **kw
    )


def finish(proc: subprocess.Popen[str], timeout: float = 120.0) -> tuple[int, str, str]:
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"still running after {timeout} s; stderr: {err[-2000:]}")
    return proc.returncode, out or "", err or ""


def clean_stderr(err: str) -> list[str]:
    lines = err.strip().splitlines()
    assert "Traceback" not in err, err
    assert len(lines) <= 3, err
    assert "\x1b[" not in err, err  # no terminal colour codes when stderr is not a terminal
    return lines


def read_line(stream: IO[str], timeout: float) -> str:
    """The next line of ``stream`` (the test fails if none comes within ``timeout`` s)."""
    got: list[str] = []
    reader = threading.Thread(target=lambda: got.append(stream.readline()), daemon=True)
    reader.start()
    reader.join(timeout)
    assert got and got[0], f"no line within {timeout} s"
    return got[0]


def one_json(out: str) -> dict[str, Any]:
    lines = [line for line in out.splitlines() if line.strip()]
    assert len(lines) == 1, out
    return json.loads(lines[0])


def complete_rrd(path: Path) -> set[str]:
    """Entity paths of a complete recording (footer and summary), else the test fails."""
    from rerun.chunk import RrdReader

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "no footer" is a warning first
        entities = set(RrdReader(path).store().schema().entity_paths())
    assert "/summary" in entities
    return entities


def events_in(path: Path) -> list[str]:
    from rerun.chunk import RrdReader

    texts: list[str] = []
    for chunk in RrdReader(path).store().stream():
        if chunk.entity_path == "/events" and not chunk.is_static:
            texts += [row[0] for row in chunk.to_record_batch().column("TextLog:text").to_pylist()]
    return texts


def wait_for_run(proc: subprocess.Popen[str], path: Path, seconds: float = 1.0) -> None:
    """Wait until the run recording to ``path`` has been going for ``seconds`` of wall time.

    Its recorder takes the path's lock (``.<name>.lock`` beside it) right before the loop
    starts, after every input was checked.
    """
    lock = path.with_name(f".{path.name}.lock")
    deadline = time.monotonic() + 60
    while not lock.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the run did not start"
        time.sleep(0.01)
    time.sleep(seconds)
    assert proc.poll() is None, proc.communicate()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# Runs that must last long enough to be stopped, frozen or raced: at a quarter of the speed the
# nominal plan takes 14 s of simulated time.
SLOW = "0.25"


def scene_copy(folder: Path, timestep: str | None = None) -> Path:
    """The default world file in ``folder``, its ``<option timestep>`` replaced if given."""
    text = (REPO / "scenes" / "world.xml").read_text()
    if timestep is not None:
        assert '<option timestep="0.002"' in text
        text = text.replace('<option timestep="0.002"', f'<option timestep="{timestep}"')
    (folder / "world.xml").write_text(text)
    return folder / "world.xml"


def robot_copy(folder: Path, gripper_timestep: str) -> Path:
    """The default robot's files in ``folder``, its gripper file given its own
    ``<option timestep>`` (options belong in the world file)."""
    src = REPO / "robots" / "iiwa14-wsg50"
    for name in ("robot.toml", "arm.xml", "gripper.xml"):
        text = (src / name).read_text()
        head = '<compiler angle="radian" autolimits="true"/>'
        if name == "gripper.xml":
            assert head in text
            text = text.replace(head, f'{head}\n  <option timestep="{gripper_timestep}"/>')
        (folder / name).write_text(text)
    return folder / "robot.toml"


@dataclass
class SilentServer:
    """A TCP server that accepts connections and never answers: its URL, and when it accepted
    each connection (``time.monotonic()``)."""

    url: str
    accepted_at: list[float] = field(default_factory=list)


@pytest.fixture
def silent_server() -> Iterator[SilentServer]:
    """A :class:`SilentServer` on 127.0.0.1."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(16)
    silent = SilentServer(f"rerun+http://127.0.0.1:{server.getsockname()[1]}/proxy")
    accepted: list[socket.socket] = []

    def loop() -> None:
        with contextlib.suppress(OSError):
            while True:
                accepted.append(server.accept()[0])
                silent.accepted_at.append(time.monotonic())

    threading.Thread(target=loop, daemon=True).start()
    yield silent
    server.close()
    for conn in accepted:
        conn.close()


class Viewer:
    """A real Rerun gRPC server (``rerun --serve-grpc``), the process a viewer runs.

    Started from rerun-sdk's binary itself: the ``rerun`` command is a launcher whose child is
    the server, and a SIGSTOP must reach the server.
    """

    def __init__(self) -> None:
        import rerun_cli

        self.port = free_port()
        self.url = f"rerun+http://127.0.0.1:{self.port}/proxy"
        exe = Path(rerun_cli.__file__).parent / "rerun"
        self.proc = subprocess.Popen(
            [str(exe), "--serve-grpc", "--port", str(self.port)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        addr = ViewerAddress(self.url, "127.0.0.1", self.port, False)
        deadline = time.monotonic() + 20
        while viewer_problem(addr, 0.5) is not None:
            assert time.monotonic() < deadline, "the Rerun server did not start"
            time.sleep(0.1)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            os.kill(self.proc.pid, signal.SIGCONT)
            self.proc.kill()
        self.proc.wait()


@pytest.fixture
def viewer() -> Iterator[Viewer]:
    v = Viewer()
    yield v
    v.close()


# ---------------------------------------------------------------------------------- viewers


@pytest.mark.slow
def test_viewer_that_never_answers_fails_in_bounded_time_and_keeps_the_file(
    tmp_path: Path, silent_server: SilentServer
) -> None:
    rrd = tmp_path / "a.rrd"
    rrd.write_bytes(OLD)
    proc = spawn("run", "--connect", silent_server.url, "--record", str(rrd))
    assert proc.stderr is not None
    first_line = read_line(proc.stderr, 120)
    gave_up = time.monotonic()
    code, out, err = finish(proc, 60)
    assert code == 3
    # Timed from the run's first connection (after its set-up, however long a loaded machine
    # makes that) to its error line: the connect timeout, and a margin.
    assert silent_server.accepted_at
    assert gave_up - silent_server.accepted_at[0] < CONNECT_TIMEOUT_S + 2.0
    (line,) = clean_stderr(first_line + err)
    assert "did not answer within" in line
    assert out == ""
    assert rrd.read_bytes() == OLD
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.rrd"]  # no temp or lock left


@pytest.mark.slow
def test_ctrl_c_works_while_the_viewer_is_frozen(tmp_path: Path, viewer: Viewer) -> None:
    rrd = tmp_path / "frozen.rrd"
    proc = spawn(
        "run",
        "--connect",
        viewer.url,
        "--record",
        str(rrd),
        "--speed",
        SLOW,
        "--pace",
        "2",
        "--json",
    )
    wait_for_run(proc, rrd)
    os.kill(viewer.proc.pid, signal.SIGSTOP)
    time.sleep(0.3)
    t0 = time.monotonic()
    proc.send_signal(signal.SIGINT)
    assert proc.stdout is not None
    summary_line = read_line(proc.stdout, 60)  # printed once the recording is complete
    took = time.monotonic() - t0
    code, out, err = finish(proc, 60)
    assert code == 130
    assert took < 4.0, (
        took
    )  # the relay gets 1 s after an interrupt, then is killed; 3 s margin for a loaded machine
    clean_stderr(err)
    summary = one_json(summary_line + out)
    assert summary["failure"] == "interrupted"
    assert summary["recording"] == str(rrd)
    complete_rrd(rrd)


@pytest.mark.slow
@pytest.mark.parametrize("how", ["stopped", "killed"])
def test_viewer_that_stops_or_vanishes_mid_run_does_not_end_the_run(
    tmp_path: Path, viewer: Viewer, how: str
) -> None:
    rrd = tmp_path / f"{how}.rrd"
    # Long enough a run to outlast the detection: about 4 s for a frozen viewer, 1 s for one
    # that refuses connections.
    if how == "stopped":
        pace, bound = 2.0, HEALTH_FAILURES * (HEALTH_PERIOD_S + PROBE_TIMEOUT_S)
    else:
        pace, bound = 4.0, HEALTH_FAILURES * HEALTH_PERIOD_S + 0.1
    t_start = time.monotonic()
    proc = spawn(
        "run",
        "--connect",
        viewer.url,
        "--record",
        str(rrd),
        "--speed",
        SLOW,
        "--pace",
        str(pace),
        "--json",
    )
    wait_for_run(proc, rrd)
    t_lost = time.monotonic() - t_start
    os.kill(viewer.proc.pid, signal.SIGSTOP if how == "stopped" else signal.SIGKILL)
    code, out, err = finish(proc, 60)
    assert code == 0
    (line,) = clean_stderr(err)
    assert line.startswith("pickplace: warning: the viewer at ")
    assert "the recording file goes on" in line
    summary = one_json(out)
    assert summary["success"] is True
    assert summary["recording"] == str(rrd)
    (event,) = [e for e in summary["events"] if e["kind"] == "viewer"]
    assert ("did not answer" if how == "stopped" else "refuses connections") in event["text"]
    complete_rrd(rrd)
    assert event["text"] in events_in(rrd)
    # Noticed within the documented bound. The paced run's simulated time at wall time w (from
    # the process start) is at most w · pace + one block (0.5 s) computed ahead of the pacing;
    # the event is emitted at the next batch (0.25 s of wall time) and reported at its tick.
    t_event = event["tick"] * 0.01
    assert t_event <= (t_lost + bound + 0.25 + 0.5) * pace + 0.5, (t_event, t_lost)


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc")
def test_nothing_listening_fails_at_once_in_one_uncoloured_line() -> None:
    proc = spawn("run", "--connect", f"rerun+http://127.0.0.1:{free_port()}/proxy")
    # From main()'s start (its handler for SIGHUP is its first act), so that the interpreter's
    # start and imports, which a loaded machine can stretch, are left out; what remains is
    # the set-up (loading, planning), which nothing outside shows the end of: STARTUP_S.
    deadline = time.monotonic() + 60
    while not handles(proc.pid, signal.SIGHUP):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.002)
    t0 = time.monotonic()
    code, out, err = finish(proc)
    assert code == 3
    assert time.monotonic() - t0 < STARTUP_S
    (line,) = clean_stderr(err)
    assert "refuses connections" in line
    assert out == ""


@pytest.mark.slow
def test_spawn_without_a_display_fails_at_once() -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    port_in_use = viewer_problem(ViewerAddress("", "127.0.0.1", 9876, False), 0.5) is None
    if port_in_use:
        pytest.skip("a viewer answers on port 9876: --spawn would use it")
    code, _, err = finish(spawn("run", "--spawn", env=env))
    assert code == 3
    (line,) = clean_stderr(err)
    assert "--spawn needs a display" in line


@pytest.mark.slow
def test_rerun_scheme_is_tls_and_says_so(viewer: Viewer) -> None:
    url = viewer.url.replace("rerun+http://", "rerun://")
    code, _, err = finish(spawn("run", "--connect", url))
    assert code == 3
    (line,) = clean_stderr(err)
    assert "TLS" in line and "rerun+http://" in line


@pytest.mark.parametrize(
    ("url", "expected"),
    [
        ("rerun+http://127.0.0.1:9876", "the path must be /proxy"),
        ("rerun+http://127.0.0.1:99999/proxy", "port"),
        ("rerun+http:///proxy", "names no host"),
        ("grpc://127.0.0.1:9876/proxy", "the scheme must be one of"),
    ],
)
def test_malformed_viewer_urls_are_bad_input(cli: Cli, url: str, expected: str) -> None:
    proc = cli("run", "--connect", url)
    assert proc.returncode == 2
    (line,) = clean_stderr(proc.stderr)
    assert expected in line


# --------------------------------------------------------------------- the recording file


@pytest.mark.parametrize(
    "args",
    [["--control-rate", "200"], ["--control-rate", "5"], ["--brick", "9,9,0"], ["--seed", "-1"]],
    ids=lambda a: " ".join(a),
)
def test_a_refused_run_does_not_touch_an_existing_recording(
    cli: Cli, tmp_path: Path, args: list[str]
) -> None:
    rrd = tmp_path / "keep.rrd"
    rrd.write_bytes(OLD)
    before = rrd.stat()
    proc = cli("run", "--record", str(rrd), *args)
    assert proc.returncode == 2
    assert len(clean_stderr(proc.stderr)) == 1
    assert rrd.read_bytes() == OLD
    assert rrd.stat().st_mtime_ns == before.st_mtime_ns
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.rrd"]


@pytest.mark.slow
def test_one_writer_per_path(tmp_path: Path) -> None:
    rrd = tmp_path / "shared.rrd"
    first = spawn("run", "--record", str(rrd), "--speed", SLOW, "--pace", "1", "--json")
    wait_for_run(first, rrd, 0.0)
    code, out, err = finish(spawn("run", "--record", str(rrd), "--json"))
    assert code == 3
    (line,) = clean_stderr(err)
    assert "is being written by another pickplace run" in line and f"pid {first.pid}" in line
    assert out == ""
    first.send_signal(signal.SIGTERM)  # no need to wait for the paced run
    code, out, err = finish(first, 60)
    assert code == 143
    clean_stderr(err)
    assert one_json(out)["recording"] == str(rrd)
    complete_rrd(rrd)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["shared.rrd"]


@pytest.mark.slow
def test_a_killed_run_leaves_the_older_file_and_the_next_run_cleans_up(tmp_path: Path) -> None:
    rrd = tmp_path / "killed.rrd"
    rrd.write_bytes(OLD)
    proc = spawn("run", "--record", str(rrd), "--speed", SLOW, "--pace", "4")
    wait_for_run(proc, rrd)
    proc.kill()
    proc.communicate()
    assert rrd.read_bytes() == OLD
    assert len(list(tmp_path.glob(".killed.rrd.*.tmp"))) == 1  # all that is left
    code, _, err = finish(spawn("run", "--record", str(rrd), "--json"))
    assert code == 0, err
    complete_rrd(rrd)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["killed.rrd"]


@pytest.mark.slow
def test_full_disk_is_exit_3_with_the_older_file_kept(tmp_path: Path) -> None:
    rrd = tmp_path / "full.rrd"
    rrd.write_bytes(OLD)
    limit = 500_000  # [bytes]; a nominal recording is several MB

    def small_disk() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    code, out, err = finish(spawn("run", "--record", str(rrd), "--json", preexec_fn=small_disk))
    assert code == 3
    (line,) = clean_stderr(err)
    assert f"cannot write the recording '{rrd}': File too large" in line
    assert "older file there is unchanged" in line
    summary = one_json(out)
    assert summary["success"] is True  # the run itself went on to its end
    assert summary["recording"] is None
    assert rrd.read_bytes() == OLD
    assert sorted(p.name for p in tmp_path.iterdir()) == ["full.rrd"]


# -------------------------------------------------------------------------- stop signals


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=str)
def test_stop_signals_finish_the_recording_and_print_the_summary(
    tmp_path: Path, sig: signal.Signals
) -> None:
    rrd = tmp_path / "stopped.rrd"
    proc = spawn("run", "--record", str(rrd), "--speed", SLOW, "--pace", "3", "--json")
    wait_for_run(proc, rrd)
    t0 = time.monotonic()
    proc.send_signal(sig)
    assert proc.stdout is not None
    summary_line = read_line(proc.stdout, 60)  # printed once the recording is complete
    # README: the run finishes in at most about 2 s (timed to the summary, not to the
    # interpreter's exit after it).
    assert time.monotonic() - t0 < 5.0
    code, out, err = finish(proc, 60)
    assert code == 128 + sig
    (line,) = clean_stderr(err)
    assert line == f"pickplace: stopped by {sig.name}"
    summary = one_json(summary_line + out)
    assert summary["failure"] == "interrupted"
    assert 0 < summary["ticks"] < 1450
    complete_rrd(rrd)
    assert events_in(rrd)[-1] == "interrupted by the user"


# ---------------------------------------------------------------------------------- sweeps


def sweep_report(out: str) -> dict[str, Any]:
    report = one_json(out)
    assert report["completed"] == sum(report["failures_by_reason"].values()) + report["successes"]
    return report


def cpu_seconds(pid: int) -> float:
    """CPU time [s] that process ``pid`` and its live forked workers have used so far."""
    total = 0
    for p in (pid, *_workers(pid)):
        with contextlib.suppress(OSError):
            fields = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()
            total += int(fields[11]) + int(fields[12])  # utime and stime, in clock ticks
    return total / os.sysconf("SC_CLK_TCK")


# CPU time after which a sweep has finished some trials: its set-up (imports, composing and
# calibrating the robot) takes about 1.6 s of it here, a trial 0.3 s, so 10 s leaves room for a
# machine several times slower, and for one several times faster it is far from 1000 trials.
# CPU time, not wall time: on a loaded machine the set-up alone can take 15 s of wall time.
SWEEP_SOME_TRIALS_CPU_S = 10.0


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc")
@pytest.mark.parametrize("workers", [1, 2])
def test_ctrl_c_stops_a_sweep_within_a_second_with_a_partial_report(workers: int) -> None:
    proc = spawn("sweep", "--trials", "1000", "--workers", str(workers), "--json")
    deadline = time.monotonic() + 300
    while cpu_seconds(proc.pid) < SWEEP_SOME_TRIALS_CPU_S:  # a few trials done
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    assert proc.poll() is None
    t0 = time.monotonic()
    proc.send_signal(signal.SIGINT)
    assert proc.stdout is not None
    report_line = read_line(proc.stdout, 30)
    took = time.monotonic() - t0
    code, out, err = finish(proc, 30)
    assert code == 130
    # The documented bound (README: the sweep stops and prints its report within a second for
    # processes): the workers are killed, no trial is waited for. Timed to the report, not to
    # the interpreter's exit after it, which a loaded machine can make last another second.
    assert took < 1.0, took
    clean_stderr(err)
    report = sweep_report(report_line + out)
    assert report["interrupted"] is True
    assert 0 < report["completed"] < 1000
    assert "interrupted" not in report["failures_by_reason"]  # a stop is not a failed trial


def _workers(pid: int) -> list[int]:
    """Children of ``pid`` forked from it (same command line; libraries start others)."""
    path = Path(f"/proc/{pid}/task/{pid}/children")
    if not path.exists():
        return []
    cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
    found = []
    for child in path.read_text().split():
        with contextlib.suppress(OSError):
            if Path(f"/proc/{child}/cmdline").read_bytes() == cmdline:
                found.append(int(child))
    return found


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc")
def test_a_dead_worker_is_a_failed_trial_with_its_seed() -> None:
    # Six trials on two workers: a live worker holds a trial until the last ones are handed
    # out (two trials alone can be over before a loaded machine gets to the kill).
    proc = spawn("sweep", "--trials", "6", "--workers", "2", "--seed", "7", "--json")
    deadline = time.monotonic() + 60
    while not (kids := _workers(proc.pid)):
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.01)
    os.kill(kids[0], signal.SIGKILL)  # a worker holds a trial from its start
    code, out, err = finish(proc, 60)
    assert code == 1
    clean_stderr(err)
    report = sweep_report(out)
    assert report["interrupted"] is False
    assert report["completed"] == 6
    assert report["failures_by_reason"]["worker-died"] == 1
    assert set(report["failed_seeds"]["worker-died"]) <= set(range(7, 13))


# --------------------------------------------------------------------- stdout and stderr


@pytest.mark.slow
def test_closed_stderr_is_no_problem() -> None:
    code, out, _ = finish(spawn("run", stderr=None, preexec_fn=lambda: os.close(2)))
    assert code == 0
    assert "SUCCESS" in out


@pytest.mark.slow
def test_full_stdout_is_exit_3_in_one_line() -> None:
    with open("/dev/full", "w") as full:
        code, _, err = finish(spawn("scenarios", "--json", stdout=full))
    assert code == 3
    (line,) = clean_stderr(err)
    assert line == "pickplace: error: cannot write the output to stdout: No space left on device"


@pytest.mark.slow
def test_a_reader_that_goes_away_is_exit_141_and_silent() -> None:
    proc = spawn("scenarios", "--json")
    assert proc.stdout is not None
    proc.stdout.close()  # like `pickplace scenarios --json | true`
    code, _, err = finish(proc)
    assert code == 141
    assert err == ""


def handles(pid: int, sig: signal.Signals) -> bool:
    """True once process ``pid`` catches ``sig`` (its SigCgt mask in /proc)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigCgt:"):
            return bool(int(line.split()[1], 16) >> (sig - 1) & 1)
    return False


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc")
@pytest.mark.parametrize("after", [0.0, 0.3])
def test_ctrl_c_during_set_up_still_gives_the_summary(after: float) -> None:
    proc = spawn("run", "--json")
    # Python itself catches SIGINT from its start; SIGHUP only once pickplace's handler is
    # installed, the first thing its main() does. Before that a Ctrl-C is Python's.
    deadline = time.monotonic() + 30
    while not handles(proc.pid, signal.SIGHUP):
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.002)
    time.sleep(after)  # imports, scene loading, planning
    proc.send_signal(signal.SIGINT)
    code, out, err = finish(proc)
    assert code == 130
    clean_stderr(err)
    summary = one_json(out)
    assert summary["failure"] == "interrupted"


# ---------------------------------------------------------- timesteps and control rates


@pytest.mark.parametrize("timestep", ["0", "1e-300", "-0.002", "0.02"])
def test_unusable_timesteps_are_bad_input(cli: Cli, tmp_path: Path, timestep: str) -> None:
    scene = scene_copy(tmp_path, timestep)
    proc = cli("run", "--scene", str(scene), cwd=tmp_path)
    assert proc.returncode == 2
    (line,) = clean_stderr(proc.stderr)
    assert "physics timestep" in line and "must be in [1e-05, 0.01] s" in line
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_a_robot_file_cannot_change_the_world_timestep(cli: Cli, tmp_path: Path) -> None:
    robot = robot_copy(tmp_path, gripper_timestep="0.001")
    proc = cli("plan", "--robot", str(robot), "--json", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == "" and one_json(proc.stdout)["feasible"]
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
    from pickplace.sim.loader import load_scene

    scene = load_scene(robot=str(robot))
    assert scene.model.opt.timestep == 0.002  # the world's
    assert any("option" in r for r in scene.robot.repairs), scene.robot.repairs


@pytest.mark.parametrize("timestep", [0.002, 0.001, 0.003, 0.0025, 1e-4])
def test_valid_rates_are_whole_numbers_of_steps_in_the_range(timestep: float) -> None:
    rates = valid_control_rates(timestep)
    assert rates == sorted(rates, reverse=True)
    for rate in rates:
        assert 100.0 <= rate <= 1000.0
        steps = 1.0 / (rate * timestep)
        assert abs(steps - round(steps)) < 1e-9
    # Every whole number of steps whose rate lies in the range is listed.
    expected = [
        1.0 / (n * timestep) for n in range(1, 2000) if 100.0 <= 1.0 / (n * timestep) <= 1000.0
    ]
    assert rates == pytest.approx(expected)


def test_rate_message_lists_this_scenes_rates(cli: Cli) -> None:
    proc = cli("run", "--control-rate", "1000")
    assert proc.returncode == 2
    (line,) = clean_stderr(proc.stderr)
    assert line.endswith("are 500 Hz / n: 500, 250, 166.667, 125, 100")


@pytest.mark.slow
def test_a_listed_rate_runs() -> None:
    code, out, err = finish(spawn("run", "--control-rate", "166.667", "--json"))
    assert code == 0, err
    summary = one_json(out)
    assert summary["success"] is True
    assert summary["sim_time_s"] == pytest.approx(summary["ticks"] * 0.006, abs=1e-9)


# -------------------------------------------------------------------- inputs and defaults


@pytest.mark.parametrize(
    ("record", "expected"),
    [
        ("", "got an empty name"),
        (".rrd", "has no name before .rrd"),
        ("dir.rrd", "is a directory"),
        ("fifo.rrd", "is a FIFO"),
        ("nowhere.rrd", "is a symbolic link to"),
    ],
)
def test_unusable_record_paths_are_named_correctly(
    cli: Cli, tmp_path: Path, record: str, expected: str
) -> None:
    (tmp_path / "dir.rrd").mkdir()
    os.mkfifo(tmp_path / "fifo.rrd")
    (tmp_path / "nowhere.rrd").symlink_to(tmp_path / "missing" / "x.rrd")
    proc = cli("run", "--record", record, cwd=tmp_path)
    assert proc.returncode == 2
    (line,) = clean_stderr(proc.stderr)
    assert expected in line


@pytest.fixture
def shared_dir() -> Iterator[Path]:
    """A folder another user may write (pytest's own tmp folders are private)."""
    folder = Path(tempfile.mkdtemp(prefix="pickplace-test-"))
    folder.chmod(0o777)
    yield folder
    for p in folder.iterdir():
        p.unlink()
    folder.rmdir()


@pytest.mark.slow
def test_read_only_file_is_named_as_such(shared_dir: Path) -> None:
    rrd = shared_dir / "ro.rrd"
    rrd.write_bytes(OLD)
    rrd.chmod(0o444)
    as_other_user: dict[str, Any] = {}
    if os.geteuid() == 0:  # root may write any file: run as nobody
        as_other_user = {"user": 65534, "group": 65534, "env": {**os.environ, "HOME": "/tmp"}}
    try:
        proc = spawn("run", "--record", str(rrd), **as_other_user)
    except PermissionError:
        pytest.skip("root, and this Python cannot run as another user (root may write it)")
    code, _, err = finish(proc)
    assert code == 2
    (line,) = clean_stderr(err)
    assert "is read-only" in line
    assert rrd.read_bytes() == OLD


@pytest.mark.slow
def test_a_symlink_is_followed_and_stays_a_symlink(tmp_path: Path) -> None:
    (tmp_path / "real").mkdir()
    link = tmp_path / "link.rrd"
    link.symlink_to(tmp_path / "real" / "run.rrd")  # dangling until the run ends
    code, out, err = finish(spawn("run", "--record", str(link), "--json"))
    assert code == 0, err
    assert link.is_symlink()
    complete_rrd(tmp_path / "real" / "run.rrd")
    assert one_json(out)["recording"] == str(link)


def test_huge_yaw_is_named(cli: Cli) -> None:
    proc = cli("run", "--brick=0,-0.55,1e300")
    assert proc.returncode == 2
    (line,) = clean_stderr(proc.stderr)
    assert "--brick: brick yaw must be in [-2π, 2π]" in line


def test_version_and_sweep_help(cli: Cli) -> None:
    from importlib.metadata import version

    proc = cli("--version")
    assert proc.returncode == 0 and proc.stdout.strip() == f"pickplace {version('pickplace')}"
    proc = cli("sweep", "--help")
    assert proc.returncode == 0
    text = " ".join(proc.stdout.split())
    for described in (
        "--scenario SCENARIO scenario name",
        "--controller CONTROLLER qp (default), qp-no-collision, pinv or dls",
        "--trials TRIALS number of trials",
        "--seed SEED seed of the first trial",
        "--workers WORKERS parallel processes",
    ):
        assert described in text, described


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="needs CPU affinity")
def test_default_workers_follow_cpu_affinity() -> None:
    code, out, err = finish(
        spawn(
            "sweep",
            "--trials",
            "1",
            "--json",
            preexec_fn=lambda: os.sched_setaffinity(0, {min(os.sched_getaffinity(0))}),
        )
    )
    assert code == 0, err
    assert one_json(out)["workers"] == 1
