"""Inputs, interrupts, outputs, the spindle and the MPG of the reference unit.

O, I1, I2 (GVE64 §13.5.11-13.5.12, GVE124 §12.5.10-12.5.11); SW, the interrupt masks and
polarities and SW6 (GVE64 §13.5.12, §13.7, GVE124 §12.5.11; A20); the spindle on address 7
(GVE64 §13.6, GVE124 §10; A19); the MPG Y (GVE64 §13.5.8; A14). An enabled input that becomes
asserted (its level equals its polarity bit) sets its cause bit in ST4/ST5, sets INTA and brakes.
"""

from __future__ import annotations

from collections.abc import Mapping

from conform.families.gve.unit.replies import OK, RANGE, Reply
from conform.families.gve.unit.state import UnitState

HANDLERS: Mapping[str, str] = {
    "O": "_cmd_O", "I1": "_cmd_I1", "I2": "_cmd_I2", "SW": "_cmd_SW", "Y": "_cmd_Y",
    "7V": "_cmd_spindle",
}
"""Command id -> handler method (merged by ``conform.families.gve.unit.dispatch``)."""


class SignalCommands(UnitState):
    """The unit's electrical side: what the host and the machine switch."""

    def set_input(self, port: int, bit: int, active: bool, t: float) -> None:
        """Assert (``active``) or release input ``bit`` of ``port`` (1: I1, 2: I2) at ``t``.

        "Asserted" follows the polarity in ST2/ST3 at this moment: with the reset polarity
        (0 = active low) asserting pulls the pin to 0. An enabled input that becomes asserted
        raises an interrupt. :meth:`set_level` sets the electrical level instead.
        """
        level = self._polarity_bit(port, bit) if active else not self._polarity_bit(port, bit)
        self.set_level(port, bit, bool(level), t)

    def set_level(self, port: int, bit: int, level: bool, t: float) -> None:
        """Set the electrical level of an input (what I1/I2 read) at ``t``."""
        mask = self._port_mask(port)
        if not 0 <= bit <= 7 or not mask & (1 << bit):
            raise ValueError(f"{self.variant.id} has no input bit {bit} on port {port}")
        self._advance(t)
        if port == 1:
            self._in1 = (self._in1 | (1 << bit)) if level else (self._in1 & ~(1 << bit))
        else:
            self._in2 = (self._in2 | (1 << bit)) if level else (self._in2 & ~(1 << bit))
        self._eval_interrupts(self._now)

    def input_level(self, port: int) -> int:
        """The byte I1 (port 1) or I2 (port 2) reads."""
        return self._in1 if port == 1 else self._in2

    @property
    def outputs(self) -> int:
        return self._outputs

    @property
    def spindle(self) -> int:
        return self._spindle

    @property
    def mpg(self) -> str:
        """The MPG mode: ``+``, ``&``, ``-`` (``none`` on units without Y)."""
        return self._mpg

    # interrupts ------------------------------------------------------------------------
    def _port_mask(self, port: int) -> int:
        if port == 1:
            return self._mask1
        if port == 2:
            return self._mask2
        raise ValueError(f"input port {port} is not 1 or 2")

    def _polarity_bit(self, port: int, bit: int) -> bool:
        self._port_mask(port)
        return bool(self._st[2 if port == 1 else 3] & (1 << bit))

    def _eval_live(self) -> tuple[int, int]:
        st = self._st
        live1 = ~(self._in1 ^ st[2]) & self._mask1 & st[0]
        live2 = ~(self._in2 ^ st[3]) & self._mask2 & st[1]
        new1 = live1 & ~self._live1
        new2 = live2 & ~self._live2
        self._live1, self._live2 = live1, live2
        return new1, new2

    def _eval_interrupts(self, t: float) -> None:
        """An enabled input that becomes asserted sets its cause bit and INTA and brakes."""
        new1, new2 = self._eval_live()
        if new1 or new2:
            self._st[4] |= new1
            self._st[5] |= new2
            self._inta = True
            self._exec.halt(t)

    # handlers --------------------------------------------------------------------------
    def _cmd_O(self, args: tuple, t: float) -> Reply:
        self._outputs = args[1]
        return OK

    def _cmd_I1(self, args: tuple, t: float) -> Reply:
        return (OK, ("%02X" % self._in1,))

    def _cmd_I2(self, args: tuple, t: float) -> Reply:
        return (OK, ("%02X" % self._in2,))

    def _cmd_SW(self, args: tuple, t: float) -> Reply:
        n, value = args
        if n not in self._words:
            return OK if self._a20_zero else RANGE
        if n == 6:
            self._write_st6(value, t)
            return OK
        self._st[n] = value
        if n < 4:
            self._eval_interrupts(t)
        return OK

    def _write_st6(self, value: int, t: float) -> None:
        """SW6 (discouraged by the manual): STOP, FREE, INTCOM stored; INTA 0->1 halts,
        1->0 resumes; RUN follows the queue and cannot be written."""
        self._st6_extra = value & (self._bit_stop | self._bit_free)
        self._intcom = bool(value & self._bit_intcom)
        inta = bool(value & self._bit_inta)
        if inta and not self._inta:
            self._inta = True
            self._exec.halt(t)
        elif not inta and self._inta:
            self._inta = False
            self._exec.resume(t)

    def _cmd_Y(self, args: tuple, t: float) -> Reply:
        mode = args[0]
        self._mpg = mode
        self._mpg_run = mode != "-"
        return (OK, ("Y" + mode,))

    def _cmd_spindle(self, args: tuple, t: float) -> Reply:
        self._spindle = args[0]
        if args[0]:
            self._outputs &= ~1 & 0xFF
        else:
            self._outputs |= 1
        return OK
