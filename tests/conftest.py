"""Shared fixtures: the default scene (the iiwa14-wsg50 in scenes/world.xml), and helpers to
run scenarios and the CLI."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from pickplace.sim.loader import load_scene
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
    lines = [line for line in proc.stdout.splitlines() if line.strip()]
    assert len(lines) == 1, (
        f"expected one JSON line, got stdout={proc.stdout!r} stderr={proc.stderr!r}"
    )
    return proc.returncode, json.loads(lines[0])
