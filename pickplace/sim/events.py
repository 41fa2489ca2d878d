"""Events: what happened at a tick of a run, for the log, the recording and the summary."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

EVENT_LEVELS: tuple[str, ...] = ("info", "warn", "error")


@dataclass(frozen=True)
class Event:
    """Something that happened at a tick: keyframe reached, grasp closed, drop, verdict.

    Attributes:
        tick: Control tick index k.
        t: Simulated time at the start of the tick, k · dt [s].
        level: One of :data:`EVENT_LEVELS`.
        kind: Short category, e.g. ``"grasp"``, ``"fault"``, ``"failure"``, ``"verdict"``.
        text: One line for a person.
    """

    tick: int
    t: float
    level: str
    kind: str
    text: str


class Emit(Protocol):
    """Records an event at ``tick`` (the run's current tick when omitted)."""

    def __call__(self, kind: str, text: str, level: str = "info", tick: int | None = None) -> None:
        """Record the event."""
