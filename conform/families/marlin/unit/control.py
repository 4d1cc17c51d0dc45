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

from conform.emulator.control import FaultControl
from conform.families.marlin.unit.faults import MarlinFaults

HELP = ("commands: fault lose N | fault busy SECONDS | fault unplug SECONDS | fault line SPEC | "
        "reset | state | truth | help")


def state(u: Any) -> dict[str, Any]:
    return {"variant": u.v.id, "time": u.now, "last_line": u.last_n, "queued": len(u.queue),
            "running": u.cur.text if u.cur else None, "planner": len(u.planner),
            "position": [round(x, 4) for x in u.position], "halted": u.halted,
            "rx_bytes": len(u.rx), "lost": u.lost, "discarded": u.discarded,
            "twice": sorted(k for k, n in u.truth.executed.items() if n > 1)}


class MarlinControl(FaultControl):
    """Marlin's control requests on the engine's shape; ``faults`` is the emulator's injector."""

    help_text = HELP
    counted = ("lose",)

    def __init__(self, faults: MarlinFaults) -> None:
        super().__init__(faults)

    def state(self, unit: Any) -> dict[str, Any]:
        return state(unit)

    def verb(self, unit: Any, cmd: str, args: list[str], t: float) -> str | None:
        if cmd == "truth" and not args:
            return "ok " + json.dumps(unit.truth.to_dict(), separators=(",", ":"))
        if cmd == "reset" and not args:
            unit.power_cycle(t)
            return "ok reset: the banner follows, line number 0"
        return None

    def fault(self, unit: Any, kind: str, x: float, t: float) -> str | None:
        if kind != "busy":
            return None
        if not 0 < x <= 3600:
            raise ValueError(f"fault busy {x:g}: expected 0..3600 seconds")
        unit.stall(t, x)
        return f"ok busy for {x:g} s"

    def unplugged(self, unit: Any, t: float) -> None:
        unit.power_off(t)       # a USB board is powered through its cable
