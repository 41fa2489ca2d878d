"""Summaries recorded before a behaviour-preserving change stay what they were.

``tests/data/golden_summaries.json`` is written by ``scripts/golden_summaries.py --write``
(its docstring says when to regenerate it). Every case is re-run here and compared field by
field, apart from the wall-clock fields: integers and texts exactly, floats within the
tolerance of their field (``TOLERANCES`` there, with the reasons), so that a file recorded on
another CPU passes here. That two runs in one process agree bit for bit is tested in
``tests/test_scenarios.py``. The tests after the first show that the comparison can fail.
The runs are the ones the scenario tests judge too (``tests.conftest.finished``), made
once per process.
"""

from __future__ import annotations

import copy
import json
import re
from typing import Any

import pytest

from scripts.golden_summaries import (
    LENGTH,
    PATH,
    TOLERANCES,
    Rule,
    compare,
    first_difference,
    print_margins,
    printed_alike,
    untolerated_fields,
    unused_rules,
)
from tests.conftest import finished, without_wall_time

RECORDS: list[dict[str, Any]] = json.loads(PATH.read_text())
SUMMARIES = [r["summary"] for r in RECORDS]


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


def test_every_float_field_has_a_tolerance_and_every_tolerance_a_field() -> None:
    assert untolerated_fields(TOLERANCES, SUMMARIES) == set()
    assert unused_rules(TOLERANCES, SUMMARIES) == []
    # Both checks can fail: a rule for no field, a field without a rule.
    stale = (*TOLERANCES, Rule("no_such_field_m", LENGTH, "stale"))
    assert unused_rules(stale, SUMMARIES) == ["no_such_field_m"]
    without_lengths = [r for r in TOLERANCES if r.pattern != "*_m"]
    assert "max_slip_m" in untolerated_fields(without_lengths, SUMMARIES)


def _changed(summary: dict[str, Any], path: tuple[str | int, ...], value: Any) -> dict[str, Any]:
    """A deep copy of ``summary`` with the value at ``path`` replaced."""
    out = copy.deepcopy(summary)
    node: Any = out
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return out


def _success() -> dict[str, Any]:
    return next(s for s in SUMMARIES if s["success"] and s["scenario"] == "pick-place")


def _failure() -> dict[str, Any]:
    return next(s for s in SUMMARIES if s["failure"] == "dropped")


def test_a_changed_outcome_or_failure_reason_is_a_difference() -> None:
    ok, bad = _success(), _failure()
    assert first_difference(ok, ok) is None
    assert ".success" in str(first_difference(_changed(ok, ("success",), False), ok))
    assert ".failure" in str(first_difference(_changed(bad, ("failure",), "collision"), bad))
    assert first_difference(_changed(ok, ("failure",), "dropped"), ok) is not None
    kind = ("events", 1, "kind")
    assert ".events[1].kind" in str(first_difference(_changed(ok, kind, "grasp"), ok))


def test_a_tick_or_a_count_off_by_one_is_a_difference() -> None:
    ok, bad = _success(), _failure()
    assert ".ticks" in str(first_difference(_changed(ok, ("ticks",), ok["ticks"] + 1), ok))
    tick = ("events", 3, "tick")
    later = _changed(ok, tick, ok["events"][3]["tick"] + 1)
    assert ".events[3].tick" in str(first_difference(later, ok))
    failure_tick = _changed(bad, ("failure_tick",), bad["failure_tick"] - 1)
    assert ".failure_tick" in str(first_difference(failure_tick, bad))
    ok_count = ("ik_status_counts", "ok")
    more = _changed(ok, ok_count, ok["ik_status_counts"]["ok"] + 1)
    assert ".ik_status_counts.ok" in str(first_difference(more, ok))
    assert first_difference(_changed(ok, ("events",), ok["events"][:-1]), ok) is not None


def test_a_position_off_by_1e_5_m_is_a_difference_and_off_by_1e_9_m_is_not() -> None:
    ok = _success()
    x = ("brick_final_xyz", 0)
    x0 = ok["brick_final_xyz"][0]
    assert ".brick_final_xyz[0]" in str(first_difference(_changed(ok, x, x0 + 1e-5), ok))
    assert first_difference(_changed(ok, x, x0 + 1e-9), ok) is None
    assert first_difference(_changed(ok, x, x0 - 1e-9), ok) is None
    error = ok["max_position_error_m"]
    assert first_difference(_changed(ok, ("max_position_error_m",), error + 1e-5), ok)
    assert first_difference(_changed(ok, ("max_position_error_m",), error + 1e-9), ok) is None


def test_times_forces_and_jacobian_measures_compare_within_their_tolerances() -> None:
    ok = _success()
    t = ("plan", "keyframes", 6, "t")
    t6 = ok["plan"]["keyframes"][6]["t"]
    assert first_difference(_changed(ok, t, t6 + 1e-8), ok) is None
    assert ".plan.keyframes[6].t" in str(first_difference(_changed(ok, t, t6 + 1e-4), ok))
    condition = ok["max_condition_number"]  # 1e-6 relative
    key = ("max_condition_number",)
    assert first_difference(_changed(ok, key, condition * (1 + 1e-8)), ok) is None
    larger = _changed(ok, key, condition * 1.001)
    assert ".max_condition_number" in str(first_difference(larger, ok))
    force = "max_robot_world_contact_force_n"  # 0 N in the nominal run: 1e-4 N absolute
    assert first_difference(_changed(ok, (force,), 1e-6), ok) is None
    assert first_difference(_changed(ok, (force,), 1e-3), ok) is not None


def test_nan_infinity_and_types_compare_exactly() -> None:
    ok = _success()
    error = ("max_position_error_m",)
    assert first_difference(_changed(ok, error, float("nan")), ok) is not None
    assert first_difference(_changed(ok, error, float("inf")), ok) is not None
    nan = _changed(ok, error, float("nan"))
    assert first_difference(nan, nan) is None
    condition = ("max_condition_number",)  # relative: ∞ against a large value still differs
    assert first_difference(_changed(ok, condition, float("inf")), ok) is not None
    assert first_difference(_changed(ok, ("ticks",), float(ok["ticks"])), ok) is not None


def test_a_float_field_without_a_tolerance_is_a_difference_even_when_equal() -> None:
    new = dict(_success(), new_metric=0.5)
    diff = first_difference(new, new)
    assert diff is not None and ".new_metric" in diff and "no tolerance" in diff


def test_printed_numbers_may_move_one_unit_in_their_last_digit() -> None:
    text = "keyframe 'lift' reached (planned t=1.53 s, tool 3.9 mm from plan)"
    assert printed_alike(text, text)
    assert printed_alike(text.replace("3.9", "4.0"), text)
    assert printed_alike(text.replace("1.53", "1.52"), text)
    assert not printed_alike(text.replace("3.9", "4.1"), text)
    assert not printed_alike(text.replace("3.9", "3.90"), text)
    assert not printed_alike(text.replace("lift", "pick"), text)
    assert not printed_alike("candidate 2 of 2, gap 9.9 mm", "candidate 1 of 2, gap 9.9 mm")
    assert not printed_alike("bin2 at 0.5", "bin1 at 0.5")
    ok = _success()
    grasp = next(i for i, e in enumerate(ok["events"]) if e["kind"] == "grasp")
    text = ok["events"][grasp]["text"]  # "grip closed: gap 49.9 mm, pad forces 39.7 / 40.3 N"
    where = ("events", grasp, "text")
    last = re.findall(r"\d+\.(\d)\b", text)[-1]  # the last number's last (tenths) digit
    head, _, tail = text.rpartition(f".{last}")
    one, two = (int(last) + 1) % 10, (int(last) + 2) % 10
    if int(last) >= 8:  # move down instead, so that no carry changes the digits before it
        one, two = int(last) - 1, int(last) - 2
    assert first_difference(_changed(ok, where, f"{head}.{one}{tail}"), ok) is None
    assert first_difference(_changed(ok, where, f"{head}.{two}{tail}"), ok) is not None
    assert first_difference(_changed(ok, ("goal",), ok["goal"] + " "), ok) is not None


def test_margins_name_the_largest_difference_of_each_tolerance(
    capsys: pytest.CaptureFixture[str],
) -> None:
    ok = _success()
    y = ok["brick_final_xyz"][1]
    moved = _changed(ok, ("brick_final_xyz", 1), y + 1e-8)
    print_margins(compare(moved, ok, TOLERANCES))
    lines = capsys.readouterr().out.splitlines()
    line = next(line for line in lines if line.startswith("brick_final_xyz[]"))
    assert "tolerance 5.00e-06, largest 1.00e-08 (500× this) at .brick_final_xyz[1]" in line
    assert any(line.startswith("target_xyz[]") and "no difference" in line for line in lines)
