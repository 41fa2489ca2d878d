"""The Ray backend gives the process backend's per-seed outcomes, on a cluster this test starts.

CI installs the ``ray`` extra (the README's test command); without Ray these tests are skipped.
Both start Ray clusters: the full tier (``slow``).
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from pickplace.sim.vary import parse_vary
from pickplace.sweep.sweep import SWEEP_WALL_TIME_FIELDS, SweepRequest, run_sweep
from tests.conftest import REPO

pytest.importorskip("ray")

# Brick mass across the grip's limit (2.35 kg: the heavier ones are refused before any physics)
# and pose noise up to half the brick's width: successes, missed grasps and refusals.
VARY = ["brick_mass=0.2:12", "pose_noise=0:0.05"]
# Fields that differ between backends by design (wall clock, the backend, its parallelism).
BACKEND_FIELDS = {*SWEEP_WALL_TIME_FIELDS, "backend", "workers"}

CLUSTER = """
import logging, sys
import ray
ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False,
         logging_level=logging.ERROR, object_store_memory=128 * 1024 * 1024)
print(ray.get_runtime_context().gcs_address, flush=True)
sys.stdin.read()  # until the test closes it
ray.shutdown()
"""


@contextlib.contextmanager
def local_cluster() -> Iterator[str]:
    """A local Ray cluster (2 CPUs) in a process of its own; yields its address and stops it
    when the block ends."""
    proc = subprocess.Popen(
        [sys.executable, "-c", CLUSTER],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        cwd=REPO,
    )
    try:
        assert proc.stdout is not None
        address = proc.stdout.readline().strip()
        assert address, "the Ray cluster did not start"
        yield address
    finally:
        assert proc.stdin is not None
        proc.stdin.close()  # ray.shutdown() stops the cluster's processes
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def cli(*args: str, env: dict[str, str] | None = None) -> subprocess.Popen[str]:
    """``pickplace ARGS`` in a subprocess, ``env`` added to the environment."""
    # Ray's clusters use token authentication (the token in ~/.ray, shared on this machine);
    # a driver that joins one says so.
    env = dict(os.environ, RAY_AUTH_MODE="token", **(env or {}))
    return subprocess.Popen(
        [sys.executable, "-m", "pickplace.cli", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
        env=env,
    )


def without_backend(report: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in report.items() if k not in BACKEND_FIELDS}


@pytest.mark.slow
def test_ray_and_process_backends_give_identical_per_seed_outcomes_for_200_trials() -> None:
    args = ["--trials", "200", "--seed", "1000", *(f"--vary={v}" for v in VARY), "--json"]
    with local_cluster() as address:
        proc = cli("sweep", "--backend", "ray", "--address", address, *args)
        out, err = proc.communicate(timeout=900)
    assert proc.returncode == 1, err  # some trials fail, by design
    assert err.strip() == ""  # none of Ray's own lines
    ray = json.loads(out)
    process = run_sweep(
        SweepRequest("pick-place-random", "qp", 200, 1000, 2, vary=parse_vary(VARY))
    )
    assert ray["backend"] == "ray" and process["backend"] == "process"
    assert ray["workers"] == 2  # the cluster's CPUs
    assert [t["seed"] for t in ray["trial_results"]] == list(range(1000, 1200))
    # Every trial's outcome, metrics and parameters, bit for bit (through JSON).
    assert ray["trial_results"] == json.loads(json.dumps(process["trial_results"]))
    assert without_backend(ray) == json.loads(json.dumps(without_backend(process)))
    reasons = set(process["failures_by_reason"])
    assert {"dropped", "missed-grasp"} <= reasons, reasons
    assert 0 < process["successes"] < 200


@pytest.mark.slow
def test_without_an_address_a_sweep_starts_its_own_cluster_where_another_is_recorded() -> None:
    """``ray start`` records its cluster in ``<temp dir>/ray/ray_current_cluster``, and
    ``ray.init()`` without an address joins the cluster recorded there (and refuses the CPUs
    given: exit 2). A sweep without ``--address`` starts its own all the same. (A temporary
    Ray folder of the test's: the machine's ``/tmp/ray`` is everyone's.)"""
    with (
        local_cluster() as address,
        tempfile.TemporaryDirectory(prefix="pp-ray-", dir="/tmp") as tmp,  # short socket paths
    ):
        (Path(tmp) / "ray").mkdir()
        (Path(tmp) / "ray" / "ray_current_cluster").write_text(address)
        proc = cli(
            "sweep", "--backend", "ray", "--workers", "1", "--trials", "1", "--json",
            env={"RAY_TMPDIR": tmp},
        )  # fmt: skip
        out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    report = json.loads(out)
    assert report["backend"] == "ray" and report["workers"] == 1 and report["successes"] == 1


def descendants(pid: int) -> list[int]:
    """Every process started by ``pid``, its children's children and so on."""
    found: list[int] = []
    todo = [pid]
    while todo:
        for task in Path(f"/proc/{todo.pop()}/task").glob("*"):
            with contextlib.suppress(OSError):
                children = [int(c) for c in (task / "children").read_text().split()]
                found += children
                todo += children
    return found


def runs_a_trial(pid: int) -> bool:
    """True once a Ray worker of the cluster that ``pid`` started runs a trial (Ray names a
    worker's process after its task)."""
    for child in descendants(pid):
        with contextlib.suppress(OSError):
            if Path(f"/proc/{child}/cmdline").read_bytes().startswith(b"ray::guarded_trial"):
                return True
    return False


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc")
def test_a_ray_sweep_on_its_own_cluster_stops_on_sigterm_with_a_partial_report() -> None:
    """Signalled once trials run (starting the cluster takes 5 to 25 s on a loaded 2-core
    machine: a fixed wait would signal it at another stage; tests/test_ray_robustness.py
    signals every stage)."""
    proc = cli("sweep", "--backend", "ray", "--workers", "2", "--trials", "400", "--json")
    deadline = time.monotonic() + 300
    while not runs_a_trial(proc.pid):  # the cluster is up, trials are running
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    assert proc.poll() is None
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    took = time.monotonic() - t0
    assert proc.returncode == 128 + signal.SIGTERM
    assert took < 5.0, took  # the driver's session killed (docs/sweeps.md: within 5 s)
    assert err.strip() == "pickplace: stopped by SIGTERM"
    report = json.loads(out)
    assert report["interrupted"] is True
    assert report["completed"] < 400
    assert report["completed"] == report["successes"] + sum(report["failures_by_reason"].values())
    assert "interrupted" not in report["failures_by_reason"]
