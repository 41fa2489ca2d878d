"""The bundled robots as ``pickplace robots`` lists them, remembered between calls.

A row needs the composed, calibrated robot (its open width and squeeze force are measured in
MuJoCo: about a second per robot). Each row is kept in a small JSON file in the user's cache
folder (:mod:`pickplace.cache`), under a key made of everything the row is measured from: the
description and every file it names (:func:`~pickplace.robot.registry.description_digest`, XML
parsing only), the world file and the source of the code that composes and calibrates. A
changed robot, world or calibration is measured again; a cache that cannot be read or written
is measured around, silently. So a listing reads files only, and answers at once after the
first.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

from pickplace.cache import read_json, source_digest, write_json
from pickplace.robot.description import RobotDescription
from pickplace.robot.registry import DEFAULT_WORLD, bundled_robots, description_digest

CACHE_FILE = "robots.json"
# The modules whose code decides a row's numbers (their source is part of the key).
_MEASURING_MODULES = tuple(
    f"robot/{name}"
    for name in ("compose.py", "calibration.py", "model.py", "parts.py", "physics.py")
)


def _code_digest() -> str:
    digest = hashlib.sha256(source_digest(_MEASURING_MODULES).encode())
    digest.update(DEFAULT_WORLD.read_bytes())
    return digest.hexdigest()


def _measure(desc: RobotDescription) -> dict[str, Any]:
    """The row's numbers from the composed robot (MuJoCo is imported here only)."""
    from pickplace.robot.compose import load_robot

    r = load_robot(desc).robot
    return {
        "name": r.name,
        "joints": r.n_joints,
        "gripper": r.gripper_kind,
        "open_width_m": r.open_width,
        "squeeze_force_n": r.squeeze_force,
    }


def robot_rows() -> list[dict[str, Any]]:
    """One row per bundled robot: ``name``, ``joints`` (arm joints), ``gripper`` (what it is,
    in words), ``open_width_m`` [m], ``squeeze_force_n`` [N] and ``description`` (the absolute
    path of its ``robot.toml``), measured once and remembered (see the module docstring).

    Raises:
        RobotError: A bundled description or a file it names is broken.
    """
    from pickplace.robot.registry import resolve_description

    stored = read_json(CACHE_FILE)
    cached: dict[str, Any] = stored if isinstance(stored, dict) else {}
    code = _code_digest()
    rows, keys, changed = [], [], False
    for name in bundled_robots():
        desc = resolve_description(name)
        key = hashlib.sha256(f"{description_digest(desc)} {code}".encode()).hexdigest()
        row = cached.get(key)
        if not isinstance(row, dict) or row.get("name") != desc.name:
            row = _measure(desc)
            cached[key] = row
            changed = True
        keys.append(key)
        rows.append({**row, "description": str(Path(desc.source).resolve())})
    if changed or len(cached) != len(keys):  # only the current rows are kept
        write_json(CACHE_FILE, {k: cached[k] for k in keys})
    return rows


__all__ = ["CACHE_FILE", "robot_rows"]
