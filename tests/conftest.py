"""Shared fixtures: the default scene (the iiwa14-wsg50 in scenes/world.xml), one finished run
per (scenario, controller, seed, robot) and process, and helpers to run the CLI in this process
or in a subprocess.

Two tiers (``pyproject.toml``): ``pytest`` runs the tests not marked ``slow`` (unit and math
tests, bad input, one run, one recording, one small sweep, one CLI subprocess); ``pytest -m
slow`` runs the rest (every scenario and seed, golden files, signals, viewers, Ray, robots).
"""

from __future__ import annotations

import copy
import functools
import json
import os
import subprocess
import sys
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mink.lie import SE3

from pickplace.planning.planner import PickPlacePlanner
from pickplace.robot.registry import DEFAULT_ROBOT
from pickplace.run.runner import RunRequest, prepare
from pickplace.sim.loader import load_scene
from pickplace.sim.loop import Simulation
from pickplace.sim.verdict import WALL_TIME_FIELDS, RunResult
from pickplace.world.placements import brick_on_floor, target_placement, uniform_placement
from pickplace.world.scene import Scene

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="session", autouse=True)
def _own_cache_dir(tmp_path_factory: pytest.TempPathFactory) -> None:
    """The suite's own cache folder (pickplace.robot.listing), never the user's; the CLI's
    subprocesses inherit it."""
    os.environ["PICKPLACE_CACHE_DIR"] = str(tmp_path_factory.mktemp("cache"))


@pytest.fixture(scope="session")
def scene() -> Scene:
    """The default scene (do not mutate its model: faults need a fresh one)."""
    return load_scene()


# ---------------------------------------------------------------------- shared runs


@dataclass(frozen=True)
class Finished:
    """A finished run: the simulation (its model, data and tick log at the end) and result.

    Shared by every test of this process that asks for the same inputs: read it, never step
    it or change its model or data.
    """

    sim: Simulation
    result: RunResult

    def summary(self) -> dict[str, Any]:
        """The run's summary (a copy of its own: a test may change it)."""
        return copy.deepcopy(self.result.summary())


def finished(
    scenario: str = "pick-place", controller: str = "qp", seed: int = 0, robot: str = DEFAULT_ROBOT
) -> Finished:
    """The run of these inputs, simulated once per test process (``prepare`` and ``run``, as
    ``pickplace run`` does without outputs), however many tests judge it.

    A test about running the same inputs again (determinism) makes its own second run.
    """
    return _finished(scenario, controller, seed, robot)


@functools.cache
def _finished(scenario: str, controller: str, seed: int, robot: str) -> Finished:
    _, _, sim = prepare(
        RunRequest(scenario=scenario, controller=controller, seed=seed, robot=robot)
    )
    return Finished(sim, sim.run())


def uniform_task(robot: str, seed: int) -> tuple[Scene, PickPlacePlanner, SE3, SE3]:
    """The scene of ``robot``, a qp planner, and pick-place-uniform's brick pose of ``seed``
    on bin 1's floor with the goal on bin 2's: what the planner tests of one uniform pose
    start from."""
    scene = load_scene(robot=robot)
    placement = uniform_placement(scene, np.random.default_rng(seed))
    X_pick = brick_on_floor(scene, placement, scene.source_bin.floor_top_z)
    X_place = brick_on_floor(scene, target_placement(scene), scene.target_bin.floor_top_z)
    return scene, PickPlacePlanner(scene, "qp"), X_pick, X_place


def without_wall_time(summary: dict[str, Any]) -> dict[str, Any]:
    """``summary`` without the fields that measure the wall clock (they differ between runs)."""
    return {k: v for k, v in summary.items() if k not in WALL_TIME_FIELDS}


# ---------------------------------------------------------------------- the CLI


def run_cli(*args: str, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
    """Run ``pickplace ARGS`` in a subprocess, exactly as a user would."""
    env = dict(os.environ)
    return subprocess.run(
        [sys.executable, "-m", "pickplace.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        cwd=REPO,
        check=False,
    )


def run_cli_json(*args: str) -> tuple[int, dict[str, Any]]:
    """Run ``pickplace run ARGS --json`` and parse its one JSON object."""
    proc = run_cli("run", *args, "--json")
    return proc.returncode, one_json(proc.stdout, proc.stderr)


def one_json(stdout: str, stderr: str = "") -> dict[str, Any]:
    """The one JSON object that ``stdout`` holds (the test fails otherwise)."""
    lines = [line for line in stdout.splitlines() if line.strip()]
    assert len(lines) == 1, f"expected one JSON line, got stdout={stdout!r} stderr={stderr!r}"
    result: dict[str, Any] = json.loads(lines[0])
    return result


@dataclass(frozen=True)
class CliRun:
    """What ``pickplace ARGS`` did: exit code, stdout and stderr."""

    returncode: int
    stdout: str
    stderr: str


# Python's own warning filters (what a ``pickplace`` process starts with, unlike pytest's),
# most general first.
_PYTHON_WARNING_FILTERS = (
    ("ignore", ResourceWarning),
    ("ignore", ImportWarning),
    ("ignore", PendingDeprecationWarning),
    ("ignore", DeprecationWarning),
)


@pytest.fixture
def cli(capfd: pytest.CaptureFixture[str]) -> Callable[..., CliRun]:
    """``pickplace ARGS`` in this process: ``pickplace.cli.main(ARGS)`` in the folder ``cwd``
    (default: the repository, as :func:`run_cli`), with file descriptors 1 and 2 captured (so
    what a library writes there counts too) and Python's warnings printed on stderr as a
    ``pickplace`` process would print them.

    Much cheaper than a subprocess (no interpreter start, imports or robot calibration), so
    bad-input tests use it; what only a process shows (signals, closed streams, exit status
    of the interpreter) is tested with :func:`run_cli` or ``tests/test_robustness.py``.
    """
    from pickplace.cli import main

    def call(*args: str, cwd: Path = REPO) -> CliRun:
        capfd.readouterr()  # whatever this test printed before
        here = os.getcwd()
        rust_log = os.environ.get("RUST_LOG")  # main() sets it for its process
        os.chdir(cwd)
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.resetwarnings()
                for action, category in _PYTHON_WARNING_FILTERS:
                    warnings.simplefilter(action, category)
                try:
                    code = main(list(args))
                except SystemExit as exc:  # as `sys.exit(main())` would end the process
                    code = exc.code if isinstance(exc.code, int) else 1
        finally:
            os.chdir(here)
            if rust_log is None:
                os.environ.pop("RUST_LOG", None)
            else:
                os.environ["RUST_LOG"] = rust_log
        out, err = capfd.readouterr()
        for w in caught:
            err += warnings.formatwarning(w.message, w.category, w.filename, w.lineno, w.line)
        return CliRun(code, out, err)

    return call
