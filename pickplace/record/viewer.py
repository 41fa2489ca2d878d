"""Streaming to a Rerun viewer without ever blocking the run.

The Rerun SDK's gRPC sink can block its caller without bound (a viewer that accepts the
connection but never answers, or was stopped, makes ``disconnect`` and interpreter exit wait
for ever, Ctrl-C included; rerun-io/rerun#9909, #12620). So the run's process never opens a gRPC
connection itself. The recording stream encodes to an in-memory
:class:`rerun.BinaryStream`; each batch of bytes goes, through a pipe fed by a writer thread, to
a relay process (``python -m pickplace.record.viewer_relay URL RECORDING_ID``) that forwards it to
the viewer.
Whatever the viewer does, the run only ever appends to a queue, and the relay can always be
killed.

Bounds (all in seconds, wall time):

- Before the run: the viewer must answer an HTTP/2 handshake (gRPC runs on HTTP/2) within
  :data:`CONNECT_TIMEOUT_S`. A refused connection fails at once.
- ``--spawn`` starts ``rerun --port 9876`` (or uses a viewer already answering there) and waits
  at most :data:`SPAWN_TIMEOUT_S` for it; without a display (Linux: neither ``DISPLAY`` nor
  ``WAYLAND_DISPLAY`` set) it fails at once, and so when the viewer process exits early.
- During the run a monitor thread repeats the handshake every :data:`HEALTH_PERIOD_S`; after
  :data:`HEALTH_FAILURES` failures in a row (each at most :data:`PROBE_TIMEOUT_S`), or when
  more than :data:`MAX_PENDING_BYTES` wait for the relay, the viewer is given up: the relay is
  killed and the run goes on (its file recording is not affected). So a viewer that freezes is
  noticed within ``HEALTH_FAILURES * (HEALTH_PERIOD_S + PROBE_TIMEOUT_S)`` (4 s), one that went
  away (refused connections) within ``HEALTH_FAILURES * HEALTH_PERIOD_S`` (1 s).
- At the end the relay gets :data:`FINISH_TIMEOUT_S` to hand the rest to the viewer, then it is
  killed.
"""

from __future__ import annotations

import contextlib
import os
import queue
import re
import shutil
import signal
import socket
import ssl
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

from pickplace.errors import InvalidInputError, OutputError
from pickplace.signals import Interrupted, active_handler

CONNECT_TIMEOUT_S = 3.0
SPAWN_TIMEOUT_S = 10.0
PROBE_TIMEOUT_S = 1.5
HEALTH_PERIOD_S = 0.5
HEALTH_FAILURES = 2
FINISH_TIMEOUT_S = 5.0
MAX_PENDING_BYTES = 256 * 2**20
SCHEMES = {"rerun+http": False, "rerun+https": True, "rerun": True}  # scheme → TLS
URL_EXAMPLE = "rerun+http://127.0.0.1:9876/proxy"

# HTTP/2 client preface and an empty SETTINGS frame; a server answers with its SETTINGS frame.
_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])
# GOAWAY (last stream 0, NO_ERROR): ends the probe connection politely.
_GOAWAY = bytes([0, 0, 8, 7, 0, 0, 0, 0, 0]) + bytes(8)
_SETTINGS_FRAME = 4
LENGTH_BYTES = 8  # bytes of the length prefix of a relayed chunk of .rrd bytes (little endian)
_ANSI = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")


@dataclass(frozen=True)
class ViewerAddress:
    """Where a viewer listens.

    Attributes:
        url: The URL as given, e.g. ``rerun+http://127.0.0.1:9876/proxy``.
        host: Host name or address.
        port: TCP port.
        tls: True for ``rerun://`` and ``rerun+https://``.
    """

    url: str
    host: str
    port: int
    tls: bool


def parse_viewer_url(url: str) -> ViewerAddress:
    """Check a ``--connect`` URL: scheme ``rerun+http``, ``rerun+https`` or ``rerun`` (TLS),
    a host, and the path ``/proxy``.

    Raises:
        InvalidInputError: The URL is not of that form (the message shows one that is).
    """
    bad = f"viewer URL '{url}' must be a Rerun viewer URL such as {URL_EXAMPLE}"
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError:
        raise InvalidInputError(
            f"{bad} (its port is not a number in [1, 65535])", field="connect"
        ) from None
    if parts.scheme not in SCHEMES:
        valid = ", ".join(f"{s}://" for s in SCHEMES)
        raise InvalidInputError(f"{bad}; the scheme must be one of {valid}", field="connect")
    if not parts.hostname:
        raise InvalidInputError(f"{bad}; it names no host", field="connect")
    if parts.path != "/proxy" or parts.query or parts.fragment:
        raise InvalidInputError(f"{bad}; the path must be /proxy", field="connect")
    tls = SCHEMES[parts.scheme]
    return ViewerAddress(url, parts.hostname, port or (443 if tls else 80), tls)


def _check_stop() -> None:
    """Raise Interrupted if a stop signal arrived (waits here must not outlast Ctrl-C)."""
    handler = active_handler()
    if handler is not None and handler.signum is not None:
        raise Interrupted(handler.signum)


def viewer_problem(addr: ViewerAddress, timeout_s: float) -> str | None:
    """None if a gRPC (HTTP/2) server answers at ``addr`` within ``timeout_s`` [s], else what
    went wrong, as words that follow "the viewer at URL"."""
    deadline = time.monotonic() + timeout_s
    try:
        sock = socket.create_connection((addr.host, addr.port), timeout=timeout_s)
    except ConnectionRefusedError:
        return "refuses connections (nothing listens there; start a viewer with `rerun`)"
    except TimeoutError:
        return f"did not accept a connection within {timeout_s:g} s"
    except OSError as exc:
        return f"cannot be reached: {exc.strerror or exc}"
    try:
        if addr.tls:
            context = ssl.create_default_context()
            context.set_alpn_protocols(["h2"])
            try:
                sock = context.wrap_socket(sock, server_hostname=addr.host)
            except (ssl.SSLError, OSError) as exc:
                reason = getattr(exc, "reason", None) or exc
                return (
                    f"failed the TLS handshake ({reason}); rerun:// and rerun+https:// use "
                    "TLS, a local viewer speaks rerun+http://"
                )
        sock.settimeout(max(0.01, deadline - time.monotonic()))
        sock.sendall(_PREFACE)
        header = b""
        while len(header) < 9:
            part = sock.recv(9 - len(header))
            if not part:
                return "closed the connection without answering (not a Rerun viewer?)"
            header += part
        if header[3] != _SETTINGS_FRAME:
            return "answered, but not as a gRPC (HTTP/2) server"
        with contextlib.suppress(OSError):
            sock.sendall(_GOAWAY)
        return None
    except TimeoutError:
        return (
            f"accepted the connection but did not answer within {timeout_s:g} s "
            "(is it frozen or stopped?)"
        )
    except OSError as exc:
        return f"broke the connection: {exc.strerror or exc}"
    finally:
        sock.close()


def _has_display() -> bool:
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _rerun_executable() -> str | None:
    beside = Path(sys.executable).parent / "rerun"
    if beside.is_file() and os.access(beside, os.X_OK):
        return str(beside)
    return shutil.which("rerun")


def _last_line(log: object) -> str:
    try:
        log.seek(0)  # type: ignore[attr-defined]
        text = log.read().decode(errors="replace")  # type: ignore[attr-defined]
    except (OSError, AttributeError):
        return ""
    lines = [_ANSI.sub("", line).strip() for line in text.splitlines()]
    lines = [line for line in lines if line]
    return lines[-1][:300] if lines else ""


def _kill_group(proc: subprocess.Popen[bytes]) -> None:
    """Kill a process started with ``start_new_session`` and its children (the ``rerun``
    command is a launcher whose child is the viewer)."""
    with contextlib.suppress(OSError):
        os.killpg(proc.pid, signal.SIGKILL)
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=1.0)


def spawn_viewer(port: int, timeout_s: float = SPAWN_TIMEOUT_S) -> ViewerAddress:
    """A viewer answering on 127.0.0.1:``port``: one already there, or a new ``rerun``.

    Raises:
        OutputError: No display, no ``rerun`` executable, the viewer exited or did not answer
            within ``timeout_s`` [s].
    """
    addr = ViewerAddress(f"rerun+http://127.0.0.1:{port}/proxy", "127.0.0.1", port, False)
    if viewer_problem(addr, PROBE_TIMEOUT_S) is None:
        return addr
    if not _has_display():
        raise OutputError(
            "--spawn needs a display, and neither DISPLAY nor WAYLAND_DISPLAY is set; record "
            "with --record FILE.rrd and open it later with `rerun FILE.rrd`, or --connect to a "
            "viewer running elsewhere"
        )
    exe = _rerun_executable()
    if exe is None:
        raise OutputError("--spawn: the `rerun` viewer executable (part of rerun-sdk) is not found")
    with tempfile.TemporaryFile() as log:
        proc = subprocess.Popen(
            [exe, "--port", str(port)],
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=log,
            start_new_session=True,  # the viewer outlives the run and ignores its Ctrl-C
        )
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                _check_stop()
            except Interrupted:
                _kill_group(proc)
                raise
            code = proc.poll()
            if code is not None:
                detail = _last_line(log)
                raise OutputError(
                    f"--spawn: the viewer exited at once (code {code})"
                    + (f": {detail}" if detail else "")
                )
            if viewer_problem(addr, min(PROBE_TIMEOUT_S, 0.5)) is None:
                return addr
            time.sleep(0.1)
        _kill_group(proc)
    raise OutputError(f"--spawn: the viewer did not answer on port {port} within {timeout_s:g} s")


class ViewerRelay:
    """A relay process that forwards the recording's bytes to one viewer (module docstring).

    Args:
        addr: The viewer.
        recording_id: Recording id the viewer shows.
        connect_timeout_s: Time the viewer has to answer before the run [s].

    Raises:
        OutputError: The viewer did not answer within ``connect_timeout_s``.
    """

    def __init__(
        self,
        addr: ViewerAddress,
        recording_id: str,
        *,
        connect_timeout_s: float = CONNECT_TIMEOUT_S,
    ) -> None:
        self.addr = addr
        self.lost: str | None = None  # why the viewer was given up (set once)
        deadline = time.monotonic() + connect_timeout_s
        problem: str | None = "did not answer"
        while time.monotonic() < deadline:  # short probes, so that Ctrl-C is seen in time
            _check_stop()
            step = min(0.5, max(0.05, deadline - time.monotonic()))
            problem = viewer_problem(addr, step)
            if problem is None or "refuses" in problem or "TLS" in problem:
                break
        if problem is not None:
            if "did not answer within" in problem:
                problem = (
                    f"accepted the connection but did not answer within {connect_timeout_s:g} s "
                    "(is it frozen or stopped?)"
                )
            raise OutputError(f"the viewer at {addr.url} {problem}")
        env = dict(os.environ)
        env.setdefault("RUST_LOG", "off")
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "pickplace.record.viewer_relay", addr.url, recording_id],
            stdin=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
            start_new_session=True,  # stopped by this process only, never by a terminal's ^C
        )
        self._queue: queue.Queue[bytes | None] = queue.Queue()
        self._pending = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._writer = threading.Thread(target=self._write_loop, daemon=True)
        self._monitor = threading.Thread(target=self._monitor_loop, daemon=True)
        self._writer.start()
        self._monitor.start()

    # ------------------------------------------------------------------ feeding

    def send(self, data: bytes) -> None:
        """Queue ``data`` (a complete .rrd byte string) for the viewer; never blocks."""
        if self.lost is not None or not data:
            return
        with self._lock:
            self._pending += len(data)
            pending = self._pending
        if pending > MAX_PENDING_BYTES:
            self._lose(f"stopped taking data ({pending / 2**20:.0f} MiB waiting)")
            return
        self._queue.put(len(data).to_bytes(LENGTH_BYTES, "little") + data)

    def _write_loop(self) -> None:
        stdin = self._proc.stdin
        assert stdin is not None
        while True:
            item = self._queue.get()
            try:
                if item is None:
                    stdin.write(bytes(LENGTH_BYTES))  # length 0: the end
                    stdin.close()
                    return
                stdin.write(item)
                stdin.flush()
            except (OSError, ValueError):
                if self.lost is None and not self._stop.is_set():
                    self._lose("relay process ended")
                return
            with self._lock:
                self._pending -= len(item) - LENGTH_BYTES

    def _monitor_loop(self) -> None:
        failures = 0
        while not self._stop.wait(HEALTH_PERIOD_S):
            if self._proc.poll() is not None:
                self._lose(f"relay process ended (code {self._proc.returncode})")
                return
            problem = viewer_problem(self.addr, PROBE_TIMEOUT_S)
            failures = failures + 1 if problem is not None else 0
            if problem is not None and failures >= HEALTH_FAILURES:
                self._lose(problem)
                return

    def _lose(self, reason: str) -> None:
        if self.lost is None:
            self.lost = reason
        self._stop.set()
        self.kill()

    # ------------------------------------------------------------------ end

    def finish(self, timeout_s: float = FINISH_TIMEOUT_S) -> str | None:
        """Let the relay hand the rest to the viewer within ``timeout_s`` [s], then stop it.

        Returns:
            None if everything was handed over, else why not (the relay is killed).
        """
        if self.lost is not None:
            self.kill()
            return None
        self._stop.set()
        self._queue.put(None)
        try:
            self._proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.kill()
            return f"the viewer at {self.addr.url} did not take the rest within {timeout_s:g} s"
        return None

    def kill(self) -> None:
        """Stop the relay at once (idempotent)."""
        self._stop.set()
        if self._proc.poll() is None:
            with contextlib.suppress(OSError):
                self._proc.kill()
        with contextlib.suppress(subprocess.TimeoutExpired):
            self._proc.wait(timeout=1.0)
        if self._proc.stdin is not None:
            with contextlib.suppress(OSError, ValueError):
                self._proc.stdin.close()
