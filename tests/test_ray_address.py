"""Checking a Ray cluster's address without Ray: its form, and that a gRPC server answers."""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Callable, Iterator

import pytest

from pickplace.errors import InvalidInputError
from pickplace.sweep.ray_address import PREFACE, check_address, speaks_http2, split_address


@contextlib.contextmanager
def server(reply: Callable[[socket.socket], None]) -> Iterator[int]:
    """A TCP server on 127.0.0.1 that calls ``reply`` on each connection; yields its port."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    held: list[socket.socket] = []

    def loop() -> None:
        with contextlib.suppress(OSError):
            while True:
                conn = srv.accept()[0]
                held.append(conn)
                reply(conn)

    threading.Thread(target=loop, daemon=True).start()
    try:
        yield int(srv.getsockname()[1])
    finally:
        srv.close()
        for conn in held:
            conn.close()


def grpc_like(conn: socket.socket) -> None:
    """What a gRPC server does: read the preface, answer with an empty SETTINGS frame."""
    got = b""
    while len(got) < len(PREFACE):
        got += conn.recv(len(PREFACE) - len(got))
    assert got == PREFACE
    conn.sendall(bytes([0, 0, 0, 4, 0, 0, 0, 0, 0]))


def web(conn: socket.socket) -> None:
    conn.sendall(b"HTTP/1.0 400 Bad Request\r\n\r\n")


def closes(conn: socket.socket) -> None:
    """Reads the preface and closes (unread data would make the close a reset)."""
    got = b""
    while len(got) < len(PREFACE):
        got += conn.recv(len(PREFACE) - len(got))
    conn.close()


def test_a_grpc_server_passes() -> None:
    with server(grpc_like) as port:
        check_address(f"127.0.0.1:{port}")
        check_address(f"ray://127.0.0.1:{port}")


@pytest.mark.parametrize(
    ("reply", "problem"),
    [(web, "its answer is not gRPC's"), (closes, "closed the connection")],
    ids=["web", "closes"],
)
def test_what_is_not_grpc_is_refused_naming_the_address_and_the_valid_forms(
    reply: Callable[[socket.socket], None], problem: str
) -> None:
    with server(reply) as port, pytest.raises(InvalidInputError) as caught:
        check_address(f"127.0.0.1:{port}")
    text = str(caught.value)
    assert f"'127.0.0.1:{port}' accepts connections but is not a Ray cluster" in text
    assert problem in text and "ray://HOST:10001 or auto" in text
    assert caught.value.field == "address"


def test_silence_is_refused_after_the_time_limit() -> None:
    with server(lambda conn: None) as port, socket.create_connection(("127.0.0.1", port)) as s:
        assert speaks_http2(s, 0.2) == "it gave no answer within 0.2 s"


def test_nothing_listening_is_refused() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # bound, not listening: connections are refused
        with pytest.raises(InvalidInputError, match="no Ray cluster answers"):
            check_address(f"127.0.0.1:{port}")


@pytest.mark.parametrize("address", ["localhost", "ray://", "h:0", "h:99999", ":6379", "h:x"])
def test_malformed_addresses_are_refused(address: str) -> None:
    with pytest.raises(InvalidInputError, match="is not a Ray cluster address"):
        split_address(address)


def test_forms() -> None:
    assert split_address("10.0.0.5:6379") == ("10.0.0.5", 6379)
    assert split_address("ray://head:10001") == ("head", 10001)
    assert split_address("[::1]:6379") == ("::1", 6379)
    check_address("auto")  # left to Ray
