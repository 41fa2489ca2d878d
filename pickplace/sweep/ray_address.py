"""A Ray cluster's address, checked before the sweep starts: its form, and that a Ray
service answers there.

Valid forms: ``HOST:PORT`` of the head's GCS (e.g. ``10.0.0.5:6379``), ``ray://HOST:PORT`` of
its Ray Client server (port 10001 by default; the ``ray`` extra installs the client), and
``auto`` (the cluster this machine's ``ray start`` recorded, left to Ray).

Ray itself retries an address for many minutes, whatever answers there. Both of Ray's
services speak gRPC, over HTTP/2: such a server answers the HTTP/2 client preface with a
SETTINGS frame at once. So an address is refused (exit 2) when nothing accepts a connection
within :data:`CONNECT_TIMEOUT_S`, or when what accepts does not answer so within as long
(a web server, a database, a silent port). With ``RAY_USE_TLS`` set the services speak TLS
first, and only the connection is checked.
"""

from __future__ import annotations

import os
import socket
import time

from pickplace.errors import InvalidInputError

# Time the address gets to accept a connection, and then to answer the preface [s].
CONNECT_TIMEOUT_S = 5.0
VALID_FORMS = "HOST:PORT of the head's GCS (e.g. 10.0.0.5:6379), ray://HOST:10001 or auto"
# The HTTP/2 client connection preface (RFC 9113, 3.4), then an empty SETTINGS frame.
PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])
FRAME_HEADER_BYTES = 9
SETTINGS_FRAME = 4


def split_address(address: str) -> tuple[str, int]:
    """``(host, port)`` of ``HOST:PORT`` or ``ray://HOST:PORT`` (``[v6]:PORT`` too).

    Raises:
        InvalidInputError: Neither form (field ``address``).
    """
    hostport = address.removeprefix("ray://")
    host, sep, port = hostport.rpartition(":")
    if not sep or not host.strip("[]") or not port.isdigit() or not 0 < int(port) < 65536:
        raise InvalidInputError(
            f"'{address}' is not a Ray cluster address: give {VALID_FORMS}", field="address"
        )
    return host.strip("[]"), int(port)


def _tls() -> bool:
    return os.environ.get("RAY_USE_TLS", "0").strip().lower() not in ("", "0", "false")


def speaks_http2(sock: socket.socket, timeout_s: float) -> str | None:
    """None if the peer of ``sock`` answers the HTTP/2 preface with a SETTINGS frame within
    ``timeout_s`` [s], else what it did instead."""
    deadline = time.monotonic() + timeout_s
    try:
        sock.sendall(PREFACE)
        header = b""
        while len(header) < FRAME_HEADER_BYTES:
            left = deadline - time.monotonic()
            if left <= 0:
                return f"it gave no answer within {timeout_s:g} s"
            sock.settimeout(left)
            chunk = sock.recv(FRAME_HEADER_BYTES - len(header))
            if not chunk:
                return "it closed the connection"
            header += chunk
    except TimeoutError:
        return f"it gave no answer within {timeout_s:g} s"
    except OSError as exc:
        return f"the connection failed: {exc.strerror or exc}"
    if header[3] != SETTINGS_FRAME or int.from_bytes(header[5:9], "big") & 0x7FFFFFFF:
        return "its answer is not gRPC's"
    return None


def check_address(address: str) -> None:
    """Refuse an address that is not of a valid form, or where no Ray service answers (see
    the module docstring). ``auto`` is left to Ray.

    Raises:
        InvalidInputError: The message names the address, what happened, and the valid
            forms (field ``address``).
    """
    if address == "auto":
        return
    host, port = split_address(address)
    try:
        sock = socket.create_connection((host, port), CONNECT_TIMEOUT_S)
    except OSError as exc:
        raise InvalidInputError(
            f"no Ray cluster answers at '{address}' ({exc.strerror or exc}); start one with "
            "'ray start --head' or leave out --address for a local one",
            field="address",
        ) from None
    with sock:
        problem = None if _tls() else speaks_http2(sock, CONNECT_TIMEOUT_S)
    if problem is not None:
        raise InvalidInputError(
            f"'{address}' accepts connections but is not a Ray cluster ({problem}); give "
            f"{VALID_FORMS}",
            field="address",
        )


__all__ = ["CONNECT_TIMEOUT_S", "VALID_FORMS", "check_address", "speaks_http2", "split_address"]
