"""Sweeps: parallel trials give the same report as serial ones; failures name their seeds."""

from __future__ import annotations

import json

import pytest

from pickplace.errors import InvalidInputError
from pickplace.sweep import SWEEP_WALL_TIME_FIELDS, SweepRequest, run_sweep
from tests.conftest import run_cli


def _without_timing(report: dict) -> dict:
    return {k: v for k, v in report.items() if k not in (*SWEEP_WALL_TIME_FIELDS, "workers")}


def test_parallel_sweep_equals_serial_sweep() -> None:
    serial = run_sweep(SweepRequest("pick-place-random", "qp", trials=4, first_seed=11, workers=1))
    parallel = run_sweep(
        SweepRequest("pick-place-random", "qp", trials=4, first_seed=11, workers=2)
    )
    assert _without_timing(serial) == _without_timing(parallel)
    assert serial["successes"] == 4
    assert serial["place_error_p95_m"] < 0.01


def test_failed_seeds_are_reported_for_rerun() -> None:
    proc = run_cli(
        "sweep", "--scenario", "fault-brick-moved", "--trials", "2", "--seed", "5", "--json"
    )
    assert proc.returncode == 1
    report = json.loads(proc.stdout)
    assert report["failures_by_reason"] == {"missed-grasp": 2}
    assert report["failed_seeds"] == {"missed-grasp": [5, 6]}


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"trials": 0}, "--trials"),
        ({"workers": 0}, "--workers"),
        ({"workers": 10_000}, "--workers"),
    ],
)
def test_bad_sweep_requests_are_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(InvalidInputError, match=message):
        SweepRequest(**kwargs).validate()


def test_sweep_cli_bad_input_is_one_line() -> None:
    proc = run_cli("sweep", "--workers", "0")
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1
