"""Virtual time of the reference unit: what is due when, and the answers that come late.

The unit never reads a clock: every call brings its time. Between calls the timers fire in
order: the watchdog of a begun line (A13), a deferred answer (H at the end of its ramp, W at
the end of its move), after which the bytes held meanwhile are processed (A16).
"""

from __future__ import annotations

from collections.abc import Sequence

from conform.families.gve.unit.replies import INF, OK
from conform.families.gve.unit.state import UnitState


class Timing(UnitState):
    """``poll``, ``next_deadline`` and the timers."""

    def poll(self, t: float) -> list[tuple[float, bytes]]:
        """Everything the unit sends up to ``t``: a list of (time due, bytes)."""
        self._advance(t)
        out = self._outbox
        if not out:
            return []
        if out[-1][0] <= t:
            self._outbox = []
            return out
        n = 0
        while n < len(out) and out[n][0] <= t:
            n += 1
        due = out[:n]
        del out[:n]
        return due

    def next_deadline(self) -> float | None:
        """The next time something happens: an answer due, a vector ending, the watchdog,
        the end of J's deaf time."""
        best = INF
        if self._outbox:
            best = self._outbox[0][0]
        te = self._next_timer()[0]
        if te < best:
            best = te
        if self._deaf_until > self._now and self._deaf_until < best:
            best = self._deaf_until
        ev = self._exec.next_event_time()
        if ev is not None and ev < best:
            best = ev if ev > self._now else self._now
        return None if best == INF else best

    def _advance(self, t: float) -> None:
        if t < self._now:
            t = self._now
        while self._timers:
            te, kind = self._next_timer()
            if te > t:
                break
            if te < self._now:
                te = self._now
            self._exec.advance(te)
            self._now = te
            self._fire(kind, te)
        self._exec.advance(t)
        self._now = t

    def _next_timer(self) -> tuple[float, str]:
        if not self._timers:
            return INF, ""
        best, kind = self._wd, "wd"
        if self._defer_t < best:
            best, kind = self._defer_t, "defer"
        if self._w_pending:
            if not self._exec.running:
                te: float | None = self._now
            else:
                te = self._exec.next_event_time()
            if te is not None and te < best:
                best, kind = te, "w"
        return best, kind

    def _update_timers(self) -> None:
        self._timers = self._wd != INF or self._defer_t != INF or self._w_pending

    def _fire(self, kind: str, t: float) -> None:
        if kind == "wd":
            self._watchdog(t)
        elif kind == "defer":
            code, fields = self._defer_reply
            self._defer_t = INF
            self._send_late(code, fields, t)
        elif kind == "w" and not self._exec.running:
            self._w_pending = False
            self._send_late(OK, (), t)
        self._update_timers()

    def _send_late(self, code: int, fields: Sequence[object], t: float) -> None:
        """A deferred answer (HALT, W) goes out; then the bytes held meanwhile (A16)."""
        ans = self.encode(code, fields)
        self._outbox.append((t, ans))
        self._last_answer = ans
        self._awaiting = False
        self._update_timers()
        lines, self._held_lines = self._held_lines, []
        chunks, self._held_chunks = self._held_chunks, []
        for i, line in enumerate(lines):
            if t < self._deaf_until:
                return
            if self._awaiting:
                self._held_lines.extend(lines[i:])
                self._held_chunks.extend(chunks)
                return
            self._process_line(line, t)
        for i, chunk in enumerate(chunks):
            if t < self._deaf_until:
                return
            if self._awaiting:
                self._held_chunks.extend(chunks[i:])
                return
            self._feed(chunk, t)
        self._start_watchdog(t)

    def _exchange_wait(self, t: float) -> tuple[float, bytes]:
        got: list[tuple[float, bytes]] = []
        now = self._now
        while True:
            got.extend(self.poll(now))
            if not (self._awaiting or self._wd != INF or self._outbox):
                break
            te = self._next_timer()[0]
            if self._outbox and self._outbox[0][0] < te:
                te = self._outbox[0][0]
            if te == INF:
                break
            now = te if te > now else now
            self._advance(now)
        if not got:
            return (t, b"")
        return (got[0][0], b"".join(b for _, b in got))
