"""The bundled robots as ``pickplace robots`` lists them, remembered between calls.

A row needs the composed, calibrated robot (its open width and squeeze force are measured in
MuJoCo: about a second per robot). Each row is kept in a small JSON file in the user's cache
folder (``$PICKPLACE_CACHE_DIR``, else ``$XDG_CACHE_HOME/pickplace``, else
``~/.cache/pickplace``), under a key made of everything the row is measured from: the
description and every file it names (:func:`~pickplace.robot.registry.description_digest`, XML
parsing only), the world file and the source of the code that composes and calibrates. A
changed robot, world or calibration is measured again; a cache that cannot be read or written
is measured around, silently. So a listing reads files only, and answers at once after the
first.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

from pickplace.robot.description import RobotDescription
from pickplace.robot.registry import DEFAULT_WORLD, bundled_robots, description_digest

CACHE_FILE = "robots.json"
# The modules whose code decides a row's numbers (their source is part of the key).
_MEASURING_MODULES = ("compose.py", "calibration.py", "model.py", "parts.py", "physics.py")


def cache_dir() -> Path:
    """The folder that holds :data:`CACHE_FILE` (see the module docstring)."""
    explicit = os.environ.get("PICKPLACE_CACHE_DIR")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "pickplace"


def _code_digest() -> str:
    here = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for name in _MEASURING_MODULES:
        digest.update((here / name).read_bytes())
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


def _read(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _write(path: Path, data: dict[str, Any]) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        temp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        temp.write_text(json.dumps(data, indent=1, sort_keys=True))
        os.replace(temp, path)
    except OSError:
        pass  # a cache that cannot be written is measured around


def robot_rows() -> list[dict[str, Any]]:
    """One row per bundled robot: ``name``, ``joints`` (arm joints), ``gripper`` (what it is,
    in words), ``open_width_m`` [m], ``squeeze_force_n`` [N] and ``description`` (the absolute
    path of its ``robot.toml``), measured once and remembered (see the module docstring).

    Raises:
        RobotError: A bundled description or a file it names is broken.
    """
    from pickplace.robot.registry import resolve_description

    path = cache_dir() / CACHE_FILE
    cached = _read(path)
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
        _write(path, {k: cached[k] for k in keys})
    return rows


__all__ = ["CACHE_FILE", "cache_dir", "robot_rows"]
