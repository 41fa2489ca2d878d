"""The ``pickplace`` command: run or plan a scenario, sweep many seeds, list scenarios and robots.

Exit codes (nothing else is ever returned, and no traceback is printed):

- 0: success.
- 1: the task failed (the JSON says why), or a sweep had a failed trial.
- 2: bad input: one line on stderr naming the problem and the valid choices; nothing was run
  and no file was touched.
- 3: an output failed: the recording could not be written (disk full, file size limit, the
  path is being written by another run), the viewer did not answer, or stdout could not be
  written. One line on stderr; the JSON summary is still printed when stdout works, and an
  older file at the ``--record`` path is left as it was.
- 128 + N: stopped by signal N, the run's summary says ``interrupted`` and its recording is
  complete: 130 Ctrl-C (SIGINT), 143 SIGTERM, 129 SIGHUP. The first signal decides the code
  and the message; later ones are ignored while the run finishes, and a signal after the
  output was written (the process is only exiting) changes nothing. 141 (SIGPIPE): stdout's
  reader went away before the output was written (``pickplace ... | head``), ``--help`` and
  ``--version`` included; nothing more is printed. Output that reached the pipe before its
  reader left was written (exit 0): ``pickplace run --help | true`` gives 0 or 141 depending
  on which of the two ends first, as for any program.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from pickplace.errors import OutputError, PickPlaceError
from pickplace.robot import DEFAULT_ROBOT  # not .registry: its imports take time
from pickplace.signals import Interrupted, InterruptGate, InterruptHandler, signal_name

if TYPE_CHECKING:
    from _typeshed import SupportsWrite

    from pickplace.run.runner import RunRequest
    from pickplace.sweep.sweep import ResolvedSweep

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_OUTPUT = 0, 1, 2, 3
EXIT_INTERRUPTED = 130  # 128 + SIGINT; other signals give 128 + their number
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE: stdout's reader went away
SCENE_HELP = "world file the robot is composed into (default: scenes/world.xml)"
ROBOT_HELP = f"bundled robot (pickplace robots) or robot.toml (default: {DEFAULT_ROBOT})"


class _Parser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line and exit code 2, and a help that
    cannot be written as any output that cannot (argparse would ignore it: exit 0)."""

    def error(self, message: str) -> NoReturn:
        if "expected one argument" in message:
            message += "; a value starting with '-' needs '=', e.g. --brick=-0.1,-0.55,0"
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def print_help(self, file: SupportsWrite[str] | None = None) -> None:
        if file is not None and file is not sys.stdout:
            super().print_help(file)
            return
        _write_stdout(self.format_help().rstrip("\n"))


class _VersionAction(argparse.Action):
    """``--version``: the version on stdout, written as any output (see :class:`_Parser`)."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: Any) -> None:
        kwargs.setdefault("help", "show the version and exit")
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, *args: Any, **kwargs: Any) -> None:
        _write_stdout(f"pickplace {_version()}")
        parser.exit()


def _int_at_least(minimum: int, what: str) -> Callable[[str], int]:
    """argparse type: a base-10 integer ≥ ``minimum``, described as ``what`` in errors."""

    def parse(text: str) -> int:
        try:
            value = int(text, 10)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a {what}, got '{text}'") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be a {what}, got {value}")
        return value

    return parse


_seed = _int_at_least(0, "non-negative integer")
_positive_int = _int_at_least(1, "positive integer")


def _finite_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got '{text}'") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got '{text}'")
    return value


def _record_path(text: str) -> Path:
    if not text.strip():
        raise argparse.ArgumentTypeError("must be a file name ending in .rrd, got an empty name")
    return Path(text)


def _brick(text: str) -> tuple[float, float, float]:
    parts = text.split(",")
    usage = "must be X,Y,YAW: three finite numbers in metres and radians, e.g. 0.05,-0.55,0.3"
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"{usage}; got '{text}'")
    try:
        x, y, yaw = (float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{usage}; got '{text}'") from None
    if not all(math.isfinite(v) for v in (x, y, yaw)):
        raise argparse.ArgumentTypeError(f"{usage}; got '{text}'")
    return (x, y, yaw)


def _version() -> str:
    """The package's version (``pickplace.__version__``, which the installed metadata reads)."""
    from pickplace import __version__

    return __version__


def _add_task_options(p: argparse.ArgumentParser, vary_help: str) -> None:
    """The options that define a task, shared by ``run`` and ``plan``."""
    p.add_argument("--scene", type=Path, help=SCENE_HELP)
    p.add_argument("--robot", default=DEFAULT_ROBOT, help=ROBOT_HELP)
    p.add_argument(
        "--scenario",
        default="pick-place",
        help="scenario name (default: pick-place; see pickplace scenarios)",
    )
    p.add_argument("--controller", default="qp", help="qp (default), qp-no-collision, pinv or dls")
    p.add_argument(
        "--seed", type=_seed, default=0, help="seed of randomised scenarios (default: 0)"
    )
    p.add_argument("--brick", type=_brick, help="brick start X,Y,YAW in bin 1 [m, m, rad]")
    _add_object(p)
    p.add_argument(
        "--speed",
        type=_finite_float,
        default=1.0,
        help="speed override in [0.001, 1]: scales every speed limit (accelerations by its square)",
    )
    _add_vary(p, vary_help)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pickplace``."""
    parser = _Parser(
        prog="pickplace",
        description=plain_text(__doc__ or ""),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    run = sub.add_parser("run", help="simulate one scenario")
    _add_task_options(
        run,
        "the parameters are drawn from --seed exactly as a sweep draws them, so a "
        "sweep trial's re-run command reproduces it; NAME=VALUE fixes a value",
    )
    run.add_argument(
        "--record",
        type=_record_path,
        metavar="FILE.rrd",
        help="write a Rerun recording to FILE.rrd (it appears there complete when the run ends)",
    )
    run.add_argument("--spawn", action="store_true", help="stream to a new Rerun viewer")
    run.add_argument("--connect", metavar="URL", help="stream to a running Rerun viewer")
    run.add_argument(
        "--control-rate",
        type=_finite_float,
        default=100.0,
        help="IK rate [Hz], a whole number of physics steps in [100, 1000] (default: 100)",
    )
    run.add_argument("--pace", type=_finite_float, help="run at most this many times real time")
    _add_attempts(run)
    run.add_argument("--json", action="store_true", help="print one JSON object on stdout")

    plan = sub.add_parser(
        "plan", help="plan a scenario and pre-flight its candidates, without physics"
    )
    _add_task_options(plan, "drawn from --seed as in pickplace run")
    plan.add_argument("--json", action="store_true", help="print one JSON object on stdout")

    sub.add_parser("scenarios", help="list the scenarios").add_argument(
        "--json", action="store_true", help="print a JSON object on stdout"
    )
    sub.add_parser("robots", help="list the bundled robots").add_argument(
        "--json", action="store_true", help="print a JSON object on stdout"
    )

    sweep = sub.add_parser("sweep", help="run many seeds of a scenario in parallel")
    sweep.add_argument(
        "--scenario",
        default="pick-place-random",
        help="scenario name (default: pick-place-random; see pickplace scenarios)",
    )
    sweep.add_argument(
        "--controller", default=None, help="qp (default), qp-no-collision, pinv or dls"
    )
    sweep.add_argument("--robot", default=None, help=ROBOT_HELP)
    sweep.add_argument(
        "--trials", type=_positive_int, default=20, help="number of trials (default: 20)"
    )
    sweep.add_argument(
        "--seed",
        type=_seed,
        default=0,
        help="seed of the first trial; trial i uses SEED + i (default: 0)",
    )
    sweep.add_argument(
        "--workers",
        type=_positive_int,
        default=None,
        help="parallel processes (default: one per CPU this process may use; 1 runs the "
        "trials in this process); with --backend ray the local cluster's CPUs, or the tasks in "
        "flight on a cluster at --address (default: its CPUs)",
    )
    sweep.add_argument(
        "--trial-timeout",
        type=_finite_float,
        metavar="SECONDS",
        help="time limit of one trial in a worker process (default: 600 s): a worker without "
        "a result by then (stopped, stuck) is killed and its trial fails with worker-timeout",
    )
    _add_vary(sweep, "drawn per trial from its seed, recorded per trial in the report")
    sweep.add_argument(
        "--compare",
        metavar="KEY=A,B",
        help="run every seed once per value, with the same parameters, and compare the success "
        "rates paired by seed, e.g. controller=qp,dls",
    )
    sweep.add_argument(
        "--speed",
        type=_finite_float,
        default=1.0,
        help="speed override in [0.001, 1] for every trial (or --vary speed=...)",
    )
    sweep.add_argument(
        "--control-rate",
        type=_finite_float,
        default=100.0,
        help="IK rate [Hz] of every trial (default: 100; or --vary control_rate=a,b)",
    )
    _add_attempts(sweep)
    _add_object(sweep)
    sweep.add_argument(
        "--backend",
        choices=("process", "ray"),
        default="process",
        help="process (default): this machine's processes; ray: Ray tasks (pip install "
        "'pickplace[ray]')",
    )
    sweep.add_argument(
        "--address",
        metavar="ADDR",
        help="with --backend ray: a running cluster's address (HOST:PORT, auto or "
        "ray://HOST:PORT); default: start a local cluster for the sweep",
    )
    sweep.add_argument(
        "--record",
        type=_record_path,
        metavar="FILE.rrd",
        help="write the sweep as a Rerun recording (start poses by outcome, success rate per "
        "varied parameter, the report); it appears there complete when the sweep ends",
    )
    sweep.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    return parser


OBJECT_HELP = (
    "the object to pick instead of the world's brick: brick, can, ball, jar, or an MJCF file "
    "with one free body with collision geoms (placed where the brick lies; --brick places it)"
)


def _add_object(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--object", metavar="NAME|FILE.xml", help=OBJECT_HELP)


def _add_attempts(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--attempts",
        type=_positive_int,
        default=1,
        metavar="N",
        help="most attempts of a run, 1 to 10 (default: 1; or --vary attempts=a,b): after a "
        "missed grasp or a drop the "
        "arm stops, the brick is left to rest and the run plans again from where it lies; "
        "after an ik-failed the collision limit caused, the rest is planned around the world "
        "as it is, the brick kept in the hand",
    )


def plain_text(doc: str) -> str:
    """A docstring as a terminal shows it: without reStructuredText's literal quotes."""
    return doc.replace("``", "")


def _add_vary(parser: argparse.ArgumentParser, how: str) -> None:
    from pickplace.sim.parameters import valid_parameters  # no numpy: --help answers at once

    parser.add_argument(
        "--vary",
        action="append",
        default=[],
        metavar="NAME=LOW:HIGH|NAME=a,b,c",
        help=f"vary a parameter, uniform in [LOW, HIGH] or over a grid; repeatable; {how}. "
        f"Names: {valid_parameters()}",
    )


# The command-line option of each input a library error can name (InvalidInputError.field).
OPTION_OF_FIELD = {
    "scenario": "--scenario",
    "controller": "--controller",
    "seed": "--seed",
    "brick": "--brick",
    "scene_path": "--scene",
    "robot": "--robot",
    "record": "--record",
    "connect": "--connect",
    "control_rate_hz": "--control-rate",
    "pace": "--pace",
    "speed": "--speed",
    "address": "--address",
    "attempts": "--attempts",
    "object": "--object",
}


def _error_text(exc: PickPlaceError) -> str:
    """One line: the library's message, prefixed with the option it is about (if any)."""
    text = " ".join(str(exc).split())
    option = OPTION_OF_FIELD.get(getattr(exc, "field", None) or "")
    return f"{option}: {text}" if option else text


class _StdoutError(Exception):
    """stdout could not be written; ``code`` is the exit code to return."""

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _to_stderr(line: str) -> None:
    """Write one line on stderr; a closed or broken stderr is silently ignored."""
    try:
        sys.stderr.write(line + "\n")
        sys.stderr.flush()
    except (OSError, ValueError):
        _point_at_devnull(2)


def _print_error(message: str) -> None:
    _to_stderr(f"pickplace: error: {_one_line(message)}")


def _print_warning(message: str) -> None:
    _to_stderr(f"pickplace: warning: {_one_line(message)}")


def _write_stdout(text: str) -> None:
    """Print ``text`` and flush; raise _StdoutError (141 broken pipe, else 3) if stdout fails."""
    try:
        sys.stdout.write(text + "\n")
        sys.stdout.flush()
    except BrokenPipeError:
        _point_at_devnull(1)  # so that the interpreter's final flush does not fail again
        raise _StdoutError(EXIT_BROKEN_PIPE) from None
    except (OSError, ValueError) as exc:
        _point_at_devnull(1)
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        _print_error(f"cannot write the output to stdout: {reason}")
        raise _StdoutError(EXIT_OUTPUT) from None


def _point_at_devnull(fd: int) -> None:
    """Make ``fd`` (1 or 2) /dev/null, dropping whatever is still buffered for it."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, fd)
        os.close(null)
    except OSError:
        pass


def _ensure_std_streams() -> None:
    """Give closed standard file descriptors /dev/null (``2>&-``), so that no file the run
    opens becomes fd 1 or 2 and no print fails; rebind a missing sys.stdout / sys.stderr."""
    for fd in (0, 1, 2):
        try:
            os.fstat(fd)
        except OSError:
            null = os.open(os.devnull, os.O_RDWR)
            if null != fd:
                os.dup2(null, fd)
                os.close(null)
    if sys.stdout is None:
        sys.stdout = open(1, "w", closefd=False)  # noqa: SIM115 (lives as long as the process)
    if sys.stderr is None:
        sys.stderr = open(2, "w", closefd=False)  # noqa: SIM115


def _progress(total: float, label: str) -> Any:
    """A rich progress bar on stderr, or None when stderr is not a terminal."""
    if not sys.stderr.isatty():
        return None
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    progress = Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:.1f}/{task.total:.1f}"),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=True,
    )
    progress.add_task(label, total=total)
    return progress


class _ProgressObserver:
    def __init__(self, progress: Any) -> None:
        self.progress = progress

    def on_start(self, run: Any) -> None:
        task = self.progress.tasks[0]
        self.progress.update(task.id, total=run.task.trajectory.end_time)
        self.progress.start()

    def on_ticks(self, run: Any, start: int, end: int) -> None:
        self.progress.update(self.progress.tasks[0].id, completed=end * run.dt)

    def on_event(self, run: Any, event: Any) -> None:
        return None

    def on_finish(self, run: Any, result: Any) -> None:
        self.progress.stop()


def _parameters_text(parameters: dict[str, Any] | None) -> str | None:
    """The drawn ``--vary`` values with their units, ``brick_mass 11.72 kg, friction 0.8``."""
    if not parameters or not parameters.get("values"):
        return None
    from pickplace.sim.parameters import PARAMETERS

    parts = []
    for name, value in parameters["values"].items():
        p = PARAMETERS.get(name)
        unit = "" if p is None or p.unit == "-" else f" {p.unit}"
        parts.append(f"{name} {value:.4g}{unit}")
    offset = parameters.get("pose_offset_applied_xy_m") or parameters.get("pose_offset_xy_m")
    if offset is not None:
        parts.append(f"brick moved by ({offset[0] * 1000:.1f}, {offset[1] * 1000:.1f}) mm")
    return ", ".join(parts)


# What to change, by the kind of a rejected candidate's first problem (planning/preflight.py).
REFUSAL_ADVICE = {
    "collision": "move the brick away from the bin wall or turn it (--brick X,Y,YAW)",
    "ik": "bring the brick or the target within the arm's reach",
    "joint-limit": "turn the brick (the YAW of --brick) so the wrist needs less rotation",
    "speed-limit": "lower the speed (--speed, or --vary speed=...)",
    "singularity": "move the brick away from the arm's base or its full stretch",
}


def _cause_text(cause: str) -> str:
    """A refusal's cause (a summary's ``refusal``) with what it means."""
    from pickplace.planning.planner import REFUSAL_CAUSES  # a run or plan has imported it

    return f"{cause} ({REFUSAL_CAUSES[cause]})" if cause in REFUSAL_CAUSES else cause


def _refusal_text(s: dict[str, Any], title: str) -> str:
    """A run refused before any physics (no-feasible-plan): each candidate's first problem
    and what to change; no metrics, since nothing moved."""
    plan = s.get("plan") or {}
    candidates = plan.get("candidates") or []
    lines = [
        f"{title}: REFUSED (no-feasible-plan): none of the {len(candidates)} candidate plans "
        "passed the pre-flight, so nothing was simulated"
    ]
    if s.get("refusal"):
        lines.append(f"  cause: {_cause_text(s['refusal'])}")
    params = _parameters_text(s.get("parameters"))
    if params:
        lines.append(f"  parameters: {params}")
    kinds: list[str] = []
    lines.append("  candidates (first problem of each):")
    for i, c in enumerate(candidates, 1):
        pr = c.get("problem")
        if pr is None:
            lines.append(f"    {i}. {c['label']}: feasible")
            continue
        lines.append(f"    {i}. {c['label']}: at t={pr['t']:.2f} s {pr['kind']}: {pr['text']}")
        if pr["kind"] not in kinds:
            kinds.append(pr["kind"])
    advice = [REFUSAL_ADVICE[k] for k in kinds if k in REFUSAL_ADVICE]
    rerun = f"pickplace plan --scenario {s['scenario']} --seed {s['seed']}"
    advice.append(f"{rerun} lists every candidate with its keyframes")
    lines.append("  to change: " + "; ".join(advice))
    if s["recording"]:
        lines.append(f"  recording: {s['recording']}")
    return "\n".join(lines)


def _human_summary(s: dict[str, Any]) -> str:
    """A run's summary in lines of text: verdict, drawn parameters, timing, metrics, the
    failure and the recording; a refused run gets :func:`_refusal_text` instead."""
    title = f"{s['scenario']} / {s['robot']} / {s['controller']} / seed {s['seed']}"
    if s["failure"] == "no-feasible-plan":
        return _refusal_text(s, title)
    verdict = "SUCCESS" if s["success"] else f"FAILED ({s['failure']})"
    lines = [f"{title}: {verdict}"]
    params = _parameters_text(s.get("parameters"))
    if params:
        lines.append(f"  parameters: {params}")
    lines.append(
        f"  sim {s['sim_time_s']:.2f} s in {s['wall_time_s']:.2f} s wall "
        f"({s['realtime_factor']:.1f}x real time), {s['ticks']} ticks"
    )
    if s["place_error_m"] is not None:
        lines.append(
            f"  brick final {[round(v, 4) for v in s['brick_final_xyz']]} m, "
            f"place error {s['place_error_m'] * 1000:.1f} mm"
        )
    lines.append(
        f"  min singular value {s['min_singular_value']:.4f}, max joint speed ratio "
        f"{s['max_joint_speed_ratio']:.3f}, max tool position error "
        f"{s['max_position_error_m'] * 1000:.1f} mm"
    )
    for r in s.get("replans") or []:
        lines.append(
            f"  replanned at t={r['t']:.2f} s (tick {r['tick']}) after {r['after']}: attempt "
            f"{r['attempt']}, plan '{r['candidate']}'"
        )
    failures = [e for e in s["events"] if e["kind"] == "failure"]
    if failures:
        e = failures[0]
        lines.append(f"  {e['text']} (tick {e['tick']}, t={e['t']:.2f} s)")
    if s["recording"]:
        lines.append(f"  recording: {s['recording']}")
    return "\n".join(lines)


def _draw(texts: Sequence[str], seed: int) -> Any:
    """The parameters ``--vary`` draws for ``seed`` (None without ``--vary``)."""
    if not texts:
        return None
    from pickplace.sim.vary import parse_vary

    return parse_vary(texts).draw(seed)


def _task_request(args: argparse.Namespace, **more: Any) -> RunRequest:
    """The run request of :func:`_add_task_options`' options, with ``more`` fields."""
    from pickplace.run.runner import RunRequest
    from pickplace.world.placements import BrickPlacement

    return RunRequest(
        scenario=args.scenario,
        controller=args.controller,
        seed=args.seed,
        brick=BrickPlacement(*args.brick) if args.brick is not None else None,
        scene_path=args.scene,
        robot=args.robot,
        speed=args.speed,
        parameters=_draw(args.vary, args.seed),
        object=args.object,
        **more,
    )


def _cmd_run(args: argparse.Namespace, stop: InterruptHandler) -> int:
    from pickplace.run.runner import execute

    progress = None if args.json else _progress(1.0, f"{args.scenario}")
    observers: list[Any] = [InterruptGate(stop)]
    if progress is not None:
        observers.append(_ProgressObserver(progress))
    req = _task_request(
        args,
        record=args.record,
        spawn=args.spawn,
        connect=args.connect,
        control_rate_hz=args.control_rate,
        pace=args.pace,
        attempts=args.attempts,
        observers=observers,
    )
    outcome = execute(req)
    result = outcome.result
    summary = result.summary()
    _write_stdout(json.dumps(summary) if args.json else _human_summary(summary))
    for warning in outcome.warnings[:1]:
        _print_warning(warning)
    interrupted = summary["failure"] == "interrupted" and stop.interrupted
    if outcome.output_error is not None:
        _print_error(outcome.output_error)
        if not interrupted:
            return EXIT_OUTPUT
    if interrupted:
        _to_stderr(f"pickplace: stopped by {signal_name(stop.signum or 2)}")
        return stop.exit_code
    if summary["failure"] == "interrupted":  # a KeyboardInterrupt raised without a signal
        return EXIT_INTERRUPTED
    return EXIT_OK if result.success else EXIT_FAILED


def _cmd_plan(args: argparse.Namespace, stop: InterruptHandler) -> int:
    from pickplace.run.runner import plan_report, resolve_request

    req = _task_request(args)
    stop.arm()  # nothing to finish or keep: a stop signal ends the planning at once
    try:
        report = plan_report(resolved := resolve_request(req))
    except Interrupted:
        _to_stderr(f"pickplace: stopped by {signal_name(stop.signum or 2)} while planning")
        return stop.exit_code
    finally:
        stop.disarm()
    out = {
        "scenario": req.scenario,
        "robot": resolved.robot.name,
        "controller": req.controller,
        "seed": req.seed,
        **report.as_dict(),
        "planning_time_s": report.planning_time_s,
        "planner_time_s": dict(report.planner_time_s),
    }
    if not report.feasible:  # why, in one word, as a refused run's summary has it
        out["refusal"] = report.refusal_cause
    _write_stdout(json.dumps(out) if args.json else _human_plan(out))
    return EXIT_OK if report.feasible else EXIT_FAILED


def _human_plan(p: dict[str, Any]) -> str:
    n = len(p["candidates"])
    head = f"{p['scenario']} / {p['robot']} / {p['controller']} / seed {p['seed']}: "
    if p["feasible"]:
        head += f"feasible plan '{p['chosen']}' ({n} candidate(s) tried"
    else:
        head += f"NO feasible plan ({n} candidate(s) tried"
    lines = [head + f" in {p['planning_time_s'] * 1000:.1f} ms)"]
    if p.get("refusal"):
        lines.append(f"  cause: {_cause_text(p['refusal'])}")
    per = p.get("planner_time_s") or {}
    if per:
        lines.append(
            "  planners: "
            + ", ".join(f"{name} {seconds * 1000:.1f} ms" for name, seconds in per.items())
        )
    m = p["margins"]
    if m:
        lines.append(
            f"  margins: min clearance {m['min_clearance_m'] * 1000:.1f} mm, min joint margin "
            f"{m['min_joint_margin_rad']:.3f} rad, peak speed ratio {m['peak_speed_ratio']:.2f}, "
            f"σmin {m['min_singular_value']:.3f}"
        )
    lines.append("  candidates:")
    for i, c in enumerate(p["candidates"], 1):
        pr = c["problem"]
        verdict = "feasible" if pr is None else f"at t={pr['t']:.2f} s {pr['kind']}: {pr['text']}"
        lines.append(f"    {i}. {c['label']}: {verdict}")
        if "motions" in c:  # its transfer was planned in C-space
            lines.append(
                "       motions: "
                + ", ".join(f"{m['from']} -> {m['to']} {m['planner']}" for m in c["motions"])
            )
    lines.append(
        "  keyframes (chosen plan):" if p["feasible"] else "  keyframes (first candidate):"
    )
    for k in p["keyframes"]:
        x, y, z = k["position"]
        lines.append(
            f"    {k['t']:6.2f} s  {k['name']:<12} p=({x:.3f}, {y:.3f}, {z:.3f}) m  "
            f"width {k['gripper_width'] * 1000:.0f} mm"
        )
    return "\n".join(lines)


def _cmd_scenarios(args: argparse.Namespace, stop: InterruptHandler) -> int:
    from pickplace.sim.catalog import CATALOG as SCENARIOS  # no numpy, MuJoCo or planner

    if args.json:
        _write_stdout(
            json.dumps(
                {s.name: {"summary": s.summary, "expected": s.expected} for s in SCENARIOS.values()}
            )
        )
        return EXIT_OK
    width = max(len(name) for name in SCENARIOS)
    _write_stdout("\n".join(f"{s.name:<{width}}  {s.summary}" for s in SCENARIOS.values()))
    return EXIT_OK


def _cmd_robots(args: argparse.Namespace, stop: InterruptHandler) -> int:
    from pickplace.robot.listing import robot_rows

    rows = robot_rows()
    if args.json:
        _write_stdout(json.dumps({"robots": rows}))
        return EXIT_OK
    width = max(len(r["name"]) for r in rows)
    _write_stdout(
        "\n".join(
            f"{r['name']:<{width}}  {r['joints']} joints, gripper: {r['gripper']}, opens "
            f"{r['open_width_m'] * 1000:.1f} mm, squeezes {r['squeeze_force_n']:.1f} N  "
            f"({r['description']})"
            for r in rows
        )
    )
    return EXIT_OK


def _cmd_sweep(args: argparse.Namespace, stop: InterruptHandler) -> int:
    from pickplace.outfile import OutputFile
    from pickplace.run.runner import validate_record_path
    from pickplace.sim.vary import parse_vary
    from pickplace.sweep.report import report_text
    from pickplace.sweep.sweep import SweepRequest, given_and_compared, parse_compare

    compare = parse_compare(args.compare) if args.compare else None
    for key, given in (("controller", args.controller), ("robot", args.robot)):
        if given is not None and compare is not None and compare.key == key:
            raise given_and_compared(key)
    req = SweepRequest(
        scenario=args.scenario,
        controller=args.controller or "qp",
        trials=args.trials,
        first_seed=args.seed,
        workers=args.workers,
        vary=parse_vary(args.vary),
        compare=compare,
        speed=args.speed,
        control_rate_hz=args.control_rate,
        backend=args.backend,
        address=args.address,
        robot=args.robot or DEFAULT_ROBOT,
        trial_timeout_s=args.trial_timeout,
        attempts=args.attempts,
        object=args.object,
    )
    resolved = req.validate()
    output = None
    if args.record is not None:
        validate_record_path(args.record)
        output = OutputFile(args.record)
        output.open()  # one writer per path: refused now, not after the sweep
    try:
        progress = None if args.json else _progress(float(req.runs), f"sweep {args.scenario}")
        if progress is not None:
            progress.start()

        def advance(_: dict[str, Any]) -> None:
            if progress is not None:
                progress.advance(progress.tasks[0].id)

        try:
            report = _sweep_unless_stopped(resolved, advance, stop)
        finally:
            stop.disarm()
            if progress is not None:
                progress.stop()
        record_error = None
        if output is not None:
            from pickplace.sweep.recording import record_sweep

            try:
                report["recording"] = str(record_sweep(output, req, report))
            except OutputError as exc:
                record_error = str(exc)
                report["recording"] = None
    finally:
        if output is not None:
            output.discard()  # nothing left to do after a commit
    _write_stdout(json.dumps(report) if args.json else report_text(report))
    if record_error is not None:
        _print_error(record_error)
    if report["interrupted"]:
        _to_stderr(f"pickplace: stopped by {signal_name(stop.signum or 2)}")
        return stop.exit_code
    if record_error is not None:
        return EXIT_OUTPUT
    return EXIT_OK if report["successes"] == report["runs"] else EXIT_FAILED


def _sweep_unless_stopped(
    resolved: ResolvedSweep, advance: Callable[[dict[str, Any]], None], stop: InterruptHandler
) -> dict[str, Any]:
    """The sweep's report: :func:`~pickplace.sweep.sweep.run_sweep` with stop signals
    delivered, or, for one noted during the set-up (imports, validation), the report of no
    trial at all, interrupted, and no sweep started."""
    from pickplace.sweep.sweep import run_sweep, sweep_report

    try:
        stop.arm()  # a signal noted earlier is delivered here
    except KeyboardInterrupt:
        return sweep_report(resolved.request, [], 0.0, interrupted=True)
    return run_sweep(resolved, on_trial=advance)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``pickplace`` command ``argv`` (default: this process's arguments) and return
    its exit code; the stop-signal handlers are this call's only (the console script is
    :func:`console`)."""
    stop = InterruptHandler().install()
    try:
        return _prepared_main(argv, stop)
    finally:
        stop.uninstall()


def console(stop: InterruptHandler) -> NoReturn:
    """Run the command of this process's arguments and exit with its code: the ``pickplace``
    console script, after ``pickplace.__main__`` installed ``stop`` (before this module's
    imports, so that a signal during them is noted like one during set-up).

    Once the command has returned, stop signals are ignored until the process is gone: its
    output is complete and its exit code stands (the default action would kill it in the
    middle of its exit, e.g. after a JSON line that says success).
    """
    try:
        code = _prepared_main(None, stop)
    finally:
        stop.retire()
    sys.exit(code)


def _prepared_main(argv: Sequence[str] | None, stop: InterruptHandler) -> int:
    _ensure_std_streams()
    # Rerun's own log lines (coloured, several per problem) would repeat what the one-line
    # messages here say; RUST_LOG=warn in the environment shows them again.
    os.environ.setdefault("RUST_LOG", "off")
    # Nothing here renders with MuJoCo's OpenGL: without it, importing mujoco starts no child
    # process (glfw's library probe), which a SIGHUP to the process group broke (a traceback).
    os.environ.setdefault("MUJOCO_GL", "disable")
    return _main(argv, stop)


def _main(argv: Sequence[str] | None, stop: InterruptHandler) -> int:
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        commands = {
            "run": _cmd_run,
            "plan": _cmd_plan,
            "scenarios": _cmd_scenarios,
            "robots": _cmd_robots,
            "sweep": _cmd_sweep,
        }
        return commands[args.command](args, stop)
    except _StdoutError as exc:
        return exc.code
    except OutputError as exc:
        _print_error(str(exc))
        return EXIT_OUTPUT
    except PickPlaceError as exc:
        _print_error(_error_text(exc))
        return EXIT_BAD_INPUT
    except (Interrupted, KeyboardInterrupt):
        _to_stderr(f"pickplace: stopped by {signal_name(stop.signum or 2)} before the run started")
        return stop.exit_code
    except SystemExit as exc:  # argparse: --help, --version, usage errors
        if exc.code not in (0, None):
            return int(exc.code) if isinstance(exc.code, int) else EXIT_BAD_INPUT
        try:
            sys.stdout.flush()
        except BrokenPipeError:
            _point_at_devnull(1)
            return EXIT_BROKEN_PIPE
        except OSError:
            _point_at_devnull(1)
            return EXIT_OUTPUT
        return EXIT_OK


if __name__ == "__main__":  # python -m pickplace.cli (python -m pickplace installs it sooner)
    console(InterruptHandler().install())
