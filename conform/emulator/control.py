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
from typing import TYPE_CHECKING, Any, Generic, TypeVar

if TYPE_CHECKING:
    from conform.link.faults import FaultInjector

ControlHandler = Callable[[Any, str, float], str]
"""(unit, request line, time) -> reply line; runs in the emulator's loop, which owns the unit
(the family's own unit type: hence Any)."""

UnitT = TypeVar("UnitT")
"""The unit type of the family whose control requests a :class:`FaultControl` answers."""


def no_commands(unit: object, line: str, t: float) -> str:
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
        self.requests: queue.SimpleQueue[tuple[str, queue.SimpleQueue[str]]] = queue.SimpleQueue()

    def ask(self, line: str, timeout: float = 5.0) -> str:
        reply: queue.SimpleQueue[str] = queue.SimpleQueue()
        self.requests.put((line, reply))
        try:
            return reply.get(timeout=timeout)
        except queue.Empty:
            return "error: the emulator did not answer"


class FaultControl(Generic[UnitT]):
    """What every family's control requests share: ``help``, ``state`` (JSON), ``fault line
    SPEC`` (the link's noise), ``fault KIND N`` for the answer faults counted in ``counted``
    (each sets ``<kind>_next`` on the family's fault injector), ``fault unplug SECONDS``, and
    the family's own verbs and faults. One line back; a request never stops the emulator.

    A family subclasses it with ``help_text``, ``counted`` and ``state``, and ``verb`` /
    ``fault`` for what only it has."""

    help_text = "commands: fault unplug SECONDS | fault line SPEC | state | help"
    counted: tuple[str, ...] = ()
    """Answer faults taking a count: ``fault lose N`` sets ``faults.lose_next``."""

    def __init__(self, faults: FaultInjector) -> None:
        self.faults = faults

    def state(self, unit: UnitT) -> dict[str, object]:
        return {}

    def verb(self, unit: UnitT, cmd: str, args: list[str], t: float) -> str | None:
        """A request of the family's own (``press door``, ``reset``); None: not one."""
        return None

    def fault(self, unit: UnitT, kind: str, x: float, t: float) -> str | None:
        """A fault of the family's own taking one number; None: not one."""
        return None

    def unplugged(self, unit: UnitT, t: float) -> None:
        """What the unit does when its cable is pulled (default: nothing beyond the link)."""

    def __call__(self, unit: UnitT, line: str, t: float) -> str:
        import json

        from conform.errors import UserError

        words = line.strip().split()
        if not words:
            return "error: empty command"
        cmd, args = words[0].lower(), words[1:]
        try:
            if cmd == "help":
                return "ok " + self.help_text
            if cmd == "state" and not args:
                return "ok " + json.dumps(self.state(unit), separators=(",", ":"))
            if cmd == "fault" and args:
                return self._fault(unit, args[0].lower(), args[1:], t)
            reply = self.verb(unit, cmd, args, t)
            if reply is not None:
                return reply
        except (ValueError, UserError) as exc:
            return f"error: {exc}"
        except Exception as exc:  # noqa: BLE001 - a request never stops the emulator
            return f"error: {type(exc).__name__}: {exc}"
        return f"error: cannot parse {line.strip()[:80]!r}; {self.help_text}"

    def _fault(self, unit: UnitT, kind: str, args: list[str], t: float) -> str:
        from conform.link.faults import FaultConfig

        f = self.faults
        if kind == "line":
            f.config = FaultConfig.parse(",".join(args)) if args else FaultConfig()
            return "ok line faults: " + (",".join(args) or "none")
        if len(args) != 1:
            raise ValueError(f"fault {kind} takes one number")
        try:
            x = float(args[0])
        except ValueError:
            raise ValueError(f"{args[0]!r} is not a number") from None
        if kind in self.counted:
            if not (0 <= x <= 1_000_000 and x == int(x)):
                raise ValueError(f"fault {kind} {args[0]}: expected a count 0..1000000")
            setattr(f, f"{kind}_next", int(x))
            return f"ok the next {int(x)} answer line(s): {kind}"
        if kind == "unplug":
            if not 0 < x <= 3600:
                raise ValueError(f"fault unplug {args[0]}: expected 0..3600 seconds")
            f.unplug(t, x)
            self.unplugged(unit, t)
            return f"ok cable pulled for {x:g} s"
        reply = self.fault(unit, kind, x, t)
        if reply is None:
            kinds = ", ".join((*self.counted, "unplug", "line"))
            raise ValueError(f"unknown fault {kind!r} ({kinds}, or see help)")
        return reply
