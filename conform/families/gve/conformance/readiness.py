"""Reaching a GVE unit again after J: the ~2 s it is deaf (GVE64 §13.4), polled with ``@`` or
waited out with the readiness measured, and what that cost. The target's reset and the state
keeper both use it."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from conform.conformance.target import HarnessError, LinkSilent, Reply

if TYPE_CHECKING:
    from conform.families.gve.conformance.target import GveTarget as Target

POLL_LINE = b"!0@\r"  # readiness after J: answered once the unit hears; not counted (A10)
POLL_EVERY = 0.1  # seconds between readiness polls after J
READY_MARGIN = 3.0  # seconds past the table's deaf time before a silent unit is a lost link
QUIET_MARGIN = 0.4  # seconds added to the measured readiness when a poll would show


@dataclass
class StateStats:
    """What reaching the checks' states cost (in the report's run data)."""

    tidy: int = 0  # checks started with commands
    resets: int = 0  # checks started with J (polled readiness)
    quiet_resets: int = 0  # J with the measured readiness (a poll would show in the check)
    fallbacks: int = 0  # tidy not confirmed by reading: J after all
    seconds: float = 0.0  # wall time spent reaching states
    readiness: float | None = None  # longest J → first answer measured (s)
    reasons: dict[str, int] = field(default_factory=dict)  # why J was needed

    def to_json(self) -> dict[str, Any]:
        return {"tidy": self.tidy, "resets": self.resets, "quiet_resets": self.quiet_resets,
                "fallbacks": self.fallbacks, "seconds": round(self.seconds, 3),
                "readiness_s": None if self.readiness is None else round(self.readiness, 3),
                "reset_reasons": dict(sorted(self.reasons.items(), key=lambda kv: -kv[1]))}


_POLL_ANSWER = re.compile(rb"^[0-9A-F],")  # @'s answer (J's own, under A17, has no field)


def power_up(tg: Target, stats: StateStats, ready_after: float, quiet: bool = False
             ) -> Reply | None:
    """J, then wait until ``tg`` hears again: polled with ``@`` every POLL_EVERY s (bounded by
    ``ready_after`` + READY_MARGIN), or — ``quiet``, when a poll would show in what follows — the
    longest readiness measured so far plus QUIET_MARGIN. A J the unit refused (a checksum
    framing it did not expect: an error code, or a unit that hears at once) is sent again in
    the other framing."""
    tg.resync()
    for attempt in range(3):
        framing = tg.checksum_on
        t_sent = tg.now()
        tg.exchange(tg.frame("!0J"), 0.0, linger=0.0)
        if quiet and stats.readiness is not None and attempt == 0:
            stats.quiet_resets += 1
            tg.wait(max(0.0, t_sent + stats.readiness + QUIET_MARGIN - tg.now()))
            tg.drain()
            tg.checksum_on = False
            tg.idle = True
            return None
        refused = False
        bound = t_sent + ready_after + READY_MARGIN
        while tg.now() < bound:
            reply = tg.exchange(POLL_LINE, POLL_EVERY, lines=2, linger=0.01)
            answers = [*([reply.stray] if reply.stray else []), *reply.lines]
            if any(a[:1] in (b"4", b"C") for a in answers):
                refused = True
                break
            if reply.lines and _POLL_ANSWER.match(reply.lines[-1]):
                ready = tg.now() - t_sent
                if ready < ready_after / 2:  # it never stopped hearing: J was not taken
                    refused = True
                    break
                stats.resets += 1
                stats.readiness = max(stats.readiness or 0.0, ready)
                tg.checksum_on = False
                tg.idle = True  # just reset: queue empty, nothing runs (GVE64 §13.4)
                tg.wait(0.02)
                tg.drain()
                if quiet:  # the poll would show: J again, with the readiness just measured
                    return power_up(tg, stats, ready_after, quiet=True)
                reply.lines = reply.lines[-1:]  # the poll's own answer (not J's, A17)
                reply.stray = b""
                return reply
        if not refused:
            raise LinkSilent(f"{tg.name}: no answer {ready_after + READY_MARGIN:.1f} s after "
                             "J, the reset command (GVE64 §13.4): the link is lost or the "
                             "unit did not reset; check the cable and power, then run again")
        tg.checksum_on = not framing
        tg.resync()
    raise HarnessError(f"{tg.name}: J refused in both checksum framings")
