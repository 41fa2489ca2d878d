"""Exception hierarchy of pickplace.

Every error raised on purpose by the package derives from :class:`PickPlaceError`.
Messages say what was wrong and what would be valid, so that the CLI can print them
as a single line.
"""

from __future__ import annotations

from collections.abc import Iterable


class PickPlaceError(Exception):
    """Base class of every error raised on purpose by pickplace."""


class InvalidInputError(PickPlaceError, ValueError):
    """A value given by the user or the caller is outside what is valid."""


class SceneError(PickPlaceError):
    """A scene file is missing, is not valid MJCF, or lacks a required element."""


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


def require_finite(name: str, value: float) -> float:
    """Return ``value`` as float, or raise if it is NaN or infinite."""
    v = float(value)
    if v != v or v in (float("inf"), float("-inf")):
        raise InvalidInputError(f"{name} must be a finite number, got {value!r}")
    return v


def require_positive(name: str, value: float) -> float:
    """Return ``value`` as float, or raise if it is not finite and > 0."""
    v = require_finite(name, value)
    if v <= 0.0:
        raise InvalidInputError(f"{name} must be > 0, got {value!r}")
    return v
