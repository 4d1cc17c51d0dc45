"""Serve a byte stream on a TCP port, the way a serial-to-network bridge does.

``TcpServerEndpoint`` listens on ``host:port`` and behaves like one serial line: one client
at a time (a new connection replaces the old one), bytes written while nobody is connected
are dropped as they would be on an unplugged cable. Clients open it with pyserial as
``socket://host:port`` (``.path`` gives that URL). Connects and disconnects are reported to
``on_event(kind, detail)`` so a recorder can log them as link events.
"""

from __future__ import annotations

import select
import socket
import threading
import time
from collections.abc import Callable

from conform.errors import LinkError
from conform.link.endpoint import PortGone, WriteTimeout

EventHook = Callable[[str, str], None]


class TcpServerEndpoint:
    """A listening socket that reads and writes like a serial port."""

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        on_event: EventHook | None = None,
        write_timeout: float | None = 5.0,
    ) -> None:
        try:
            self._listener = socket.create_server((host, port), reuse_port=False)
        except OSError as exc:
            raise LinkError(f"tcp {host}:{port}: cannot listen: {exc.strerror or exc}") from None
        self._listener.setblocking(False)
        self.host, self.port = self._listener.getsockname()[:2]
        self._client: socket.socket | None = None
        self._peer = ""
        self._lock = threading.Lock()
        self._closed = False
        self.on_event = on_event
        self.write_timeout = write_timeout

    @property
    def path(self) -> str:
        return f"socket://{self.host}:{self.port}"

    @property
    def name(self) -> str:
        return self.path

    @property
    def connected(self) -> bool:
        return self._client is not None

    def _event(self, kind: str, detail: str) -> None:
        if self.on_event is not None:
            self.on_event(kind, detail)

    def _accept(self) -> None:
        try:
            conn, addr = self._listener.accept()
        except (BlockingIOError, InterruptedError):
            return
        conn.setblocking(False)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        with self._lock:
            old, self._client = self._client, conn
            self._peer = f"{addr[0]}:{addr[1]}"
        if old is not None:
            old.close()
            self._event("disconnect", "client replaced by a new connection")
        self._event("open", f"client {self._peer} connected to {self.path}")

    def _drop(self, why: str) -> None:
        with self._lock:
            conn, self._client = self._client, None
        if conn is not None:
            conn.close()
            self._event("disconnect", f"client {self._peer} {why}")

    def wait_client(self, timeout: float | None = None) -> bool:
        """Block until a client is connected (``True``) or ``timeout`` passes."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while self._client is None:
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                return False
            self._check_open()
            ready, _, _ = select.select([self._listener], [], [], left)
            if ready:
                self._accept()
        return True

    def _check_open(self) -> None:
        if self._closed:
            raise PortGone(f"{self.path}: server closed")

    def read(self, max_bytes: int = 4096, timeout: float | None = 0.1) -> bytes:
        """Bytes from the current client; accepts new clients while it waits."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            self._check_open()
            conn = self._client
            watch: list[socket.socket] = [self._listener] + ([conn] if conn else [])
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                ready, _, _ = select.select(watch, [], [], left)
            except (OSError, ValueError):
                self._check_open()
                continue
            if self._listener in ready:
                self._accept()
            if conn is not None and conn in ready:
                try:
                    data = conn.recv(max_bytes)
                except (BlockingIOError, InterruptedError):
                    data = None
                except OSError as exc:
                    self._drop(f"failed: {exc.strerror or exc}")
                    data = None
                if data:
                    return data
                if data == b"":
                    self._drop("disconnected")
            if deadline is not None and time.monotonic() >= deadline:
                return b""

    def write(self, data: bytes) -> None:
        """Send to the connected client; with no client the bytes go nowhere."""
        self._check_open()
        conn = self._client
        if conn is None:
            return
        view = memoryview(data)
        deadline = None if self.write_timeout is None else time.monotonic() + self.write_timeout
        while view:
            try:
                n = conn.send(view)
                view = view[n:]
                continue
            except (BlockingIOError, InterruptedError):
                pass
            except OSError as exc:
                self._drop(f"failed: {exc.strerror or exc}")
                return
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                raise WriteTimeout(f"{self.path}: client did not read in time")
            select.select([], [conn], [], left)

    def write_some(self, data: bytes) -> int:
        """Send what the socket takes now, never wait; return how many bytes were taken (all of
        them when no client is connected: they go nowhere, as on an unplugged cable)."""
        self._check_open()
        conn = self._client
        if conn is None:
            return len(data)
        try:
            return conn.send(data)
        except (BlockingIOError, InterruptedError):
            return 0
        except OSError as exc:
            self._drop(f"failed: {exc.strerror or exc}")
            return len(data)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        with self._lock:
            conn, self._client = self._client, None
        if conn is not None:
            conn.close()
        self._listener.close()

    def __enter__(self) -> TcpServerEndpoint:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"TcpServerEndpoint({self.path!r})"
