"""Servers on the loopback interface that are not Dask schedulers, for ``--dask`` addresses.

Each kind behaves as a program a user may find at an address they took for a scheduler's:
a web server (it waits for a request, then answers HTTP), a server that greets first (SSH,
SMTP), one that hangs up at once, one that sends binary bytes whose first eight read as a
huge or a small frame length (what Dask's client would allocate), one that says nothing.
:func:`server` starts one kind once per process, in a daemon thread, on a free port, and
returns its ``tcp://127.0.0.1:PORT`` address.
"""

from __future__ import annotations

import functools
import socket
import struct
import threading

__all__ = ["KINDS", "server"]

#: What each kind does with a connection: read first or not, then send these bytes (None: hang up).
_BEHAVIOUR: dict[str, tuple[bool, bytes | None]] = {
    "http": (True, b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"),
    "http-first": (False, b"HTTP/1.1 200 OK\r\nContent-Length: 2\r\n\r\nok"),
    "ssh": (False, b"SSH-2.0-OpenSSH_9.6\r\n"),
    "smtp": (False, b"220 mail.example.org ESMTP ready\r\n"),
    "hang-up": (False, None),
    "huge-frame": (False, struct.pack("<Q", 3 << 60) + bytes(64)),
    "small-frame": (False, struct.pack("<Q", 16) + b"\xff" * 16),
    "zero-frame": (False, bytes(8)),
    "short": (False, b"\x01\x02\x03"),
    "silent": (True, b""),
}
KINDS = tuple(_BEHAVIOUR)


def _serve(listener: socket.socket, read_first: bool, answer: bytes | None) -> None:
    while True:
        try:
            conn, _ = listener.accept()
        except OSError:
            return
        threading.Thread(target=_handle, args=(conn, read_first, answer), daemon=True).start()


def _handle(conn: socket.socket, read_first: bool, answer: bytes | None) -> None:
    with conn:
        try:
            conn.settimeout(30.0)
            if read_first:
                conn.recv(65536)
            if answer is None:
                return
            if answer:
                conn.sendall(answer)
            conn.recv(65536)  # keep the line open until the client hangs up
        except OSError:
            return


@functools.cache
def server(kind: str) -> str:
    """The address of a server of ``kind`` (one of :data:`KINDS`), started on first use."""
    read_first, answer = _BEHAVIOUR[kind]
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    listener.bind(("127.0.0.1", 0))
    listener.listen(16)
    threading.Thread(target=_serve, args=(listener, read_first, answer), daemon=True).start()
    return f"tcp://127.0.0.1:{listener.getsockname()[1]}"
