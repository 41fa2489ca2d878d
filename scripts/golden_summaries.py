"""Record (or check) the JSON summaries that a behaviour-preserving change must not alter.

The file ``tests/data/golden_summaries.json`` holds one summary per case, without the fields
that measure wall-clock time (``pickplace.sim.verdict.WALL_TIME_FIELDS``). ``tests/test_golden.py``
re-runs every case and compares. A change that alters behaviour on purpose (a new plan, new
timing, a new robot) regenerates the file deliberately with

    python scripts/golden_summaries.py --write

and says so in its commit message; ``--check`` (the default) only compares and prints the first
difference of each case that changed, and ``--margins`` prints, per tolerance, the largest
difference seen and how far it is from the tolerance.

Cases: ``pick-place`` with qp, pinv and dls; ``singular-reach`` with qp and pinv; every fault
scenario with qp; ``pick-place-random`` seeds 0-19 with qp.

What "unchanged" means
----------------------
Floating-point results differ between CPUs, BLAS kernels and library builds: the file was
recorded where OpenBLAS picks its Haswell (AVX2) kernels, and on an AVX-512 machine the same
runs differ from the 8th digit on (the IK's linear algebra goes through numpy's LAPACK, and
contacts carry the differences on through a run). A golden file therefore states what is the
same physics, field by field, and a run matches it when:

- integers, booleans, ``None`` and strings are equal, of the same type: outcomes, failure
  reasons, event kinds and levels, the tick of every event and of a failure, tick counts,
  ``ik_status_counts``, plan and keyframe names. A tick off by one is a different run.
- texts that print measured values (event texts, plan problems) have the same words and
  integers; each decimal number may move by one unit in its last printed digit (a value within
  1e-8 of a rounding boundary prints one digit apart on another CPU).
- every float is within the tolerance of its field in :data:`TOLERANCES`, a table from the
  field's JSON path (list indices as ``[]``, ``*`` for any text) to a tolerance and the
  reason for it; the first matching entry applies. A float no entry matches is a difference of
  its own, even when equal: a new field fails here, where it is added, not later on another
  CPU.

Each tolerance is (a) at least 100× the largest difference seen between the recorded file and
runs under five OpenBLAS kernels on one machine (``OPENBLAS_CORETYPE`` Haswell, which
reproduces the file bit for bit, SkylakeX, the machine's own, Sandybridge, Nehalem and
Prescott; ``--margins`` prints them), and (b) far below what a different run changes: a
different grasp, slip, plan or failure tick moves the brick and the tool by 0.1 mm or more
(the precision the event texts print) and times by a 10 ms tick. The largest differences seen,
per kind:

=============  =====================  ======================================================
kind           tolerance              largest difference seen (field)
=============  =====================  ======================================================
length [m]     5e-6                   1.0e-8 (brick_final_xyz), 3.0e-8 in float32 recordings
time [s]       1e-5                   2.3e-8 (plan.keyframes[].t)
angle [rad]    5e-6                   4.6e-9 (max_orientation_error_rad)
unit [1]       5e-6                   1.2e-10 (quaternions), 6e-8 steps in float32
speed          2e-4 m/s, rad/s        3.4e-7 rad/s (recorded joint speeds)
speed ratio    2e-4                   6.8e-7 (plan.margins.peak_speed_ratio)
force [N]      1e-4, or 1e-5 rel.     2.0e-6 at 43.6 N (pad force), 9.1e-6 at 559 N (contact)
torque [N m]   1e-5, or 1e-5 rel.     3.4e-10 (holding torques)
Jacobian       1e-6 rel., 1e-9        7.4e-10 relative (σ, condition numbers, manipulability)
=============  =====================  ======================================================

Bit-for-bit determinism, two runs in one process, is tested in ``tests/test_scenarios.py``.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import re
import sys
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from pickplace.run.runner import RunRequest, run
from pickplace.sim.scenarios import SCENARIOS
from pickplace.sim.verdict import WALL_TIME_FIELDS

PATH = Path(__file__).resolve().parent.parent / "tests" / "data" / "golden_summaries.json"


# ------------------------------------------------------------------------ tolerances


@dataclass(frozen=True)
class Tolerance:
    """How far a float may lie from its recorded value and still be the same physics.

    Two floats agree when equal (NaN with NaN, ∞ with ∞) or when finite and
    ``|a - b| <= max(abs, rel · max(|a|, |b|))``.

    Attributes:
        abs: Absolute tolerance, in the field's unit.
        rel: Relative tolerance [1].
        why: Why this size (measured differences, what a different run would change).
    """

    abs: float
    rel: float
    why: str

    def bound(self, a: float, b: float) -> float:
        """The largest ``|a - b|`` allowed between ``a`` and ``b`` (in their unit)."""
        return max(self.abs, self.rel * max(abs(a), abs(b)))


LENGTH = Tolerance(
    5e-6,
    0.0,
    "lengths [m]: 480× the 1.0e-8 m seen between CPU kernels, 20× below the 0.1 mm a "
    "different grasp, slip or failure tick moves the brick or the tool",
)
TIME = Tolerance(
    1e-5,
    0.0,
    "times [s]: 400× the 2.3e-8 s seen between CPU kernels, 1/1000 of a 10 ms tick",
)
ANGLE = Tolerance(
    5e-6,
    0.0,
    "angles [rad]: the length tolerance at the arm's 1 m reach; 1000× the 4.6e-9 rad seen",
)
UNIT = Tolerance(
    5e-6,
    0.0,
    "components of unit quaternions and vectors [1]: a rotation of at most 1e-5 rad; 80× the "
    "6e-8 steps of float32",
)
SPEED = Tolerance(
    2e-4,
    0.0,
    "speeds [m/s, rad/s]: 2 µm or µrad per 10 ms tick; 500× the 3.4e-7 rad/s seen",
)
SPEED_RATIO = Tolerance(
    2e-4,
    0.0,
    "speed / speed limit [1]: 290× the 6.8e-7 seen (a sampled peak moves with the plan's times); "
    "a limit exceeded is a failure reason, compared exactly",
)
FORCE = Tolerance(
    1e-4,
    1e-5,
    "forces [N]: 1e-5 of the value, 4e-4 N at the 40 N grip; 220× the 2e-6 N seen at 43.6 N; "
    "no contact stays within 1e-4 N of zero",
)
TORQUE = Tolerance(
    1e-5,
    1e-5,
    "torques [N m]: the brick's 2 N weight times the length tolerance; 1e-5 of the value for "
    "heavier loads; 3e4× the 3.4e-10 N m seen",
)
JACOBIAN = Tolerance(
    1e-9,
    1e-6,
    "singular values, condition numbers, manipulability: 1e-6 of the value, 1000× the 7.4e-10 "
    "seen; 1e-9 near a singularity",
)
RATE = Tolerance(0.0, 1e-6, "rates [Hz]: settings; only another setting changes them")
EXACT = Tolerance(0.0, 0.0, "equal or different: integers held as floats, constants of the code")
PRINTED = Tolerance(
    1.0,
    0.0,
    "printed decimal numbers: one unit in the last printed digit, the words and integers exactly",
)


@dataclass(frozen=True)
class Rule:
    """One entry of a tolerance table: the fields it applies to and how they compare.

    Attributes:
        pattern: JSON path of the fields, keys joined by ``.``, list indices as ``[]``, ``*``
            for any text (also across ``.``), e.g. ``plan.keyframes[].t`` or ``*_m``.
        tolerance: The tolerance of one value (``value``), of each value summed (``sum``), or
            of each number printed in a text, in units of its last digit (``text``).
        reason: What the fields are [unit], in a few words.
        kind: ``value``: a float. ``sum``: a float that sums the ``values`` numbers of a column
            whose ``min`` and ``max`` sit beside it; it may move by ``values`` × the tolerance
            at the larger of ``|min|`` and ``|max|`` (every value moving its tolerance the same
            way). ``text``: a string, see :func:`printed_alike`.
    """

    pattern: str
    tolerance: Tolerance
    reason: str
    kind: Literal["value", "sum", "text"] = "value"

    def bound(self, a: float, b: float, siblings: Any) -> float:
        """The largest ``|a - b|`` this rule allows between two values of its fields.

        Args:
            a: The new value.
            b: The recorded value.
            siblings: The recorded dict that holds the field (a sum's ``values``, ``min`` and
                ``max``).

        Returns:
            The bound, in the field's unit.

        Raises:
            ValueError: A sum without its column's ``values`` count beside it.
        """
        if self.kind != "sum":
            return self.tolerance.bound(a, b)
        if not isinstance(siblings, Mapping) or not isinstance(siblings.get("values"), int):
            raise ValueError(f"{self.pattern}: a sum needs its column's 'values' count beside it")
        extremes = (siblings.get("min"), siblings.get("max"))
        magnitude = max((abs(v) for v in extremes if isinstance(v, float)), default=0.0)
        return siblings["values"] * self.tolerance.bound(magnitude, magnitude)


# The summaries' table: first match wins. Fields named with their unit (``*_m``, ``*_s``,
# ``*_rad``, ``*_n``, ``*_hz``) match by that suffix; the others are named one by one.
TOLERANCES: tuple[Rule, ...] = (
    Rule("brick_start_xyz[]", LENGTH, "where the brick starts [m] (scenario, seed)"),
    Rule("brick_final_xyz[]", LENGTH, "where the brick comes to rest [m]"),
    Rule("target_xyz[]", LENGTH, "where the brick is to be placed [m]"),
    Rule("plan.keyframes[].position[]", LENGTH, "keyframe tool positions [m]"),
    Rule("plan.keyframes[].gripper_width", LENGTH, "keyframe finger gaps [m]"),
    Rule("plan.keyframes[].quaternion_wxyz[]", UNIT, "keyframe tool orientations [1]"),
    Rule("plan.keyframes[].t", TIME, "keyframe times of the plan [s]"),
    Rule("events[].t", TIME, "sim time of an event [s] (its tick compares exactly)"),
    Rule("*_s", TIME, "times [s]: cycle, simulated, failure, checked until"),
    Rule("*_m", LENGTH, "distances [m]: tracking and place errors, slip, clearances"),
    Rule("*_rad", ANGLE, "angles [rad]: orientation error, joint margins and violations"),
    Rule("*_n", FORCE, "largest robot-world contact force [N]"),
    Rule("*_hz", RATE, "pre-flight check rate [Hz]"),
    Rule("*speed_ratio", SPEED_RATIO, "peak joint speed / limit, executed and planned [1]"),
    Rule("max_condition_number", JACOBIAN, "largest condition number of the tool Jacobian [1]"),
    Rule("min_manipulability_w1", JACOBIAN, "smallest manipulability w1 of the tool Jacobian"),
    Rule("*min_singular_value", JACOBIAN, "smallest σ of the tool Jacobian: run, plan, pre-flight"),
    Rule("events[].text", PRINTED, "event texts, which print measured values", kind="text"),
)


# ------------------------------------------------------------------------ comparison


def field_of(where: str) -> str:
    """The table path of a location: ``.plan.keyframes[6].t`` → ``plan.keyframes[].t``."""
    return re.sub(r"\[\d+\]", "[]", where).lstrip(".")


@functools.cache
def _glob(pattern: str) -> re.Pattern[str]:
    return re.compile(".*".join(re.escape(part) for part in pattern.split("*")))


def rule_for(rules: Sequence[Rule], where: str) -> Rule | None:
    """The first rule whose pattern matches the location ``where`` (e.g. ``.events[3].t``)."""
    field = field_of(where)
    return next((r for r in rules if _glob(r.pattern).fullmatch(field)), None)


# A decimal number printed in a text: digits, a point, digits; not part of a word or a longer
# number (``bin1`` and ``4.0.1`` are words).
_DECIMAL = re.compile(r"(?<![\w.])-?\d+\.\d+")


def printed_alike(a: str, b: str, units: float = 1.0) -> bool:
    """Whether two texts are the same apart from rounding of the decimal numbers they print.

    The texts between the numbers (integers included) must be equal; each pair of decimal
    numbers must have the same number of decimals and differ by at most ``units`` in the last
    one (``3.2`` and ``3.3``, not ``3.2`` and ``3.4`` or ``3.20``).

    Args:
        a: The new text.
        b: The recorded text.
        units: Units of the last printed digit a number may move by.

    Returns:
        True if alike.
    """
    if _DECIMAL.split(a) != _DECIMAL.split(b):
        return False
    for x, y in zip(_DECIMAL.findall(a), _DECIMAL.findall(b), strict=True):
        if len(x.split(".")[1]) != len(y.split(".")[1]):
            return False
        if abs(int(x.replace(".", "")) - int(y.replace(".", ""))) > units:
            return False
    return True


@dataclass(frozen=True)
class Comparison:
    """One leaf (or a structural mismatch) of two documents compared.

    Attributes:
        where: Location, e.g. ``.plan.keyframes[6].t``.
        rule: The rule applied, if any.
        difference: What differs, or None if alike.
        gap: ``|new - recorded|`` for floats, else 0 (in the field's unit).
        bound: The largest gap the rule allows, else 0 (in the field's unit).
    """

    where: str
    rule: Rule | None
    difference: str | None
    gap: float = 0.0
    bound: float = 0.0


def compare(
    a: Any, b: Any, rules: Sequence[Rule], where: str = "", siblings: Any = None
) -> Iterator[Comparison]:
    """Compare a new document ``a`` with the recorded ``b``, leaf by leaf (module docstring).

    Args:
        a: New value (JSON data: dicts, lists, floats, ints, strings, booleans, None).
        b: Recorded value.
        rules: The tolerance table.
        where: Location of ``a`` and ``b`` in their documents.
        siblings: The recorded dict or list that holds ``b``.

    Yields:
        One comparison per leaf, and one per key only on one side or list of another length.
    """
    if isinstance(a, dict) and isinstance(b, dict):
        for key in sorted(set(a) | set(b)):
            if key not in a or key not in b:
                side = "new" if key in a else "recorded"
                yield Comparison(f"{where}.{key}", None, f"{where}.{key}: only in {side}")
            else:
                yield from compare(a[key], b[key], rules, f"{where}.{key}", b)
        return
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            yield Comparison(where, None, f"{where}: {len(a)} items, recorded {len(b)}")
            return
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            yield from compare(x, y, rules, f"{where}[{i}]", b)
        return
    differs = f"{where}: {a!r}, recorded {b!r}"
    if isinstance(a, float) and isinstance(b, float):
        rule = rule_for(rules, where)
        if rule is None or rule.kind == "text":
            yield Comparison(where, rule, f"{differs}: no tolerance for this float field")
            return
        bound = rule.bound(a, b, siblings)
        if a == b or (math.isnan(a) and math.isnan(b)):
            yield Comparison(where, rule, None, 0.0, bound)
        elif math.isfinite(a) and math.isfinite(b) and abs(a - b) <= bound:
            yield Comparison(where, rule, None, abs(a - b), bound)
        else:  # beyond the tolerance, or a NaN or an infinity against another value
            gap = abs(a - b) if math.isfinite(a) and math.isfinite(b) else math.inf
            why = f"by {gap:.3g}, tolerance {bound:.3g}: {rule.reason}"
            yield Comparison(where, rule, f"{differs} ({why})", gap, bound)
        return
    if isinstance(a, str) and isinstance(b, str):
        rule = rule_for(rules, where)
        if rule is not None and rule.kind == "text":
            alike = printed_alike(a, b, rule.tolerance.abs)
            yield Comparison(where, rule, None if alike else f"{differs} ({rule.reason})")
            return
    alike = a == b and type(a) is type(b)
    yield Comparison(where, None, None if alike else differs)


def first_difference(a: Any, b: Any, rules: Sequence[Rule] = TOLERANCES) -> str | None:
    """Where the new document ``a`` first differs from the recorded ``b`` beyond ``rules``."""
    return next((c.difference for c in compare(a, b, rules) if c.difference), None)


def leaves(value: Any, where: str = "") -> Iterator[tuple[str, Any]]:
    """Every leaf of a JSON document with its location (e.g. ``.events[3].t``)."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield from leaves(item, f"{where}.{key}")
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield from leaves(item, f"{where}[{i}]")
    else:
        yield where, value


def untolerated_fields(rules: Sequence[Rule], documents: Iterable[Any]) -> set[str]:
    """Table paths of the floats in ``documents`` that no rule (of kind value or sum) covers."""
    out = set()
    for document in documents:
        for where, value in leaves(document):
            rule = rule_for(rules, where)
            if isinstance(value, float) and (rule is None or rule.kind == "text"):
                out.add(field_of(where))
    return out


def unused_rules(rules: Sequence[Rule], documents: Iterable[Any]) -> list[str]:
    """Patterns of the rules by which no leaf of ``documents`` is compared (stale entries)."""
    used = set()
    for document in documents:
        for where, value in leaves(document):
            rule = rule_for(rules, where)
            if rule is not None and (rule.kind == "text") == isinstance(value, str):
                used.add(rule.pattern)
    return [r.pattern for r in rules if r.pattern not in used]


def print_margins(comparisons: Iterator[Comparison]) -> None:
    """Print, per rule, the largest float difference relative to its tolerance, and where."""

    def share(c: Comparison) -> float:
        return c.gap / c.bound if c.bound else (math.inf if c.gap else 0.0)

    worst: dict[str, Comparison] = {}
    for c in comparisons:
        if c.rule is not None and c.rule.kind != "text":
            best = worst.get(c.rule.pattern)
            if best is None or share(c) > share(best):
                worst[c.rule.pattern] = c
    for pattern, c in worst.items():
        room = f"{c.bound / c.gap:.3g}× this" if c.gap else "no difference"
        print(f"{pattern:45s} tolerance {c.bound:8.2e}, largest {c.gap:8.2e} ({room}) at {c.where}")


# ------------------------------------------------------------------------ the cases


def cases() -> list[dict[str, Any]]:
    """The (scenario, controller, seed) triples whose summaries are kept."""
    out: list[dict[str, Any]] = [
        {"scenario": "pick-place", "controller": c, "seed": 0} for c in ("qp", "pinv", "dls")
    ]
    out += [{"scenario": "singular-reach", "controller": c, "seed": 0} for c in ("qp", "pinv")]
    out += [
        {"scenario": name, "controller": "qp", "seed": 0}
        for name in SCENARIOS
        if name.startswith("fault-")
    ]
    out += [{"scenario": "pick-place-random", "controller": "qp", "seed": s} for s in range(20)]
    return out


def summary_of(case: dict[str, Any]) -> dict[str, Any]:
    """The case's summary without its wall-clock fields."""
    summary = run(RunRequest(**case)).summary()
    for key in WALL_TIME_FIELDS:
        summary.pop(key, None)
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="regenerate the recorded file")
    parser.add_argument(
        "--margins", action="store_true", help="print the largest difference per tolerance"
    )
    args = parser.parse_args(argv)
    if args.write:
        records = [{"case": c, "summary": summary_of(c)} for c in cases()]
        PATH.parent.mkdir(parents=True, exist_ok=True)
        PATH.write_text(json.dumps(records, indent=1, sort_keys=True) + "\n")
        print(f"wrote {len(records)} summaries to {PATH}")
        return 0
    records = json.loads(PATH.read_text())
    changed = 0
    comparisons: list[Comparison] = []
    for rec in records:
        found = list(compare(summary_of(rec["case"]), rec["summary"], TOLERANCES))
        comparisons += found
        diff = next((c.difference for c in found if c.difference), None)
        if diff:
            changed += 1
            print(f"{rec['case']}: {diff}")
    if args.margins:
        print_margins(iter(comparisons))
    print(f"{changed} of {len(records)} summaries differ")
    return 1 if changed else 0


if __name__ == "__main__":
    sys.exit(main())
