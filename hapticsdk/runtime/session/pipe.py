"""The command pipe of a live session: the application writes pickled commands
(``multiprocessing.connection`` framing); the servo's :class:`_CommandReader` reads
them without ever blocking.

Part of :mod:`hapticsdk.runtime.session`.
"""

from __future__ import annotations

import os
import pickle
from typing import Any


def _grow_pipe(conn: Any) -> None:
    """Linux: give the command pipe 1 MiB (the default limit for an unprivileged
    process), so that a message of pickled renderers or tables (the piezo's table is
    about 300 kB) is written at once instead of as the servo drains 64 kB at a time. Elsewhere, or when refused,
    the servo's reader takes a message in as many ticks as it needs."""
    try:
        import fcntl
        fcntl.fcntl(conn.fileno(), fcntl.F_SETPIPE_SZ, 1 << 20)
    except (ImportError, AttributeError, OSError, ValueError):
        pass


class _CommandReader:
    """The servo's end of the command pipe, read without ever blocking.

    POSIX: the pipe's descriptor is made non-blocking and whatever has arrived is read
    into a buffer each call; complete messages are cut out of it with
    ``multiprocessing.connection``'s framing (a 4-byte big-endian length, or -1 and an
    8-byte length, then the pickle), so a message the application is still writing
    (larger than the pipe's atomic write) waits for the next call instead of stalling
    the servo. Elsewhere ``Connection.poll(0)`` / ``recv()``. ``eof`` turns True when
    every writer has closed the pipe (the application exited)."""

    def __init__(self, conn: Any) -> None:
        self.conn = conn
        self.fd: int | None = None
        self.buf = bytearray()
        self.eof = False
        if os.name == "posix":
            try:
                fd = conn.fileno()
                os.set_blocking(fd, False)
                self.fd = fd
            except (OSError, AttributeError, ValueError):
                self.fd = None

    def read(self) -> list:
        """The messages complete now (possibly none); never blocks."""
        if self.fd is None:
            out = []
            if not self.eof:
                try:
                    while self.conn.poll(0):
                        out.append(self.conn.recv())
                except (EOFError, OSError):
                    self.eof = True
            return out
        buf = self.buf
        while not self.eof:
            try:
                chunk = os.read(self.fd, 65536)
            except BlockingIOError:
                break
            except OSError:
                self.eof = True
                break
            if not chunk:
                self.eof = True
                break
            buf += chunk
            if len(chunk) < 65536:
                break
        msgs = []
        while len(buf) >= 4:
            n = int.from_bytes(buf[:4], "big", signed=True)
            head = 4
            if n == -1:
                if len(buf) < 12:
                    break
                n = int.from_bytes(buf[4:12], "big")
                head = 12
            if len(buf) < head + n:
                break
            msgs.append(pickle.loads(bytes(buf[head:head + n])))
            del buf[:head + n]
        return msgs
