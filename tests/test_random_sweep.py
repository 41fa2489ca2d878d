"""pick-place-random over 300 seeds nobody looked at: slow, run by CI."""

from __future__ import annotations

import os

import pytest

from pickplace.sweep.sweep import SweepRequest, run_sweep

SEEDS = 300
# What the pre-flight checks: a run whose pre-flight passed must not fail for these.
PREDICTED = {"collision", "limit-violated", "ik-failed", "no-feasible-plan"}


@pytest.mark.slow
def test_random_pick_place_succeeds_on_299_of_300_seeds_and_agrees_with_the_preflight() -> None:
    report = run_sweep(
        SweepRequest("pick-place-random", "qp", SEEDS, 0, workers=os.cpu_count() or 1)
    )
    assert report["trials"] == SEEDS
    assert report["successes"] >= SEEDS - 1, report["failed_seeds"]
    # Every run's plan passed the pre-flight (the scenario draws again until one does), so
    # none may fail for a reason the pre-flight checks.
    assert not set(report["failures_by_reason"]) & PREDICTED, report["failed_seeds"]
