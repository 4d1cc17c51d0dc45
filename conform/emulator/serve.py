"""Serve the reference unit on a real byte stream (a pty or TCP) on wall-clock time.

The thin I/O adapter around any family's sans-I/O unit (:class:`SansIOUnit`): it reads what
the host writes, hands it to the unit with the time it arrived, and writes the unit's answers
when they are due. Options add wire pacing (``baud``: 10 bits per byte, both directions), fault
injection (:mod:`conform.link.faults`), a recording (:class:`conform.capture.Recorder`) and a
control socket to change inputs while it runs (:mod:`conform.emulator.control`; the requests
are the family's ``control_handler`` hook).

What is recorded is what crosses the emulator's port: ``host`` chunks as read from it,
``unit`` chunks as written to it (after faults), plus link events for injected disconnects.
"""

from __future__ import annotations

import os
import queue
import socket
import stat
import tempfile
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol

from conform.emulator.control import ControlHandler, no_commands
from conform.errors import LinkError, UserError
from conform.link.endpoint import Endpoint, PortGone
from conform.link.faults import FaultInjector

MAX_WAIT = 0.02  # the loop wakes at least this often (control commands, stop requests)


class SansIOUnit(Protocol):
    """What the emulator needs from a family's unit: bytes and a time in, bytes out when due.
    Inputs (buttons, limit switches) are the family's: its ``control_handler`` hook drives them."""

    @property
    def now(self) -> float:
        """The unit's clock (the last time it was given)."""

    def receive(self, data: bytes, t: float) -> None:
        """Bytes from the host that arrived at ``t``."""

    def poll(self, t: float) -> list[tuple[float, bytes]]:
        """Everything due by ``t``: (due time, bytes to the host)."""

    def next_deadline(self) -> float | None:
        """When the unit next has something to do (None: only when bytes arrive)."""


class ControlRequests(Protocol):
    """Where an emulator's loop takes its control requests: (line, queue for the reply)."""

    requests: queue.SimpleQueue[tuple[str, queue.SimpleQueue[str]]]


class ControlServer:
    """A unix socket that accepts one-line control requests (see conform.emulator.control).

    Requests are queued for the serving loop, which owns the unit; the connection thread
    waits for the reply. The socket is made mode 0600 inside a fresh 0700 directory (whatever
    the umask), so only its owner can press a button; with ``path`` it is then linked to that
    name, which must not exist (a socket nobody listens on, left by an emulator that died, is
    replaced; anything else is refused).
    """

    def __init__(self, path: str | None = None) -> None:
        parent = os.path.dirname(os.path.abspath(path)) if path is not None else None
        self._dir = tempfile.mkdtemp(prefix=".conform-emu-" if parent else "conform-emu-",
                                     dir=parent)
        self._private = os.path.join(self._dir, "control.sock")
        self._linked: tuple[int, int] | None = None
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            os.chmod(self._dir, 0o700)
            self._sock.bind(self._private)
            os.chmod(self._private, 0o600)
            if path is not None:
                _claim(path, self._private)
                st = os.stat(path)
                self._linked = (st.st_dev, st.st_ino)
            self._sock.listen(8)
        except BaseException:
            self._sock.close()
            self._remove_private()
            raise
        self.path = path if path is not None else self._private
        self.requests: queue.SimpleQueue[tuple[str, queue.SimpleQueue[str]]] = queue.SimpleQueue()
        self._sock.settimeout(0.2)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="emulator-control", daemon=True)
        self._thread.start()

    def _remove_private(self) -> None:
        for remove, name in ((os.unlink, self._private), (os.rmdir, self._dir)):
            try:
                remove(name)
            except OSError:
                pass

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            threading.Thread(target=self._handle, args=(conn,), daemon=True).start()

    def _handle(self, conn: socket.socket) -> None:
        with conn:
            conn.settimeout(5.0)
            buf = b""
            try:
                while b"\n" not in buf:
                    chunk = conn.recv(4096)
                    if not chunk:
                        break
                    buf += chunk
                reply_q: queue.SimpleQueue[str] = queue.SimpleQueue()
                self.requests.put((buf.decode(errors="replace").strip(), reply_q))
                try:
                    reply = reply_q.get(timeout=5.0)
                except queue.Empty:
                    reply = "error: the emulator did not answer"
                conn.sendall(reply.encode() + b"\n")
            except OSError:
                pass

    def close(self) -> None:
        self._stop.set()
        try:
            self._sock.close()
        finally:
            if self._linked is not None:  # remove our name, not what may have replaced it
                try:
                    st = os.lstat(self.path)
                    if (st.st_dev, st.st_ino) == self._linked:
                        os.unlink(self.path)
                except OSError:
                    pass
            self._remove_private()


def _claim(path: str, private: str) -> None:
    """Give the socket at ``private`` the name ``path`` without replacing anything of the
    user's; a leftover socket nobody listens on is the only thing replaced."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        st = None
    if st is not None:
        if not stat.S_ISSOCK(st.st_mode):
            raise UserError(f"--control {path}: exists and is not a socket; not replacing it")
        probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            probe.settimeout(1.0)
            probe.connect(path)
        except OSError:
            os.unlink(path)  # stale: its emulator is gone
        else:
            raise UserError(f"--control {path}: another process is listening on it")
        finally:
            probe.close()
    try:
        os.link(private, path)
    except FileExistsError:
        raise UserError(f"--control {path}: exists (created meanwhile); not replacing it") from None


class Emulator:
    """Run ``unit`` behind ``endpoint`` until :meth:`stop` (or a signal handler) is called.

    ``control_handler`` answers the requests of ``control`` (the family's control commands);
    ``reopen`` builds a fresh endpoint after an injected disconnect (pty: same symlink;
    TCP: same port); ``report`` receives one-line notices (new device paths, link events).
    """

    def __init__(
        self,
        unit: SansIOUnit,
        endpoint: Endpoint,
        *,
        baud: int | None = None,
        injector: FaultInjector | None = None,
        recorder: Any = None,
        control: ControlRequests | None = None,
        reopen: Callable[[], Endpoint] | None = None,
        report: Callable[[str], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        control_handler: ControlHandler | None = None,
    ) -> None:
        self.unit = unit
        self.control_handler: ControlHandler = control_handler or no_commands
        self.endpoint = endpoint
        self.bit_time = 10.0 / baud if baud else 0.0
        self.injector = injector
        self.recorder = recorder
        self.control = control
        self.reopen = reopen
        self.report = report or (lambda _msg: None)
        self.clock = clock
        self.sleep = sleep
        self._incoming: list[tuple[float, bytes]] = []
        self._outgoing: list[tuple[float, bytes]] = []
        self._rx_free = self._tx_free = 0.0
        self._down_until: float | None = None
        self._stop = threading.Event()
        self.bytes_in = self.bytes_out = 0
        self.bytes_dropped = 0  # answer bytes the host did not read in time
        self._dropping = 0

    def stop(self) -> None:
        self._stop.set()

    @property
    def stopping(self) -> bool:
        return self._stop.is_set()

    def run(self) -> None:
        """Serve until stopped; always closes the endpoint."""
        try:
            while not self._stop.is_set():
                self.step()
        finally:
            self.endpoint.close()

    # ------------------------------------------------------------------------------------
    def step(self) -> None:
        """One round: read, deliver, run control requests, collect and write answers."""
        now = self.clock()
        if self.injector is not None and self.injector.disconnect_due(now):
            self._disconnect(now)
        if self._down_until is not None:
            self._while_down(now)
            return
        timeout = self._wait(now)
        try:
            data = self.endpoint.read(4096, timeout)
        except PortGone as exc:
            self.report(f"port gone: {exc}")
            self._link_event("close", str(exc))
            self._stop.set()
            return
        now = self.clock()
        if data:
            self.bytes_in += len(data)
            if self.recorder is not None:
                self.recorder.chunk("host", data)
            self._schedule_in(data, now)
        self._deliver(now)
        self._run_control(now)
        self._collect(now)
        self._write_due(self.clock())

    def _wait(self, now: float) -> float:
        wake = now + MAX_WAIT
        nd = self.unit.next_deadline()
        for t in (nd, self._incoming[0][0] if self._incoming else None,
                  self._outgoing[0][0] if self._outgoing else None):
            if t is not None and t < wake:
                wake = t
        return max(0.0, wake - now)

    def _schedule_in(self, data: bytes, now: float) -> None:
        deliveries = self.injector.feed("host", data, now) if self.injector else [(now, data)]
        for t, chunk in deliveries:
            if self.bit_time:
                t = max(t, self._rx_free) + len(chunk) * self.bit_time
                self._rx_free = t
            self._incoming.append((t, chunk))

    def _deliver(self, now: float) -> None:
        while self._incoming and self._incoming[0][0] <= now:
            t, chunk = self._incoming.pop(0)
            self.unit.receive(chunk, t)

    def _collect(self, now: float) -> None:
        for due, data in self.unit.poll(now):
            deliveries = self.injector.feed("unit", data, due) if self.injector else [(due, data)]
            for t, chunk in deliveries:
                if self.bit_time:
                    t = max(t, self._tx_free) + len(chunk) * self.bit_time
                    self._tx_free = t
                self._outgoing.append((t, chunk))

    def _write_due(self, now: float) -> None:
        while self._outgoing and self._outgoing[0][0] <= now:
            _, chunk = self._outgoing.pop(0)
            try:
                n = self._write(chunk)
            except PortGone as exc:
                self.report(f"port gone: {exc}")
                self._stop.set()
                return
            except (OSError, LinkError) as exc:
                self.report(f"answer dropped: {exc}")
                continue
            self._count_dropped(len(chunk) - n)
            if n:
                self.bytes_out += n
                if self.recorder is not None:
                    self.recorder.chunk("unit", chunk[:n])

    def _write(self, chunk: bytes) -> int:
        """Write without waiting where the endpoint can: a UART has no flow control, so what
        the host does not read is lost and the unit goes on serving."""
        write_some = getattr(self.endpoint, "write_some", None)
        if write_some is None:
            self.endpoint.write(chunk)
            return len(chunk)
        return write_some(chunk)

    def _count_dropped(self, lost: int) -> None:
        if lost > 0:
            if not self._dropping:
                self.report("the host does not read: answers are lost until it does")
            self._dropping += lost
            self.bytes_dropped += lost
        elif self._dropping:
            self.report(f"the host reads again ({self._dropping} bytes were lost)")
            self._dropping = 0

    def _run_control(self, now: float) -> None:
        if self.control is None:
            return
        while True:
            try:
                line, reply_q = self.control.requests.get_nowait()
            except queue.Empty:
                return
            reply_q.put(self.control_handler(self.unit, line, max(now, self.unit.now)))

    # injected disconnects -----------------------------------------------------------------
    def _disconnect(self, now: float) -> None:
        assert self.injector is not None
        self._down_until = self.injector.down_until
        self._incoming.clear()
        self._outgoing.clear()
        self._link_event("disconnect", "fault injection: link dropped")
        self.report(f"fault: link down for {self.injector.config.downtime:g} s")
        if self.reopen is not None:
            unplug = getattr(self.endpoint, "unplug", None)   # a pty: keeps its number
            (unplug or self.endpoint.close)()

    def _while_down(self, now: float) -> None:
        self._run_control(now)
        self.unit.poll(now)  # answers produced while the link is down are lost
        assert self._down_until is not None
        if now < self._down_until:
            self.sleep(min(MAX_WAIT, self._down_until - now))
            return
        self._down_until = None
        if self.reopen is not None:
            self.endpoint = self.reopen()
            self.report(f"link up again: {self.endpoint.name}")
        self._link_event("reconnect", "fault injection: link restored")

    def _link_event(self, kind: str, detail: str) -> None:
        if self.recorder is not None:
            try:
                self.recorder.link_event(kind, detail, side="unit")
            except (ValueError, OSError):
                pass
