"""Sweep trials as Ray tasks, on a running Ray cluster or on a local one started for the sweep.

Ray is an optional extra (``pip install 'pickplace[ray]'``); :func:`require_ray` says how to
get it. Every node of a cluster needs the same pickplace installed.

The sweep's process never imports Ray. It starts a driver process
(:mod:`pickplace.sweep.ray_driver`) in a session of its own, with stdout and stderr a log
file, and relays the results the driver sends. So:

- a stop signal to the sweep's process group (Ctrl-C, ``timeout``, a closed terminal) reaches
  the sweep alone, whose handler stays in place all along; never Ray's GCS, raylet or workers,
  nor Ray's own handlers (which print a stack dump and abort);
- Ray's log lines ("(raylet) A worker died …", its C++ core's retries) go to that log file,
  never to stdout or stderr;
- when the sweep ends, for whatever reason, every process of the driver's session is killed
  and waited for (:func:`pickplace.sweep.session.end_session`): the driver, and with a local
  cluster its GCS, raylet, dashboard and runtime-env agents and workers.

- ``address`` None: the driver starts a local cluster with ``workers`` CPUs (default: the
  CPUs this process may use), without dashboard. A stop kills it at once (the results are
  here already); at the end of the sweep it gets :data:`SHUTDOWN_WAIT_S` to shut down.
- ``address`` given (checked by :func:`pickplace.sweep.ray_address.check_address`): the
  driver connects, keeps ``workers`` tasks in flight (default: the cluster's CPUs) and gets
  :data:`SHUTDOWN_WAIT_S` after a stop or the end to cancel its tasks and disconnect; the
  cluster keeps running (and ends the tasks of a driver that went away). A cluster with token
  authentication (Ray's default for clusters it starts) needs ``RAY_AUTH_MODE=token`` in this
  process's environment, and the token, as Ray's documentation says.

A task whose worker dies is a trial failed with ``worker-died``; a driver that dies, or whose
cluster fails under it, fails the trials it did not report the same way.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType
from typing import IO, Any

import pickplace
from pickplace.errors import InvalidInputError
from pickplace.signals import active_handler, deferred_interrupts
from pickplace.sweep.ray_address import check_address
from pickplace.sweep.ray_driver import Failed, Finished, Order, Started, Stop, TrialDone
from pickplace.sweep.session import end_session
from pickplace.sweep.trial import POLL_PERIOD_S, WORKER_DIED, Add, Job, TrialSpec, lost_trial

INSTALL_COMMAND = "pip install 'pickplace[ray]'"
# Time the driver gets to start a local cluster or join one [s]: Ray's own start takes 2 to
# 25 s on a loaded 2-core machine, and gives up on a cluster that does not answer after 60 s.
START_TIMEOUT_S = 180.0
# Time the driver gets to shut its cluster down, or to disconnect from one [s].
SHUTDOWN_WAIT_S = 3.0
# Time to wait for the killed processes of the driver's session to be gone [s].
KILL_WAIT_S = 2.0


def require_ray() -> ModuleType:
    """The ``ray`` module (for the driver process; the sweep's own only checks that Ray is
    installed, :func:`ray_installed`).

    Raises:
        InvalidInputError: Ray is not installed; the message gives the install command.
    """
    try:
        import ray
    except ImportError:
        raise InvalidInputError(
            f"--backend ray needs Ray, which is not installed here: {INSTALL_COMMAND}"
        ) from None
    return ray


def ray_installed() -> bool:
    """True if Ray can be imported here (without importing it)."""
    import importlib.util

    return importlib.util.find_spec("ray") is not None


def check_ray(address: str | None) -> None:
    """Refuse the Ray backend when Ray is missing or ``address`` is not a Ray cluster's.

    Raises:
        InvalidInputError: Ray is not installed (the message gives the install command), or
            the address is refused (:func:`~pickplace.sweep.ray_address.check_address`).
    """
    if not ray_installed():
        raise InvalidInputError(
            f"--backend ray needs Ray, which is not installed here: {INSTALL_COMMAND}"
        )
    if address is not None:
        check_address(address)


class Driver:
    """The driver process (:mod:`pickplace.sweep.ray_driver`) and the connection to it.

    Attributes:
        process: The driver, leader of its own session.
        conn: This end of the connection.
        log: Its stdout and stderr (a temporary file, gone once closed).
    """

    def __init__(self, order: Order) -> None:
        """Start the driver and send it ``order``; call it inside
        :func:`~pickplace.signals.deferred_interrupts` (a driver must never run without
        its caller knowing)."""
        self.log: IO[bytes] = tempfile.TemporaryFile()  # noqa: SIM115 (closed in close())
        self.conn, theirs = mp.Pipe(duplex=True)
        env = _driver_environment()
        try:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "pickplace.sweep.ray_driver", str(theirs.fileno())],
                stdin=subprocess.DEVNULL,
                stdout=self.log,
                stderr=self.log,
                pass_fds=(theirs.fileno(),),
                start_new_session=True,
                env=env,
            )
        except BaseException:
            self.conn.close()
            self.log.close()
            raise
        finally:
            theirs.close()
        with contextlib.suppress(OSError):  # a driver that died at once: receive() says so
            self.conn.send(order)

    def receive(self, timeout_s: float) -> Any:
        """The driver's next message, None if none within ``timeout_s`` [s], or
        :class:`Finished` if the driver is gone."""
        try:
            if not self.conn.poll(timeout_s):
                return None
            return self.conn.recv()
        except (EOFError, OSError):
            return Finished()

    def exit_text(self) -> str:
        """How the driver ended (or ``still running``)."""
        code = self.process.poll()
        if code is None:
            return "still running"
        return f"killed by signal {-code}" if code < 0 else f"exit {code}"

    def log_text(self) -> str:
        """What the driver and Ray wrote on its stdout and stderr (the first 64 kB)."""
        try:
            self.log.seek(0)
            return self.log.read(65536).decode(errors="replace")
        except (OSError, ValueError):
            return ""

    def close(self, grace_s: float) -> None:
        """Stop the driver: :class:`Stop`, ``grace_s`` [s] to end by itself (cut short by a
        stop signal), then every process of its session killed and waited for."""
        with deferred_interrupts():
            if grace_s > 0 and self.process.poll() is None:
                with contextlib.suppress(OSError, ValueError):
                    self.conn.send(Stop())
                deadline = time.monotonic() + grace_s
                handler = active_handler()
                stopping = handler is not None and handler.interrupted  # this is the stop
                while self.process.poll() is None and time.monotonic() < deadline:
                    if handler is not None and handler.interrupted and not stopping:
                        break  # a stop signal during the end of the sweep: no more waiting
                    time.sleep(0.02)
            end_session(self.process.pid, KILL_WAIT_S)
            self.process.wait()
            self.conn.close()
            self.log.close()


def _driver_environment() -> dict[str, str]:
    """This process's environment, with the folder of the pickplace it runs first on
    ``PYTHONPATH`` when that is a source tree (not an installed package's folder): the driver
    and, through the environment a local cluster's processes inherit, its workers run the
    same code as this process."""
    env = dict(os.environ)
    source = Path(pickplace.__file__).resolve().parent.parent
    if source.name not in ("site-packages", "dist-packages"):
        path = env.get("PYTHONPATH")
        env["PYTHONPATH"] = str(source) + (os.pathsep + path if path else "")
    return env


def _refusal(driver: Driver, address: str | None, reason: str) -> InvalidInputError:
    """The error of a cluster that could not be started or reached."""
    where = f"the Ray cluster at '{address}'" if address else "a local Ray cluster"
    hint = ""
    if "InvalidAuthToken" in driver.log_text():
        hint = (
            "; the cluster uses token authentication: run with RAY_AUTH_MODE=token and "
            "its token (RAY_AUTH_TOKEN, or ~/.ray/auth_token as 'ray start' left it)"
        )
    return InvalidInputError(
        f"--backend ray: cannot start or reach {where}: {reason}{hint}",
        field="address" if address else None,
    )


def run_ray(
    specs: Sequence[TrialSpec],
    jobs: Sequence[Job],
    add: Add,
    address: str | None,
    workers: int | None,
) -> tuple[int, float]:
    """Run ``jobs`` as Ray tasks, handing each result to ``add`` as it arrives.

    Args:
        specs: The trial specs (a job names one by index).
        jobs: (spec index, seed) per run.
        add: Gets each compact summary or lost-trial entry.
        address: A running cluster's address, or None for a local cluster.
        workers: CPUs of the local cluster, or tasks in flight on a running one.

    Returns:
        The parallelism used (the local cluster's CPUs, or the tasks in flight), and the
        time spent starting or joining the cluster [s].

    Raises:
        InvalidInputError: Ray is missing, or the cluster cannot be started or reached.
        KeyboardInterrupt: An interrupt; the driver's session was ended.
    """
    check_ray(None)
    t0 = time.perf_counter()
    grace = 0.0 if address is None else SHUTDOWN_WAIT_S
    driver: Driver | None = None
    try:
        with deferred_interrupts():
            driver = Driver(Order(tuple(specs), tuple(jobs), address, workers))
        started = _wait_started(driver, address, t0)
        reported: set[tuple[str, int]] = set()
        problem = None
        while True:
            message = driver.receive(POLL_PERIOD_S)
            if isinstance(message, TrialDone):
                entry = message.entry
                if entry.get("failure") == "interrupted":  # the worker was stopped
                    raise KeyboardInterrupt
                reported.add((str(entry.get("arm", "")), int(entry["seed"])))
                add(entry)
            elif isinstance(message, Failed):
                problem = message.message
            elif isinstance(message, Finished):
                break
        grace = SHUTDOWN_WAIT_S
        if len(reported) < len(jobs):  # the driver died, or its cluster failed under it
            with contextlib.suppress(subprocess.TimeoutExpired):
                driver.process.wait(timeout=1.0)
            why = problem or f"the driver process ended ({driver.exit_text()})"
            _lost_the_rest(specs, jobs, reported, add, why)
        return started.parallelism, started.start_s
    finally:
        if driver is not None:
            driver.close(grace)


def _wait_started(driver: Driver, address: str | None, t0: float) -> Started:
    """The driver's :class:`Started`.

    Raises:
        InvalidInputError: It failed, ended or did not start within :data:`START_TIMEOUT_S`.
    """
    while time.perf_counter() - t0 < START_TIMEOUT_S:
        message = driver.receive(POLL_PERIOD_S)
        if isinstance(message, Started):
            return message
        if isinstance(message, Failed):
            raise _refusal(driver, address, message.message)
        if isinstance(message, Finished):
            driver.process.wait()
            lines = [line for line in driver.log_text().splitlines() if line.strip()]
            last = f": {' '.join(lines[-1].split())[:300]}" if lines else ""
            ended = f"the Ray driver process ended ({driver.exit_text()}){last}"
            raise _refusal(driver, address, ended)
    raise _refusal(driver, address, f"not up within {START_TIMEOUT_S:g} s")


def _lost_the_rest(
    specs: Sequence[TrialSpec],
    jobs: Sequence[Job],
    reported: set[tuple[str, int]],
    add: Add,
    why: str,
) -> None:
    """Fail, as ``worker-died``, the jobs the driver never reported (it died, or its
    cluster failed under it)."""
    for arm, seed in jobs:
        label = specs[arm].arm
        if (label, seed) not in reported:
            add(lost_trial(seed, WORKER_DIED, f"the Ray driver gave no result: {why}", label))


__all__ = [
    "INSTALL_COMMAND",
    "KILL_WAIT_S",
    "SHUTDOWN_WAIT_S",
    "START_TIMEOUT_S",
    "Driver",
    "check_address",
    "check_ray",
    "ray_installed",
    "require_ray",
    "run_ray",
]
