"""Make the README's screenshots from fresh recordings, in the real Rerun viewer.

Records the nominal run, a missed-grasp fault run and a 100-trial sweep (brick mass varied),
then opens each ``.rrd`` in the native viewer on a virtual screen with the ``rrd-shot`` tool
(``$RRD_SHOT``, else ``rrd-shot`` on PATH: a tool that opens a recording in the viewer on
a virtual screen and saves a screenshot, ``rrd-shot FILE.rrd OUT.png``) and saves:

- ``docs/images/run.png``: ``pickplace run`` (pick-place, iiwa14-wsg50, qp, seed 0);
- ``docs/images/missed-grasp.png``: ``pickplace run --scenario fault-brick-moved``;
- ``docs/images/sweep.png``: ``pickplace sweep --trials 100 --vary brick_mass=0.5:15``.

Usage: python scripts/screenshots.py [--out docs/images] [--only run,missed-grasp,sweep]
Without the tool it says so and exits 2 (nothing is written).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
SHOTS: dict[str, list[str]] = {
    "run": ["run"],
    "missed-grasp": ["run", "--scenario", "fault-brick-moved"],
    "sweep": ["sweep", "--trials", "100", "--vary", "brick_mass=0.5:15"],
}
SIZE = "1600x900"  # the window the blueprints are laid out for [px]


def find_tool() -> str | None:
    """The rrd-shot command, or None."""
    explicit = os.environ.get("RRD_SHOT")
    if explicit:
        return explicit
    return shutil.which("rrd-shot")


def shoot(name: str, tool: str, out: Path, folder: Path) -> Path:
    """Record ``SHOTS[name]`` to a fresh ``.rrd`` and screenshot it to ``out/name.png``.

    Raises:
        RuntimeError: The recording or the screenshot was not made.
    """
    rrd = folder / f"{name}.rrd"
    cmd = [sys.executable, "-m", "pickplace.cli", *SHOTS[name], "--record", str(rrd)]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, check=False)
    if not rrd.is_file():
        raise RuntimeError(f"{' '.join(cmd)} wrote no recording: {proc.stderr.strip()}")
    png = out / f"{name}.png"
    shot = subprocess.run([tool, str(rrd), str(png), SIZE], capture_output=True, text=True)
    if shot.returncode != 0 or not png.is_file():
        raise RuntimeError(f"rrd-shot failed for {name}: {shot.stderr.strip()}")
    return png


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "images")
    parser.add_argument("--only", default=",".join(SHOTS), help="comma-separated shot names")
    args = parser.parse_args(argv)
    names = [n for n in args.only.split(",") if n]
    unknown = [n for n in names if n not in SHOTS]
    if unknown:
        parser.error(f"unknown shot(s) {', '.join(unknown)}; valid: {', '.join(SHOTS)}")
    tool = find_tool()
    if tool is None:
        print("screenshots: no rrd-shot tool (set RRD_SHOT or put it on PATH)", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="pickplace-shots-") as tmp:
        for name in names:
            print(shoot(name, tool, args.out, Path(tmp)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
