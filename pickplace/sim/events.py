"""Events: what happened at a tick of a run, for the log, the recording and the summary."""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Protocol

EVENT_LEVELS: tuple[str, ...] = ("info", "warn", "error")


class EventKind(str, enum.Enum):
    """What an event is about. A ``str`` enum: it compares equal to, and serialises as, its
    value (``"failure"``), which is what the summary's ``events[].kind`` holds."""

    KEYFRAME = "keyframe"
    """The plan passed a keyframe."""
    GRASP = "grasp"
    """The gripper closed on the brick and holds it."""
    RELEASE = "release"
    """The gripper opened and let the brick go."""
    DROP = "drop"
    """The brick left the gripper while it should be held."""
    FAULT = "fault"
    """An injected fault took effect."""
    FAILURE = "failure"
    """A check failed: the run's failure reason and its text."""
    VERDICT = "verdict"
    """The run's verdict (or that it was interrupted)."""
    PLAN = "plan"
    """What the plan could not honour (a warning at tick 0), or the chosen plan."""
    REPLAN = "replan"
    """The plan being executed was replaced: the stop after a failed attempt, or the next
    attempt's plan (:mod:`pickplace.sim.recovery`)."""
    SENSOR = "sensor"
    """A contact sensor saw more contacts than it reports."""
    MUJOCO_WARNING = "mujoco-warning"
    """MuJoCo warned while composing or simulating."""
    VIEWER = "viewer"
    """A live viewer stopped answering or went away."""


@dataclass(frozen=True)
class Event:
    """Something that happened at a tick: keyframe reached, grasp closed, drop, verdict.

    Attributes:
        tick: Control tick index k.
        t: Simulated time at the start of the tick, k · dt [s].
        level: One of :data:`EVENT_LEVELS`.
        kind: What it is about.
        text: One line for a person.
    """

    tick: int
    t: float
    level: str
    kind: EventKind
    text: str


class Emit(Protocol):
    """Records an event at ``tick`` (the run's current tick when omitted)."""

    def __call__(
        self, kind: EventKind, text: str, level: str = "info", tick: int | None = None
    ) -> None:
        """Record the event."""
