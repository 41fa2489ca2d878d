"""Gripper calibrations kept on disk, so that a second process (every sweep worker) reuses one.

A calibration runs the gripper for seconds of simulated time; for a published gripper that is
seconds of wall time, in every process. Each one measured is written to the user's cache
directory — ``$PICKPLACE_CACHE_DIR``, else ``$XDG_CACHE_HOME/pickplace``, else
``~/.cache/pickplace`` — as ``calibration-<key>.json``, where the key (computed by the caller)
digests the content of every file involved: the gripper file, its includes and assets, the
description's gripper fields, the brick, the physics options, and the source of the code that
measures (:data:`CODE_FILES`), so an edit to any of them measures again.

JSON, not pickle: a cache file is data, read back field by field into a
:class:`~pickplace.robot.calibration.GripperCalibration` (floats are written with ``repr`` and
come back bit for bit). A file that cannot be read or does not match the record's fields is
ignored (measured again and overwritten); a cache directory that cannot be written is skipped
silently — the cache only saves time.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from pickplace.robot.calibration import GripperCalibration

CACHE_ENV = "PICKPLACE_CACHE_DIR"
"""Environment variable naming the cache directory (tests point it at a temporary one)."""

CODE_FILES = ("calibration.py", "parts.py", "physics.py", "mjcf.py", "calibration_cache.py")
"""The modules of ``pickplace/robot`` whose source is part of every key."""

_ARRAYS = {
    f.name for f in dataclasses.fields(GripperCalibration) if f.type in ("np.ndarray", np.ndarray)
}
_ARRAY_PAIRS = {"pad_faces"}
_STRING_TUPLES = {"actuators", "joints", "other_contacts", "footprint_geoms"}


def cache_dir() -> Path:
    """The directory calibrations are kept in (see the module docstring)."""
    explicit = os.environ.get(CACHE_ENV)
    if explicit:
        return Path(explicit)
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg else Path.home() / ".cache"
    return base / "pickplace"


def code_digest() -> str:
    """SHA-256 of the source of :data:`CODE_FILES`: a changed measurement measures again."""
    here = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for name in CODE_FILES:
        digest.update((here / name).read_bytes())
    return digest.hexdigest()


def _path(key: str) -> Path:
    return cache_dir() / f"calibration-{key}.json"


def _to_json(calibration: GripperCalibration) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for f in dataclasses.fields(calibration):
        value = getattr(calibration, f.name)
        if f.name in _ARRAY_PAIRS:
            out[f.name] = [np.asarray(v).tolist() for v in value]
        elif f.name == "pads":
            out[f.name] = [list(side) for side in value]
        elif isinstance(value, np.ndarray):
            out[f.name] = value.tolist()
        elif isinstance(value, tuple):
            out[f.name] = list(value)
        else:
            out[f.name] = value
    return out


def _from_json(record: dict[str, Any]) -> GripperCalibration:
    names = {f.name for f in dataclasses.fields(GripperCalibration)}
    if set(record) != names:
        raise ValueError("fields differ")
    values: dict[str, Any] = {}
    for name, value in record.items():
        if name in _ARRAY_PAIRS:
            values[name] = (np.array(value[0], dtype=float), np.array(value[1], dtype=float))
        elif name == "pads":
            values[name] = (tuple(value[0]), tuple(value[1]))
        elif name in _ARRAYS:
            values[name] = np.array(value, dtype=float)
        elif name in _STRING_TUPLES:
            values[name] = tuple(value)
        else:
            values[name] = value
    return GripperCalibration(**values)


def load(key: str) -> GripperCalibration | None:
    """The calibration stored under ``key``, or None (absent or unreadable)."""
    try:
        return _from_json(json.loads(_path(key).read_text(encoding="utf-8")))
    except (OSError, ValueError, TypeError, KeyError, IndexError):
        return None


def store(key: str, calibration: GripperCalibration) -> None:
    """Keep ``calibration`` under ``key`` (atomically; silently not if the directory is not
    writable)."""
    path = _path(key)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".calibration-", suffix=".tmp")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as out:
                json.dump(_to_json(calibration), out)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    except OSError:
        return
