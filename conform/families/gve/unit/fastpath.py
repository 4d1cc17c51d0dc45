"""The fast path of the reference unit: plain C/L lines read by one regex, and ``exchange``.

A plain vector line (the parser's strict form, a subset of lenient) is most of what a sender
sends; it is matched by one precompiled regex instead of the general parser, with the same
result (a hypothesis test checks it). ``exchange`` sends a line and runs virtual time to its
complete answer, taking a shortcut when nothing else is pending.
"""

from __future__ import annotations

import re

from conform.families.gve.unit.replies import INF, OK
from conform.families.gve.unit.state import UnitState


class FastPath(UnitState):
    """``exchange`` and the fast reading of plain C/L lines."""

    def exchange(self, line: bytes, t: float) -> tuple[float, bytes]:
        """Send ``line`` at ``t`` and run virtual time until its complete answer.

        Returns (time the answer is due, answer bytes); ``(t, b"")`` for the documented
        silence. HALT and W answer late; ``>`` may answer two lines (returned together).
        """
        if (self._fast and not self._timers and not self._partial and not self._outbox
                and self._packet is None and t >= self._now and t >= self._deaf_until):
            cs_on = self._checksum_on
            m = (self._fast_cs if cs_on else self._fast_plain).match(line)
            if m is not None and (not cs_on or (sum(line[:-3]) & 0xFF) == int(m.group(3), 16)):
                kind, nums = m.group(1, 2)
                d = tuple(map(int, nums.split(b",")))
                if min(d) >= self._pulse_lo and max(d) <= self._pulse_hi:
                    if len(d) < self._naxes:
                        d += self._pad[len(d)]
                    self._exec.advance(t)
                    self._now = t
                    name = "C" if kind == b"C" else "L"
                    reply = self.handlers[name](d, t)
                    if reply.__class__ is int:
                        ans = self.encode(reply)  # type: ignore[arg-type]
                        self._last_line = line[:-1]
                        self._last_answer = ans
                        if reply == OK or self._a10 != 2:  # never 2 nor a checksum error
                            self._index = (self._index + 1) & 0xFF
                        return (t + self.answer_delay, ans)
                    self._answer(line[:-1], reply, t, name, None)
                    return self._exchange_wait(t)
        self.receive(line, t)
        out = self._outbox
        if (len(out) == 1 and not self._awaiting and self._wd == INF
                and out[0][0] <= self._now):
            self._outbox = []
            return out[0]
        return self._exchange_wait(t)

    def _compile_fast_path(self) -> None:
        """One regex for a plain C/L line (the parser's strict form, a subset of lenient)."""
        spec_l = self._specs["L"].params[0]
        self._pulse_lo, self._pulse_hi = spec_l.lo, spec_l.hi
        need = spec_l.min_count or self._naxes
        # at most 20 digits: a longer numeral goes to the parser, which answers it (5) without
        # converting it (int() refuses more than 4 300 digits)
        fields = rb"(-?[0-9]{1,20}(?:,-?[0-9]{1,20}){%d,%d})" % (need - 1, self._naxes - 1)
        head = b"!%d([CL])" % self.variant.interpolator_address
        self._fast_plain = re.compile(head + fields + rb"\r\Z")
        self._fast_cs = re.compile(head + fields + rb",([0-9A-Fa-f]{2})\r\Z")
        self._pad = [(0,) * (self._naxes - k) for k in range(self._naxes + 1)]

    def _fast_args(self, m: re.Match[bytes], data: bytes) -> tuple[int, ...] | None:
        """The vector of a fast-path match, or None to let the parser give the rejection."""
        if self._checksum_on and (sum(data[:-3]) & 0xFF) != int(m.group(3), 16):
            return None
        d = tuple(map(int, m.group(2).split(b",")))
        if min(d) < self._pulse_lo or max(d) > self._pulse_hi:
            return None
        if len(d) < self._naxes:
            d += self._pad[len(d)]
        return d

    def _fast_vector(self, m: re.Match[bytes], data: bytes, t: float) -> bool:
        d = self._fast_args(m, data)
        if d is None:
            return False
        name = "C" if m.group(1) == b"C" else "L"
        reply = self.handlers[name](d, t)
        self._answer(data[:-1], reply, t, name, None)
        return True
