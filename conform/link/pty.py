"""Pseudo-terminals that look like a serial port to any program.

``PtyEndpoint`` owns the master side; a sender, a terminal program or pyserial opens
``.path`` (the slave device) as if it were ``/dev/ttyUSB0``. The slave is put in raw mode
(no echo, no line discipline) so bytes pass through untouched. By default the endpoint keeps
its own handle on the slave open, so a peer may close and reopen the device without the
master seeing a hang-up; closing the endpoint is how a test "unplugs" the port.
"""

from __future__ import annotations

import errno
import os
import select
import time
import tty

from conform.link.endpoint import PortGone, WriteTimeout


class PtyEndpoint:
    """The master side of a fresh pty pair; ``.path`` is the device a peer opens.

    ``link`` creates a symlink to the slave (a stable name across restarts, e.g. for
    ``--reconnect`` tests); ``write_timeout`` bounds how long ``write`` waits for a peer that
    does not read.
    """

    def __init__(
        self,
        *,
        link: str | os.PathLike[str] | None = None,
        hold_slave: bool = True,
        write_timeout: float | None = 5.0,
    ) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        self._master: int | None = master
        self._slave: int | None = slave
        self.device = os.ttyname(slave)
        self.write_timeout = write_timeout
        self._link = os.fspath(link) if link is not None else None
        if self._link is not None:
            if os.path.islink(self._link):
                os.unlink(self._link)
            os.symlink(self.device, self._link)
        if not hold_slave:
            os.close(slave)
            self._slave = None

    @property
    def path(self) -> str:
        """What a peer opens: the symlink if one was asked for, else the slave device."""
        return self._link if self._link is not None else self.device

    @property
    def name(self) -> str:
        return self.path

    @property
    def closed(self) -> bool:
        return self._master is None

    def fileno(self) -> int:
        if self._master is None:
            raise PortGone(f"{self.path}: pty is closed")
        return self._master

    def read(self, max_bytes: int = 4096, timeout: float | None = 0.1) -> bytes:
        """Bytes the peer wrote, as soon as any arrive; ``b""`` after ``timeout`` seconds."""
        fd = self.fileno()
        try:
            ready, _, _ = select.select([fd], [], [], timeout)
            if not ready:
                return b""
            return os.read(fd, max_bytes)
        except BlockingIOError:
            return b""
        except (OSError, ValueError) as exc:
            if self._master is None:
                raise PortGone(f"{self.path}: pty closed") from None
            if isinstance(exc, OSError) and exc.errno == errno.EIO:
                raise PortGone(f"{self.path}: peer hung up") from None
            raise PortGone(f"{self.path}: {exc}") from None

    def write(self, data: bytes) -> None:
        """Send all of ``data`` to the peer, waiting while the pty buffer is full."""
        view = memoryview(data)
        deadline = None if self.write_timeout is None else time.monotonic() + self.write_timeout
        while view:
            fd = self.fileno()
            try:
                n = os.write(fd, view)
                view = view[n:]
                continue
            except BlockingIOError:
                pass
            except OSError as exc:
                raise PortGone(f"{self.path}: write failed: {exc.strerror}") from None
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                raise WriteTimeout(f"{self.path}: peer did not read {len(view)} bytes in time")
            try:
                select.select([], [fd], [], left)
            except (OSError, ValueError):
                raise PortGone(f"{self.path}: pty closed") from None

    def write_some(self, data: bytes) -> int:
        """Write what the pty takes now, never wait; return how many bytes it took.

        For a device without flow control (a UART): what the peer does not read is lost.
        """
        fd = self.fileno()
        try:
            return os.write(fd, data)
        except BlockingIOError:
            return 0
        except OSError as exc:
            raise PortGone(f"{self.path}: write failed: {exc.strerror}") from None

    def unplug(self) -> None:
        """Hang up the peer (it sees EIO; the device node goes) but keep the pty's number
        taken until ``close``: while a line is down, a peer reopening the old path finds
        nothing rather than the next pty anyone opened, which the kernel would give it."""
        self._drop_link()
        self._close_fds("_master")

    def _close_fds(self, *attrs: str) -> None:
        for attr in attrs:
            fd = getattr(self, attr)
            setattr(self, attr, None)
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass

    def _drop_link(self) -> None:
        if self._link is not None and self._master is not None and os.path.islink(self._link):
            try:
                if os.readlink(self._link) == self.device:
                    os.unlink(self._link)
            except OSError:
                pass

    def close(self) -> None:
        """Drop the link, then close both sides (the peer then sees EIO: an unplugged port).
        In that order: once closed, the pty's number goes to the next pty anyone opens, and a
        peer reopening the link must not reach that one."""
        self._drop_link()
        self._close_fds("_master", "_slave")

    def __enter__(self) -> PtyEndpoint:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"PtyEndpoint({self.path!r})"
