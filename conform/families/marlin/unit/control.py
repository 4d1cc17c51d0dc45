"""The Marlin emulator's control requests, one text line each way over the emulator's unix
socket (``conform emulate control SOCKET ...``)::

    fault lose N          the next N ok lines never arrive
    fault busy SECONDS    the unit is busy (a long move, a heater) for that long: nothing is
                          read, ``busy: processing`` every keepalive interval
    fault unplug SECONDS  the cable is pulled; when it is back the board has restarted
    fault line SPEC       the link's noise from now on (conform.link.faults, e.g.
                          host.corrupt=1e-3); an empty SPEC clears it
    reset                 a reset (DTR pulse, reset button): the banner, line number 0
    state                 JSON: line number, queue, planner, halted, lines run twice ...
    truth                 JSON: the ground truth (how often each numbered line ran)
    help
"""

from __future__ import annotations

import json
from typing import Any

from conform.families.marlin.unit.faults import MarlinFaults
from conform.link.faults import FaultConfig

HELP = ("commands: fault lose N | fault busy SECONDS | fault unplug SECONDS | fault line SPEC | "
        "reset | state | truth | help")


def state(u: Any) -> dict[str, Any]:
    return {"variant": u.v.id, "time": u.now, "last_line": u.last_n, "queued": len(u.queue),
            "running": u.cur.text if u.cur else None, "planner": len(u.planner),
            "position": [round(x, 4) for x in u.position], "halted": u.halted,
            "rx_bytes": len(u.rx), "lost": u.lost, "discarded": u.discarded,
            "twice": sorted(k for k, n in u.truth.executed.items() if n > 1)}


class MarlinControl:
    """Runs control requests against a Marlin unit; ``faults`` is the emulator's injector."""

    def __init__(self, faults: MarlinFaults) -> None:
        self.faults = faults

    def __call__(self, unit: Any, line: str, t: float) -> str:
        words = line.strip().split()
        if not words:
            return "error: empty command"
        cmd, args = words[0].lower(), words[1:]
        try:
            if cmd == "help":
                return "ok " + HELP
            if cmd == "state":
                return "ok " + json.dumps(state(unit), separators=(",", ":"))
            if cmd == "truth":
                return "ok " + json.dumps(unit.truth.to_dict(), separators=(",", ":"))
            if cmd == "reset" and not args:
                unit.power_cycle(t)
                return "ok reset: the banner follows, line number 0"
            if cmd == "fault" and args:
                return self._fault(unit, args[0].lower(), args[1:], t)
        except ValueError as exc:
            return f"error: {exc}"
        except Exception as exc:  # noqa: BLE001 - a request never stops the emulator
            return f"error: {type(exc).__name__}: {exc}"
        return f"error: cannot parse {line.strip()[:80]!r}; {HELP}"

    def _fault(self, unit: Any, kind: str, args: list[str], t: float) -> str:
        f = self.faults
        if kind == "line":
            f.config = FaultConfig.parse(",".join(args)) if args else FaultConfig()
            return "ok line faults: " + (",".join(args) or "none")
        if len(args) != 1:
            raise ValueError(f"fault {kind} takes one number")
        try:
            x = float(args[0])
        except ValueError:
            raise ValueError(f"{args[0]!r} is not a number") from None
        if kind == "lose":
            if not (0 <= x <= 1_000_000 and x == int(x)):
                raise ValueError(f"fault lose {args[0]}: expected a count 0..1000000")
            f.lose_next = int(x)
            return f"ok the next {int(x)} ok line(s) will be lost"
        if not 0 < x <= 3600:
            raise ValueError(f"fault {kind} {args[0]}: expected 0..3600 seconds")
        if kind == "busy":
            unit.stall(t, x)
            return f"ok busy for {x:g} s"
        if kind == "unplug":
            f.unplug(t, x)
            unit.power_off(t)       # a USB board is powered through its cable
            return f"ok cable pulled for {x:g} s"
        raise ValueError(f"unknown fault {kind!r} (lose, busy, unplug, line)")
