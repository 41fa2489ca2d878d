"""The viewer relay process: what :class:`pickplace.record.viewer.ViewerRelay` starts.

It reads .rrd byte strings from stdin and forwards them to a Rerun viewer, so the run's own
process never holds a gRPC connection that could block it. Separate from
:mod:`pickplace.record.viewer` because it needs the recording's blueprint, and the recorder needs
the
viewer module.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import tempfile
import threading
from pathlib import Path

import rerun as rr
from rerun.chunk import RrdReader

from pickplace.record.blueprint import build_blueprint
from pickplace.record.recording import APPLICATION_ID
from pickplace.record.viewer import FINISH_TIMEOUT_S, LENGTH_BYTES


def _read_exact(stream: object, n: int) -> bytes:
    out = bytearray()
    while len(out) < n:
        part = stream.read(n - len(out))  # type: ignore[attr-defined]
        if not part:
            break
        out += part
    return bytes(out)


def relay_main(argv: list[str]) -> int:
    """``python -m pickplace.record.viewer_relay URL RECORDING_ID``: .rrd byte strings, each
    prefixed
    by its length (8 bytes, little endian; length 0 ends), from stdin to the viewer at URL."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides when the relay stops
    url, recording_id = argv
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
    rec.set_sinks(rr.GrpcSink(url), default_blueprint=build_blueprint())
    stdin = sys.stdin.buffer
    with tempfile.TemporaryDirectory(prefix="pickplace-relay-") as folder:
        segment = Path(folder) / "segment.rrd"
        while True:
            header = _read_exact(stdin, LENGTH_BYTES)
            n = int.from_bytes(header, "little") if len(header) == LENGTH_BYTES else 0
            if n == 0:
                break
            segment.write_bytes(_read_exact(stdin, n))
            rec.send_chunks(RrdReader(segment).stream())
            segment.unlink()
    # The parent stops waiting after FINISH_TIMEOUT_S; never outlive it (e.g. if it died).
    timer = threading.Timer(FINISH_TIMEOUT_S, os._exit, args=(1,))
    timer.daemon = True
    timer.start()
    with contextlib.suppress(RuntimeError):
        rec.flush(timeout_sec=FINISH_TIMEOUT_S)
    rec.disconnect()
    return 0


if __name__ == "__main__":
    os._exit(relay_main(sys.argv[1:]))  # skip exit hooks: everything is flushed above
