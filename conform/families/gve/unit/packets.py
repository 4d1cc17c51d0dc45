"""Packets of the reference unit: ``*S`` ... ``*E<n>`` (GVE64 §13.3.3, GVE124 §12.3.3; A12).

Inside a packet C and B are executed without answers of their own (anything else is an error
unless A12 = accept-any); ``*E<n>`` answers ``code,count``.
"""

from __future__ import annotations

from collections.abc import Mapping

from conform.families.gve.protocol.commands import Rejection
from conform.families.gve.unit.replies import DEFER, INF, OK, SYNTAX, Reply
from conform.families.gve.unit.state import UnitState

_PACKET_OK = frozenset(("C", "B"))


class Packet:
    """An open packet: lines executed, the error to report, whether later lines are dropped."""

    __slots__ = ("count", "error", "stopped")

    def __init__(self) -> None:
        self.count = 0
        self.error: int | None = None
        self.stopped = False


HANDLERS: Mapping[str, str] = {"*S": "_cmd_packet_start", "*E": "_cmd_packet_end"}
"""Command id -> handler method (merged by ``conform.families.gve.unit.dispatch``)."""


class PacketCommands(UnitState):
    """``*S``, ``*E`` and the lines between them."""

    def _cmd_packet_start(self, args: tuple, t: float) -> Reply:
        self._packet = Packet()
        return None

    def _cmd_packet_end(self, args: tuple, t: float) -> Reply:
        return SYNTAX  # *E without *S

    def _packet_line(self, line: bytes, t: float) -> None:
        """A line inside ``*S`` ... ``*E`` (GVE64 §13.3.3; errors: A12)."""
        pk = self._packet
        assert pk is not None
        r = self._parse(line)
        if r.name == "*E":
            if r.__class__ is Rejection:
                self._packet = None
                self._answer(line, r.code, t, "*E", r.kind)
                return
            self._packet = None
            n = r.args[0]  # type: ignore[union-attr]
            if pk.error is not None:
                code = pk.error
            else:
                code = OK if n == pk.count else SYNTAX
            self._answer(line, (code, (pk.count,)), t, "*E", None)
            return
        if r.__class__ is Rejection:
            if r.code is None:
                return
            if self._a10 == 1:
                self._index = (self._index + 1) & 0xFF
            self._packet_error(r.code)
            return
        if self._a10 == 1:
            self._index = (self._index + 1) & 0xFF
        if pk.stopped:
            return
        if r.name not in _PACKET_OK and (self._a12 != "accept-any" or r.name == "*S"):
            self._packet_error(SYNTAX)
            return
        reply = self._execute(r, t)
        if reply is DEFER:  # a halt or reference move inside a packet: no answer of its own
            self._awaiting = False
            self._defer_t = INF
            self._w_pending = False
            self._update_timers()
            reply = OK
        if self._packet is None:  # J inside an accept-any packet reset the unit
            return
        code = reply if reply.__class__ is int else (reply[0] if reply.__class__ is tuple else OK)
        if code == OK:
            pk.count += 1
            if self._a10 != 1:
                self._index = (self._index + 1) & 0xFF
        else:
            self._packet_error(code)  # type: ignore[arg-type]

    def _packet_error(self, code: int) -> None:
        pk = self._packet
        assert pk is not None
        if self._a12 == "skip-bad":
            pk.error = code
            return
        if pk.error is None:
            pk.error = code
        pk.stopped = True
