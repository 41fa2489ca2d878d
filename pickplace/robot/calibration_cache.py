"""Gripper calibrations kept on disk, so that a second process (every sweep worker) reuses one.

A calibration runs the gripper for seconds of simulated time; for a published gripper that is
seconds of wall time, in every process. Each one measured is written to the user's cache folder
(:mod:`pickplace.cache`) as ``calibration-<key>.json``, where the key (computed by the caller)
digests the content of every file involved: the gripper file, its includes and assets, the
description's gripper fields, the brick, the physics options, and the source of the code that
measures (:data:`CODE_FILES`), so an edit to any of them measures again.

A record is read back field by field into a
:class:`~pickplace.robot.calibration.GripperCalibration` (floats are written with ``repr`` and
come back bit for bit); one that does not match the record's fields is ignored (measured again
and overwritten).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from typing import Any

import numpy as np

from pickplace.cache import read_json, source_digest, write_json
from pickplace.robot.calibration import GripperCalibration

CODE_FILES = tuple(
    f"robot/{name}"
    for name in ("calibration.py", "parts.py", "physics.py", "mjcf.py", "calibration_cache.py")
)
"""The modules whose source is part of every key (paths relative to the package)."""

_ARRAYS = {
    f.name for f in dataclasses.fields(GripperCalibration) if f.type in ("np.ndarray", np.ndarray)
}
_ARRAY_PAIRS = {"pad_faces"}
_STRING_TUPLES = {"actuators", "joints", "other_contacts", "footprint_geoms"}


def code_digest() -> str:
    """SHA-256 of the source of :data:`CODE_FILES`: a changed measurement measures again."""
    return source_digest(CODE_FILES)


def _name(key: str) -> str:
    return f"calibration-{key}.json"


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
    record = read_json(_name(key))
    try:
        return _from_json(record) if isinstance(record, dict) else None
    except (ValueError, TypeError, KeyError, IndexError):
        return None


def digest(calibration: GripperCalibration) -> str:
    """SHA-256 of every field of ``calibration`` as it is stored (floats exactly, by ``repr``):
    part of the key of a model whose spec the calibration edited."""
    text = json.dumps(_to_json(calibration), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def store(key: str, calibration: GripperCalibration) -> None:
    """Keep ``calibration`` under ``key`` (see :func:`pickplace.cache.write_json`)."""
    write_json(_name(key), _to_json(calibration))
