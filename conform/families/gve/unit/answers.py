"""Answers of the reference unit and the books kept on them: ``>``'s last exchange, the ``@``
index (A10, A29).

An answer is the code digit with INTA in bit 3 (A24), its fields, a checksum when checksums
are on, CR (GVE64 §13.7, GVE124 §12.6).
"""

from __future__ import annotations

from collections.abc import Sequence

from conform.families.gve.protocol.answers import encode_answer
from conform.families.gve.unit.replies import DEFER, OK, WATCHDOG, Reply
from conform.families.gve.unit.state import UnitState

_RECOVERY = frozenset(("@", ">"))


class Answers(UnitState):
    """Encoding answers and sending a handler's reply."""

    def encode(self, code: int, fields: Sequence[object] = ()) -> bytes:
        """One answer line: code digit (INTA per A24), fields, checksum when on, CR."""
        inta = self._inta and (self._inta_all or code == 0)
        if not fields:
            key = code | (8 if inta else 0) | (16 if self._checksum_on else 0)
            cached = self._enc_cache[key]
            if cached is None:
                cached = self._enc_cache[key] = encode_answer(
                    code, inta, (), checksum_on=self._checksum_on)
            return cached
        return encode_answer(code, inta, fields, checksum_on=self._checksum_on)

    def _answer(self, line: bytes, reply: Reply, t: float, name: str | None,
                kind: str | None) -> None:
        """Send the reply to ``line`` and keep the books (``>``, the ``@`` index, A10)."""
        if reply.__class__ is int:
            ans = self.encode(reply)
            code = reply
        elif reply.__class__ is tuple:
            code, fields = reply  # type: ignore[misc]
            ans = self.encode(code, fields)
        elif reply is DEFER:
            self._last_line = line
            self._last_answer = None
            self._count(name, OK, kind)
            return
        elif reply is None:
            self._count(name, OK, kind)
            return
        else:  # raw bytes: ">" and "J"
            self._outbox.append((t + self.answer_delay, reply))  # type: ignore[arg-type]
            if name == ">" and self._a10 == 1:
                self._index = (self._index + 1) & 0xFF
            return
        self._outbox.append((t + self.answer_delay, ans))
        if kind != "checksum" or self._a29_store_bad:
            self._last_line = line
            self._last_answer = ans
        self._count(name, code, kind)

    def _count(self, name: str | None, code: int, kind: str | None) -> None:
        """A10: does this line advance the ``@`` index?"""
        a10 = self._a10
        if name == "J":  # the reset zeroed the index
            return
        if a10 == 1:
            pass
        elif name in _RECOVERY:
            return
        elif a10 == 0:
            if code == WATCHDOG or kind == "checksum":
                return
        elif code != OK:
            return
        self._index = (self._index + 1) & 0xFF
