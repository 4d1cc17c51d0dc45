"""Faults for Marlin scenarios and the control socket, on top of the link's own
(:class:`conform.link.faults.FaultInjector`: noise on the host's lines, which Marlin answers
with checksum errors and ``Resend:``; latency; disconnects).

Decided at run time: the next few ``ok`` lines lost (``lose_next``) or a share of them at random
(``lose``), and the cable pulled (``unplug``): the pty closes for a while and, since a USB
board is powered and reset through its cable, the unit has restarted (banner, line number 0)
when it is back (:func:`conform.families.marlin.unit.serve.reopen_with_reset`).
"""

from __future__ import annotations

from conform.link.faults import FaultConfig, FaultInjector


class MarlinFaults(FaultInjector):
    def __init__(self, config: FaultConfig | None = None, seed: int | None = None,
                 t0: float = 0.0, *, lose: float = 0.0) -> None:
        super().__init__(config or FaultConfig(), seed, t0)
        self.lose = lose
        self.lose_next = 0
        self.counts.update(lost_oks=0, unplugged=0)

    def feed(self, direction: str, data: bytes, t: float) -> list[tuple[float, bytes]]:
        if direction == "unit" and data.startswith(b"ok") and t >= self.down_until:
            if self.lose_next or (self.lose and self.rng.random() < self.lose):
                self.lose_next = max(0, self.lose_next - 1)
                self.counts["lost_oks"] += 1
                return []
        return super().feed(direction, data, t)
