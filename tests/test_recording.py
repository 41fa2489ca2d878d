"""The Rerun recording of a real run, read back from the .rrd file."""

from __future__ import annotations

import dataclasses
import json
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rerun as rr
from rerun.chunk import RrdReader

from pickplace.control.controllers import make_controller
from pickplace.errors import InvalidInputError, OutputError, RecordingError
from pickplace.record.recording import Recorder
from pickplace.sim.checks import FailureReason
from pickplace.sim.loader import load_scene
from pickplace.sim.loop import RunResult, Simulation
from pickplace.sim.scenarios import BuildRequest, get_scenario
from pickplace.world.scene import Scene
from scripts.golden_recording import read_columns

RECORDING_ID = "pick-place/qp/seed-0"


@dataclass
class Entity:
    """Everything logged at one entity: static components and temporal rows."""

    static: dict[str, Any] = field(default_factory=dict)
    rows: dict[str, list[Any]] = field(default_factory=lambda: defaultdict(list))

    def n_rows(self, column: str) -> int:
        return len(self.rows[column])


@dataclass
class Recording:
    path: Path
    result: RunResult
    scene: Scene
    reader: RrdReader
    entities: dict[str, Entity]


def read_entities(path: Path) -> dict[str, Entity]:
    """Entity path (without the leading '/') → its static components and temporal rows
    (ordered by tick), as the golden recording reads them."""
    return {
        name: Entity(static=e["static"], rows=defaultdict(list, e["rows"]))
        for name, e in read_columns(path).items()
    }


def run_recorded(path: Path, *, stop_at: int | None = None) -> tuple[RunResult, Scene]:
    scene = load_scene()
    task = get_scenario("pick-place").build(BuildRequest(scene, "pick-place", 0))
    if stop_at is not None:
        task = dataclasses.replace(task, faults=[_CtrlC(stop_at)])
    controller = make_controller("qp", scene, 0.01)
    observers: list[Any] = [Recorder(path, recording_id=RECORDING_ID, flush_every=100)]
    result = Simulation(scene, task, controller, observers=observers).run()
    return result, scene


class _CtrlC:
    """Presses Ctrl-C at the start of a given tick, as a SIGINT in the middle of a run would."""

    name = "ctrl-c"

    def __init__(self, tick: int) -> None:
        self.tick = tick

    def apply(self, run: Simulation, tick: int) -> str | None:
        if tick == self.tick:
            raise KeyboardInterrupt
        return None


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Recording:
    path = tmp_path_factory.mktemp("rec") / "nominal.rrd"
    result, scene = run_recorded(path)
    assert result.success, result.summary()
    return Recording(path, result, scene, RrdReader(path), read_entities(path))


def body_path(name: str) -> str:
    return f"world/bodies/{rr.escape_entity_path_part(name)}"


# ---------------------------------------------------------------------------- file


def test_application_and_recording_id(recording: Recording) -> None:
    stores = recording.reader.recordings()
    assert len(stores) == 1
    assert stores[0].application_id == "pickplace"
    assert stores[0].recording_id == RECORDING_ID


@pytest.mark.slow
def test_a_run_s_recording_id_names_its_robot(tmp_path: Path) -> None:
    """Two runs that differ only in the robot must not merge in one viewer."""
    from pickplace.run.runner import RunRequest, run

    ids = set()
    for robot in ("iiwa14-wsg50", "panda-hand"):
        path = tmp_path / f"{robot}.rrd"
        run(RunRequest(scenario="pick-place", robot=robot, record=path))
        (store,) = RrdReader(path).recordings()
        assert store.recording_id == f"pick-place/{robot}/qp/seed-0"
        ids.add(store.recording_id)
    assert len(ids) == 2


def test_blueprint_is_embedded(recording: Recording) -> None:
    assert recording.reader.blueprints()


def test_world_is_z_up_and_has_the_scene_geometry(recording: Recording) -> None:
    ents = recording.entities
    assert "world" in ents and ents["world"].static  # ViewCoordinates
    for path in (
        "world/static/floor",
        f"{body_path('bin1')}/bin1_floor",
        f"{body_path('bin2')}/bin2_wall_px",
        f"{body_path('brick')}/brick",
        f"{body_path('arm/link7')}/{rr.escape_entity_path_part('arm/link7_visual')}",
        f"{body_path('gripper/left_finger')}/{rr.escape_entity_path_part('gripper/left_pad_visual')}",
    ):
        assert path in ents, path
        assert any(k.endswith(":translation") for k in ents[path].static), path
    # Collision geoms (group 3) are not drawn.
    assert (
        f"{body_path('arm/link7')}/{rr.escape_entity_path_part('arm/link7_collision')}" not in ents
    )
    brick_color = ents[f"{body_path('brick')}/brick"].static["Boxes3D:colors"]
    assert brick_color == [0xCC1A1AFF]  # rgba (0.8, 0.1, 0.1, 1)


def test_bins_are_static_bodies(recording: Recording) -> None:
    bin2 = recording.entities[body_path("bin2")]
    assert bin2.static["Transform3D:translation"][0] == pytest.approx([0.55, 0.0, 0.0], abs=1e-7)
    assert not bin2.rows


def test_plan_is_recorded(recording: Recording) -> None:
    ents = recording.entities
    strip = ents["world/plan/path"].static["LineStrips3D:strips"]
    assert len(strip) == 1 and len(strip[0]) == 400
    names = [
        kf.name
        for kf in get_scenario("pick-place")
        .build(BuildRequest(recording.scene, "pick-place", 0))
        .trajectory.keyframes
    ]
    shown = []
    for name in names:
        kf = ents[f"world/plan/keyframes/{name}"].static
        (label,) = kf["Points3D:labels"]
        assert name in label.split(" / ")
        if kf["Points3D:show_labels"] == [True]:
            shown.extend(label.split(" / "))
        assert kf["TransformAxes3D:axis_length"] == [pytest.approx(0.05)]
    assert sorted(shown) == sorted(names)  # each name printed once
    assert "Boxes3D:half_sizes" in ents["world/plan/target_bin"].static


# ---------------------------------------------------------------------------- per tick


@pytest.mark.parametrize("body", ["arm/link7", "brick", "gripper/left_finger"])
def test_moving_bodies_have_one_transform_per_tick(recording: Recording, body: str) -> None:
    ent = recording.entities[body_path(body)]
    ticks = recording.result.ticks
    assert ent.rows["tick"] == list(range(ticks))
    assert ent.n_rows("Transform3D:translation") == ticks
    assert ent.n_rows("Transform3D:quaternion") == ticks
    assert ent.n_rows("sim_time") == ticks


def test_brick_transform_ends_where_the_run_says(recording: Recording) -> None:
    ent = recording.entities[body_path("brick")]
    final = ent.rows["Transform3D:translation"][-1][0]
    np.testing.assert_allclose(final, recording.result.brick_final_xyz, atol=1e-6)  # float32
    q = np.array(ent.rows["Transform3D:quaternion"][-1][0])
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-6)


def test_tool_frames_and_ellipsoid_per_tick(recording: Recording) -> None:
    ents, ticks = recording.entities, recording.result.ticks
    lengths = set()
    for name in ("planned", "commanded", "actual"):
        ent = ents[f"world/tool/{name}"]
        assert ent.n_rows("Transform3D:translation") == ticks
        lengths.add(ent.static["TransformAxes3D:axis_length"][0])
    assert len(lengths) == 3  # distinguishable triads
    ell = ents["world/tool/manipulability_ellipsoid"]
    assert ell.n_rows("Ellipsoids3D:half_sizes") == ticks
    assert "Ellipsoids3D:half_sizes" not in ell.static  # static would hide the temporal rows
    q = np.array([row[0] for row in ell.rows["Ellipsoids3D:quaternions"]])
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)


def test_singular_values(recording: Recording) -> None:
    ent = recording.entities["plots/kinematics/singular_values"]
    rows = ent.rows["Scalars:scalars"]
    assert len(rows) == recording.result.ticks
    assert all(len(r) == 6 for r in rows)
    assert ent.static["SeriesLines:names"] == [f"σ{i}" for i in range(1, 7)]
    smin = min(min(r) for r in rows)
    assert smin == pytest.approx(recording.result.summary()["min_singular_value"], abs=1e-12)


@pytest.mark.parametrize(
    ("path", "width"),
    [
        ("plots/kinematics/singular_values_translational", 3),
        ("plots/kinematics/condition", 2),
        ("plots/kinematics/manipulability", 4),
        ("plots/kinematics/manipulability_translational", 4),
        ("plots/tracking/position_error", 1),
        ("plots/tracking/orientation_error", 1),
        ("plots/joints/position", 7),
        ("plots/joints/position_normalized", 7),
        ("plots/joints/speed", 7),
        ("plots/joints/speed_ratio", 7),
        ("plots/gripper/width", 2),
        ("plots/gripper/pad_force", 2),
        ("plots/ik/tick_us", 1),
        ("plots/ik/status", 1),
        ("plots/statics/holding_torque", 7),
    ],
)
def test_plot_has_one_row_per_tick(recording: Recording, path: str, width: int) -> None:
    ent = recording.entities[path]
    rows = ent.rows["Scalars:scalars"]
    assert len(rows) == recording.result.ticks
    assert {len(r) for r in rows} == {width}
    assert len(ent.static["SeriesLines:names"]) == width


def test_joint_limit_series(recording: Recording) -> None:
    ents, sc = recording.entities, recording.scene
    limits = ents["plots/joints/position_limits"].rows["Scalars:scalars"]
    assert len(limits) >= 2
    expected = np.concatenate([sc.robot.q_min, sc.robot.q_max])
    for row in limits:
        np.testing.assert_allclose(row, expected)
    # The constant lines span the whole run.
    t = ents["plots/joints/position_limits"].rows["tick"]
    assert min(t) == 0 and max(t) == recording.result.ticks - 1
    normalized = np.array(ents["plots/joints/position_normalized"].rows["Scalars:scalars"])
    assert normalized.min() >= 0.0 and normalized.max() <= 1.0
    for row in ents["plots/joints/position_normalized_limits"].rows["Scalars:scalars"]:
        assert row == [0.0, 1.0]
    for row in ents["plots/joints/speed_ratio_limit"].rows["Scalars:scalars"]:
        assert row == [1.0]
    ratio = np.array(ents["plots/joints/speed_ratio"].rows["Scalars:scalars"])
    assert ratio.max() == pytest.approx(recording.result.summary()["max_joint_speed_ratio"])


def test_events_and_verdict(recording: Recording) -> None:
    ent = recording.entities["events"]
    texts = [row[0] for row in ent.rows["TextLog:text"]]
    assert texts == [e.text for e in recording.result.events]
    assert texts.count("verdict: success") == 1
    assert ent.rows["TextLog:level"][-1] == ["INFO"]
    grasp = texts.index(next(t for t in texts if t.startswith("grip closed")))
    event = recording.result.events[grasp]
    assert ent.rows["tick"][grasp] == event.tick


def test_summary_document(recording: Recording) -> None:
    (text,) = recording.entities["summary"].static["TextDocument:text"]
    body = text.strip().removeprefix("```json").removesuffix("```")
    summary = json.loads(body)
    assert summary["success"] is True
    assert summary["ticks"] == recording.result.ticks
    assert summary["recording"] == str(recording.path)


# ---------------------------------------------------------------------------- robustness


def test_interrupted_run_is_complete_and_readable(tmp_path: Path) -> None:
    path = tmp_path / "interrupted.rrd"
    result, _ = run_recorded(path, stop_at=150)
    assert result.failure is FailureReason.INTERRUPTED
    assert result.ticks == 150
    ents = read_entities(path)  # the footer is there: store() works
    assert ents[body_path("arm/link7")].n_rows("Transform3D:translation") == 150
    assert ents["plots/kinematics/singular_values"].n_rows("Scalars:scalars") == 150
    assert ents["events"].rows["TextLog:text"][-1] == ["interrupted by the user"]
    assert "TextDocument:text" in ents["summary"].static


def test_interrupt_before_the_first_tick(tmp_path: Path) -> None:
    path = tmp_path / "at-once.rrd"
    result, _ = run_recorded(path, stop_at=0)
    assert result.ticks == 0
    ents = read_entities(path)
    assert (
        f"{body_path('arm/link7')}/{rr.escape_entity_path_part('arm/link7_visual')}" in ents
    )  # the static geometry is there
    assert body_path("arm/link7") not in ents  # no tick, no pose
    assert "TextDocument:text" in ents["summary"].static


def test_missing_directory_raises_output_error_on_open(tmp_path: Path) -> None:
    rec = Recorder(tmp_path / "missing" / "run.rrd", recording_id="x")  # checks no path yet
    with pytest.raises(OutputError, match="cannot lock"):
        rec.open()
    assert rec.closed
    assert not (tmp_path / "missing").exists()


def test_a_sink_is_required_and_flush_every_is_checked(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="needs a file path"):
        Recorder(None, recording_id="x")
    with pytest.raises(InvalidInputError, match="flush_every"):
        Recorder(tmp_path / "a.rrd", recording_id="x", flush_every=0)
    with pytest.raises(InvalidInputError, match="flush_interval_s"):
        Recorder(tmp_path / "a.rrd", recording_id="x", flush_interval_s=0.0)


def test_closed_before_the_run_finished_keeps_the_older_file(tmp_path: Path) -> None:
    path = tmp_path / "kept.rrd"
    path.write_bytes(b"older")
    rec = Recorder(path, recording_id="kept")
    rec.open()
    rec.rec.log("summary", rr.TextDocument("not a finished run"), static=True)
    rec.close()
    rec.close()  # idempotent
    assert rec.closed and rec.written is None
    assert path.read_bytes() == b"older"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.rrd"]  # no temp, no lock


def test_a_recorder_records_one_run(tmp_path: Path) -> None:
    rec = Recorder(tmp_path / "once.rrd", recording_id="once")
    rec.close()
    with pytest.raises(RecordingError, match="one Recorder per run"):
        rec.open()


def test_the_file_appears_only_when_the_run_ends(tmp_path: Path) -> None:
    path = tmp_path / "late.rrd"
    seen: list[bool] = []

    class Watcher:
        def on_start(self, run: Simulation) -> None:
            seen.append(path.exists())

        def on_ticks(self, run: Simulation, start: int, end: int) -> None:
            seen.append(path.exists())

        def on_event(self, run: Simulation, event: Any) -> None:
            return None

        def on_finish(self, run: Simulation, result: RunResult) -> None:
            return None

    scene = load_scene()
    task = get_scenario("pick-place").build(BuildRequest(scene, "pick-place", 0))
    task = dataclasses.replace(task, faults=[_CtrlC(120)])
    recorder = Recorder(path, recording_id=RECORDING_ID)
    Simulation(
        scene, task, make_controller("qp", scene, 0.01), observers=[Watcher(), recorder]
    ).run()
    assert seen and not any(seen)
    assert recorder.written == path
    assert "/summary" in RrdReader(path).store().schema().entity_paths()


# ---------------------------------------------------------------------------- how it opens
# A run's recording opens on the answer: the verdict in view, the time cursor at the
# failure tick or the end, plot axes fitted to the data, keyframe labels apart.


def opening_blueprint(path: Path) -> dict[str, dict[str, Any]]:
    """Entity path → {component: value} of the blueprint the file opens on: the one sent last
    (make_active), told apart from the provisional one by its fitted plot axes."""
    reader = RrdReader(path)
    stores = []
    for store in reader.blueprints():
        parts: dict[str, dict[str, Any]] = defaultdict(dict)
        for chunk in reader.store(store=store).stream():
            batch = chunk.to_record_batch()
            for name in batch.schema.names:
                if ":" in name:
                    parts[chunk.entity_path][name] = batch.column(name).to_pylist()[-1]
        stores.append(dict(parts))
    assert len(stores) == 2  # the provisional one (a live viewer's) and the final one
    return max(stores, key=lambda s: sum(p.endswith("/ScalarAxis") for p in s))


def view_named(bp: dict[str, dict[str, Any]], title: str) -> str:
    return next(p for p, c in bp.items() if c.get("ViewBlueprint:display_name") == [title])


def test_a_success_opens_on_its_verdict_at_the_end(recording: Recording) -> None:
    (text,) = recording.entities["verdict"].static["TextDocument:text"]
    assert text.startswith(f"**SUCCESS in {recording.result.sim_time_s:.2f} s")
    assert "Brick placed" in text and "mm from its target" in text
    bp = opening_blueprint(recording.path)
    verdict = view_named(bp, "Verdict")
    assert bp[verdict]["ViewBlueprint:space_origin"] == ["verdict"]
    assert bp[verdict]["ViewBlueprint:class_identifier"] == ["TextDocument"]
    panel = bp["/time_panel"]
    assert panel["TimePanelBlueprint:play_state"] == [3]  # following: the end of the run
    assert "TimePanelBlueprint:time_selection" not in panel


def test_plot_axes_are_fitted_to_the_recorded_data(recording: Recording) -> None:
    bp = opening_blueprint(recording.path)
    sigma = view_named(bp, "Singular values σ of J [m/rad, -]")
    ((lo, hi),) = bp[f"{sigma}/ScalarAxis"]["ScalarAxis:range"]
    values = np.array(
        recording.entities["plots/kinematics/singular_values"].rows["Scalars:scalars"]
    )
    assert lo == 0.0 and values.max() < hi <= 1.1 * values.max()
    normalized = view_named(bp, "Joint position [0 lower … 1 upper limit]")
    ((lo, hi),) = bp[f"{normalized}/ScalarAxis"]["ScalarAxis:range"]
    assert lo <= 0.0 and hi >= 1.0  # the limit lines are inside


def test_a_failure_opens_at_its_tick_with_its_reason_and_its_plot(tmp_path: Path) -> None:
    from pickplace.run.runner import RunRequest, run

    path = tmp_path / "missed.rrd"
    result = run(RunRequest(scenario="fault-brick-moved", record=path))
    assert str(result.failure) == "missed-grasp"
    (text,) = read_entities(path)["verdict"].static["TextDocument:text"]
    head = (
        f"**FAILED: missed-grasp at t = {result.failure_time_s:.2f} s "
        f"(tick {result.failure_tick})**"
    )
    assert text.startswith(head)
    assert "finger gap" in text and "need >= 25.0 mm" in text
    bp = opening_blueprint(path)
    panel = bp["/time_panel"]
    t_ns = round(result.failure_time_s * 1e9)
    (selection,) = panel["TimePanelBlueprint:time_selection"]
    assert selection["min"] == t_ns and t_ns < selection["max"] < t_ns + 10_000_000
    assert panel["TimePanelBlueprint:loop_mode"] == [2]  # loop the selection
    assert panel["TimePanelBlueprint:play_state"] == [2]  # playing (into the selection)
    pad = view_named(bp, "Pad force [N]")
    tabs = next(
        c for c in bp.values() if c.get("ContainerBlueprint:display_name") == ["Gripper / IK"]
    )
    assert tabs["ContainerBlueprint:active_tab"] == [pad.lstrip("/")]


def test_keyframe_labels_are_apart_in_the_opening_view(recording: Recording) -> None:
    from pickplace.record.blueprint import (
        LABEL_CHAR_PX,
        LABEL_HEIGHT_PX,
        LABEL_PAD_PX,
        label_groups,
        project_to_view,
    )

    ents = recording.entities
    shown = [
        (e.static["Points3D:labels"][0], e.static["Transform3D:translation"])
        for p, e in ents.items()
        if p.startswith("world/plan/keyframes/") and e.static.get("Points3D:show_labels") == [True]
    ]
    texts = [label for label, _ in shown]
    assert "pre-pick / lift" in texts and "pick / settle / grip-closed" in texts
    px = project_to_view(np.array([xyz for _, xyz in shown]))
    widths = [LABEL_CHAR_PX * len(s) + LABEL_PAD_PX for s in texts]
    for i in range(len(shown)):
        for j in range(i):
            dx, dy = np.abs(px[i] - px[j])
            apart = dy >= LABEL_HEIGHT_PX or dx >= 0.5 * (widths[i] + widths[j])
            assert apart, (texts[i], texts[j])
    # Two keyframes at one place always share a label; two far apart never do.
    groups = label_groups(
        ["a", "b", "c"], np.array([[0.0, -0.5, 0.1], [0.0, -0.5, 0.1], [0.6, 0.0, 0.1]])
    )
    assert groups == [[0, 1], [2]]
