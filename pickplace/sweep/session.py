"""The processes of a session: find them, and end them all.

A process started with ``start_new_session`` leads a session of its own, and everything it
starts stays in it (a Ray worker gets a process group of its own, but not a session), also
once reparented when its parent died; only ``setsid`` leaves it. So a session's id names
every process a child started, however deep, and nothing else: the Ray backend
(:mod:`pickplace.sweep.ray_backend`) ends its driver's session this way, the local cluster's
processes (GCS, raylet, agents, workers) included. Found through ``/proc`` (Linux); elsewhere
only the session leader's process group is reached.
"""

from __future__ import annotations

import contextlib
import os
import signal
import time
from pathlib import Path

PROC = Path("/proc")
POLL_S = 0.01  # how often a wait looks again [s]


def members(sid: int) -> list[int]:
    """The live processes of session ``sid`` (zombies, already dead, are left out).

    Without ``/proc``: the session leader's process group, as far as ``os.killpg`` shows.
    """
    if not PROC.is_dir():
        try:
            os.killpg(sid, 0)
        except OSError:
            return []
        return [sid]
    found = []
    for entry in PROC.iterdir():
        if not entry.name.isdigit():
            continue
        with contextlib.suppress(OSError, IndexError, ValueError):
            # Fields after the command name (which may hold spaces and parentheses):
            # state, ppid, pgrp, session, ...
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            if int(fields[3]) == sid and fields[0] != "Z":
                found.append(int(entry.name))
    return found


def end_session(sid: int, timeout_s: float = 2.0) -> list[int]:
    """Kill (SIGKILL) every process of session ``sid`` and wait until they are gone.

    Args:
        sid: The session's id (its leader's process id).
        timeout_s: How long to wait for them to go [s]; SIGKILL is repeated meanwhile, for
            processes started while the first one was sent.

    Returns:
        The processes still there after ``timeout_s`` (none in practice: SIGKILL cannot be
        caught; a process in uninterruptible sleep goes when the kernel lets it).
    """
    deadline = time.monotonic() + timeout_s
    while True:
        alive = members(sid)
        if not alive or time.monotonic() >= deadline:
            return alive
        for pid in alive:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
        if not PROC.is_dir():
            with contextlib.suppress(OSError):
                os.killpg(sid, signal.SIGKILL)
        time.sleep(POLL_S)


__all__ = ["end_session", "members"]
