"""Sweeps: parallel trials give the same report as serial ones; failures name their seeds.

The command line runs in this process (the ``cli`` fixture), its sweeps included.
"""

from __future__ import annotations

import json
import shlex
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from pickplace.errors import InvalidInputError
from pickplace.outfile import OutputFile
from pickplace.sim.vary import parse_vary
from pickplace.sweep.recording import record_sweep
from pickplace.sweep.report import report_text
from pickplace.sweep.stats import compare_paired
from pickplace.sweep.sweep import (
    SWEEP_WALL_TIME_FIELDS,
    SweepRequest,
    parse_compare,
    run_sweep,
)
from pickplace.sweep.trial import TRIAL_KEYS
from tests.conftest import CliRun, one_json
from tests.test_recording import read_entities


def _without_timing(report: dict) -> dict:
    return {k: v for k, v in report.items() if k not in (*SWEEP_WALL_TIME_FIELDS, "workers")}


def test_parallel_sweep_equals_serial_sweep() -> None:
    serial = run_sweep(SweepRequest("pick-place-random", "qp", trials=4, first_seed=11, workers=1))
    parallel = run_sweep(
        SweepRequest("pick-place-random", "qp", trials=4, first_seed=11, workers=2)
    )
    assert _without_timing(serial) == _without_timing(parallel)
    assert serial["successes"] == 4
    assert serial["place_error_p95_m"] < 0.01


Cli = Callable[..., CliRun]


@pytest.mark.slow
def test_failed_seeds_are_reported_for_rerun(cli: Cli) -> None:
    proc = cli("sweep", "--scenario", "fault-brick-moved", "--trials", "2", "--seed", "5", "--json")
    assert proc.returncode == 1
    report = json.loads(proc.stdout)
    assert report["failures_by_reason"] == {"missed-grasp": 2}
    assert report["failed_seeds"] == {"missed-grasp": [5, 6]}


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"trials": 0}, "--trials"),
        ({"workers": 0}, "--workers"),
        ({"workers": 10_000}, "--workers"),
    ],
)
def test_bad_sweep_requests_are_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(InvalidInputError, match=message):
        SweepRequest(**kwargs).validate()


def test_sweep_cli_bad_input_is_one_line(cli: Cli) -> None:
    proc = cli("sweep", "--workers", "0")
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1


# ---------------------------------------------------------------------- varied parameters

MASS_FRICTION = ["brick_mass=0.2:3", "friction=0.2,1"]
G = 9.81


@pytest.fixture(scope="module")
def varied() -> dict:
    plan = parse_vary(MASS_FRICTION)
    return run_sweep(SweepRequest("pick-place-random", "qp", 8, 20, 2, vary=plan))


@pytest.mark.slow
def test_each_trial_records_its_draw_and_the_bins_add_up(varied: dict) -> None:
    plan = parse_vary(MASS_FRICTION)
    trials = varied["trial_results"]
    assert [t["seed"] for t in trials] == list(range(20, 28))
    for t in trials:
        assert t["parameters"] == plan.draw(t["seed"]).as_dict()
        assert "events" not in t and "plan" not in t  # compact: no event list, no plan
    for name, bins in varied["by_parameter"].items():
        assert sum(b["trials"] for b in bins) == 8, name
        assert sum(b["successes"] for b in bins) == varied["successes"], name
    assert [b["low"] for b in varied["by_parameter"]["friction"]] == [0.2, 1.0]


@pytest.mark.slow
def test_no_brick_is_refused_for_its_mass_the_physics_judges_it(varied: dict) -> None:
    # μ · 2 pads · 40 N holds m · g at rest up to m = 1.63 kg with μ = 0.2: heavier ones are
    # planned (with a warning), carried, and dropped, never refused.
    for t in varied["trial_results"]:
        v = t["parameters"]["values"]
        assert t["failure"] != "no-feasible-plan", t
        if v["friction"] * 2 * 40.0 < v["brick_mass"] * G:
            assert t["failure"] == "dropped", t
    assert "dropped" in varied["failures"]


@pytest.mark.slow
def test_a_failed_trial_re_runs_alone_from_the_printed_command(varied: dict, cli: Cli) -> None:
    reason, failure = next(iter(varied["failures"].items()))
    command = shlex.split(failure["rerun"])
    assert command[:2] == ["pickplace", "run"]
    proc = cli(*command[1:], "--json")
    assert proc.returncode == 1
    summary = one_json(proc.stdout, proc.stderr)
    trial = next(t for t in varied["trial_results"] if t["seed"] == failure["example_seed"])
    assert {k: summary.get(k) for k in TRIAL_KEYS} == {k: trial[k] for k in TRIAL_KEYS}
    failure_event = next(e["text"] for e in summary["events"] if e["kind"] == "failure")
    assert trial["failure_text"].startswith(failure_event)
    assert summary["failure"] == reason


@pytest.mark.slow
def test_the_text_report_states_rate_interval_failures_metrics_and_bins(varied: dict) -> None:
    text = report_text(varied)
    assert text.startswith("pick-place-random / iiwa14-wsg50 / qp: ")  # as a run names itself
    r = varied["success_interval"]
    assert f"(95 % Wilson {100 * r['low']:.1f} %–{100 * r['high']:.1f} %)" in text
    for reason, f in varied["failures"].items():
        assert f"{reason}: {f['count']}" in text
        assert f"re-run: {f['rerun']}" in text
    assert "success by brick_mass [kg]" in text and "success by friction" in text
    assert "cycle time [s]: p50" in text


# ---------------------------------------------------------------------- paired comparison


@pytest.mark.slow
def test_compare_runs_every_seed_per_arm_with_the_same_parameters() -> None:
    # pick-place (not -random, whose pose draws are repeated until the run's own controller's
    # pre-flight passes, so arms may get different poses for one seed).
    plan = parse_vary(["pose_noise=0:0.05"])
    req = SweepRequest(
        "pick-place", trials=3, first_seed=40, workers=2, vary=plan,
        compare=parse_compare("controller=qp,dls"),
    )  # fmt: skip
    report = run_sweep(req)
    assert report["runs"] == report["completed"] == 6 and report["controller"] is None
    trials = report["trial_results"]
    by_arm = {a: [t for t in trials if t["arm"] == a] for a in ("controller=qp", "controller=dls")}
    assert [t["controller"] for t in by_arm["controller=dls"]] == ["dls"] * 3
    for qp, dls in zip(by_arm["controller=qp"], by_arm["controller=dls"], strict=True):
        assert qp["seed"] == dls["seed"]
        assert qp["parameters"] == dls["parameters"]
        assert qp["brick_start_xyz"] == dls["brick_start_xyz"]
    (paired,) = report["compare"]["paired"]
    expected = compare_paired(
        [t["success"] for t in by_arm["controller=qp"]],
        [t["success"] for t in by_arm["controller=dls"]],
    )
    assert paired == {"a": "controller=qp", "b": "controller=dls", **expected.as_dict()}
    for label, arm in report["compare"]["arms"].items():
        assert arm["completed"] == 3
        assert arm["successes"] == sum(t["success"] for t in by_arm[label])
    text = report_text(report)
    assert "controller=qp − controller=dls on 3 paired seeds" in text
    assert "Newcombe" in text


# ---------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--vary", "mass=1:2"], "valid: brick_mass [kg]"),
        (["--vary", "control_rate=100:500"], "grid of values only"),
        (["--vary", "control_rate=100,300"], "not a whole number of physics steps"),
        (["--compare", "controller=qp"], "two or more different values"),
        (["--compare", "controller=qp,fast"], "fast"),
        (["--compare", "colour=red,blue"], "can compare controller"),
        (["--controller", "dls", "--compare", "controller=qp,dls"], "give one"),
        (["--compare", "robot=panda-hand,nosuch"], "--compare robot=...: unknown robot 'nosuch'"),
        (
            ["--speed", "0.5", "--vary", "speed=0.2:0.4"],
            "--speed: the speed is given and also varied; give one of them",
        ),
        (["--address", "10.0.0.1:6379"], "--address needs --backend ray"),
        (["--backend", "spark"], "invalid choice"),
        (["--backend", "ray", "--address", "localhost"], "not a Ray cluster address"),
    ],
)
def test_bad_sweep_options_are_exit_2_in_one_line(cli: Cli, args: list[str], message: str) -> None:
    proc = cli("sweep", "--trials", "1", *args)
    assert proc.returncode == 2, proc.stderr
    (line,) = proc.stderr.strip().splitlines()
    assert message in line


def test_without_ray_the_ray_backend_is_exit_2_with_the_install_command(
    cli: Cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray fails, as when it is missing
    proc = cli("sweep", "--trials", "1", "--backend", "ray")
    assert proc.returncode == 2
    (line,) = proc.stderr.strip().splitlines()
    assert "pip install 'pickplace[ray]'" in line


# ---------------------------------------------------------------------- recording


@pytest.mark.slow
def test_a_sweep_recording_appears_complete_with_its_report(cli: Cli, tmp_path: Path) -> None:
    path = tmp_path / "sweep.rrd"
    proc = cli(
        "sweep", "--trials", "3", "--seed", "2", "--vary", "pose_noise=0:0.03",
        "--record", str(path), "--json",
    )  # fmt: skip
    assert proc.returncode in (0, 1), proc.stderr
    report = json.loads(proc.stdout)
    assert report["recording"] == str(path)
    ents = read_entities(path)
    assert {"report", "world/legend", "plots/success_by/pose_noise/bars"} <= set(ents)
    points = [p for n, e in ents.items() if n.startswith("world/trials/") and
              "Points3D:positions" in e.static for p in e.static["Points3D:positions"]]  # fmt: skip
    assert len(points) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sweep.rrd"]  # no temp, no lock


@pytest.mark.slow
def test_a_compared_sweep_is_recorded_per_arm(tmp_path: Path) -> None:
    plan = parse_vary(["brick_mass=0.2:3"])
    req = SweepRequest(
        "pick-place", trials=2, workers=1, vary=plan, compare=parse_compare("controller=qp,dls")
    )
    report = run_sweep(req)
    path = tmp_path / "compare.rrd"
    output = OutputFile(path)
    output.open()
    assert record_sweep(output, req, report) == path
    ents = read_entities(path)
    for arm in ("controller-qp", "controller-dls"):
        assert f"plots/{arm}/success_by/brick_mass/counts" in ents
        assert any(n.startswith(f"world/trials/{arm}/") for n in ents)
    (text,) = ents["report"].static["TextDocument:text"]
    assert "controller=qp − controller=dls" in text


def test_a_job_for_a_worker_that_died_is_not_an_error_but_its_death() -> None:
    """Sending a job to a worker killed an instant earlier (its pipe closed) raised
    BrokenPipeError out of the sweep (exit 1, no report); the send is let go, and the worker's
    sentinel reports the job as worker-died."""
    import multiprocessing as mp

    from pickplace.sweep.sweep import _Worker

    ctx = mp.get_context("fork")
    worker = _Worker.__new__(_Worker)
    worker.conn, child = ctx.Pipe()
    child.close()  # the worker's end, as a killed worker leaves it
    worker.give((0, 7))  # no exception
    assert worker.job == (0, 7)
    worker.conn.close()
