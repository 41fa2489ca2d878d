"""Record (or check) the JSON summaries that a behaviour-preserving change must not alter.

The file ``tests/data/golden_summaries.json`` holds one summary per case, without the fields
that measure wall-clock time (``pickplace.sim.verdict.WALL_TIME_FIELDS``). ``tests/test_golden.py``
re-runs every case and compares. A change that alters behaviour on purpose (a new plan, new
timing, a new robot) regenerates the file deliberately with

    python scripts/golden_summaries.py --write

and says so in its commit message; ``--check`` (the default) only compares and prints the first
difference of each case that changed.

Cases: ``pick-place`` with qp, pinv and dls; ``singular-reach`` with qp and pinv; every fault
scenario with qp; ``pick-place-random`` seeds 0-19 with qp.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from pickplace.run.runner import RunRequest, run
from pickplace.sim.scenarios import SCENARIOS
from pickplace.sim.verdict import WALL_TIME_FIELDS

PATH = Path(__file__).resolve().parent.parent / "tests" / "data" / "golden_summaries.json"


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


def first_difference(a: Any, b: Any, where: str = "") -> str | None:
    """Where ``a`` and ``b`` first differ (floats within 1e-9 relative count as equal)."""
    if isinstance(a, dict) and isinstance(b, dict):
        for key in sorted(set(a) | set(b)):
            if key not in a or key not in b:
                return f"{where}.{key}: only in {'new' if key in a else 'recorded'}"
            diff = first_difference(a[key], b[key], f"{where}.{key}")
            if diff:
                return diff
        return None
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return f"{where}: {len(a)} items, recorded {len(b)}"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            diff = first_difference(x, y, f"{where}[{i}]")
            if diff:
                return diff
        return None
    if isinstance(a, float) and isinstance(b, float):
        if math.isnan(a) and math.isnan(b):
            return None
        if math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12):
            return None
    elif a == b and type(a) is type(b):
        return None
    return f"{where}: {a!r}, recorded {b!r}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="regenerate the recorded file")
    args = parser.parse_args(argv)
    if args.write:
        records = [{"case": c, "summary": summary_of(c)} for c in cases()]
        PATH.parent.mkdir(parents=True, exist_ok=True)
        PATH.write_text(json.dumps(records, indent=1, sort_keys=True) + "\n")
        print(f"wrote {len(records)} summaries to {PATH}")
        return 0
    records = json.loads(PATH.read_text())
    changed = 0
    for rec in records:
        diff = first_difference(summary_of(rec["case"]), rec["summary"])
        if diff:
            changed += 1
            print(f"{rec['case']}: {diff}")
    print(f"{changed} of {len(records)} summaries differ")
    return 1 if changed else 0


if __name__ == "__main__":
    sys.exit(main())
