"""The grbl emulator's control requests: drive its input pins and inject faults while it runs.

One text line per request, one line back (``ok ...`` or ``error: ...``), over the same unix
socket as GVE's (:class:`conform.emulator.serve.ControlServer`, ``conform emulate control``)::

    press NAME | release NAME   an input pin (conform.families.grbl.unit.inputs): probe, door,
                                limit-x/-y/-z, hold, start, reset
    fault lose N                the next N answer lines (ok / error:N) never arrive
    fault garble N              the next N answer lines arrive damaged
    fault unplug SECONDS        the cable is pulled: the pty closes, and when it is back the
                                board has restarted (banner, planner empty)
    fault line SPEC             the link's noise from now on (conform.link.faults spec,
                                e.g. corrupt=1e-3,latency=1-16; an empty SPEC clears it)
    state                       JSON: state, position, pins, buffers, bytes lost, ...
    help

:class:`GrblControl` is pure (no sockets): called with the unit, the request and the time.
"""

from __future__ import annotations

from typing import Any

from conform.emulator.control import FaultControl
from conform.families.grbl.unit.faults import GrblFaults
from conform.families.grbl.unit.inputs import PINS, set_input

HELP = ("commands: press NAME | release NAME | fault lose N | fault garble N | "
        "fault unplug SECONDS | fault line SPEC | state | help; "
        f"inputs: {', '.join(PINS)}")


def state(u: Any) -> dict[str, Any]:
    """The grbl unit's state as plain data (for ``state`` and tests)."""
    return {"variant": u.v.id, "time": u.now, "state": u.state, "hold_sub": u.hold_sub,
            "critical": u._critical, "position": [round(x, 6) for x in u.position],
            "pins": "".join(sorted(u.pins)), "door_open": u.door_open,
            "planner_free": u.planner.free, "rx_free": u.rx_free, "lost": u.lost,
            "lines_done": u.lines_done, "probe": [*u.prb, int(u.prb_ok)],
            "overrides": [u.ov_feed, u.ov_rapid, u.ov_spindle]}


class GrblControl(FaultControl):
    """grbl's control requests on the engine's shape; ``faults`` is the emulator's injector."""

    help_text = HELP
    counted = ("lose", "garble")

    def __init__(self, faults: GrblFaults) -> None:
        super().__init__(faults)

    def state(self, unit: Any) -> dict[str, Any]:
        return state(unit)

    def verb(self, unit: Any, cmd: str, args: list[str], t: float) -> str | None:
        if cmd in ("press", "release") and len(args) == 1:
            set_input(unit, args[0].lower(), cmd == "press", t)
            return f"ok {unit.state}" + (f" Pn:{''.join(sorted(unit.pins))}" if unit.pins else "")
        return None
