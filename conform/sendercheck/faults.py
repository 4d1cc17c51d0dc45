"""Faults a scenario scripts on top of :class:`conform.link.faults.FaultInjector`.

The injector's own faults (noise, garbled answers, converter latency) stay as they are;
this adds what a scenario needs to decide at run time: whole answers lost at random
(``lose``), and a dead line for a while (``kill_link``): every byte either way is dropped
while the emulator keeps reading, as when a cable is pulled and plugged back in.
"""

from __future__ import annotations

from conform.link.faults import FaultConfig, FaultInjector


class ScriptedFaults(FaultInjector):
    def __init__(self, config: FaultConfig, seed: int | None = None, t0: float = 0.0, *,
                 lose: float = 0.0) -> None:
        super().__init__(config, seed, t0)
        self.lose = lose
        self.counts["lost_answers"] = 0
        self.dead: tuple[float, float] | None = None

    def kill_link(self, t: float, downtime: float) -> None:
        """From ``t`` for ``downtime`` seconds nothing crosses the line."""
        self.dead = (t, t + downtime)

    def feed(self, direction: str, data: bytes, t: float) -> list[tuple[float, bytes]]:
        dead = self.dead
        if dead is not None and dead[0] <= t < dead[1]:
            self.counts["dropped"] += len(data)
            return []
        if direction == "unit" and self.lose and b"\r" in data and self.rng.random() < self.lose:
            self.counts["lost_answers"] += 1
            return []
        return super().feed(direction, data, t)
