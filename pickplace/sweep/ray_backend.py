"""Sweep trials as Ray tasks, on a running Ray cluster or on a local one started for the sweep.

Ray is an optional extra (``pip install 'pickplace[ray]'``); :func:`require_ray` says how to
get it. Each trial is one task of :func:`pickplace.sweep.trial.guarded_trial` (one CPU, never
retried), so a trial gives the same summary as with the process backend: the run depends on
its seed and parameters only. Every node of a cluster needs the same pickplace installed
(``pip install 'pickplace[ray]'`` in the nodes' Python).

- ``address`` None: ``ray.init`` starts a local cluster with ``workers`` CPUs (default: the
  CPUs this process may use), without dashboard, and shuts it down when the sweep ends.
- ``address`` given (``HOST:PORT`` of the head's GCS, ``auto``, or ``ray://HOST:PORT``): the
  sweep connects as a driver, keeps ``workers`` tasks in flight (default: twice the cluster's
  CPUs) and disconnects at the end; the cluster keeps running. An address where nothing
  answers is refused within :data:`CONNECT_TIMEOUT_S`. A cluster with token authentication
  (Ray's default for clusters it starts) needs ``RAY_AUTH_MODE=token`` in this process's
  environment, and the token, as Ray's documentation says.

At most twice the parallelism is in flight at once, so a 100,000-trial sweep holds a few
dozen task references, never the whole list. A task whose worker dies (a crash, the OOM
killer, a lost node) is a trial failed with ``worker-died``; an interrupt (Ctrl-C, SIGTERM,
SIGHUP: a KeyboardInterrupt here) cancels the tasks in flight at once (``force``) and the
report covers the trials finished. Ray's own log lines and its workers' output are not
shown; ``ray.init`` replaces the SIGTERM handler, which is put back right after.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import socket
import sys
import tempfile
import threading
import time
from collections.abc import Iterator, Sequence
from types import ModuleType
from typing import IO, Any

from pickplace.errors import InvalidInputError
from pickplace.signals import STOP_SIGNALS
from pickplace.sweep.trial import (
    POLL_PERIOD_S,
    WORKER_DIED,
    WORKER_ERROR,
    Add,
    Job,
    TrialSpec,
    available_cpus,
    guarded_trial,
    lost_trial,
)

INSTALL_COMMAND = "pip install 'pickplace[ray]'"
# Object store of a local cluster [bytes]: results travel inline (a few kB each), so a small
# store is plenty (Ray's minimum is 75 MiB).
LOCAL_OBJECT_STORE_BYTES = 128 * 1024 * 1024
# Tasks kept in flight per unit of parallelism.
IN_FLIGHT_FACTOR = 2
# Time a cluster's address gets to accept a connection [s].
CONNECT_TIMEOUT_S = 5.0


def require_ray() -> ModuleType:
    """The ``ray`` module.

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


def check_address(address: str) -> None:
    """Refuse an address at which nothing accepts a connection within
    :data:`CONNECT_TIMEOUT_S` (Ray itself would retry for many minutes).

    ``auto`` (the cluster this machine's ``ray start`` reports) is left to Ray.

    Raises:
        InvalidInputError: Not ``HOST:PORT``, ``ray://HOST:PORT`` or ``auto``, or nothing
            answers there (field ``address``).
    """
    if address == "auto":
        return
    hostport = address.removeprefix("ray://")
    host, sep, port = hostport.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise InvalidInputError(
            f"'{address}' is not a Ray cluster address: give HOST:PORT of the head (e.g. "
            "10.0.0.5:6379), ray://HOST:10001 or auto",
            field="address",
        )
    try:
        socket.create_connection((host.strip("[]"), int(port)), CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        raise InvalidInputError(
            f"no Ray cluster answers at '{address}' ({exc.strerror or exc}); start one with "
            "'ray start --head' or leave out --address for a local one",
            field="address",
        ) from None


def _init(ray: ModuleType, address: str | None, workers: int | None) -> None:
    """Start or join the cluster, quietly, keeping this process's stop-signal handlers."""
    main = threading.current_thread() is threading.main_thread()
    previous = {s: signal.getsignal(s) for s in STOP_SIGNALS} if main else {}
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
    captured = tempfile.TemporaryFile()  # noqa: SIM115 (closed in the finally below)
    try:
        # Ray's own start-up lines (e.g. about its authentication token) go to its logger;
        # its C++ core's (it retries a refused connection, one warning a second) to stderr,
        # kept aside while joining a cluster and turned into one line if that fails.
        logging.getLogger("ray").setLevel(logging.ERROR)
        with _stderr_to(captured if address is not None else None):
            ray.init(**options)
    except SystemExit as exc:
        # Ray's SIGTERM handler, installed while it starts, exits: make it the stop it is.
        if exc.code != signal.SIGTERM:
            raise
        ours = previous.get(signal.SIGTERM)
        if callable(ours):
            ours(signal.SIGTERM, None)  # pickplace's handler notes it (and raises when armed)
        raise KeyboardInterrupt from None
    except (ConnectionError, RuntimeError, ValueError, TimeoutError) as exc:
        where = f"the Ray cluster at '{address}'" if address else "a local Ray cluster"
        captured.seek(0)
        hint = ""
        if b"InvalidAuthToken" in captured.read():
            hint = (
                "; the cluster uses token authentication: run with RAY_AUTH_MODE=token and "
                "its token (RAY_AUTH_TOKEN, or ~/.ray/auth_token as 'ray start' left it)"
            )
        raise InvalidInputError(
            f"--backend ray: cannot start or reach {where}: "
            f"{' '.join(str(exc).split())[:300]}{hint}",
            field="address" if address else None,
        ) from None
    finally:
        captured.close()
        for sig, handler in previous.items():
            if handler is not None:
                signal.signal(sig, handler)


@contextlib.contextmanager
def _stderr_to(file: IO[bytes] | None) -> Iterator[None]:
    """Point file descriptor 2 at ``file`` for the block (None: leave it)."""
    if file is None:
        yield
        return
    with contextlib.suppress(OSError, ValueError):
        sys.stderr.flush()
    saved = os.dup(2)
    os.dup2(file.fileno(), 2)
    try:
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _parallelism(ray: ModuleType, address: str | None, workers: int | None) -> int:
    if workers is not None:
        return workers
    if address is None:
        return available_cpus()
    return max(1, int(ray.cluster_resources().get("CPU", 1)))


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
        KeyboardInterrupt: An interrupt; the tasks in flight were cancelled.
    """
    ray = require_ray()
    pending: dict[Any, Job] = {}
    try:
        t0 = time.perf_counter()
        _init(ray, address, workers)
        start_s = time.perf_counter() - t0
        parallel = _parallelism(ray, address, workers)
        task = ray.remote(num_cpus=1, max_retries=0)(guarded_trial)
        spec_refs = [ray.put(s) for s in specs]
        queue = iter(jobs)

        def submit() -> None:
            job = next(queue, None)
            if job is not None:
                pending[task.remote(spec_refs[job[0]], job[1])] = job

        for _ in range(IN_FLIGHT_FACTOR * parallel):
            submit()
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1, timeout=POLL_PERIOD_S)
            for ref in done:
                arm, seed = pending.pop(ref)
                result = _result(ray, ref, seed, specs[arm].arm)
                if result.get("failure") == "interrupted":  # the worker was stopped
                    raise KeyboardInterrupt
                add(result)
                submit()
        return parallel, start_s
    except KeyboardInterrupt:
        for ref in pending:
            with contextlib.suppress(Exception):
                ray.cancel(ref, force=True)
        raise
    finally:
        pending.clear()
        with contextlib.suppress(Exception):
            ray.shutdown()


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
        return lost_trial(seed, WORKER_DIED, _one_line(exc), arm)
    except errors.RayError as exc:
        return lost_trial(seed, WORKER_ERROR, _one_line(exc), arm)


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text[:300]}"


def ray_installed() -> bool:
    """True if Ray can be imported here (without importing it)."""
    import importlib.util

    return importlib.util.find_spec("ray") is not None


__all__ = ["INSTALL_COMMAND", "check_address", "ray_installed", "require_ray", "run_ray"]
