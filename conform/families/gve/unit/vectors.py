"""Vectors and the motion queue of the reference unit: L, C, H, G, D, K, R and W.

GVE64 §13.5.2 / GVE124 §12.5.2 (vectors; A4, A5), §13.5.9 / §12.5.8 (H, G, D, K, R; A15),
§13.5.7 / §12.5.7 (the reference move W, simulated with ``switches``). The motion itself is
:class:`conform.families.gve.unit.motion.MotionExecutor`'s.
"""

from __future__ import annotations

from collections.abc import Mapping

from conform.families.gve.unit.motion import MIN_SPEED, MotionStateError
from conform.families.gve.unit.replies import DEFER, NOTHING_TO_GO, OK, QUEUE_FULL, RUNNING, Reply
from conform.families.gve.unit.state import UnitState

HANDLERS: Mapping[str, str] = {
    "L": "_cmd_L", "C": "_cmd_C", "W": "_cmd_W", "K": "_cmd_K", "R": "_cmd_R",
    "H": "_cmd_H", "D": "_cmd_D", "G": "_cmd_G",
}
"""Command id -> handler method (merged by ``conform.families.gve.unit.dispatch``)."""


class VectorCommands(UnitState):
    """The queue and what moves the machine."""

    def _queue_full(self) -> bool:
        ex = self._exec
        if self._kept is not None:
            return ex.queue_len >= 1
        limit = ex.capacity
        if self._a5_excl and ex.running:
            limit += 1
        return ex.queue_len >= limit

    def _cmd_C(self, args: tuple, t: float) -> Reply:
        if self._mpg_run:
            return RUNNING
        if self._kept is not None:
            return QUEUE_FULL  # after K only one L vector fits (GVE64 §13.5.9)
        ex = self._exec
        n = ex.queue_len
        if n >= self._capacity and not (self._a5_excl and n == self._capacity and ex.running):
            return QUEUE_FULL
        ex.push(args, True)
        return OK

    def _cmd_L(self, args: tuple, t: float) -> Reply:
        if self._mpg_run:
            return RUNNING
        ex = self._exec
        if self._kept is not None or not self._a4_queued:
            if ex.queue_len:
                return QUEUE_FULL
        elif self._queue_full():
            return QUEUE_FULL
        ex.push(args, False)
        return OK

    def _cmd_W(self, args: tuple, t: float) -> Reply:
        axis, to_switch, speed_to, from_switch, speed_from = args
        if self._inta:
            return RUNNING  # an interrupted unit would not start the move before G
        if to_switch == 0:
            return OK
        i = self.variant.axes.index(axis)
        direction = 1 if to_switch > 0 else -1
        dist = self.switches[axis]
        found = abs(to_switch) >= dist
        legs = [(min(abs(to_switch), dist) * direction, speed_to)]
        back = min(from_switch, self.switch_release) if found else 0
        if back:
            legs.append((-direction * back, speed_from))
        ex = self._exec
        params = ex.params
        for length, speed in legs:
            d = [0] * self._naxes
            d[i] = length
            ex.params = params.replace(v=float(max(speed, MIN_SPEED)), vl=None)
            ex.push(tuple(d), False)
        ex.params = params
        self._awaiting = True
        self._w_pending = True
        self._update_timers()
        return DEFER

    def _cmd_K(self, args: tuple, t: float) -> Reply:
        if self._kept is not None:
            return RUNNING  # KEEP only once without RESTORE (GVE64 §13.5.9)
        try:
            self._exec.park()
        except MotionStateError:
            return RUNNING
        self._kept = (self._st[4], self._st[5], self._inta, self._intcom, self._st6_extra)
        self._st[4] = self._st[5] = 0
        self._inta = self._intcom = False
        self._st6_extra = 0
        return OK

    def _cmd_R(self, args: tuple, t: float) -> Reply:
        if self._kept is None:
            return OK  # nothing kept: without effect
        try:
            self._exec.restore()
        except MotionStateError:
            return RUNNING
        self._st[4], self._st[5], self._inta, self._intcom, self._st6_extra = self._kept
        self._kept = None
        return OK

    def _cmd_H(self, args: tuple, t: float) -> Reply:
        t_stop = self._exec.halt(t)
        self._inta = True
        self._intcom = True
        if t_stop <= t:
            return OK
        self._awaiting = True
        self._defer_t = t_stop
        self._defer_reply = (OK, ())
        self._update_timers()
        return DEFER

    def _cmd_D(self, args: tuple, t: float) -> Reply:
        try:
            self._exec.clear()
        except MotionStateError:
            return RUNNING
        self._st[4] = self._st[5] = 0
        self._inta = self._intcom = False
        self._st6_extra = 0
        return OK

    def _cmd_G(self, args: tuple, t: float) -> Reply:
        if not self._inta:
            return OK if self._a15_zero else NOTHING_TO_GO
        something = self._exec.queue_len > 0
        self._exec.resume(t)
        self._inta = self._intcom = False
        self._st[4] = self._st[5] = 0
        return OK if something else NOTHING_TO_GO
