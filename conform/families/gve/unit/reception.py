"""Line reception of the reference unit: framing, the watchdog, reading lines, checksums.

Bytes are split into lines (A1), a begun ``!`` line that does not complete in time is answered
2 (A13), each complete line is read by the tables' :class:`CommandParser` (address, checksum,
mnemonic, syntax, range; GVE64 §13.3, §13.5, GVE124 §12.3) and goes to the packet or to the
dispatch. ``%`` switches checksums (GVE64 §13.3.2, GVE124 §12.3.2).
"""

from __future__ import annotations

import re
from collections.abc import Mapping

from conform.families.gve.protocol.checksum import split_checksum
from conform.families.gve.protocol.commands import Command, CommandParser, Rejection
from conform.families.gve.spec import Dialect, Spec, Variant
from conform.families.gve.unit.replies import INF, OK, RANGE, SYNTAX, WATCHDOG, Reply
from conform.families.gve.unit.state import UnitState

WATCHDOG_S: Mapping[str, float | None] = {"100ms": 0.1, "20ms": 0.02, "1s": 1.0, "off": None}
"""A13: how long a begun line may take."""

_HEX_EW = re.compile(rb"!(\d)(E[FU]W)([0-9A-Fa-f]+),([0-9A-Fa-f]{8})\Z")
_parser_cache: dict[tuple, CommandParser] = {}
_MEMO_LINE = 80  # longest line whose reading a unit keeps
_MEMO_SIZE = 4096  # readings kept (then forgotten all at once)


def parser_for(variant: Variant, dialect: Dialect, spec: Spec) -> CommandParser:
    """The tables' parser for this variant and dialect (shared by the units that use it)."""
    key = (id(spec), variant.id, tuple(sorted(dialect.choices.items())))
    parser = _parser_cache.get(key)
    if parser is None:
        parser = CommandParser(variant, dialect, dict(spec.commands))
        if len(_parser_cache) > 64:
            _parser_cache.clear()
        _parser_cache[key] = parser
    return parser


HANDLERS: Mapping[str, str] = {"%": "_cmd_checksum"}
"""Command id -> handler method (merged by ``conform.families.gve.unit.dispatch``)."""


class LineReception(UnitState):
    """Bytes in, lines out to the packet or the dispatch; ``%``."""


    @property
    def checksum_on(self) -> bool:
        return self._checksum_on

    def receive(self, data: bytes, t: float) -> None:
        """Bytes from the host that arrived at time ``t`` (seconds)."""
        if not data:
            return
        self._advance(t)
        t = self._now
        if t < self._deaf_until:
            return
        if self._awaiting:
            if self._hold:
                self._held_chunks.append(bytes(data))
            return
        if self._fast and not self._partial and self._packet is None:
            m = (self._fast_cs if self._checksum_on else self._fast_plain).match(data)
            if m is not None and self._fast_vector(m, data, t):
                return
        self._feed(bytes(data), t)

    def _feed(self, data: bytes, t: float) -> None:
        lines = self._splitter.feed(data)
        if lines:
            self._wd = INF
            for i, line in enumerate(lines):
                self._process_line(line, t)
                if t < self._deaf_until:
                    self._splitter.clear()
                    break
                if self._awaiting:
                    if self._hold:
                        self._held_lines.extend(lines[i + 1:])
                    else:
                        self._splitter.clear()
                    break
        self._start_watchdog(t)

    def _start_watchdog(self, t: float) -> None:
        pending = self._splitter.unfinished
        self._partial = bool(pending)
        if not pending:
            self._wd = INF
        elif (self._wd == INF and self._watchdog_s is not None and not self._awaiting
              and b"!" in pending):
            self._wd = t + self._watchdog_s
        self._update_timers()

    def _watchdog(self, t: float) -> None:
        """The line begun with ``!`` did not complete in time (A13): answer 2, drop it."""
        pending = self._splitter.clear()
        self._partial = False
        self._wd = INF
        start = pending.rfind(b"!")
        line = pending[start:]
        if len(line) < 2 or not 0x30 <= line[1] <= 0x39:
            return
        if line[1] - 0x30 not in self._parser.addresses:
            return
        if self._packet is not None:
            self._packet_error(WATCHDOG)
            return
        self._answer(line, WATCHDOG, t, None, "watchdog")

    def _parse(self, line: bytes) -> Command | Rejection:
        """The line's reading (a pure function of the line and the checksum state: readings
        of short lines are kept, a host repeats its lines)."""
        memo = self._parsed[1 if self._checksum_on else 0]
        r = memo.get(line)
        if r is not None:
            return r
        r = self._parser.parse(line, self._checksum_on)
        if self._hex_floats and r.name in ("EFW", "EUW"):
            if r.__class__ is Command or r.kind in ("syntax", "range"):
                r = self._parse_hex_write(line, r)
        if len(line) <= _MEMO_LINE:
            if len(memo) >= _MEMO_SIZE:
                memo.clear()
            memo[line] = r
        return r

    def _parse_hex_write(self, line: bytes, r: Command | Rejection) -> Command | Rejection:
        """A18 hex-bytes: ``EFWaa,xxxxxxxx`` / ``EUWaa,xxxxxxxx``, 4 bytes little-endian."""
        body = line
        with_sum = False
        if self._checksum_on:
            body, value = split_checksum(line)
            with_sum = value is not None
        m = _HEX_EW.match(body)
        if m is None:
            return Rejection("syntax", SYNTAX, f"{r.name}: expected aa,xxxxxxxx (A18 hex-bytes)",
                             line, r.name, line[1] - 0x30)
        address = int(m.group(3), 16)
        if address > 252:
            return Rejection("range", RANGE, f"{r.name}: address {address:X} > FC", line, r.name,
                             line[1] - 0x30)
        return Command(line[1] - 0x30, r.name, (address, bytes.fromhex(m.group(4).decode())),
                       with_sum, line)

    def _process_line(self, line: bytes, t: float) -> None:
        if self._packet is not None:
            self._packet_line(line, t)
            return
        r = self._parse(line)
        if r.__class__ is Rejection:
            if r.code is None:
                return
            self._answer(line, r.code, t, r.name, r.kind)
            return
        self._answer(line, self._execute(r, t), t, r.name, None)

    def _cmd_checksum(self, args: tuple, t: float) -> Reply:
        self._checksum_on = args[0] == "+"
        return OK
