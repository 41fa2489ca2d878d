"""What the terminal says explains itself: help without markup and with defaults, a
refused run's refusal instead of metrics, the drawn parameters with units, absolute robot
paths, a robot folder, the sweep's recording line and a comparison counted in seeds."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import pytest

from pickplace.cli import _human_summary
from pickplace.planning.planner import REFUSAL_CAUSES, PickPlacePlanner
from pickplace.robot import listing
from pickplace.robot.description import RobotDescription
from pickplace.robot.registry import bundled_robots
from pickplace.run.runner import RunRequest, prepare
from pickplace.sim.catalog import CATALOG
from pickplace.sim.parameters import PARAMETERS
from pickplace.sim.scenarios import SCENARIOS
from pickplace.sim.vary import PARAMETERS as VARY_PARAMETERS
from tests.conftest import REPO, run_cli


def test_help_has_no_restructuredtext_markup_and_names_the_defaults() -> None:
    top = run_cli("--help")
    assert top.returncode == 0 and "``" not in top.stdout
    assert "The pickplace command: run or plan a scenario" in top.stdout
    for command in ("run", "plan"):
        text = run_cli(command, "--help").stdout
        assert "``" not in text
        flat = " ".join(text.split())
        assert "scenario name (default: pick-place;" in flat
        assert "seed of randomised scenarios (default: 0)" in flat
        assert "Names: brick_mass [kg] in [0.01, 100]" in flat  # from the light table
    sweep = " ".join(run_cli("sweep", "--help").stdout.split())
    assert "trial i uses SEED + i (default: 0)" in sweep


def test_version_is_printed_on_stdout() -> None:
    proc = run_cli("--version")
    assert proc.returncode == 0 and proc.stderr == ""
    assert proc.stdout.startswith("pickplace ") and len(proc.stdout.split()) == 2


def test_the_quick_listings_read_the_same_tables_as_the_runs() -> None:
    """scenarios and --help read light modules (no numpy, MuJoCo): the same rows as the
    scenario registry and the parameter draws."""
    assert list(CATALOG) == list(SCENARIOS)
    for name, info in CATALOG.items():
        s = SCENARIOS[name]
        assert (s.summary, s.outcomes(), s.uses_brick, s.random) == (
            info.summary,
            info.outcomes(),
            info.uses_brick,
            info.random,
        )
    assert VARY_PARAMETERS is PARAMETERS


def test_a_refused_run_prints_the_refusal_not_a_run_s_metrics() -> None:
    from tests.test_planner import _poses

    _, task, sim = prepare(RunRequest())
    X_pick, X_place = _poses(sim.scene, -0.14, -0.095, 0.0)  # in a corner of bin 1
    report = PickPlacePlanner(sim.scene, "qp").plan(X_pick, X_place)
    assert not report.feasible
    task.planning = report
    task.plan = report.plan
    summary = sim.run().summary()
    assert summary["failure"] == "no-feasible-plan"
    text = _human_summary(summary)
    head, *rest = text.splitlines()
    assert head.startswith("pick-place / iiwa14-wsg50 / qp / seed 0: REFUSED (no-feasible-plan)")
    assert f"none of the {len(report.candidates)} candidate plans" in head
    assert rest[0] == f"  cause: footprint ({REFUSAL_CAUSES['footprint']})"
    for word in ("ticks", "real time", "singular value", "place error", "nan"):
        assert word not in text, text
    listed = [line for line in rest if line.startswith("    ")]
    assert len(listed) == len(report.candidates)
    for line, c in zip(listed, report.candidates, strict=True):
        assert c.label in line and c.preflight.problem is not None
        assert c.preflight.problem.kind in line
    advice = next(line for line in rest if line.startswith("  to change: "))
    assert "pickplace plan --scenario pick-place --seed 0" in advice
    kinds = {c.preflight.problem.kind for c in report.candidates if c.preflight.problem}
    assert kinds & {"collision", "ik", "joint-limit", "speed-limit", "singularity"}
    assert len(advice.split(";")) >= 2  # a change for the problems, and where to look


@pytest.mark.slow  # composes every robot, or starts CLI processes
def test_a_varied_run_prints_what_it_drew_with_units() -> None:
    proc = run_cli("run", "--vary", "brick_mass=0.5:15", "--vary", "friction=0.8", "--seed", "0")
    line = next(s for s in proc.stdout.splitlines() if s.startswith("  parameters: "))
    json_proc = run_cli("run", "--vary", "brick_mass=0.5:15", "--seed", "0", "--json")
    mass = json.loads(json_proc.stdout)["parameters"]["values"]["brick_mass"]
    assert f"brick_mass {mass:.4g} kg" in line
    assert "friction 0.8" in line and "friction 0.8 -" not in line  # a factor has no unit
    plain = run_cli("run").stdout
    assert "parameters:" not in plain


def test_a_failed_run_names_the_failure_s_tick() -> None:
    proc = run_cli("run", "--scenario", "fault-gripper-disabled")
    assert proc.returncode == 1
    line = next(s for s in proc.stdout.splitlines() if s.startswith("  missed-grasp: "))
    assert "(tick " in line and ", t=" in line


@pytest.mark.slow  # composes every robot, or starts CLI processes
def test_a_robot_folder_is_read_through_its_robot_toml(tmp_path: Path) -> None:
    copy = tmp_path / "my-panda"
    shutil.copytree(REPO / "robots" / "panda-hand", copy)
    proc = run_cli("plan", "--robot", str(copy), "--json")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["robot"] == "panda-hand"
    empty = tmp_path / "empty"
    empty.mkdir()
    proc = run_cli("plan", "--robot", str(empty))
    assert proc.returncode == 2
    assert proc.stderr.strip() == (
        f"pickplace: error: --robot: robot folder '{empty}' holds no robot.toml; valid: "
        f"{', '.join(bundled_robots())}, a robot.toml path or a folder holding one"
    )


def test_robot_rows_are_remembered_by_what_they_are_measured_from(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("PICKPLACE_CACHE_DIR", str(tmp_path))
    first = listing.robot_rows()
    cache = json.loads((tmp_path / listing.CACHE_FILE).read_text())
    assert len(cache) == len(first) == len(bundled_robots())
    measured: list[str] = []

    def stub(desc: RobotDescription) -> dict[str, Any]:
        measured.append(desc.name)
        return {"name": desc.name, "joints": -1}

    monkeypatch.setattr(listing, "_measure", stub)
    assert listing.robot_rows() == first and measured == []  # read, not measured
    (tmp_path / listing.CACHE_FILE).write_text("not json")
    again = listing.robot_rows()  # a broken cache is measured again (here: by the stub)
    assert measured == [r["name"] for r in first]
    assert [r["joints"] for r in again] == [-1] * len(first)


@pytest.mark.slow  # composes every robot, or starts CLI processes
def test_sweep_report_has_its_recording_line_and_counts_seeds_in_a_comparison(
    tmp_path: Path,
) -> None:
    path = tmp_path / "compare.rrd"
    proc = run_cli(
        "sweep",
        "--trials",
        "2",
        "--workers",
        "1",
        "--compare",
        "controller=qp,dls",
        "--record",
        str(path),
        timeout=300,
    )
    assert proc.returncode in (0, 1), proc.stderr
    lines = proc.stdout.splitlines()
    assert "2 seeds × 2 arms (controller)" in lines[0], lines[0]
    assert "/4 succeeded" not in lines[0]
    arms = [s for s in lines if s.startswith("  controller=") and "seeds succeeded" in s]
    assert [s.split(":")[0].strip() for s in arms] == ["controller=qp", "controller=dls"]
    assert all("/2 seeds succeeded" in s for s in arms)
    assert lines[-1] == f"  recording: {path}"
    assert path.is_file()
