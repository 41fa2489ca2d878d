"""The recording stays what it was, and every per-tick entity holds exactly the tick log's data.

``tests/data/golden_recording.json`` (written by ``scripts/golden_recording.py``, whose
docstring says when to regenerate it) pins the entities of the nominal run's recording, their
static components, the size and range of their temporal columns, and the embedded blueprint:
counts, names and texts exactly, numbers within the tolerance of what they hold (the table in
that script), so that a file recorded on another CPU passes here. The tick log of the very same
run then fixes every value of the per-tick entities exactly.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rerun as rr

from pickplace.record.blueprint import build_blueprint
from pickplace.sim.loop import Simulation
from pickplace.sim.ticklog import TickLog
from pickplace.world.scene import Scene
from scripts.golden_recording import (
    PATH,
    TOLERANCES,
    describe_blueprint,
    describe_recording,
    first_difference,
    read_columns,
    record_nominal_run,
)
from scripts.golden_summaries import untolerated_fields, unused_rules

GOLDEN: dict[str, Any] = json.loads(PATH.read_text())


@dataclass
class Recorded:
    path: Path
    sim: Simulation
    columns: dict[str, dict[str, Any]]

    @property
    def ticks(self) -> int:
        return int(self.sim.ticks)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    path = tmp_path_factory.mktemp("golden") / "nominal.rrd"
    sim = record_nominal_run(path)
    return Recorded(path, sim, read_columns(path))


@pytest.mark.slow
def test_entities_and_their_contents_are_unchanged(recorded: Recorded) -> None:
    diff = first_difference(describe_recording(recorded.path), GOLDEN["entities"], "entities")
    assert diff is None, diff


def test_blueprint_is_unchanged() -> None:
    diff = first_difference(describe_blueprint(build_blueprint()), GOLDEN["blueprint"], "blueprint")
    assert diff is None, diff


def test_every_number_has_a_tolerance_and_every_tolerance_a_field() -> None:
    assert untolerated_fields(TOLERANCES, [GOLDEN]) == set()
    assert unused_rules(TOLERANCES, [GOLDEN]) == []


def _entities_with(path: str, component: str, **stats: Any) -> dict[str, Any]:
    """The recorded entities with some statistics of one temporal column replaced."""
    entities = copy.deepcopy(GOLDEN["entities"])
    entities[path]["temporal"][component].update(stats)
    return entities


def _entities_diff(entities: dict[str, Any]) -> str | None:
    return first_difference(entities, GOLDEN["entities"], "entities")


def test_the_comparison_sees_a_changed_style_and_a_missing_entity() -> None:
    entities = GOLDEN["entities"]
    assert _entities_diff(entities) is None
    plot = "plots/joints/speed"
    changed = dict(entities[plot], static=dict(entities[plot]["static"], **{"x": 1}))
    assert plot in str(_entities_diff(dict(entities, **{plot: changed})))
    fewer = {k: v for k, v in entities.items() if k != plot}
    assert _entities_diff(fewer) is not None


def test_the_comparison_sees_a_row_more_and_a_value_beyond_its_tolerance() -> None:
    force, scalars = "plots/gripper/pad_force", "Scalars:scalars"
    column = GOLDEN["entities"][force]["temporal"][scalars]
    assert _entities_diff(_entities_with(force, scalars, rows=column["rows"] + 1)) is not None
    last_tick = GOLDEN["entities"][force]["temporal"]["tick"]["max"]
    assert _entities_diff(_entities_with(force, "tick", max=last_tick + 1.0)) is not None
    # Forces to 1e-5 relative: 4e-4 N at the 43.6 N peak.
    assert _entities_diff(_entities_with(force, scalars, max=column["max"] + 1e-6)) is None
    assert _entities_diff(_entities_with(force, scalars, max=column["max"] + 1e-2)) is not None
    # A sum of n values may move by n × the tolerance at its largest value, no more.
    bound = column["values"] * 1e-5 * max(abs(column["min"]), abs(column["max"]))
    assert _entities_diff(_entities_with(force, scalars, sum=column["sum"] + 0.9 * bound)) is None
    assert _entities_diff(_entities_with(force, scalars, sum=column["sum"] + 1.1 * bound))
    brick, translation = "world/bodies/brick", "Transform3D:translation"
    largest = GOLDEN["entities"][brick]["temporal"][translation]["max"]  # [m]
    assert _entities_diff(_entities_with(brick, translation, max=largest + 1e-9)) is None
    assert _entities_diff(_entities_with(brick, translation, max=largest + 1e-5)) is not None


def test_event_texts_compare_their_words_exactly_and_printed_numbers_to_a_digit() -> None:
    entities = copy.deepcopy(GOLDEN["entities"])
    items = entities["events"]["temporal"]["TextLog:text"]["items"]
    grasp = next(i for i, item in enumerate(items) if item[0].startswith("grip closed"))
    text = items[grasp][0]  # "grip closed: gap 49.9 mm, pad forces 39.9 / 40.1 N"
    items[grasp] = [text.replace("49.9", "50.0")]
    assert _entities_diff(entities) is None
    items[grasp] = [text.replace("49.9", "50.1")]
    assert "TextLog:text" in str(_entities_diff(entities))
    items[grasp] = [text]
    items[-1] = ["verdict: failure: dropped"]
    assert "TextLog:text" in str(_entities_diff(entities))


def _inf_to_nan(a: np.ndarray) -> np.ndarray:
    out = np.array(a, dtype=np.float64)
    out[~np.isfinite(out)] = np.nan
    return out


# What each plot shows, from the tick log and the scene: (T,) or (T, N) per run.
PLOTS: dict[str, Callable[[TickLog, Scene], np.ndarray]] = {
    "plots/kinematics/singular_values": lambda log, sc: log.sigma,
    "plots/kinematics/singular_values_translational": lambda log, sc: log.sigma_t,
    "plots/kinematics/condition": lambda log, sc: np.column_stack([log.condition, log.condition_t]),
    "plots/kinematics/manipulability": lambda log, sc: log.manipulability,
    "plots/kinematics/manipulability_translational": lambda log, sc: log.manipulability_t,
    "plots/tracking/position_error": lambda log, sc: log.position_error,
    "plots/tracking/orientation_error": lambda log, sc: log.orientation_error,
    "plots/joints/position": lambda log, sc: log.q,
    "plots/joints/position_normalized": lambda log, sc: (
        (log.q - sc.robot.q_min) / (sc.robot.q_max - sc.robot.q_min)
    ),
    "plots/joints/speed": lambda log, sc: log.qdot_cmd,
    "plots/joints/speed_ratio": lambda log, sc: np.abs(log.qdot_cmd) / sc.robot.v_max,
    "plots/gripper/width": lambda log, sc: np.column_stack([log.gripper_cmd, log.gripper_gap]),
    "plots/gripper/pad_force": lambda log, sc: log.pad_force,
    "plots/ik/tick_us": lambda log, sc: log.ik_us,
    "plots/ik/status": lambda log, sc: log.ik_status,
    "plots/statics/holding_torque": lambda log, sc: log.holding_torque,
    "plots/plan/tool_speed": lambda log, sc: np.linalg.norm(log.V_WG_plan[:, :3], axis=1),
    "plots/plan/segment": lambda log, sc: log.plan_segment,
}
# The constant lines: one row at the first and one at the last tick.
LIMIT_LINES: dict[str, Callable[[Scene], list[float]]] = {
    "plots/joints/position_limits": lambda sc: [*sc.robot.q_min, *sc.robot.q_max],
    "plots/joints/position_normalized_limits": lambda sc: [0.0, 1.0],
    "plots/joints/speed_ratio_limit": lambda sc: [1.0],
}


@pytest.mark.slow
def test_every_plot_entity_is_known_here(recorded: Recorded) -> None:
    plots = {p for p in recorded.columns if p.startswith("plots/")}
    assert plots == set(PLOTS) | set(LIMIT_LINES)


@pytest.mark.slow
@pytest.mark.parametrize("path", sorted(PLOTS))
def test_plot_rows_are_the_tick_log_values(recorded: Recorded, path: str) -> None:
    sim, n = recorded.sim, recorded.ticks
    rows = recorded.columns[path]["rows"]
    assert rows["tick"] == list(range(n))
    np.testing.assert_array_equal(
        np.array(rows["sim_time"]), np.round(sim.log.t[:n] * 1e9).astype(np.int64)
    )
    expected = _inf_to_nan(PLOTS[path](sim.log, sim.scene)[:n]).reshape(n, -1)
    np.testing.assert_array_equal(np.array(rows["Scalars:scalars"]), expected)


@pytest.mark.slow
@pytest.mark.parametrize("path", sorted(LIMIT_LINES))
def test_limit_lines_have_a_row_at_the_first_and_the_last_tick(
    recorded: Recorded, path: str
) -> None:
    rows = recorded.columns[path]["rows"]
    assert rows["tick"] == [0, recorded.ticks - 1]
    value = LIMIT_LINES[path](recorded.sim.scene)
    assert rows["Scalars:scalars"] == [value, value]


def _xyzw(wxyz: np.ndarray) -> np.ndarray:
    return wxyz[..., [1, 2, 3, 0]]


@pytest.mark.slow
def test_tool_frames_bodies_and_ellipsoid_are_the_tick_log_poses(recorded: Recorded) -> None:
    log, n, cols = recorded.sim.log, recorded.ticks, recorded.columns

    def rows32(path: str, component: str) -> np.ndarray:
        rows = cols[path]["rows"]
        assert rows["tick"] == list(range(n)), path
        return np.array([row[0] for row in rows[component]], dtype=np.float32)

    poses = {
        "world/tool/planned": (log.p_WG_plan, log.quat_WG_plan),
        "world/tool/commanded": (log.p_WG_cmd, log.quat_WG_cmd),
        "world/tool/actual": (log.p_WG, log.quat_WG),
    }
    model = recorded.sim.model
    for b in range(1, model.nbody):
        if model.body_weldid[b] != 0:
            name = rr.escape_entity_path_part(model.body(b).name)
            poses[f"world/bodies/{name}"] = (log.body_pos[:, b], log.body_quat[:, b])
    assert len(poses) > 3
    for path, (p, quat) in poses.items():
        translation = rows32(path, "Transform3D:translation")
        np.testing.assert_array_equal(translation, p[:n].astype(np.float32), err_msg=path)
        quaternion = rows32(path, "Transform3D:quaternion")
        np.testing.assert_array_equal(quaternion, _xyzw(quat[:n]).astype(np.float32), path)
    ellipsoid = "world/tool/manipulability_ellipsoid"
    half = 0.1 * log.sigma_t[:n]
    half[~np.isfinite(half)] = 0.0
    np.testing.assert_array_equal(
        rows32(ellipsoid, "Ellipsoids3D:half_sizes"), half.astype(np.float32)
    )
    np.testing.assert_array_equal(
        rows32(ellipsoid, "Ellipsoids3D:centers"), log.p_WG[:n].astype(np.float32)
    )
    np.testing.assert_array_equal(
        rows32(ellipsoid, "Ellipsoids3D:quaternions"), _xyzw(log.quat_t[:n]).astype(np.float32)
    )
