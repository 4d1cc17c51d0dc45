"""Motion parameters and the EEPROM of the reference unit.

T, $, A, V, B, VL, VK, VN (GVE64 §13.5.2-13.5.4, GVE124 §12.5.2-12.5.4; A2, A6, A7, A26), the
speed changes of queued vectors XA, XU, XD, XM (GVE64 §13.5.5, GVE124 §12.5.5; A8), and the
EEPROM ER, EW, EFR, EUR, EFW, EUW (GVE64 §13.5.10, GVE124 §12.5.9; A18, A28).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from conform.families.gve.unit.eeprom import format_float
from conform.families.gve.unit.motion import (
    MIN_SPEED,
    MotionParams,
    speed_xa,
    speed_xd,
    speed_xm,
    speed_xu,
)
from conform.families.gve.unit.replies import OK, RANGE, Reply
from conform.families.gve.unit.state import UnitState

HANDLERS: Mapping[str, str] = {
    "T": "_cmd_T", "$": "_cmd_short", "A": "_cmd_A", "V": "_cmd_V", "VL": "_cmd_VL",
    "B": "_cmd_B", "VK": "_cmd_VK", "VN": "_cmd_VN", "XA": "_cmd_XA", "XU": "_cmd_XU",
    "XD": "_cmd_XD", "XM": "_cmd_XM", "ER": "_cmd_ER", "EW": "_cmd_EW", "EFR": "_cmd_EFR",
    "EUR": "_cmd_EUR", "EFW": "_cmd_EFW", "EUW": "_cmd_EUW",
}
"""Command id -> handler method (merged by ``conform.families.gve.unit.dispatch``)."""


class ParameterCommands(UnitState):
    """Modal values of the following vectors, speed changes of the queued ones, EEPROM."""


    @property
    def modal(self) -> dict[str, Any]:
        return {"A": self._A, "V": self._V, "B": self._B, "T": self._T, "$": self._short,
                "VL": self._VL, "XM": self._XM, "VK": self._VK}

    @property
    def eeprom(self) -> bytes:
        return bytes(self._eeprom.data)

    def _rebuild_params(self) -> None:
        v = self._V * self._XM / 100.0
        vl = None
        if any(x < self.variant.max_rate for x in self._VL):
            vl = tuple(float(x) for x in self._VL)
        self._exec.params = MotionParams(
            v=v if v > MIN_SPEED else MIN_SPEED, a=self._A * 1000.0, b=float(self._B),
            short=self._short, pause=self._T / 1000.0, vk=self._VK, vl=vl)

    # modal: a value for the vectors pushed from now on (the queued ones keep theirs)
    def _set_modal(self, attr: str, value: Any) -> Reply:
        setattr(self, attr, value)
        self._rebuild_params()
        return OK

    def _cmd_T(self, args: tuple, t: float) -> Reply:
        return self._set_modal("_T", args[0])

    def _cmd_short(self, args: tuple, t: float) -> Reply:
        return self._set_modal("_short", args[0])

    def _cmd_A(self, args: tuple, t: float) -> Reply:
        return self._set_modal("_A", args[0])

    def _cmd_V(self, args: tuple, t: float) -> Reply:
        return self._set_modal("_V", args[0])

    def _cmd_VL(self, args: tuple, t: float) -> Reply:
        return self._set_modal("_VL", tuple(args))

    def _cmd_B(self, args: tuple, t: float) -> Reply:
        return self._set_modal("_B", args[0])

    def _cmd_VK(self, args: tuple, t: float) -> Reply:
        return self._set_modal("_VK", True)

    def _cmd_VN(self, args: tuple, t: float) -> Reply:
        return self._set_modal("_VK", False)

    # speed changes of queued vectors
    def _cmd_XA(self, args: tuple, t: float) -> Reply:
        self._exec.apply_speed(t, speed_xa(self._exec.params.v), accel=self._A * 1000.0)
        return OK

    def _cmd_XU(self, args: tuple, t: float) -> Reply:
        self._exec.apply_speed(t, speed_xu)
        return OK

    def _cmd_XD(self, args: tuple, t: float) -> Reply:
        self._exec.apply_speed(t, speed_xd)
        return OK

    def _cmd_XM(self, args: tuple, t: float) -> Reply:
        self._XM = args[0]
        self._rebuild_params()
        self._exec.apply_speed(t, speed_xm(float(self._V), float(self._XM)))
        return OK

    # EEPROM
    def _cmd_ER(self, args: tuple, t: float) -> Reply:
        return (OK, ("%02X" % self._eeprom.read_byte(args[0]),))

    def _cmd_EW(self, args: tuple, t: float) -> Reply:
        self._eeprom.write_byte(args[0], args[1])
        return OK

    def _cmd_EFR(self, args: tuple, t: float) -> Reply:
        return (OK, (format_float(self._eeprom.read_float(args[0])),))

    def _cmd_EUR(self, args: tuple, t: float) -> Reply:
        return (OK, (str(self._eeprom.read_uint(args[0])),))

    def _cmd_EFW(self, args: tuple, t: float) -> Reply:
        address, value = args
        if isinstance(value, bytes):
            self._eeprom.write_raw(address, value)
        else:
            try:
                self._eeprom.write_float(address, value)
            except (OverflowError, ValueError):
                return RANGE
        return OK

    def _cmd_EUW(self, args: tuple, t: float) -> Reply:
        address, value = args
        if isinstance(value, bytes):
            self._eeprom.write_raw(address, value)
        else:
            self._eeprom.write_uint(address, value)
        return OK
