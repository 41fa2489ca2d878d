"""Ray sweeps stopped by signals at random moments: does each one end as documented?

Runs ``pickplace sweep --backend ray --json --record …`` N times (default 30), each in a
session of its own, and sends one stop signal at a random moment of its life (during the
imports, while the local cluster starts, while its tasks start or run): SIGINT, SIGTERM and
SIGHUP in turn, to the process alone and to its process group (what Ctrl-C, ``timeout`` or a
closed terminal send). Each run passes when:

- it exits with 128 + N within :data:`STOP_BOUND_S` of the signal;
- stdout is exactly one JSON object, the report, with ``"interrupted": true``;
- stderr is at most three lines, without a traceback;
- the recording is complete (it reads back with its report) and no ``.tmp`` or ``.lock`` file
  is left beside it;
- no process it started is left: every process that inherited the run's marker variable
  (:data:`MARKER`, in the environment of everything the sweep starts, Ray's processes
  included) is gone, checked 1 s after the exit.

The table gives each run's signal, target, moment, phase (``imports``: no Ray process yet;
``cluster``: Ray's processes starting; ``tasks``: a trial running), exit code, time to exit
and the failed checks; the last line counts the passes. Leftover processes of a failed run are
killed before the next one.

Usage: python scripts/ray_signals.py [--runs N] [--seed S] [--latest SECONDS] [--json]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
MARKER = "PICKPLACE_RAY_SIGNALS_RUN"
STOP_BOUND_S = 5.0  # docs/sweeps.md: a Ray sweep ends within 5 s of a stop signal
SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
TARGETS = ("process", "group")
# Command-line fragments of a local Ray cluster's processes, for the phase column.
RAY_NAMES = (b"gcs_server", b"raylet", b"ray::", b"default_worker", b"ray/dashboard")


@dataclass
class Outcome:
    """One signalled sweep.

    Attributes:
        run: Its index.
        signal: The signal's name.
        target: ``process`` or ``group``.
        at_s: When it was sent, after the start [s].
        phase: What the sweep was doing then (see the module docstring).
        code: Its exit code.
        exit_s: From the signal to the exit [s].
        completed: Trials the report counts (None without a report).
        problems: The checks it failed (empty: passed).
    """

    run: int
    signal: str
    target: str
    at_s: float
    phase: str = ""
    code: int | None = None
    exit_s: float | None = None
    completed: int | None = None
    problems: list[str] = field(default_factory=list)


def marked(tag: str) -> list[int]:
    """Live processes whose environment holds ``MARKER=tag`` (zombies are not counted)."""
    needle = f"{MARKER}={tag}".encode()
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        with contextlib.suppress(OSError):
            if needle not in (entry / "environ").read_bytes().split(b"\0"):
                continue
            state = (entry / "stat").read_text().rsplit(")", 1)[1].split()[0]
            if state != "Z":
                found.append(int(entry.name))
    return found


def phase_of(tag: str) -> str:
    """``imports``, ``cluster`` or ``tasks`` (see the module docstring)."""
    phase = "imports"
    for pid in marked(tag):
        with contextlib.suppress(OSError):
            cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
            if cmdline.startswith(b"ray::guarded_trial"):
                return "tasks"
            if any(name in cmdline for name in RAY_NAMES):
                phase = "cluster"
    return phase


def kill_all(pids: list[int]) -> None:
    for pid in pids:
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)


def readable(rrd: Path) -> str | None:
    """None if ``rrd`` is a complete sweep recording, else what is wrong."""
    from rerun.chunk import RrdReader

    if not rrd.exists():
        return "no recording"
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # "no footer" is a warning first
            entities = set(RrdReader(rrd).store().schema().entity_paths())
    except Exception as exc:
        return f"recording unreadable: {type(exc).__name__}"
    return None if "/report" in entities else "recording without its report"


def one_run(index: int, sig: signal.Signals, target: str, at_s: float, trials: int) -> Outcome:
    """Start a sweep, signal it ``at_s`` after its start, and check how it ended."""
    outcome = Outcome(index, sig.name, target, round(at_s, 2))
    tag = f"{os.getpid()}-{index}"
    with tempfile.TemporaryDirectory(prefix="pp-ray-signals-") as tmp:
        rrd = Path(tmp) / "sweep.rrd"
        args = ["sweep", "--backend", "ray", "--workers", "2", "--trials", str(trials)]
        proc = subprocess.Popen(
            [sys.executable, "-m", "pickplace", *args, "--json", "--record", str(rrd)],
            cwd=REPO,
            env={**os.environ, MARKER: tag},
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,  # its own group: a signal to it spares this script
        )
        t0 = time.monotonic()
        while time.monotonic() - t0 < at_s and proc.poll() is None:
            outcome.phase = phase_of(tag)
            time.sleep(0.05)
        if proc.poll() is not None:
            outcome.problems.append("ended before the signal")
        outcome.phase = phase_of(tag)
        sent = time.monotonic()
        with contextlib.suppress(OSError):
            if target == "group":
                os.killpg(proc.pid, sig)
            else:
                os.kill(proc.pid, sig)
        try:
            out, err = proc.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            kill_all([proc.pid])
            out, err = proc.communicate()
            outcome.problems.append("still running 120 s after the signal")
        outcome.exit_s = round(time.monotonic() - sent, 2)
        outcome.code = proc.returncode
        if proc.returncode != 128 + sig:
            outcome.problems.append(f"exit {proc.returncode}, not {128 + sig}")
        if outcome.exit_s > STOP_BOUND_S:
            outcome.problems.append(f"exit {outcome.exit_s:.1f} s after the signal")
        lines = [line for line in out.splitlines() if line.strip()]
        try:
            (line,) = lines
            report = json.loads(line)
            outcome.completed = report["completed"]
            if report["interrupted"] is not True:
                outcome.problems.append("report not interrupted")
        except (ValueError, KeyError, TypeError):
            outcome.problems.append(f"stdout is not one JSON report ({len(lines)} lines)")
        if "Traceback" in err or len(err.strip().splitlines()) > 3:
            outcome.problems.append(f"stderr: {' | '.join(err.strip().splitlines()[-3:])[:160]}")
        problem = readable(rrd)
        if problem:
            outcome.problems.append(problem)
        left = sorted(p.name for p in Path(tmp).iterdir() if p.name != "sweep.rrd")
        if left:
            outcome.problems.append(f"left beside the recording: {', '.join(left)}")
        time.sleep(1.0)
        strays = marked(tag)
        if strays:
            names = []
            for pid in strays:
                with contextlib.suppress(OSError):
                    names.append(Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[0])
            shown = ", ".join(sorted({n.decode(errors="replace")[-40:] for n in names}))
            outcome.problems.append(f"{len(strays)} processes left ({shown})")
            kill_all(strays)
    return outcome


def table(outcomes: list[Outcome]) -> str:
    """The outcomes as a text table, one run a row, and the count of passes."""
    head = f"{'run':>3} {'signal':<7} {'target':<7} {'at s':>5} {'phase':<7} {'rc':>4} "
    head += f"{'exit s':>6} {'done':>4}  result"
    rows = [head]
    for o in outcomes:
        done = "-" if o.completed is None else str(o.completed)
        result = "; ".join(o.problems) or "ok"
        rows.append(
            f"{o.run:>3} {o.signal:<7} {o.target:<7} {o.at_s:>5.1f} {o.phase:<7} "
            f"{o.code!s:>4} {o.exit_s!s:>6} {done:>4}  {result}"
        )
    passed = sum(not o.problems for o in outcomes)
    rows.append(f"{passed}/{len(outcomes)} passed")
    return "\n".join(rows)


def main() -> int:
    """Run the signalled sweeps; exit 0 when every one passed."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=30, help="number of sweeps (default: 30)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the moments (default: 0)")
    parser.add_argument(
        "--latest",
        type=float,
        default=16.0,
        help="latest moment of a signal after the start [s] (default: 16: past the imports "
        "and the cluster's start on a loaded 2-core machine)",
    )
    parser.add_argument("--trials", type=int, default=400, help="trials of each sweep")
    parser.add_argument("--json", action="store_true", help="the outcomes as JSON, not a table")
    args = parser.parse_args()
    rng = random.Random(args.seed)
    combos = [(s, t) for t in TARGETS for s in SIGNALS]
    outcomes = []
    for i in range(args.runs):
        sig, target = combos[i % len(combos)]
        outcome = one_run(i, sig, target, rng.uniform(0.3, args.latest), args.trials)
        outcomes.append(outcome)
        if not args.json:
            print(table([outcome]).splitlines()[1], flush=True)
    if args.json:
        print(json.dumps([asdict(o) for o in outcomes]))
    else:
        print(table(outcomes))
    return 0 if all(not o.problems for o in outcomes) else 1


if __name__ == "__main__":
    sys.exit(main())
