"""Status and read-back of the reference unit: identity, position, status words, recovery.

``?``, Q (GVE64 §13.5.1, GVE124 §12.5.1); P, PF, P4, N, N<axis> (GVE64 §13.5.6, GVE124
§12.5.6; A27); SR, F and ST6 with RUN/INTA (GVE64 §13.5.12, GVE124 §12.5.11; A20); ``@`` and
``>`` (GVE64 §13.5.13, GVE124 §12.5.12; A9, A10). The read-only views of the same state are here.
"""

from __future__ import annotations

from collections.abc import Mapping

from conform.families.gve.unit.replies import OK, RANGE, Reply
from conform.families.gve.unit.state import UnitState


def _wrap32(x: int) -> int:
    """A 32-bit signed position counter."""
    return ((x + 0x80000000) & 0xFFFFFFFF) - 0x80000000


HANDLERS: Mapping[str, str] = {
    "?": "_cmd_version", "Q": "_cmd_Q", "P": "_cmd_P", "PF": "_cmd_PF", "P4": "_cmd_P4",
    "N": "_cmd_N", "N<axis>": "_cmd_N_axis", "SR": "_cmd_SR", "F": "_cmd_F",
    "@": "_cmd_index", ">": "_cmd_repeat",
}
"""Command id -> handler method (merged by ``conform.families.gve.unit.dispatch``)."""


class ReadbackCommands(UnitState):
    """What the host can read back, as answers and as views."""


    # read-only views ----------------------------------------------------------------
    @property
    def position(self) -> tuple[int, ...]:
        pos = self._exec.position
        return tuple(_wrap32(p + o) for p, o in zip(pos, self._offsets, strict=True))

    @property
    def queue_len(self) -> int:
        return self._exec.queue_len

    def status(self, n: int) -> int:
        """ST0..ST6 as SR would read it (0 for a word the variant lacks)."""
        if n == 6:
            return self._st6()
        return self._st[n] if n in self._words else 0

    @property
    def inta(self) -> bool:
        return self._inta

    @property
    def run(self) -> bool:
        return self._exec.queue_len > 0 or self._mpg_run

    @property
    def moving(self) -> bool:
        """Axes under way or braking: the only time a position read may differ from the one
        a moment later. RUN alone is not motion (A14's reset-blocks sets it at rest)."""
        return self._exec.running

    @property
    def index(self) -> int:
        return self._index

    @property
    def last_exchange(self) -> tuple[bytes | None, bytes | None]:
        """(last command line, its answer) as ``>`` would repeat them."""
        return self._last_line, self._last_answer

    def _st6(self) -> int:
        v = self._st6_extra
        if self._exec.braking:
            v |= self._bit_stop
        if self._intcom:
            v |= self._bit_intcom
        if self._exec.queue_len > 0 or self._mpg_run:
            v |= self._bit_run
        if self._inta:
            v |= self._bit_inta
        return v

    # identification
    def _cmd_version(self, args: tuple, t: float) -> Reply:
        return (OK, (self.variant.firmware,))

    def _cmd_Q(self, args: tuple, t: float) -> Reply:
        return (OK, (self.variant.processor_id,))

    # position
    def _cmd_P(self, args: tuple, t: float) -> Reply:
        return (OK, self.position[:2])

    def _cmd_PF(self, args: tuple, t: float) -> Reply:
        return (OK, self.position[:3])

    def _cmd_P4(self, args: tuple, t: float) -> Reply:
        return (OK, self.position[:4])

    def _cmd_N(self, args: tuple, t: float) -> Reply:
        self._offsets = [-p for p in self._exec.position]
        return OK

    def _cmd_N_axis(self, args: tuple, t: float) -> Reply:
        axis, value = args
        i = self.variant.axes.index(axis)
        self._offsets[i] = value - self._exec.position[i]
        return OK

    # status
    def _cmd_SR(self, args: tuple, t: float) -> Reply:
        n = args[0]
        if n not in self._words:
            return (OK, ("00",)) if self._a20_zero else RANGE
        return (OK, ("%02X" % self.status(n),))

    def _cmd_F(self, args: tuple, t: float) -> Reply:
        v = self._st6() | (self._bit_full if self._queue_full() else 0)
        return (OK, ("%02X" % v,))

    # recovery
    def _cmd_index(self, args: tuple, t: float) -> Reply:
        index = (self._index + 1) & 0xFF if self._a10 == 1 else self._index
        return (OK, ("%02X" % index if self._a9 == "hex-index" else str(index),))

    def _cmd_repeat(self, args: tuple, t: float) -> Reply:
        answer = self._last_answer if self._last_answer is not None else self.encode(OK)
        if self._a9 == "repeat-answer-only" or self._last_line is None:
            return answer
        # the repeated line is one line of the answer: a lone CR it held (possible only under
        # A1=crlf) would end it early and turn its tail into a bogus answer, so it is left out
        return self._last_line.replace(b"\r", b"") + b"\r" + answer
