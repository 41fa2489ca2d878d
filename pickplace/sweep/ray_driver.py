"""The Ray driver: a process of its own that starts or joins the cluster and runs the trials.

:mod:`pickplace.sweep.ray_backend` starts it as ``python -m pickplace.sweep.ray_driver FD``
in a session of its own, its stdout and stderr a log file, and talks to it over the
connection on file descriptor ``FD``: it sends an :class:`Order`, the driver answers with
:class:`Started` (or :class:`Failed`), a :class:`TrialDone` per trial as it ends, then
:class:`Finished`; :class:`Stop` from the backend ends the loop early. So the sweep's own
process never imports Ray: Ray's signal handlers (which ``ray.init`` installs and
``ray.shutdown`` leaves at the default action at the C level), its crashes in its threads at
exit, its log lines ("(raylet) A worker died …") and its processes stay in here, where the
backend ends them all at once (:func:`pickplace.sweep.session.end_session`).

This process ignores the stop signals, also after ``ray.init`` put its own SIGTERM handler in
(only the backend decides when it stops, by :class:`Stop` or by killing its session, which has
no terminal anyway), dies with its parent (``PR_SET_PDEATHSIG``, Linux), and ends with
``os._exit`` once its work is sent: nothing it does after that can change the sweep.

Each trial is one task of :func:`pickplace.sweep.trial.guarded_trial` (one CPU, never
retried), so a trial gives the same summary as with the process backend. At most
:data:`IN_FLIGHT_FACTOR` times the parallelism is in flight at once, so a 100,000-trial sweep
holds a few dozen task references, never the whole list. A task whose worker dies (a crash,
the OOM killer, a lost node) is a trial failed with ``worker-died``.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import signal
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection
from types import ModuleType
from typing import Any

from pickplace.signals import STOP_SIGNALS
from pickplace.sweep.trial import (
    POLL_PERIOD_S,
    WORKER_DIED,
    WORKER_ERROR,
    Job,
    TrialSpec,
    available_cpus,
    guarded_trial,
    lost_trial,
)

# Object store of a local cluster [bytes]: results travel inline (a few kB each), so a small
# store is plenty (Ray's minimum is 75 MiB).
LOCAL_OBJECT_STORE_BYTES = 128 * 1024 * 1024
# Tasks kept in flight per unit of parallelism.
IN_FLIGHT_FACTOR = 2
PR_SET_PDEATHSIG = 1  # prctl option: the signal this process gets when its parent dies


@dataclass(frozen=True)
class Order:
    """What the driver is to run.

    Attributes:
        specs: The trial specs (a job names one by index).
        jobs: (spec index, seed) per run, in order.
        address: A running cluster's address, or None for a local cluster.
        workers: CPUs of the local cluster, or tasks in flight on a running one (None: the
            CPUs available here, or the cluster's).
    """

    specs: tuple[TrialSpec, ...]
    jobs: tuple[Job, ...]
    address: str | None
    workers: int | None


@dataclass(frozen=True)
class Started:
    """The cluster is up (or joined).

    Attributes:
        parallelism: The local cluster's CPUs, or the tasks kept in flight on a running one.
        start_s: Time spent starting or joining it [s].
    """

    parallelism: int
    start_s: float


@dataclass(frozen=True)
class Failed:
    """The cluster could not be started or reached.

    Attributes:
        message: Ray's error, on one line.
    """

    message: str


@dataclass(frozen=True)
class TrialDone:
    """One trial's compact summary, or its lost-trial entry.

    Attributes:
        entry: The summary or entry.
    """

    entry: dict[str, Any]


@dataclass(frozen=True)
class Finished:
    """Every trial is done (or the loop was stopped)."""


@dataclass(frozen=True)
class Stop:
    """From the backend: cancel the tasks in flight and end."""


def _init(ray: ModuleType, address: str | None, workers: int | None) -> None:
    """Start or join the cluster, quietly."""
    options: dict[str, Any] = {
        "include_dashboard": False,
        "log_to_driver": False,
        "logging_level": logging.ERROR,
        "configure_logging": True,
    }
    if address is None:
        options.update(
            # "local": a new cluster even when another one runs on this machine (without it
            # ray.init joins the one /tmp/ray/ray_current_cluster names, and refuses num_cpus).
            address="local",
            num_cpus=workers or available_cpus(),
            num_gpus=0,
            object_store_memory=LOCAL_OBJECT_STORE_BYTES,
        )
    else:
        options["address"] = address
    logging.getLogger("ray").setLevel(logging.ERROR)
    ray.init(**options)


def _parallelism(ray: ModuleType, address: str | None, workers: int | None) -> int:
    if workers is not None:
        return workers
    if address is None:
        return available_cpus()
    return max(1, int(ray.cluster_resources().get("CPU", 1)))


def run_tasks(ray: ModuleType, order: Order, conn: Connection, parallel: int) -> None:
    """Run the order's jobs as tasks, sending each result as it arrives, until all are done
    or :class:`Stop` comes (the tasks in flight are then cancelled)."""
    task = ray.remote(num_cpus=1, max_retries=0)(guarded_trial)
    spec_refs = [ray.put(s) for s in order.specs]
    queue = iter(order.jobs)
    pending: dict[Any, Job] = {}

    def submit() -> None:
        job = next(queue, None)
        if job is not None:
            pending[task.remote(spec_refs[job[0]], job[1])] = job

    for _ in range(IN_FLIGHT_FACTOR * parallel):
        submit()
    while pending:
        if conn.poll(0):
            conn.recv()  # Stop
            break
        done, _ = ray.wait(list(pending), num_returns=1, timeout=POLL_PERIOD_S)
        for ref in done:
            arm, seed = pending.pop(ref)
            conn.send(TrialDone(_result(ray, ref, seed, order.specs[arm].arm)))
            submit()
    for ref in pending:
        with contextlib.suppress(Exception):
            ray.cancel(ref, force=True)


def _result(ray: ModuleType, ref: Any, seed: int, arm: str) -> dict[str, Any]:
    """The task's summary, or a lost-trial entry when its worker died or Ray failed it."""
    errors = ray.exceptions
    died = tuple(
        getattr(errors, name)
        for name in ("WorkerCrashedError", "NodeDiedError", "OutOfMemoryError", "ObjectLostError")
        if hasattr(errors, name)
    )
    try:
        result: dict[str, Any] = ray.get(ref)
        return result
    except died as exc:
        return lost_trial(seed, WORKER_DIED, one_line(exc), arm)
    except errors.RayError as exc:
        return lost_trial(seed, WORKER_ERROR, one_line(exc), arm)


def one_line(exc: BaseException) -> str:
    """``Type: message`` on one line, at most about 300 characters."""
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text[:300]}"


def _die_with_parent() -> None:
    """Get SIGKILL when the parent (the sweep) dies, however it dies (Linux only)."""
    if not sys.platform.startswith("linux"):
        return
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
    if os.getppid() == 1:  # the parent is already gone
        os._exit(1)


def drive(conn: Connection) -> None:
    """Receive the :class:`Order`, start or join the cluster, run the trials, disconnect."""
    order: Order = conn.recv()
    import ray

    t0 = time.perf_counter()
    try:
        _init(ray, order.address, order.workers)
    except Exception as exc:  # Ray's errors here are of many types; each one is a refusal
        conn.send(Failed(" ".join(str(exc).split())[:300]))
        return
    for sig in STOP_SIGNALS:  # ray.init installed a SIGTERM handler of its own
        signal.signal(sig, signal.SIG_IGN)
    start_s = time.perf_counter() - t0
    parallel = _parallelism(ray, order.address, order.workers)
    conn.send(Started(parallel, start_s))
    try:
        run_tasks(ray, order, conn, parallel)
    except Exception as exc:  # the cluster failed under the sweep (e.g. its head died)
        conn.send(Failed(one_line(exc)))
    finally:
        with contextlib.suppress(OSError):
            conn.send(Finished())
        with contextlib.suppress(Exception):
            ray.shutdown()


def main(argv: Sequence[str]) -> None:
    """The driver process: ``python -m pickplace.sweep.ray_driver FD`` (never returns)."""
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)
    _die_with_parent()
    try:
        drive(Connection(int(argv[1])))
    except (EOFError, OSError):  # the backend went away: nothing to report to
        pass
    finally:
        with contextlib.suppress(Exception):
            sys.stdout.flush()
            sys.stderr.flush()
    os._exit(0)


__all__ = [
    "IN_FLIGHT_FACTOR",
    "LOCAL_OBJECT_STORE_BYTES",
    "Failed",
    "Finished",
    "Order",
    "Started",
    "Stop",
    "TrialDone",
    "drive",
    "main",
    "one_line",
    "run_tasks",
]


if __name__ == "__main__":
    # Run as the module's real name, not as __main__: the messages this process sends are
    # pickled by their class's module, which the backend imports by that name.
    from pickplace.sweep import ray_driver

    ray_driver.main(sys.argv)
