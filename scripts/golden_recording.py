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

``tests/test_recording_golden.py`` records the run again and compares. A change that alters the
recording on purpose (a new plot, another colour, another layout) regenerates the file
deliberately with

    python -m scripts.golden_recording --write

(from the repository root) and says so in its commit message; without ``--write`` it only
compares and prints the first difference (``--margins``: and the largest difference per
tolerance).

The comparison is that of ``scripts/golden_summaries.py`` (its docstring gives the reasons and
the differences measured between CPU kernels), with this file's table, :data:`TOLERANCES`:

- exact: entity paths, component names, row, value and NaN counts, labels, other texts and
  colours, the tick and sim-time columns (integers: ticks, nanoseconds), IK status codes, plan
  segment indices, line widths and the blueprint (constants of the code);
- event texts: words and integers exact, printed decimals to one unit in the last digit;
- the ``min`` and ``max`` of a column (and every static value) to the tolerance of what it
  holds: lengths for positions, sizes and path points [m], unit for quaternions and normals,
  the plots by their quantity (angles, speeds, forces, torques, Jacobian measures);
- a column's ``sum`` to ``values`` × the tolerance at its largest ``|min|`` or ``|max|``: what
  every value moving by its tolerance the same way would add up to.

Positions, sizes and orientations are float32 in a recording: a float64 difference of 1e-9
can move them by one float32 step (6e-8 at 1 m, 3e-8 m seen in the plan's path), 80× below
the length tolerance.
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
from scripts.golden_summaries import (
    ANGLE,
    EXACT,
    FORCE,
    JACOBIAN,
    LENGTH,
    PRINTED,
    SPEED,
    SPEED_RATIO,
    TORQUE,
    UNIT,
    Rule,
    Tolerance,
    compare,
    print_margins,
)

PATH = Path(__file__).resolve().parent.parent / "tests" / "data" / "golden_recording.json"
# Entities whose values depend on the wall clock or the file name: only their shape is kept.
WALL_CLOCK_STATIC = ("summary", "__properties")
WALL_CLOCK_TEMPORAL = ("plots/ik/tick_us",)
SKIPPED_COLUMNS = ("rerun.controls.RowId",)


def _column(entity: str, component: str, tolerance: Tolerance, reason: str) -> tuple[Rule, ...]:
    """Rules for a temporal column's ``min`` and ``max`` (values) and ``sum`` (of its values)."""
    column = f"entities.{entity}.temporal.{component}"
    return (
        Rule(f"{column}.min", tolerance, reason),
        Rule(f"{column}.max", tolerance, reason),
        Rule(f"{column}.sum", tolerance, reason, kind="sum"),
    )


def _static(component: str, tolerance: Tolerance, reason: str) -> Rule:
    """The rule for a static component of the 3D entities (every number in its lists)."""
    return Rule(f"entities.world*.static.{component}[]*", tolerance, reason)


# The recording's table: first match wins (see the module docstring; the tolerances and their
# reasons are in scripts/golden_summaries.py).
TOLERANCES: tuple[Rule, ...] = (
    Rule("blueprint.*", EXACT, "layout shares, constants of build_blueprint"),
    Rule("entities.events.temporal.TextLog:text.items[][]", PRINTED, "event texts", kind="text"),
    *_column("*", "tick", EXACT, "tick numbers"),
    *_column("*", "sim_time", EXACT, "sim time [ns], an integer"),
    Rule("entities.plots/*.static.SeriesLines:widths[]", EXACT, "line widths, style constants"),
    *_column("plots/kinematics/*", "Scalars:scalars", JACOBIAN, "σ, condition, manipulability"),
    *_column("plots/tracking/position_error", "Scalars:scalars", LENGTH, "tool position error"),
    *_column("plots/tracking/orientation_error", "Scalars:scalars", ANGLE, "tool angle error"),
    *_column("plots/joints/position", "Scalars:scalars", ANGLE, "joint positions [rad]"),
    *_column("plots/joints/position_limits", "Scalars:scalars", ANGLE, "joint limits [rad]"),
    # Ranges of several rad: a fraction of one moves less than the angle tolerance.
    *_column("plots/joints/position_normalized*", "Scalars:scalars", ANGLE, "q / range [1]"),
    *_column("plots/joints/speed", "Scalars:scalars", SPEED, "commanded joint speeds [rad/s]"),
    *_column("plots/joints/speed_ratio*", "Scalars:scalars", SPEED_RATIO, "speed / limit [1]"),
    *_column("plots/statics/holding_torque", "Scalars:scalars", TORQUE, "holding torques"),
    *_column("plots/plan/tool_speed", "Scalars:scalars", SPEED, "planned tool speed [m/s]"),
    *_column("plots/plan/segment", "Scalars:scalars", EXACT, "plan segment indices"),
    *_column("plots/gripper/width", "Scalars:scalars", LENGTH, "finger gap [m]"),
    *_column("plots/gripper/pad_force", "Scalars:scalars", FORCE, "pad normal forces [N]"),
    *_column("plots/ik/status", "Scalars:scalars", EXACT, "IK status codes"),
    *_column("world/*", "Transform3D:translation", LENGTH, "body and tool positions [m]"),
    *_column("world/*", "Transform3D:quaternion", UNIT, "body and tool orientations [1]"),
    *_column("world/*", "Ellipsoids3D:centers", LENGTH, "ellipsoid centre, the tool [m]"),
    *_column("world/*", "Ellipsoids3D:half_sizes", LENGTH, "ellipsoid, 0.1 m × σt [m]"),
    *_column("world/*", "Ellipsoids3D:quaternions", UNIT, "ellipsoid orientation [1]"),
    _static("*:translation", LENGTH, "static poses [m]"),
    _static("*:quaternion", UNIT, "static orientations [1]"),
    _static("Boxes3D:quaternions", UNIT, "the target bin's orientation [1]"),
    _static("*:translations", LENGTH, "capsule offsets [m]"),
    _static("Points3D:positions", LENGTH, "keyframe points [m]"),
    _static("Boxes3D:centers", LENGTH, "the target bin's centre [m]"),
    _static("LineStrips3D:strips", LENGTH, "the planned path's points [m]"),
    _static("Mesh3D:vertex_positions", LENGTH, "the floor's corners [m]"),
    _static("Mesh3D:vertex_normals", UNIT, "the floor's normals [1]"),
    _static("*:half_sizes", LENGTH, "box sizes [m]"),
    _static("*:lengths", LENGTH, "capsule and cylinder lengths [m]"),
    _static("*:radii", LENGTH, "radii of shapes, points and lines [m]"),
    _static("*:line_radii", LENGTH, "the ellipsoid's line radius [m]"),
    _static("TransformAxes3D:axis_length", LENGTH, "frame axes' length [m]"),
)


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


def first_difference(now: Any, recorded: Any, part: str) -> str | None:
    """Where ``now`` first differs from ``recorded`` beyond :data:`TOLERANCES`.

    Args:
        now: The new ``part`` of the golden file's content.
        recorded: The recorded one.
        part: ``entities`` or ``blueprint``.

    Returns:
        The first difference, or None.
    """
    found = compare(now, recorded, TOLERANCES, where=f".{part}")
    return next((c.difference for c in found if c.difference), None)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="regenerate the recorded file")
    parser.add_argument(
        "--margins", action="store_true", help="print the largest difference per tolerance"
    )
    args = parser.parse_args(argv)
    now = describe()
    if args.write:
        PATH.parent.mkdir(parents=True, exist_ok=True)
        PATH.write_text(json.dumps(now, indent=1, sort_keys=True) + "\n")
        print(f"wrote {len(now['entities'])} entities and the blueprint to {PATH}")
        return 0
    comparisons = list(compare(now, json.loads(PATH.read_text()), TOLERANCES))
    if args.margins:
        print_margins(iter(comparisons))
    diff = next((c.difference for c in comparisons if c.difference), None)
    print(diff or "the recording is unchanged")
    return 1 if diff else 0


if __name__ == "__main__":
    sys.exit(main())
