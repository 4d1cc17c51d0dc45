"""An emulator's control socket, the family-neutral part: one text line per request, one line
back (``ok ...`` or ``error: ...``). What the lines mean is the family's (GVE: inputs by name,
``state``: conform.families.gve.unit.control), handed to the emulator as its ``commands``
hook; :func:`send_control` is the client ``conform emulate control`` and ``--inputs-control``
use.
"""

from __future__ import annotations

import queue
import socket
from collections.abc import Callable
from typing import Any

ControlHandler = Callable[[Any, str, float], str]
"""(unit, request line, time) -> reply line; runs in the emulator's loop, which owns the unit."""


def no_commands(unit: Any, line: str, t: float) -> str:
    """The reply of an emulator whose family has no control commands."""
    return "error: this emulator takes no control commands"


def send_control(path: str, line: str, timeout: float = 5.0) -> str:
    """Send one control line to an emulator's socket; return its reply."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(timeout)
        sock.connect(path)
        sock.sendall(line.strip().encode() + b"\n")
        buf = b""
        while not buf.endswith(b"\n"):
            chunk = sock.recv(65536)
            if not chunk:
                break
            buf += chunk
    return buf.decode(errors="replace").strip()


class LocalControl:
    """An emulator's control queue without a socket, for an emulator served in this process
    (check-sender's sessions): the emulator's loop takes the requests, so the unit is only
    ever touched by the thread that owns it."""

    def __init__(self) -> None:
        self.requests: queue.SimpleQueue = queue.SimpleQueue()

    def ask(self, line: str, timeout: float = 5.0) -> str:
        reply: queue.SimpleQueue[str] = queue.SimpleQueue()
        self.requests.put((line, reply))
        try:
            return reply.get(timeout=timeout)
        except queue.Empty:
            return "error: the emulator did not answer"
