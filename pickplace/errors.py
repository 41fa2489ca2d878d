"""Exception hierarchy of pickplace.

Every error raised on purpose by the package derives from :class:`PickPlaceError`.
Messages say what was wrong and what would be valid, so that the CLI can print them
as a single line.
"""

from __future__ import annotations

import math
import os
import reprlib
import stat
from collections.abc import Iterable
from pathlib import Path


class PickPlaceError(Exception):
    """Base class of every error raised on purpose by pickplace."""


class InvalidInputError(PickPlaceError, ValueError):
    """A value given by the user or the caller is outside what is valid.

    Messages use the library's words (``control rate``, ``brick pose``); ``field`` names the
    input they are about (e.g. ``"control_rate_hz"``, a :class:`~pickplace.run.runner.RunRequest`
    field) so that a front end can say which of its options was wrong.
    """

    def __init__(self, message: str, field: str | None = None) -> None:
        super().__init__(message)
        self.field = field


class SceneError(PickPlaceError):
    """A scene (world) file is missing, is not valid MJCF, or lacks a required element.

    ``field`` is the input it is about: the world file (``RunRequest.scene_path``,
    ``--scene``).
    """

    field = "scene_path"


class ObjectError(SceneError):
    """The object to pick (``--object``) is unusable: its file cannot be read, it is not one
    free body, it has no collision geom, or the gripper cannot open around it.

    ``field`` is the input it is about: ``RunRequest.object``, ``--object``.
    """

    field = "object"


class RobotError(PickPlaceError):
    """A robot description, or an arm or gripper file it names, is missing or unusable.

    The message is one line naming the file, the field or element, and what would be valid;
    ``field`` is the input it is about: the robot (``RunRequest.robot``, ``--robot``).
    """

    field = "robot"


class UnknownNameError(PickPlaceError, KeyError):
    """A name (site, joint, scenario, controller, ...) does not exist.

    The message lists the names that do exist.
    """

    def __init__(self, kind: str, name: str, valid: Iterable[str]) -> None:
        self.kind = kind
        self.name = name
        self.valid = sorted(valid)
        shown = ", ".join(self.valid) if self.valid else "(none)"
        super().__init__(f"unknown {kind} '{name}'; valid: {shown}")

    def __str__(self) -> str:  # KeyError would otherwise quote the message.
        return str(self.args[0])


class PlanError(PickPlaceError, ValueError):
    """Keyframes, timing or trajectory inputs are inconsistent."""


class ControllerError(PickPlaceError):
    """A differential-IK controller was misconfigured or failed."""


class RecordingError(PickPlaceError):
    """A recording could not be opened or written."""


class OutputError(RecordingError):
    """A requested output failed for a reason outside the inputs: the viewer does not answer,
    the disk is full, or another run is writing the same recording path (CLI exit code 3)."""


def require_finite(
    name: str, value: object, error: type[PickPlaceError] = InvalidInputError
) -> float:
    """Return ``value`` as float, or raise ``error`` if it is not a finite number.

    Args:
        name: How to call the value in the message, with its unit (e.g. ``"t [s]"``).
        value: The value to check.
        error: Exception class to raise (default :class:`InvalidInputError`).
    """
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise error(f"{name} must be a finite number, got {value!r}") from None
    if not math.isfinite(v):
        raise error(f"{name} must be a finite number, got {value!r}")
    return v


def require_positive(
    name: str, value: object, error: type[PickPlaceError] = InvalidInputError
) -> float:
    """Return ``value`` as float, or raise ``error`` if it is not a finite number > 0."""
    try:
        v = require_finite(name, value, error)
    except PickPlaceError:
        v = math.nan
    if not v > 0.0:
        raise error(f"{name} must be a finite number > 0, got {value!r}")
    return v


def require_non_negative(
    name: str, value: object, error: type[PickPlaceError] = InvalidInputError
) -> float:
    """Return ``value`` as float, or raise ``error`` if it is not a finite number >= 0."""
    v = require_finite(name, value, error)
    if v < 0.0:
        raise error(f"{name} must be >= 0, got {value!r}")
    return v


_QUOTE = reprlib.Repr()
_QUOTE.maxlist = _QUOTE.maxtuple = _QUOTE.maxset = 8
_QUOTE.maxdict = 4
_QUOTE.maxlevel = 3
_QUOTE.maxstring = _QUOTE.maxother = 60


def quoted(value: object) -> str:
    """``repr(value)`` shortened for a message: lists cut after 8 items (``...``), strings and
    numbers after 60 characters, nesting after 3 levels, so that a message quoting a huge or
    deep input (a 200,000-number list) stays one short line."""
    return _QUOTE.repr(value)


_NOT_A_FILE = {
    stat.S_IFDIR: "a directory",
    stat.S_IFIFO: "a FIFO",
    stat.S_IFCHR: "a character device",
    stat.S_IFBLK: "a block device",
    stat.S_IFSOCK: "a socket",
}


def file_problem(path: Path) -> str | None:
    """None if ``path`` is a regular file (a symbolic link to one counts); else what it is
    instead, for a message: ``"does not exist"``, ``"is a directory"``, ``"is a FIFO"``, ``"is a
    character device"`` (``/dev/zero``), ... (never opened: a FIFO or device would block or never
    end)."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return "is a symbolic link to a missing file" if os.path.islink(path) else "does not exist"
    except OSError as exc:
        return f"cannot be read ({exc.strerror})"
    if stat.S_ISREG(mode):
        return None
    return f"is {_NOT_A_FILE.get(stat.S_IFMT(mode), 'not a regular file')}"
