"""Record (or check) what a recording holds, for changes to recording.py that must not alter it.

The file ``tests/data/golden_recording.json`` describes the recording of the nominal run
(``pick-place``, ``qp``, seed 0) as read back from its ``.rrd`` file:

- ``entities``: every entity path, with its static components and their values, and, per
  temporal component, the number of rows and of values, NaNs among them, and the sum, minimum
  and maximum of its numbers (rows ordered by tick), or its values when they are text. Left
  out because they measure the wall clock or name a temporary file: the recording start time
  (``__properties``), the summary document's
  text and the values of ``plots/ik/tick_us`` (their row and value counts stay).
- ``blueprint``: the embedded default blueprint as a tree of its containers, views and panels
  with every setting (names, origins, contents, shares, properties), without the random ids.

``tests/test_recording_golden.py`` records the run again and compares (floats to 1e-9
relative). A change that alters the recording on purpose (a new plot, another colour, another
layout) regenerates the file deliberately with

    python -m scripts.golden_recording --write

(from the repository root) and says so in its commit message; without ``--write`` it only
compares and prints the first difference.
"""

from __future__ import annotations

import argparse
import enum
import json
import math
import sys
import tempfile
import uuid
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from rerun.chunk import RrdReader

from pickplace.record.blueprint import build_blueprint
from pickplace.run.runner import RunRequest, prepare
from pickplace.sim.loop import Simulation
from scripts.golden_summaries import first_difference

PATH = Path(__file__).resolve().parent.parent / "tests" / "data" / "golden_recording.json"
# Entities whose values depend on the wall clock or the file name: only their shape is kept.
WALL_CLOCK_STATIC = ("summary", "__properties")
WALL_CLOCK_TEMPORAL = ("plots/ik/tick_us",)
SKIPPED_COLUMNS = ("rerun.controls.RowId",)


def record_nominal_run(path: Path) -> Simulation:
    """Run the nominal case recorded to ``path``; returns the finished simulation."""
    _, _, sim = prepare(RunRequest(record=path))
    result = sim.run()
    if not result.success:
        raise RuntimeError(f"the nominal run failed: {result.failure}")
    return sim


def read_columns(path: Path) -> dict[str, dict[str, Any]]:
    """Entity path (no leading '/') → ``{"static": {component: value}, "rows": {component:
    [row, ...]}}``, temporal rows ordered by tick."""
    entities: dict[str, dict[str, Any]] = defaultdict(
        lambda: {"static": {}, "rows": defaultdict(list)}
    )
    for chunk in RrdReader(path).store().stream():
        entity = entities[chunk.entity_path.lstrip("/")]
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name in SKIPPED_COLUMNS:
                continue
            column = batch.column(name)
            if name == "sim_time":
                column = column.cast("int64")  # duration [ns]
            values = column.to_pylist()
            if chunk.is_static:
                entity["static"][name] = values[-1]
            else:
                entity["rows"][name].extend(values)
    for entity in entities.values():
        rows = entity["rows"]
        if "tick" in rows:  # temporal chunks may arrive in any order: sort rows by tick
            order = np.argsort(rows["tick"], kind="stable")
            for name, values in rows.items():
                if len(values) == len(order):
                    rows[name] = [values[i] for i in order]
        entity["rows"] = dict(rows)
    return dict(entities)


def _leaves(value: Any) -> list[Any]:
    """The scalars of a nested list, in order."""
    if isinstance(value, list):
        return [leaf for item in value for leaf in _leaves(item)]
    return [value]


def _column_stats(rows: list[Any], keep_values: bool) -> dict[str, Any]:
    leaves = _leaves(rows)
    out: dict[str, Any] = {"rows": len(rows), "values": len(leaves)}
    if not keep_values:
        return out
    if all(isinstance(v, bool | int | float) for v in leaves) and leaves:
        numbers = [float(v) for v in leaves]
        finite = [v for v in numbers if not math.isnan(v)]
        out["nan"] = len(numbers) - len(finite)
        out["sum"] = math.fsum(finite)
        out["min"] = min(finite) if finite else None
        out["max"] = max(finite) if finite else None
    else:
        out["items"] = rows
    return out


def describe_recording(path: Path) -> dict[str, Any]:
    """The ``entities`` part of the golden file for the recording at ``path``."""
    out: dict[str, Any] = {}
    for entity_path, entity in sorted(read_columns(path).items()):
        static = entity["static"]
        out[entity_path] = {
            "static": (
                sorted(static) if entity_path in WALL_CLOCK_STATIC else dict(sorted(static.items()))
            ),
            "temporal": {
                name: _column_stats(rows, entity_path not in WALL_CLOCK_TEMPORAL or name == "tick")
                for name, rows in sorted(entity["rows"].items())
            },
        }
    return out


def describe_blueprint(node: Any) -> Any:
    """A blueprint object as plain data: every attribute but the random ids; rerun archetypes
    (view properties, panel states) by their repr, which lists their values."""
    if node is None or isinstance(node, bool | int | float | str):
        return node
    if isinstance(node, list | tuple):
        return [describe_blueprint(item) for item in node]
    if isinstance(node, dict):
        return {str(k): describe_blueprint(v) for k, v in sorted(node.items())}
    if isinstance(node, enum.Enum):
        return str(node)
    if hasattr(node, "as_component_batches"):  # an archetype
        return repr(node)
    if hasattr(node, "__dict__"):
        fields = {
            k: describe_blueprint(v)
            for k, v in sorted(vars(node).items())
            if not isinstance(v, uuid.UUID)
        }
        return {"type": type(node).__name__, **fields}
    return repr(node)


def describe() -> dict[str, Any]:
    """The golden file's content, from a fresh recording of the nominal run."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "nominal.rrd"
        record_nominal_run(path)
        entities = describe_recording(path)
    return {"blueprint": describe_blueprint(build_blueprint()), "entities": entities}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="regenerate the recorded file")
    args = parser.parse_args(argv)
    now = describe()
    if args.write:
        PATH.parent.mkdir(parents=True, exist_ok=True)
        PATH.write_text(json.dumps(now, indent=1, sort_keys=True) + "\n")
        print(f"wrote {len(now['entities'])} entities and the blueprint to {PATH}")
        return 0
    diff = first_difference(now, json.loads(PATH.read_text()))
    print(diff or "the recording is unchanged")
    return 1 if diff else 0


if __name__ == "__main__":
    sys.exit(main())
