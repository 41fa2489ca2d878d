"""Ray sweeps under signals, dead workers and wrong addresses, through the real CLI.

Each test starts ``python -m pickplace sweep --backend ray`` in a session of its own (so that a
signal to its process group spares pytest), with a marker variable in its environment that
every process it starts inherits, Ray's included: a process left with the marker after the
sweep ended is a process left behind. Each checks the exit code, the time from the signal to
the exit (128 + N within 5 s, docs/sweeps.md), that stdout is exactly one JSON report, that
stderr has no traceback, that the recording is complete and nothing else is left beside it.

Waits are for something to happen (a Ray process, a trial running, the driver gone), never a
fixed sleep. Every test starts a Ray cluster: the full tier (``slow``).
"""

from __future__ import annotations

import contextlib
import http.server
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import uuid
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from pickplace.sweep.ray_address import CONNECT_TIMEOUT_S
from pickplace.sweep.session import end_session
from tests.conftest import REPO
from tests.test_robustness import clean_stderr, free_port, handles, one_json

pytest.importorskip("ray")
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc"),
]

MARKER = "PICKPLACE_TEST_RAY_RUN"
STOP_BOUND_S = 5.0  # docs/sweeps.md: a Ray sweep ends within 5 s of a stop signal
WAIT_S = 240.0  # generous bound on a Ray cluster's start on a loaded machine [s]


class Sweep:
    """A ``pickplace sweep --backend ray`` process in a session of its own.

    Attributes:
        proc: The process.
        tag: Its marker (the value of :data:`MARKER` in its environment).
        folder: Where its recording goes (``sweep.rrd``).
    """

    def __init__(self, folder: Path, *args: str, record: bool = True) -> None:
        self.tag = uuid.uuid4().hex
        self.folder = folder
        extra = ["--record", str(folder / "sweep.rrd")] if record else []
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "pickplace", "sweep", "--backend", "ray", *args, "--json",
             *extra],
            cwd=REPO,
            env={**os.environ, MARKER: self.tag, "RAY_AUTH_MODE": "token"},
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )  # fmt: skip
        self.signalled_at: float | None = None

    def processes(self) -> list[tuple[int, bytes]]:
        """(pid, command line) of every live process with this sweep's marker."""
        return marked(self.tag)

    def wait_for(self, what: Callable[[list[bytes]], bool], timeout: float = WAIT_S) -> None:
        """Until ``what`` holds for the command lines of the sweep's processes."""
        deadline = time.monotonic() + timeout
        while not what([cmd for _, cmd in self.processes()]):
            assert self.proc.poll() is None, self.proc.communicate()
            assert time.monotonic() < deadline, "timed out"
            time.sleep(0.005)

    def signal(self, sig: signal.Signals, group: bool) -> None:
        self.signalled_at = time.monotonic()
        if group:
            os.killpg(self.proc.pid, sig)
        else:
            os.kill(self.proc.pid, sig)

    def finish(self, timeout: float = 300.0) -> tuple[int, str, str, float]:
        """Exit code, stdout, stderr, and the time from the signal to the exit [s]."""
        try:
            out, err = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            out, err = self.proc.communicate()
            pytest.fail(f"still running after {timeout} s; stderr: {err[-2000:]}")
        took = time.monotonic() - (self.signalled_at or time.monotonic())
        return self.proc.returncode, out, err, took

    def kill_leftovers(self) -> None:
        for pid, _ in self.processes():
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)


def marked(tag: str) -> list[tuple[int, bytes]]:
    """(pid, command line) of the live processes whose environment holds ``MARKER=tag``."""
    needle = f"{MARKER}={tag}".encode()
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        with contextlib.suppress(OSError, IndexError):
            if needle not in (entry / "environ").read_bytes().split(b"\0"):
                continue
            if (entry / "stat").read_text().rsplit(")", 1)[1].split()[0] == "Z":
                continue
            found.append((int(entry.name), (entry / "cmdline").read_bytes()))
    return found


@pytest.fixture
def folder() -> Iterator[Path]:
    """A folder of the test's for the recording (short, for Ray's socket paths)."""
    with tempfile.TemporaryDirectory(prefix="pp-ray-test-", dir="/tmp") as tmp:
        yield Path(tmp)


def cluster_starting(cmds: list[bytes]) -> bool:
    """Ray's GCS runs and no trial yet: the local cluster is starting."""
    return any(b"gcs_server" in c for c in cmds) and not trial_running(cmds)


def trial_running(cmds: list[bytes]) -> bool:
    """A Ray worker runs a trial (Ray names a worker's process after its task)."""
    return any(c.startswith(b"ray::guarded_trial") for c in cmds)


def complete_sweep_rrd(path: Path) -> None:
    """The sweep recording at ``path`` reads back complete, with its report."""
    from rerun.chunk import RrdReader

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "no footer" is a warning first
        entities = set(RrdReader(path).store().schema().entity_paths())
    assert "/report" in entities


def assert_stopped(sweep: Sweep, sig: signal.Signals) -> dict[str, Any]:
    """The sweep ended by ``sig`` as documented; its report."""
    code, out, err, took = sweep.finish()
    time.sleep(0.5)  # anything left would still be there
    left = sweep.processes()
    sweep.kill_leftovers()
    assert code == 128 + sig, (code, err[-3000:])
    assert took < STOP_BOUND_S, took
    (line,) = clean_stderr(err)
    assert line == f"pickplace: stopped by {sig.name}"
    report = one_json(out)
    assert report["interrupted"] is True
    assert report["completed"] == report["successes"] + sum(report["failures_by_reason"].values())
    assert report["recording"] == str(sweep.folder / "sweep.rrd")
    complete_sweep_rrd(sweep.folder / "sweep.rrd")
    assert [p.name for p in sweep.folder.iterdir()] == ["sweep.rrd"]  # no .tmp, no .lock
    assert left == [], left
    return report


# ---------------------------------------------------------------------------- signals


@pytest.mark.parametrize(
    "sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT], ids=lambda s: s.name
)
def test_a_signal_to_the_group_while_the_cluster_starts_stops_at_once_leaving_nothing(
    folder: Path, sig: signal.Signals
) -> None:
    """What ``timeout`` or a closed terminal sends: it took 29–30 s, and Ray's dashboard and
    runtime-env agents outlived the sweep."""
    sweep = Sweep(folder, "--workers", "2", "--trials", "200")
    sweep.wait_for(cluster_starting)
    sweep.signal(sig, group=True)
    report = assert_stopped(sweep, sig)
    assert report["completed"] == 0


@pytest.mark.parametrize(
    "sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT], ids=lambda s: s.name
)
def test_a_signal_to_the_group_while_tasks_start_gives_the_report_and_no_crash(
    folder: Path, sig: signal.Signals
) -> None:
    """SIGTERM there was Ray's stack dump and an abort (rc -6) with workers orphaned; any
    signal sometimes a segfault or abort 5–6 s later, after the report."""
    sweep = Sweep(folder, "--workers", "2", "--trials", "200")
    sweep.wait_for(trial_running)
    sweep.signal(sig, group=True)
    assert_stopped(sweep, sig)


def test_sigterm_once_the_cluster_is_shut_down_is_still_handled(folder: Path) -> None:
    """After ``ray.shutdown()`` in the sweep's process SIGTERM had the default action at the C
    level: rc -15, no report, ``.tmp`` and ``.lock`` left. The driver's session ends before
    the report is written; the sweep's own handler must still be there, then."""
    sweep = Sweep(folder, "--workers", "2", "--trials", "2")
    sweep.wait_for(lambda cmds: any(b"pickplace.sweep.ray_driver" in c for c in cmds))
    sweep.wait_for(lambda cmds: not any(b"pickplace.sweep.ray_driver" in c for c in cmds))
    assert handles(sweep.proc.pid, signal.SIGTERM)  # at the C level
    sweep.signal(signal.SIGTERM, group=False)
    code, out, err, took = sweep.finish()
    assert code in (0, 1, 143), (code, err)  # before the end of the sweep, or after it
    assert took < STOP_BOUND_S, took
    clean_stderr(err)
    report = one_json(out)
    assert report["interrupted"] is (code == 143)
    assert report["completed"] == 2  # every trial had ended
    complete_sweep_rrd(folder / "sweep.rrd")
    assert [p.name for p in folder.iterdir()] == ["sweep.rrd"]
    assert sweep.processes() == []


# ------------------------------------------------------------------------- dead workers


def test_a_dead_ray_worker_is_a_failed_trial_and_stdout_stays_one_json_object(
    folder: Path,
) -> None:
    """Ray printed its coloured "(raylet) A worker died …" on stdout before the JSON."""
    sweep = Sweep(folder, "--workers", "2", "--trials", "6", "--seed", "7", record=False)
    sweep.wait_for(trial_running)
    pid = next(p for p, cmd in sweep.processes() if cmd.startswith(b"ray::guarded_trial"))
    os.kill(pid, signal.SIGKILL)
    code, out, err, _ = sweep.finish()
    assert code == 1, err
    assert err.strip() == ""  # none of Ray's lines
    report = one_json(out)
    assert report["completed"] == 6
    assert report["failures_by_reason"]["worker-died"] == 1
    assert set(report["failed_seeds"]["worker-died"]) <= set(range(7, 13))
    assert sweep.processes() == []


# ---------------------------------------------------------------------------- addresses


@contextlib.contextmanager
def silent_server() -> Iterator[int]:
    """A TCP server on 127.0.0.1 that accepts and never answers; yields its port."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(16)
    accepted: list[socket.socket] = []

    def loop() -> None:
        with contextlib.suppress(OSError):
            while True:
                accepted.append(server.accept()[0])

    threading.Thread(target=loop, daemon=True).start()
    try:
        yield int(server.getsockname()[1])
    finally:
        server.close()
        for conn in accepted:
            conn.close()


@contextlib.contextmanager
def web_server() -> Iterator[int]:
    """An HTTP/1 server on 127.0.0.1 (it answers, but not as gRPC); yields its port."""
    server = http.server.HTTPServer(("127.0.0.1", 0), http.server.BaseHTTPRequestHandler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        yield int(server.server_address[1])
    finally:
        server.shutdown()
        server.server_close()


@pytest.mark.parametrize("server", [silent_server, web_server], ids=["silent", "web"])
@pytest.mark.parametrize("scheme", ["", "ray://"])
def test_an_address_where_something_else_answers_is_refused_in_bounded_time(
    folder: Path, server: Callable[[], contextlib.AbstractContextManager[int]], scheme: str
) -> None:
    """Ray retried such an address for ever (still running at 100 s)."""
    with server() as port:
        address = f"{scheme}127.0.0.1:{port}"
        t0 = time.monotonic()
        sweep = Sweep(folder, "--trials", "1", "--address", address)
        code, out, err, _ = sweep.finish(60)
        took = time.monotonic() - t0
    assert code == 2
    assert took < CONNECT_TIMEOUT_S + 10.0, took  # the answer's time limit, the CLI's start
    (line,) = clean_stderr(err)
    assert line.startswith(f"pickplace: error: --address: '{address}' accepts connections")
    assert "is not a Ray cluster" in line and "ray://HOST:10001 or auto" in line
    assert out == ""
    assert list(folder.iterdir()) == []  # not even a lock file


@contextlib.contextmanager
def head_node() -> Iterator[tuple[int, int]]:
    """A Ray head (``ray start --head --block``, 2 CPUs) in a session of its own, with its
    own temporary folder; yields its GCS port and its Ray Client server's port, and ends
    the session when the block ends (``ray stop`` would stop every cluster here)."""
    gcs, client = free_port(), free_port()
    with tempfile.TemporaryDirectory(prefix="pp-ray-head-", dir="/tmp") as tmp:
        ray_cli = Path(sys.executable).parent / "ray"
        proc = subprocess.Popen(
            [str(ray_cli), "start", "--head", "--block", f"--port={gcs}",
             f"--ray-client-server-port={client}", "--num-cpus=2", "--include-dashboard=false",
             "--node-ip-address=127.0.0.1", f"--temp-dir={tmp}/ray"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
            env={**os.environ, "RAY_TMPDIR": tmp},
        )  # fmt: skip
        try:
            deadline = time.monotonic() + WAIT_S
            while True:
                with contextlib.suppress(OSError):
                    socket.create_connection(("127.0.0.1", client), 1.0).close()
                    break
                assert proc.poll() is None and time.monotonic() < deadline, "no Ray head"
                time.sleep(0.2)
            yield gcs, client
        finally:
            assert end_session(proc.pid, 10.0) == []
            proc.wait()


# Ray's own client server sometimes fails to start a session's server on a fresh head (seen in
# 1 CI run of 4 on 2 busy cores; its log was empty): a Ray fault, not this project's, retried
# with a new head.
RAY_CLIENT_SERVER_FLAKE = "Starting Ray client server failed"


def test_a_ray_client_address_works_with_the_ray_extra(folder: Path) -> None:
    """``ray://`` failed with "requires ray[client]", which the extra did not install."""
    for _ in range(3):
        with head_node() as (_, client):
            sweep = Sweep(folder, "--trials", "3", "--address", f"ray://127.0.0.1:{client}")
            code, out, err, _ = sweep.finish()
        if RAY_CLIENT_SERVER_FLAKE not in err:
            break
    assert code == 0, err
    assert err.strip() == ""
    report = one_json(out)
    assert report["backend"] == "ray" and report["workers"] == 2  # the cluster's CPUs
    assert report["successes"] == 3
    complete_sweep_rrd(folder / "sweep.rrd")
    assert sweep.processes() == []
