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

The exit code of a stopped process is ``128 + signal number``: 130 for SIGINT, 143 for
SIGTERM, 129 for SIGHUP. Without an installed handler (library use) nothing changes: Python
raises KeyboardInterrupt on SIGINT anywhere, as usual.
"""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

STOP_SIGNALS: tuple[signal.Signals, ...] = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)
)

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

    # ------------------------------------------------------------------ internals

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        if self.signum is None:
            self.signum = signum
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
    "STOP_SIGNALS",
    "InterruptGate",
    "InterruptHandler",
    "Interrupted",
    "active_handler",
    "deferred_interrupts",
    "ignore_in_child",
    "signal_name",
]
