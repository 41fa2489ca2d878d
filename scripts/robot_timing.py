"""How long composing and calibrating each robot takes (target: ≤ 1 s per robot, cold).

Prints, per bundled robot (or per description given on the command line), the wall time of
:func:`pickplace.robot.compose.load_robot` with an empty calibration cache ("cold") and again with
the calibration cached ("cached"), and the simulated time calibration took. Timings are of
this machine at this moment: compare them with each other, not across machines.

    python scripts/robot_timing.py [ROBOT_OR_TOML ...] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

from pickplace.robot.compose import clear_calibration_cache, load_robot
from pickplace.robot.registry import bundled_robots

TARGET_S = 1.0


def time_robot(name: str) -> dict[str, Any]:
    """Cold and cached load times [s] of one robot, and its calibration's simulated time."""
    clear_calibration_cache()
    t0 = time.perf_counter()
    composition = load_robot(name)
    cold = time.perf_counter() - t0
    t0 = time.perf_counter()
    load_robot(name)
    cached = time.perf_counter() - t0
    r = composition.robot
    return {
        "robot": r.name,
        "joints": r.n_joints,
        "cold_s": cold,
        "cached_s": cached,
        "calibration_sim_s": r.calibration.sim_time,
        "home": r.home_source,
        "met": cold <= TARGET_S,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("robots", nargs="*", help="bundled names or robot.toml paths")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = parser.parse_args(argv)
    load_robot()  # imports and first-call costs outside the measurement
    rows = [time_robot(name) for name in (args.robots or bundled_robots())]
    if args.json:
        print(json.dumps({"target_s": TARGET_S, "robots": rows}))
    else:
        for row in rows:
            print(
                f"{row['robot']:24s} {row['joints']} joints  cold {row['cold_s']:.3f} s  "
                f"cached {row['cached_s']:.3f} s  calibration simulated "
                f"{row['calibration_sim_s']:.2f} s  home {row['home']:11s} "
                f"{'met' if row['met'] else 'MISSED'} (≤ {TARGET_S:g} s)"
            )
    return 0 if all(row["met"] for row in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
