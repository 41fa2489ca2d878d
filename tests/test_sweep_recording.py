"""The sweep recording, read back from the .rrd file: bin, trial points, charts, report."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rerun.chunk import RrdReader

from pickplace.errors import InvalidInputError, RecordingError
from pickplace.sim.vary import ParameterDraw, VaryPlan, parse_vary
from pickplace.sweep.bins import success_by_parameter
from pickplace.sweep.recording import (
    CALLOUT_OFFSET,
    CHART_HEIGHT,
    METRICS,
    ONE_ROW_OF_COUNTS,
    RATE_COLOR,
    RATE_LOW_COLOR,
    SUCCESS_COLOR,
    bin_outline_W,
    callout_anchors_W,
    map_outcome,
    outcome_colors,
    rate_color,
    report_markdown,
    write_sweep_recording,
)
from pickplace.sweep.report import report_text
from pickplace.sweep.stats import wilson_interval
from pickplace.sweep.sweep import SweepRequest, run_sweep, sweep_report
from pickplace.world.placements import random_placement
from pickplace.world.scene import Scene
from tests.test_recording import Entity, read_entities

HEAVY_KG = 8.0  # the made-up outcome rule of the synthetic sweep: heavier bricks drop


def _rgba(color: tuple[float, float, float]) -> int:
    """Packed RGBA uint32 of an opaque float colour, as Rerun stores it."""
    r, g, b = (round(c * 255) for c in color)
    return (r << 24) | (g << 16) | (b << 8) | 0xFF


def synthetic_trials(
    scene: Scene, plan: VaryPlan, seeds: range
) -> tuple[list[dict[str, Any]], list[ParameterDraw]]:
    """Trial summaries with real start poses (pick-place-random's draw) and an invented
    outcome: heavy bricks are dropped, the rest succeed."""
    draws = [plan.draw(s) for s in seeds]
    trials = []
    for d in draws:
        p = random_placement(scene, np.random.default_rng(d.seed))
        z = scene.source_bin.floor_top_z + float(scene.brick_half_extents[2])
        ok = d.values["brick_mass"] < HEAVY_KG
        trials.append(
            {
                "scenario": "pick-place-random",
                "controller": "qp",
                "seed": d.seed,
                "success": ok,
                "failure": None if ok else "dropped",
                "brick_start_xyz": [p.x, p.y, z],
                "place_error_m": 0.001 * (1 + d.seed % 5) if ok else 0.7,
                "max_slip_m": 0.0005 if ok else 0.021,
                "sim_time_s": 14.0,
                "min_singular_value": 0.2 + 0.001 * (d.seed % 7),
                "max_joint_speed_ratio": 0.3,
            }
        )
    return trials, draws


@pytest.fixture(scope="module")
def synthetic(scene: Scene, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    plan = parse_vary(["brick_mass=0.2:12", "pose_noise=0,0.02"])
    trials, draws = synthetic_trials(scene, plan, range(10, 40))
    req = SweepRequest("pick-place-random", "qp", len(trials), 10, 1, vary=plan)
    report = sweep_report(req, trials, 1.0)
    path = tmp_path_factory.mktemp("sweep") / "sweep.rrd"
    write_sweep_recording(path, trials, report, plan, draws, scene=scene, bins=4)
    return {
        "path": path,
        "plan": plan,
        "trials": trials,
        "draws": draws,
        "report": report,
        "entities": read_entities(path),
    }


def test_one_point_per_trial_at_its_start_position(synthetic: dict[str, Any]) -> None:
    ents: dict[str, Entity] = synthetic["entities"]
    trials = synthetic["trials"]
    ok = [t for t in trials if t["success"]]
    dropped = [t for t in trials if not t["success"]]
    assert ok and dropped  # the synthetic sweep has both outcomes
    for group, path in ((ok, "world/trials/success"), (dropped, "world/trials/dropped")):
        static = ents[path].static
        np.testing.assert_allclose(
            static["Points3D:positions"], [t["brick_start_xyz"] for t in group], atol=1e-6
        )
        labels = static["Points3D:labels"]
        assert [int(label.rsplit(" ", 1)[1]) for label in labels] == [t["seed"] for t in group]
    assert all(
        label.startswith("dropped · seed ") for label in ents[path].static["Points3D:labels"]
    )
    assert ents["world/trials/success"].static["Points3D:colors"] == [_rgba(SUCCESS_COLOR)]
    assert ents["world/trials/dropped"].static["Points3D:colors"] != [_rgba(SUCCESS_COLOR)]


def test_trial_points_lie_over_the_bin_floor_drawn_from_the_scene(
    synthetic: dict[str, Any], scene: Scene
) -> None:
    ents = synthetic["entities"]
    floor = np.array(ents["world/source_bin/floor"].static["Mesh3D:vertex_positions"])
    bin_ = scene.source_bin
    p_B = bin_.to_bin_frame(floor)
    np.testing.assert_allclose(np.abs(p_B[:, :2]), [bin_.inner_half_extents] * 4, atol=1e-6)
    np.testing.assert_allclose(floor[:, 2], bin_.floor_top_z, atol=1e-6)
    points = np.vstack(
        [ents[f"world/trials/{o}"].static["Points3D:positions"] for o in ("success", "dropped")]
    )
    assert bin_.contains_xy(points)
    # The footprint of the floor mesh covers every point (x, y within its corners).
    assert np.all(points[:, 0] >= floor[:, 0].min()) and np.all(points[:, 0] <= floor[:, 0].max())
    assert np.all(points[:, 1] >= floor[:, 1].min()) and np.all(points[:, 1] <= floor[:, 1].max())
    strips = ents["world/source_bin/walls"].static["LineStrips3D:strips"]
    rim_z = {round(p[2], 6) for strip in strips for p in strip}
    assert rim_z == {round(bin_.floor_top_z, 6), round(bin_.wall_top_z, 6)}


def test_outline_of_a_rotated_bin_follows_its_frame(scene: Scene) -> None:
    # bin2 is turned by 90 degrees about z: its corners still sit at ±inner half extents of
    # its own frame, at its floor and rim heights.
    bin_ = scene.target_bin
    floor, rim = bin_outline_W(bin_)
    for corners, z in ((floor, bin_.floor_top_z), (rim, bin_.wall_top_z)):
        p_B = bin_.to_bin_frame(corners)
        np.testing.assert_allclose(np.abs(p_B[:, :2]), [bin_.inner_half_extents] * 4, atol=1e-9)
        np.testing.assert_allclose(corners[:, 2], z)
    hx, hy = bin_.inner_half_extents
    extent = np.ptp(floor[:, :2], axis=0)
    np.testing.assert_allclose(sorted(extent), sorted([2 * hx, 2 * hy]), atol=1e-9)


def test_pose_offsets_are_arrows_of_the_drawn_length(synthetic: dict[str, Any]) -> None:
    arrows = synthetic["entities"]["world/trials/pose_offsets"].static
    vectors = np.array(arrows["Arrows3D:vectors"])
    drawn = [d.values["pose_noise"] for d in synthetic["draws"]]
    np.testing.assert_allclose(np.linalg.norm(vectors, axis=1), drawn, atol=1e-7)
    np.testing.assert_allclose(vectors[:, 2], 0.0)
    np.testing.assert_allclose(
        arrows["Arrows3D:origins"], [t["brick_start_xyz"] for t in synthetic["trials"]], atol=1e-6
    )


def test_legend_counts_every_outcome(synthetic: dict[str, Any]) -> None:
    labels = synthetic["entities"]["world/legend"].static["Points3D:labels"]
    n_ok = sum(t["success"] for t in synthetic["trials"])
    assert labels == [f"success ({n_ok})", f"dropped ({len(synthetic['trials']) - n_ok})"]


def _bar_rates(ent: Entity) -> list[float]:
    """Success rates [0, 1] drawn by a chart's filled boxes: the outline (centre ± half size)
    plus its stroke (radius) spans from the axis (y = 0) up to -rate·CHART_HEIGHT."""
    centers = np.array(ent.static["Boxes2D:centers"])
    half = np.array(ent.static["Boxes2D:half_sizes"])
    radii = np.array(ent.static["Boxes2D:radii"])
    np.testing.assert_allclose(centers[:, 1] + half[:, 1] + radii, 0.0, atol=1e-5)  # on the axis
    top = centers[:, 1] - half[:, 1] - radii
    return list(-top / CHART_HEIGHT)


def _rgb(packed: int) -> tuple[int, int, int]:
    """A Rerun colour (0xRRGGBBAA) as its red, green and blue bytes."""
    return ((packed >> 24) & 255, (packed >> 16) & 255, (packed >> 8) & 255)


def test_charts_show_the_success_rate_per_bin(synthetic: dict[str, Any]) -> None:
    ents = synthetic["entities"]
    by = success_by_parameter(synthetic["plan"], synthetic["draws"], synthetic["trials"], 4)
    for name, stats in by.items():
        base = f"plots/success_by/{name}"
        filled = [s for s in stats if s.rate is not None]
        rates = _bar_rates(ents[f"{base}/bars"])
        # An empty or 0 % bar keeps a sliver (0.3 of 60 units) so that it shows.
        expected = [max(s.rate.rate, 0.3 / CHART_HEIGHT) for s in filled if s.rate]
        assert rates == pytest.approx(expected, abs=1e-5)
        counts = ents[f"{base}/counts"].static["Points2D:labels"]
        assert counts == [f"{s.successes}/{s.trials}" if s.trials else "none" for s in stats]
        whiskers = ents[f"{base}/intervals"].static["LineStrips2D:strips"]
        assert len(whiskers) == 3 * len(filled)  # a line and two caps per bar
        for s, line in zip(filled, whiskers[::3], strict=True):
            assert s.rate is not None
            ends = sorted(-p[1] / CHART_HEIGHT for p in line)
            assert ends == pytest.approx([s.rate.low, s.rate.high], abs=1e-5)
        # Bars are coloured by their rate (red 0 %, amber 50 %, green 100 %), not all green.
        colors = ents[f"{base}/bars"].static["Boxes2D:colors"]
        want = [rate_color(s.rate.rate) for s in filled if s.rate]
        assert [_rgb(c) for c in colors] == [tuple(round(255 * v) for v in w) for w in want]
        # Counts of neighbouring bars sit on alternate rows when there are many bars.
        heights = [p[1] for p in ents[f"{base}/counts"].static["Points2D:positions"]]
        if len(stats) > ONE_ROW_OF_COUNTS:
            tops = [-(s.rate.high if s.rate else 0.0) * CHART_HEIGHT - 6.5 for s in stats]
            assert [round(h - top, 6) for h, top in zip(heights, tops, strict=True)] == [
                -7.0 * (k % 2) for k in range(len(stats))
            ]
    assert rate_color(0.0) == pytest.approx(RATE_LOW_COLOR)
    assert rate_color(1.0) == pytest.approx(RATE_COLOR)
    mass = by["brick_mass"]
    assert mass[0].rate is not None and mass[0].rate.rate == 1.0  # light bricks succeed
    assert mass[-1].rate is not None and mass[-1].rate.rate == 0.0  # heavy ones are dropped
    noise_ticks = ents["plots/success_by/pose_noise/x_ticks"].static["Points2D:labels"]
    assert noise_ticks == ["0", "0.02"]  # a grid: one bar per value


def test_report_document(synthetic: dict[str, Any]) -> None:
    (text,) = synthetic["entities"]["report"].static["TextDocument:text"]
    trials = synthetic["trials"]
    n_ok = sum(t["success"] for t in trials)
    r = wilson_interval(n_ok, len(trials))
    assert f"{n_ok} of {len(trials)} succeeded" in text
    assert f"{100 * r.low:.1f}–{100 * r.high:.1f} %" in text
    dropped = sorted(t["seed"] for t in trials if not t["success"])
    assert f"| dropped | {len(dropped)} | {' '.join(map(str, dropped))} |" in text
    assert f"--seed {dropped[0]} --vary brick_mass=0.2:12 --vary pose_noise=0,0.02`" in text
    assert "## Success rate by brick_mass [kg]" in text
    for m in METRICS:
        if any(m.key in t for t in trials):
            assert m.label in text
    body = text.split("```json\n", 1)[1].rsplit("\n```", 1)[0]
    shown = {k: v for k, v in synthetic["report"].items() if k != "trial_results"}
    assert json.loads(body) == json.loads(json.dumps(shown))  # the per-trial list is left out


def test_metrics_show_the_bad_tail(scene: Scene) -> None:
    plan = parse_vary(["brick_mass=0.2:1"])
    trials, _ = synthetic_trials(scene, plan, range(20))
    req = SweepRequest("pick-place-random", "qp", len(trials), 0, 1, vary=plan)
    text = report_markdown(sweep_report(req, trials, 1.0))
    sigma = min(t["min_singular_value"] for t in trials)
    (row,) = [line for line in text.splitlines() if line.startswith("| smallest σ")]
    assert row.rstrip(" |").endswith(f"{sigma:.3g}")  # worst = the minimum, not the maximum
    slip = max(t["max_slip_m"] for t in trials) * 1000
    (row,) = [line for line in text.splitlines() if line.startswith("| slip")]
    assert row.rstrip(" |").endswith(f"{slip:.3g}")


def test_the_recording_embeds_its_blueprint(synthetic: dict[str, Any]) -> None:
    reader = RrdReader(synthetic["path"])
    (entry,) = reader.recordings()
    assert entry.application_id == "pickplace"
    assert entry.recording_id == "sweep/pick-place-random/qp/seeds-10-39"
    assert reader.blueprints()


def test_many_failures_are_labelled_but_labels_shown_only_when_few(
    scene: Scene, tmp_path: Path
) -> None:
    plan = parse_vary(["brick_mass=9:12"])  # every trial fails
    trials, draws = synthetic_trials(scene, plan, range(30))
    report = sweep_report(SweepRequest(trials=len(trials), workers=1, vary=plan), trials, 1.0)
    write_sweep_recording(tmp_path / "many.rrd", trials, report, plan, draws, scene=scene)
    entities = read_entities(tmp_path / "many.rrd")
    many = entities["world/trials/dropped"].static
    assert len(many["Points3D:labels"]) == 30 and many["Points3D:show_labels"] == [False]
    assert "world/callouts/labels" not in entities  # 30 rows would not fit beside the bin
    few_report = sweep_report(SweepRequest(trials=3, workers=1, vary=plan), trials[:3], 1.0)
    write_sweep_recording(
        tmp_path / "few.rrd", trials[:3], few_report, plan, draws[:3], scene=scene
    )
    entities = read_entities(tmp_path / "few.rrd")
    callouts = entities["world/callouts/labels"].static
    assert callouts["Points3D:show_labels"] == [True]
    assert sorted(callouts["Points3D:labels"]) == sorted(
        f"dropped · seed {t['seed']}" for t in trials[:3]
    )
    (leaders,) = [v for k, v in entities["world/callouts/leaders"].static.items() if "strips" in k]
    assert len(leaders) == 3


def test_callouts_stand_in_one_column_beside_the_bin_a_row_apart_in_the_points_order(
    scene: Scene,
) -> None:
    bin_ = scene.source_bin
    hx, hy = bin_.inner_half_extents
    rng = np.random.default_rng(7)
    R_WB = bin_.X_WB.rotation().as_matrix()
    p_B = np.column_stack([rng.uniform(-hx, hx, 12), rng.uniform(-hy, hy, 12), np.zeros(12)])
    p_W = p_B @ R_WB.T + bin_.X_WB.translation()
    anchors_B = (callout_anchors_W(bin_, p_W) - bin_.X_WB.translation()) @ R_WB
    np.testing.assert_allclose(anchors_B[:, 0], -hx - CALLOUT_OFFSET)  # outside the -x wall
    rows = np.sort(anchors_B[:, 1])
    np.testing.assert_allclose(np.diff(rows), 2 * hy / 12)  # evenly spaced, one row each
    assert rows[0] > -hy and rows[-1] < hy
    # The higher a point in the bin, the higher its label: leader lines keep their order.
    assert list(np.argsort(anchors_B[:, 1])) == list(np.argsort(p_B[:, 1]))


def test_outcome_colours_are_distinct() -> None:
    outcomes = ["success", "dropped", "weird", "missed-grasp", "stranger", "dropped"]
    colors = outcome_colors(outcomes)
    assert list(colors) == ["success", "dropped", "weird", "missed-grasp", "stranger"]
    assert len(set(colors.values())) == 5
    assert colors["success"] == SUCCESS_COLOR


def test_a_sweep_stopped_before_any_trial_ended_is_recorded_with_its_report(
    scene: Scene, tmp_path: Path
) -> None:
    plan = parse_vary(["brick_mass=0.2:1"])
    report = sweep_report(
        SweepRequest(trials=5, first_seed=3, vary=plan), [], 0.0, interrupted=True
    )
    path = write_sweep_recording(tmp_path / "x.rrd", [], report, plan, scene=scene)
    ents = read_entities(path)
    assert "report" in ents and "world/source_bin/floor" in ents
    assert not [n for n in ents if n.startswith("world/trials") or n == "world/legend"]
    assert "plots/success_by/brick_mass/axes" in ents  # its chart, without bars


def test_bad_input_is_refused(scene: Scene, tmp_path: Path) -> None:
    plan = parse_vary(["brick_mass=0.2:1"])
    trials, draws = synthetic_trials(scene, plan, range(3))
    with pytest.raises(InvalidInputError, match="no parameter draw"):
        write_sweep_recording(tmp_path / "y.rrd", trials, {}, plan, draws[:1], scene=scene)
    with pytest.raises(RecordingError, match="cannot open the recording sink"):
        write_sweep_recording(tmp_path / "missing" / "z.rrd", trials, {}, scene=scene)


@pytest.mark.slow
def test_a_real_sweep_is_recorded(tmp_path: Path, scene: Scene) -> None:
    summaries: list[dict[str, Any]] = []
    req = SweepRequest("pick-place-random", "qp", trials=3, first_seed=4, workers=1)
    report = run_sweep(req, on_trial=summaries.append)
    path = write_sweep_recording(tmp_path / "real.rrd", summaries, report, scene=scene)
    ents = read_entities(path)
    drawn = [
        p
        for name, ent in ents.items()
        if name.startswith("world/trials/")
        for p in ent.static["Points3D:positions"]
    ]
    assert len(drawn) == 3
    np.testing.assert_allclose(
        sorted(map(tuple, drawn)), sorted(tuple(t["brick_start_xyz"]) for t in summaries), atol=1e-6
    )
    assert not any(name.startswith("plots/") for name in ents)  # nothing varied, no chart
    (text,) = ents["report"].static["TextDocument:text"]
    assert f"{report['successes']} of 3 succeeded" in text


def test_refusals_are_counted_and_drawn_by_cause(scene: Scene, tmp_path: Path) -> None:
    """A coverage sweep's refusals: the report counts them per cause (most frequent first),
    its text says so, and the bin's picture has one coloured group per cause."""
    plan = parse_vary(["brick_mass=0.2:1"])  # light bricks: every trial succeeds, but
    trials, draws = synthetic_trials(scene, plan, range(8))
    causes = ["footprint", "singularity", "footprint", None, "footprint", "joint-limit"]
    for t, cause in zip(trials, causes, strict=False):  # these five, refused
        if cause is not None:
            t.update(success=False, failure="no-feasible-plan", refusal=cause)
    report = sweep_report(SweepRequest(trials=len(trials), workers=1, vary=plan), trials, 1.0)
    refused = report["failures"]["no-feasible-plan"]
    assert refused["count"] == 5
    assert list(refused["by_cause"].items()) == [
        ("footprint", 3),
        ("joint-limit", 1),
        ("singularity", 1),
    ]
    assert "by cause: footprint 3, joint-limit 1, singularity 1" in report_text(report)
    assert "| … footprint | 3 | |" in report_markdown(report)
    write_sweep_recording(tmp_path / "causes.rrd", trials, report, plan, draws, scene=scene)
    entities = read_entities(tmp_path / "causes.rrd")
    footprint = entities["world/trials/no-feasible-plan/footprint"].static
    np.testing.assert_allclose(
        footprint["Points3D:positions"],
        [t["brick_start_xyz"] for t in trials if t.get("refusal") == "footprint"],
        atol=1e-6,
    )
    assert all(
        label.startswith("no-feasible-plan (footprint) · seed ")
        for label in footprint["Points3D:labels"]
    )
    colors = {
        entities[f"world/trials/no-feasible-plan/{c}"].static["Points3D:colors"][0]
        for c in ("footprint", "singularity", "joint-limit")
    }
    assert len(colors) == 3 and _rgba(SUCCESS_COLOR) not in colors
    legend = entities["world/legend"].static["Points3D:labels"]
    assert "no-feasible-plan (footprint) (3)" in legend
    assert map_outcome(trials[3]) == "success" and "refusal" not in trials[3]
