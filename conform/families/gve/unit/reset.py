"""Reset of the reference unit: the power-up state and J with its deaf time.

The reset state of GVE64 §13.4 / GVE124 §12.4 comes from the variant's reset table and the
open questions A14, A25, A26; J (GVE64 §13.5.13, GVE124 §12.5.12; A17) resets at once, then
the unit ignores every byte for ``ready_after_s`` (about 2 s). EEPROM and input levels survive.
"""

from __future__ import annotations

from collections.abc import Mapping

from conform.families.gve.unit.motion import MotionExecutor
from conform.families.gve.unit.replies import INF, OK, Reply
from conform.families.gve.unit.state import UnitState

HANDLERS: Mapping[str, str] = {"J": "_cmd_J"}
"""Command id -> handler method (merged by ``conform.families.gve.unit.dispatch``)."""


class ResetCommands(UnitState):
    """Power-up, J and the deaf time after it."""


    @property
    def deaf(self) -> bool:
        """True during the ~2 s after J."""
        return self._now < self._deaf_until

    def _cmd_J(self, args: tuple, t: float) -> Reply:
        answer = self.encode(OK) if self._a17_answer else None
        self._power_up(t)
        self._deaf_until = t + self._ready_after
        return answer

    def _power_up(self, t: float) -> None:
        """The reset state of GVE64 §13.4 / GVE124 §12.4 (tables + A14, A25, A26)."""
        v = self.variant
        r = v.reset
        self._exec = MotionExecutor(axes=self._naxes, capacity=v.queue, max_rate=v.max_rate)
        self._exec.advance(t)
        self._offsets = [0] * self._naxes
        self._A = int(r.get("A", 20))
        self._V = int(r.get("V", 1000))
        self._B = int(r.get("B", 35000))
        self._short = int(r.get("$", 512))
        self._T = self._t_reset
        self._VL = (int(r.get("VL", v.max_rate)),) * self._naxes
        self._XM = int(r.get("XM", 100))
        self._VK = self._vk_reset
        self._rebuild_params()
        status = int(r.get("status", 0))
        self._st = [status] * 6
        self._inta = False
        self._intcom = False
        self._st6_extra = 0
        self._live1 = self._live2 = 0
        self._eval_live()
        self._outputs = int(r.get("outputs", 0xFF))
        self._spindle = int(r.get("spindle", 0))
        self._checksum_on = bool(r.get("checksum", False))
        self._index = int(r.get("index", 0)) & 0xFF
        mpg = str(r.get("mpg", "none")) if v.has("Y") else "none"
        self._mpg = mpg
        self._mpg_run = self._a14_blocks and mpg in ("+", "&")
        self._ready_after = float(r.get("ready_after_s", 2.0))
        self._packet = None
        self._last_line = None
        self._last_answer = None
        self._kept = None
        self._awaiting = False
        self._defer_t = INF
        self._defer_reply = (OK, ())
        self._w_pending = False
        self._held_lines = []
        self._held_chunks = []
        self._wd = INF
        self._partial = False
        self._timers = False
        self._splitter.clear()
