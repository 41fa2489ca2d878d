"""Stop requests: SIGINT (Ctrl-C), SIGTERM and SIGHUP all stop a run the same way.

:class:`Simulation.run <pickplace.sim.loop.Simulation.run>` turns a :class:`KeyboardInterrupt`
raised during the loop into the failure ``interrupted`` and still finishes the recording. This
module makes the other stop signals (what ``timeout``, ``docker stop`` and CI cancellation send,
or a closed terminal) do exactly that, and makes sure the interrupt only lands where it can be
handled:

- Before :meth:`InterruptHandler.arm` (imports, scene loading, validation, opening the
  recording) a signal is only noted; it is delivered as soon as the run is armed, which
  :class:`InterruptGate` does at the end of the first block of ticks, inside the loop. So an
  early Ctrl-C still gives a summary and a complete recording, never a traceback.
- Code inside :func:`deferred_interrupts` (sending a batch to the recording) is never cut in
  the middle: a signal there is delivered when the block ends.
- Only the first signal is delivered; later ones are noted and ignored while the run finishes
  (which is bounded: see ``pickplace.record.recording``).
- Long set-up work (planning: candidates, pre-flights) calls :func:`stop_point` as it goes. A
  signal noted before the run is armed is kept for the run's first block, unless the work is
  still going :data:`SETUP_STOP_WAIT_S` after both the signal and its own first stop point:
  then the stop point raises it. A set-up of normal length is never cut (the run still ends
  with a summary); a long planning stops within about that time of the signal.

The exit code of a stopped process is ``128 + signal number``: 130 for SIGINT, 143 for
SIGTERM, 129 for SIGHUP. Without an installed handler (library use) nothing changes: Python
raises KeyboardInterrupt on SIGINT anywhere, as usual.
"""

from __future__ import annotations

import signal
import time
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

STOP_SIGNALS: tuple[signal.Signals, ...] = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)
)

# How long a stop request noted before the run starts waits for it, once set-up work that
# checks for it (planning) has gone on as long [s]: far more than a normal planning takes
# (0.1–1 s), and well within the 2 s a stop may take.
SETUP_STOP_WAIT_S = 1.0

_active: InterruptHandler | None = None


class Interrupted(KeyboardInterrupt):
    """A stop signal delivered as a KeyboardInterrupt (so ``Simulation.run`` handles it).

    Attributes:
        signum: The signal's number.
    """

    def __init__(self, signum: int) -> None:
        super().__init__(signal_name(signum))
        self.signum = signum


def signal_name(signum: int) -> str:
    """``SIGTERM`` for 15, and so on."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


class InterruptHandler:
    """Handler of :data:`STOP_SIGNALS` in the main thread (see the module docstring).

    Attributes:
        signum: The first stop signal received, or None.
    """

    def __init__(self) -> None:
        self.signum: int | None = None
        self._noted_at: float | None = None  # time.monotonic() of the first signal [s]
        self._work_since: float | None = None  # of the first stop point [s]
        self._armed = False
        self._delivered = False
        self._depth = 0
        self._previous: dict[int, Any] = {}

    # ------------------------------------------------------------------ installation

    def install(self) -> InterruptHandler:
        """Handle the stop signals from now on (main thread only); return self."""
        global _active
        for sig in STOP_SIGNALS:
            self._previous[sig] = signal.signal(sig, self._on_signal)
        _active = self
        return self

    def uninstall(self) -> None:
        """Restore the handlers that were there before :meth:`install`."""
        global _active
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)
        self._previous.clear()
        if _active is self:
            _active = None

    def retire(self) -> None:
        """Ignore the stop signals from now on, in place of this handler: for a process whose
        work is done and that only exits (restoring the default action would let a late
        signal kill it in the middle of its exit, after its output said how it ended)."""
        global _active
        for sig in STOP_SIGNALS:
            signal.signal(sig, signal.SIG_IGN)
        self._previous.clear()
        if _active is self:
            _active = None

    # ------------------------------------------------------------------ state

    @property
    def interrupted(self) -> bool:
        """True once a stop signal has been received (delivered or not)."""
        return self.signum is not None

    @property
    def exit_code(self) -> int:
        """``128 + signum`` of the first signal (130 for SIGINT)."""
        return 128 + (self.signum if self.signum is not None else int(signal.SIGINT))

    def arm(self) -> None:
        """Deliver signals from now on; one noted earlier is delivered at once."""
        self._armed = True
        self._deliver_pending()

    def disarm(self) -> None:
        """Only note signals from now on (while a run finishes)."""
        self._armed = False

    @contextmanager
    def deferred(self) -> Iterator[None]:
        """A block that a signal does not cut: it is delivered when the block ends."""
        self._depth += 1
        try:
            yield
        except BaseException:
            self._depth -= 1
            raise
        self._depth -= 1
        self._deliver_pending()

    def stop_point(self) -> None:
        """A point where long set-up work may be cut short (see the module docstring).

        Raises:
            Interrupted: A stop request has waited :data:`SETUP_STOP_WAIT_S` since both it
                arrived and the first stop point; it counts as delivered.
        """
        now = time.monotonic()
        if self._work_since is None:
            self._work_since = now
        if self._armed or self._delivered or self.signum is None or self._noted_at is None:
            return
        if now - max(self._noted_at, self._work_since) >= SETUP_STOP_WAIT_S:
            self._delivered = True
            raise Interrupted(self.signum)

    # ------------------------------------------------------------------ internals

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        if self.signum is None:
            self.signum = signum
            self._noted_at = time.monotonic()
        self._deliver_pending()

    def _deliver_pending(self) -> None:
        if self._armed and self._depth == 0 and self.signum is not None and not self._delivered:
            self._delivered = True
            raise Interrupted(self.signum)


def active_handler() -> InterruptHandler | None:
    """The installed handler, if any."""
    return _active


@contextmanager
def deferred_interrupts() -> Iterator[None]:
    """:meth:`InterruptHandler.deferred` of the installed handler; a no-op without one."""
    if _active is None:
        yield
    else:
        with _active.deferred():
            yield


def stop_point() -> None:
    """:meth:`InterruptHandler.stop_point` of the installed handler; a no-op without one
    (library use, sweep workers)."""
    if _active is not None:
        _active.stop_point()


def ignore_in_child() -> None:
    """In a worker process: ignore SIGINT (the parent decides when to stop), default
    action for the other stop signals, and forget the parent's handler."""
    global _active
    _active = None
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN if sig == signal.SIGINT else signal.SIG_DFL)


class InterruptGate:
    """Observer that arms ``handler`` once the loop runs and disarms it when the run ends.

    Put it first in the observer list: its :meth:`on_ticks` runs at the end of the first block,
    inside the loop, where an interrupt ends the run with a summary.
    """

    def __init__(self, handler: InterruptHandler) -> None:
        self.handler = handler

    def on_start(self, run: Any) -> None:
        return None

    def on_ticks(self, run: Any, start: int, end: int) -> None:
        self.handler.arm()

    def on_event(self, run: Any, event: Any) -> None:
        return None

    def on_finish(self, run: Any, result: Any) -> None:
        self.handler.disarm()


__all__ = [
    "SETUP_STOP_WAIT_S",
    "STOP_SIGNALS",
    "InterruptGate",
    "InterruptHandler",
    "Interrupted",
    "active_handler",
    "deferred_interrupts",
    "ignore_in_child",
    "signal_name",
    "stop_point",
]
