"""Faults for grbl scenarios and the control socket, on top of the link's own
(:class:`conform.link.faults.FaultInjector`: noise, latency, garbled lines, disconnects).

What a scenario or a control request decides at run time: answer lines (``ok``/``error:N``)
lost or garbled, at random (``lose``/``garble``, a probability per answer) or the next few
(``lose_next``/``garble_next``); and the cable pulled (``unplug``): the link goes down for a
while, the pty is closed and made again, and the board restarts when it is plugged back (a
USB-powered Arduino loses power with its cable), which the emulator's reopen hook applies
(:func:`conform.families.grbl.serve.reopen_with_power_cycle`).
"""

from __future__ import annotations

from conform.link.faults import FaultConfig, FaultInjector

ANSWER_PREFIXES = (b"ok", b"error:")


class GrblFaults(FaultInjector):
    def __init__(self, config: FaultConfig | None = None, seed: int | None = None,
                 t0: float = 0.0, *, lose: float = 0.0, garble: float = 0.0) -> None:
        super().__init__(config or FaultConfig(), seed, t0)
        self.lose, self.garble = lose, garble
        self.lose_next = self.garble_next = 0
        self.counts.update(lost_answers=0, garbled_answers=0, unplugged=0)

    def feed(self, direction: str, data: bytes, t: float) -> list[tuple[float, bytes]]:
        if direction == "unit" and data.startswith(ANSWER_PREFIXES) and t >= self.down_until:
            if self.lose_next or (self.lose and self.rng.random() < self.lose):
                self.lose_next = max(0, self.lose_next - 1)
                self.counts["lost_answers"] += 1
                return []
            if self.garble_next or (self.garble and self.rng.random() < self.garble):
                self.garble_next = max(0, self.garble_next - 1)
                self.counts["garbled_answers"] += 1
                data = self._noise(data)
        return super().feed(direction, data, t)

    def _noise(self, data: bytes) -> bytes:
        """The answer's text (not its line end) with one to all of its bytes replaced."""
        body, end = data.rstrip(b"\r\n"), data[len(data.rstrip(b"\r\n")):]
        start = self.rng.randrange(len(body))
        stop = self.rng.randrange(start, len(body)) + 1
        noise = bytes(self.rng.choice(b"#%&*+-./0123456789:;@ABCDEFXYZ\x7f\xff")
                      for _ in range(stop - start))
        return body[:start] + noise + body[stop:] + end
