"""Summaries recorded before a behaviour-preserving change stay what they were.

``tests/data/golden_summaries.json`` is written by ``scripts/golden_summaries.py --write``
(its docstring says when to regenerate it). Every case is re-run here and compared field by
field, apart from the wall-clock fields; floats agree to 1e-9 relative. The runs are the ones
the scenario tests judge too (``tests.conftest.finished``), made once per process.
"""

from __future__ import annotations

import json
from typing import Any

import pytest

from scripts.golden_summaries import PATH, first_difference
from tests.conftest import finished, without_wall_time

RECORDS: list[dict[str, Any]] = json.loads(PATH.read_text())


def _case_id(record: dict[str, Any]) -> str:
    c = record["case"]
    return f"{c['scenario']}-{c['controller']}-seed{c['seed']}"


@pytest.mark.slow
@pytest.mark.parametrize("record", RECORDS, ids=[_case_id(r) for r in RECORDS])
def test_summary_is_unchanged(record: dict[str, Any]) -> None:
    # What scripts/golden_summaries.py's summary_of gives: the same run and fields.
    summary = without_wall_time(finished(**record["case"]).summary())
    diff = first_difference(summary, record["summary"])
    assert diff is None, diff


def test_first_difference_sees_a_changed_value() -> None:
    """The comparison itself can fail: a changed float, string or list length is found."""
    base = RECORDS[0]["summary"]
    assert first_difference(base, base) is None
    changed = dict(base, place_error_m=(base["place_error_m"] or 0.0) + 1e-6)
    assert "place_error_m" in str(first_difference(changed, base))
    assert first_difference(dict(base, failure="dropped"), base) is not None
    assert first_difference(dict(base, events=base["events"][:-1]), base) is not None
