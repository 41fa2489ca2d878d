"""Published arm + gripper files, unmodified, as a user meets them: does each compose, succeed
on the nominal pick-and-place and on random seeds, and how long does composing take?

Each combination is a ``robot.toml`` of a few lines written from ``docs/robots.md`` alone
(:data:`COMBINATIONS`), over a MuJoCo Menagerie checkout given on the command line (the
repository bundles only the models its tests need, ``robots/menagerie/``). Every figure comes
from the CLI in a fresh process, with a calibration cache of its own (a temporary directory):

* composes: ``pickplace plan`` exits 0, or the one-line refusal it printed (exit 2);
* compose time, first (empty cache) and cached (a second process): as ``scripts/bench.py``;
* nominal: ``pickplace run --scenario pick-place``;
* random seeds: ``pickplace sweep --scenario pick-place-random`` over ``--seeds``.

    python -m scripts.published_robots [--menagerie DIR] [--robosuite DIR] [--seed 97000]
        [--trials 10] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pickplace.cache import CACHE_ENV
from scripts.bench import COMPOSE_SCRIPT

# Speed limits from the makers' data sheets [rad/s], one per joint.
_FRANKA = "[2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61]"
_FR3 = "[2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26]"
_UR = "[3.1416, 3.1416, 3.1416, 3.1416, 3.1416, 3.1416]"  # UR5e: 180 °/s every joint
_UR10E = "[2.0944, 2.0944, 3.1416, 3.1416, 3.1416, 3.1416]"  # 120 °/s base, shoulder
_GEN3 = "[1.3963, 1.3963, 1.3963, 1.3963, 1.2218, 1.2218, 1.2218]"
_IIWA14 = "[1.4835, 1.4835, 1.7453, 1.3090, 2.2689, 2.3562, 2.3562]"
_SAWYER = "[1.74, 1.328, 1.957, 1.957, 3.485, 3.485, 4.545]"  # intera_sdk URDF
_XARM7 = "[3.1416, 3.1416, 3.1416, 3.1416, 3.1416, 3.1416, 3.1416]"
_SIX_180 = "[3.1416, 3.1416, 3.1416, 3.1416, 3.1416, 3.1416]"
_2F85 = "robotiq_2f85/2f85.xml"
_HAND = "franka_emika_panda/hand.xml"


@dataclass(frozen=True)
class Combination:
    """One arm + gripper from published files.

    Attributes:
        name: The robot's name.
        arm: The arm's MJCF file, relative to the Menagerie checkout.
        gripper: The gripper's MJCF file, alike.
        speed_limits: The ``[arm] speed_limits`` line's value [rad/s].
        gripper_lines: More ``[gripper]`` lines (e.g. ``squeeze_force``).
        arm_lines: More ``[arm]`` lines (e.g. ``angle``).
    """

    name: str
    arm: str
    gripper: str
    speed_limits: str
    gripper_lines: tuple[str, ...] = ()
    arm_lines: tuple[str, ...] = ()

    def toml(self, menagerie: Path) -> str:
        """The description, its files in ``menagerie``."""
        lines = [
            f'name = "{self.name}"',
            "[arm]",
            f'mjcf = "{menagerie / self.arm}"',
            f"speed_limits = {self.speed_limits}",
            *self.arm_lines,
            "[gripper]",
            f'mjcf = "{menagerie / self.gripper}"',
            *self.gripper_lines,
        ]
        return "\n".join(lines) + "\n"


_SQUEEZE_70 = ("squeeze_force = 70.0  # N: the Franka hand's continuous force",)
COMBINATIONS = (
    Combination("panda-hand", "franka_emika_panda/panda_nohand.xml", _HAND, _FRANKA, _SQUEEZE_70),
    Combination("fr3-hand", "franka_fr3/fr3.xml", _HAND, _FR3, _SQUEEZE_70),
    Combination("ur5e-2f85", "universal_robots_ur5e/ur5e.xml", _2F85, _UR),
    Combination("ur10e-2f85", "universal_robots_ur10e/ur10e.xml", _2F85, _UR10E),
    Combination(
        "gen3-2f85",
        "kinova_gen3_7dof/gen3_7dof.xml",
        _2F85,
        _GEN3,
        # What the refusal of the plain mount names: its last body's z points into the arm.
        ("mount_quat = [0, 0, 1, 0]", "mount_pos = [0, 0, -0.0644]"),
    ),
    Combination("iiwa14-2f85", "kuka_iiwa_14/iiwa14.xml", _2F85, _IIWA14),
    Combination("sawyer-2f85", "rethink_robotics_sawyer/sawyer.xml", _2F85, _SAWYER),
    Combination("xarm7-hand", "ufactory_xarm7/xarm7_nohand.xml", "ufactory_xarm7/hand.xml", _XARM7),
    Combination("lite6-2f85", "ufactory_lite6/lite6.xml", _2F85, _SIX_180),
    Combination(
        "z1-2f85",
        "unitree_z1/z1.xml",
        _2F85,
        _SIX_180,
        ("mount_quat = [0.70710678, 0, 0.70710678, 0]  # the Z1 flange points along its x",),
    ),
)
"""The Menagerie arm + gripper combinations measured, each written from the docs alone."""

_RS = "robosuite/models/assets"
_RADIAN = ('angle = "radian"  # robosuite\'s files have no <compiler angle>',)
ROBOSUITE_COMBINATIONS = (
    Combination(
        "rs-panda-gripper",
        f"{_RS}/robots/panda/robot.xml",
        f"{_RS}/grippers/panda_gripper.xml",
        _FRANKA,
        _RADIAN,
        _RADIAN,
    ),
    Combination(
        "rs-sawyer-robotiq140",
        f"{_RS}/robots/sawyer/robot.xml",
        f"{_RS}/grippers/robotiq_gripper_140.xml",
        _SAWYER,
        _RADIAN,
        _RADIAN,
    ),
    Combination(
        "rs-sawyer-rethink",
        f"{_RS}/robots/sawyer/robot.xml",
        f"{_RS}/grippers/rethink_gripper.xml",
        _SAWYER,
        _RADIAN,
        _RADIAN,
    ),
    Combination(
        "rs-xarm7-gripper",
        f"{_RS}/robots/xarm7/robot.xml",
        f"{_RS}/grippers/xarm7_gripper.xml",
        _XARM7,
        _RADIAN,
        _RADIAN,
    ),
    Combination(
        "rs-kinova3-robotiq140",
        f"{_RS}/robots/kinova3/robot.xml",
        f"{_RS}/grippers/robotiq_gripper_140.xml",
        _GEN3,
        _RADIAN,
        _RADIAN,
    ),
    Combination(
        "rs-iiwa-robotiq140",
        f"{_RS}/robots/iiwa/robot.xml",
        f"{_RS}/grippers/robotiq_gripper_140.xml",
        _IIWA14,
        _RADIAN,
        _RADIAN,
    ),
)
"""robosuite 1.5.2's arms with their own or a Robotiq gripper (its Robotiq 85 names a mesh
its wheel does not ship, ``robotiq_arg2f_base_link_vis.stl``; the Rethink gripper opens 59 mm,
too little for the brick) (files from its wheel:
``pip download --no-deps robosuite==1.5.2``, unzipped)."""


def _cli(*args: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pickplace", *args], capture_output=True, text=True, env=env
    )


def measure(combo: Combination, menagerie: Path, seed: int, trials: int) -> dict[str, Any]:
    """One combination's row: composes (or its refusal), compose times [s], nominal outcome,
    random seeds succeeded."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / combo.name / "robot.toml"
        path.parent.mkdir()
        path.write_text(combo.toml(menagerie))
        env = dict(os.environ, **{CACHE_ENV: str(Path(tmp) / "cache")})
        row: dict[str, Any] = {
            "robot": combo.name,
            "lines": len(combo.toml(menagerie).split("\n")) - 1,
        }

        def timed() -> float | None:
            run = subprocess.run(
                [sys.executable, "-c", COMPOSE_SCRIPT, str(path)],
                capture_output=True,
                text=True,
                env=env,
            )
            return float(run.stdout.split()[-1]) if run.returncode == 0 else None

        row["compose_first_s"] = timed()
        plan = _cli("plan", "--robot", str(path), env=env)
        row["composes"] = plan.returncode in (0, 1)  # 1: composed, no feasible plan
        if not row["composes"]:
            row["refusal"] = plan.stderr.strip().splitlines()[-1] if plan.stderr else ""
            row["exit"] = plan.returncode
            return row
        row["compose_cached_s"] = timed()
        nominal = _cli("run", "--robot", str(path), "--json", env=env)
        summary = json.loads(nominal.stdout) if nominal.stdout else {}
        row["nominal"] = "success" if summary.get("success") else summary.get("failure")
        if plan.returncode == 1:  # the plan's first lines: why no candidate passed
            row["nominal_refusal"] = " / ".join(plan.stdout.splitlines()[:4])
        sweep = _cli(
            "sweep",
            "--robot",
            str(path),
            "--trials",
            str(trials),
            "--seed",
            str(seed),
            "--workers",
            "1",
            "--json",
            env=env,
        )
        report = json.loads(sweep.stdout) if sweep.stdout else {}
        row["random"] = f"{report.get('successes')}/{report.get('trials')}"
        row["failed_seeds"] = report.get("failed_seeds")
        return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--menagerie", type=Path, help="a Menagerie checkout")
    parser.add_argument("--robosuite", type=Path, help="robosuite's unzipped wheel")
    parser.add_argument("--seed", type=int, default=97000, help="first random seed")
    parser.add_argument("--trials", type=int, default=10, help="random seeds per robot")
    parser.add_argument("--only", nargs="*", default=None, help="combinations by name")
    parser.add_argument("--json", action="store_true", help="one JSON line per robot")
    args = parser.parse_args(argv)
    groups = [(args.menagerie, COMBINATIONS), (args.robosuite, ROBOSUITE_COMBINATIONS)]
    if args.menagerie is None and args.robosuite is None:
        parser.error("--menagerie DIR or --robosuite DIR (or both) is needed")
    for root, combo in ((r, c) for r, group in groups if r is not None for c in group):
        if args.only and combo.name not in args.only:
            continue
        row = measure(combo, root.resolve(), args.seed, args.trials)
        print(json.dumps(row) if args.json else row, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
