"""Real serial ports and anything pyserial opens by URL, behind the ``Endpoint`` interface.

``open_port("/dev/ttyUSB0", 115200)``, ``open_port("socket://127.0.0.1:7000")``,
``open_port("loop://")`` or the path of an emulator's pty all give a ``SerialEndpoint``.
The port is opened non-blocking (pyserial ``timeout=0``) and ``read`` waits with ``select``
on the port's descriptor, so a read returns the moment bytes arrive rather than when a
buffer fills: that is what keeps the proxy's added latency low and sniffer timestamps close
to the wire.
"""

from __future__ import annotations

import os
import select
import stat
import time
from collections.abc import Iterator
from contextlib import contextmanager

import serial

from conform.errors import LinkError
from conform.link.endpoint import PortGone, WriteTimeout

try:
    from termios import error as _TermiosError
except ImportError:                     # no termios (Windows): pyserial raises SerialException
    class _TermiosError(Exception):     # type: ignore[no-redef]
        pass


# What opening a port can raise. pyserial lets termios.error (not an OSError) through when the
# line hangs up between opening the device and flushing it: a USB adapter pulled, or an
# emulator's pty dropping its line, at that moment.
OPEN_ERRORS: tuple[type[Exception], ...] = (serial.SerialException, ValueError, OSError, _TermiosError)


class SerialEndpoint:
    """A pyserial port with ``read(max, timeout)`` that returns as soon as bytes arrive."""

    def __init__(self, port: serial.SerialBase, url: str, timeout: float | None = 0.1) -> None:
        self._port = port
        self.url = url
        self.timeout = timeout
        try:
            self._fd: int | None = port.fileno()
        except (AttributeError, NotImplementedError, OSError, serial.SerialException):
            self._fd = None

    @property
    def name(self) -> str:
        return self.url

    @property
    def path(self) -> str:
        return self.url

    @property
    def baud(self) -> int:
        return int(self._port.baudrate)

    @property
    def serial(self) -> serial.SerialBase:
        """The underlying pyserial object (modem lines, break, buffers)."""
        return self._port

    @property
    def closed(self) -> bool:
        return not self._port.is_open

    def set_baud(self, baud: int) -> None:
        try:
            self._port.baudrate = baud
        except (ValueError, serial.SerialException) as exc:
            raise LinkError(f"{self.url}: cannot set baud {baud}: {exc}") from None

    def read(self, max_bytes: int = 4096, timeout: float | None = -1.0) -> bytes:
        """Up to ``max_bytes`` as soon as any arrive; a negative ``timeout`` means the default."""
        if timeout is not None and timeout < 0:
            timeout = self.timeout
        if not self._port.is_open:
            raise PortGone(f"{self.url}: port is closed")
        try:
            if self._fd is not None:
                ready, _, _ = select.select([self._fd], [], [], timeout)
                if not ready:
                    return b""
                return self._port.read(max_bytes)
            return self._poll_read(max_bytes, timeout)
        except serial.SerialException as exc:
            raise PortGone(f"{self.url}: {exc}") from None
        except (OSError, ValueError, TypeError) as exc:
            if not self._port.is_open:
                raise PortGone(f"{self.url}: port closed") from None
            raise PortGone(f"{self.url}: {exc}") from None

    def _poll_read(self, max_bytes: int, timeout: float | None) -> bytes:
        """For URL handlers without a descriptor (``loop://``, ``spy://``...)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            waiting = self._port.in_waiting
            if waiting:
                return self._port.read(min(waiting, max_bytes))
            if deadline is not None and time.monotonic() >= deadline:
                return b""
            time.sleep(0.0005)

    def write(self, data: bytes) -> None:
        if not self._port.is_open:
            raise PortGone(f"{self.url}: port is closed")
        try:
            self._port.write(data)
        except serial.SerialTimeoutException:
            raise WriteTimeout(f"{self.url}: write timed out") from None
        except serial.SerialException as exc:
            raise PortGone(f"{self.url}: {exc}") from None
        except (OSError, ValueError, TypeError) as exc:
            raise PortGone(f"{self.url}: {exc}") from None

    def close(self) -> None:
        try:
            self._port.close()
        except (OSError, serial.SerialException):
            pass

    def __enter__(self) -> SerialEndpoint:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"SerialEndpoint({self.url!r})"


def open_port(
    url: str, baud: int = 115200, timeout: float | None = 0.1, *, write_timeout: float | None = 5.0
) -> SerialEndpoint:
    """Open a device path or any pyserial URL, 8N1 at ``baud``.

    ``timeout`` is the default wait of ``read`` when none is passed per call. Failure is a
    ``LinkError`` naming the port, never a traceback.
    """
    if not url:
        raise LinkError("no port given")
    if (url, baud) in _HELD:
        return _held(url, baud, timeout, write_timeout)
    return _open(url, baud, timeout, write_timeout)


def _open(url: str, baud: int, timeout: float | None, write_timeout: float | None
          ) -> SerialEndpoint:
    try:
        port = serial.serial_for_url(
            url,
            baudrate=baud,
            bytesize=serial.EIGHTBITS,
            parity=serial.PARITY_NONE,
            stopbits=serial.STOPBITS_ONE,
            timeout=0,
            write_timeout=write_timeout,
            do_not_open=True,
        )
        port.open()
    except OPEN_ERRORS as exc:
        raise LinkError(f"{url}: cannot open: {_one_line(exc)}") from None
    return SerialEndpoint(port, url, timeout)


_PTY_MAJORS = range(136, 144)   # Unix98 pty slaves (the kernel's devices.txt)


def _is_pty(path: str) -> bool:
    """Whether ``path`` is a pty's device node itself (not a symlink to one)."""
    try:
        st = os.lstat(path)
    except OSError:
        return False
    return stat.S_ISCHR(st.st_mode) and os.major(st.st_rdev) in _PTY_MAJORS


class Reopener:
    """Opens ``url`` now and again after the port was lost (``--reconnect``).

    The kernel gives a closed pty's number to the next pty anyone opens, so a pty's device
    path /dev/pts/N opened again after its pty went away would reach another program's port.
    While a reopener lives it holds the first pty it opened (a descriptor it never reads), so
    the number cannot pass on: once that pty is gone the path stays gone. A symlink, the
    stable name made again for each new pty, is followed as it points.
    """

    def __init__(self, url: str, baud: int) -> None:
        self.url = url
        self.baud = baud
        self._hold: int | None = None
        self._first = True

    def __call__(self) -> SerialEndpoint:
        port = open_port(self.url, self.baud)
        if self._first:
            self._first = False
            if _is_pty(self.url):
                try:
                    self._hold = os.open(self.url, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
                except OSError:
                    pass
        return port

    def close(self) -> None:
        """Let the pty's number go (at the end of the run that reopens it)."""
        hold, self._hold = self._hold, None
        if hold is not None:
            os.close(hold)


_HELD: dict[tuple[str, int], SerialEndpoint | None] = {}


class _Borrowed(SerialEndpoint):
    """The held port as one caller sees it: its own default read timeout; closing it leaves
    the port open for the next caller."""

    def close(self) -> None:
        pass


def _held(url: str, baud: int, timeout: float | None, write_timeout: float | None
          ) -> SerialEndpoint:
    first = _HELD[(url, baud)]
    if first is None or first.closed:
        first = _HELD[(url, baud)] = _open(url, baud, timeout, write_timeout)
    return _Borrowed(first.serial, url, timeout)


@contextmanager
def held_open(url: str, baud: int) -> Iterator[None]:
    """While inside, every ``open_port(url, baud)`` gets the one port opened by the first of
    them, and closing it leaves it open; it is closed at the end. A board that resets when
    its port is opened (DTR) then resets once, not once for each question asked of it
    before the work (a probe, then the stream)."""
    key = (url, baud)
    if key in _HELD:            # already held further out: that hold closes it
        yield
        return
    _HELD[key] = None
    try:
        yield
    finally:
        port = _HELD.pop(key, None)
        if port is not None:
            port.close()


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__
