"""Notice a peer opening and closing a pty device (Linux inotify).

The proxy keeps its own handle on the sender's pty so that a sender may close and reopen
the device; the price is that the master side never sees a hangup. Watching the device
node for opens and closes tells when the last peer handle went away (``disconnect``) and
when one came back (``reconnect``). Where inotify is unavailable the watch does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import select
import struct
import threading
from collections.abc import Callable

IN_CLOSE_WRITE, IN_CLOSE_NOWRITE, IN_OPEN = 0x08, 0x10, 0x20
_EVENT = struct.Struct("iIII")


class PeerWatch:
    """Calls ``on_change(kind, detail)`` with ``disconnect`` / ``reconnect`` for ``path``."""

    def __init__(self, path: str, on_change: Callable[[str, str], None], poll: float = 0.2) -> None:
        self.path = path
        self.on_change = on_change
        self.poll = poll
        self.opens = 0
        self._seen_peer = False
        self._stop = threading.Event()
        self._fd = -1
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
            fd = libc.inotify_init1(os.O_NONBLOCK | os.O_CLOEXEC)
            if fd >= 0 and libc.inotify_add_watch(
                    fd, os.fsencode(path), IN_OPEN | IN_CLOSE_WRITE | IN_CLOSE_NOWRITE) < 0:
                os.close(fd)
                fd = -1
            self._fd = fd
        except (OSError, AttributeError):
            self._fd = -1
        self._thread = threading.Thread(target=self._run, name="peer-watch", daemon=True)
        if self._fd >= 0:
            self._thread.start()

    @property
    def active(self) -> bool:
        return self._fd >= 0

    def feed(self, masks: list[int]) -> None:
        """Count opens and closes; report the edges (sans-I/O core, tested directly)."""
        for mask in masks:
            before = self.opens
            if mask & IN_OPEN:
                self.opens += 1
            if mask & (IN_CLOSE_WRITE | IN_CLOSE_NOWRITE):
                self.opens = max(0, self.opens - 1)
            if before == 0 and self.opens > 0:
                if self._seen_peer:
                    self.on_change("reconnect", f"{self.path} opened again by the sender")
                self._seen_peer = True
            elif before > 0 and self.opens == 0:
                self.on_change("disconnect", f"{self.path} closed by the sender")

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._fd], [], [], self.poll)
                if not ready:
                    continue
                data = os.read(self._fd, 4096)
            except OSError:
                return
            masks, pos = [], 0
            while pos + _EVENT.size <= len(data):
                _wd, mask, _cookie, n = _EVENT.unpack_from(data, pos)
                masks.append(mask)
                pos += _EVENT.size + n
            self.feed(masks)

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(1.0)
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1
