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

import json
from typing import Any

from conform.errors import UserError
from conform.families.grbl.unit.faults import GrblFaults
from conform.families.grbl.unit.inputs import PINS, set_input
from conform.link.faults import FaultConfig

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


class GrblControl:
    """Runs control requests against a grbl unit; ``faults`` is the emulator's injector."""

    def __init__(self, faults: GrblFaults) -> None:
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
            if cmd in ("press", "release") and len(args) == 1:
                set_input(unit, args[0].lower(), cmd == "press", t)
                return f"ok {unit.state}" + (f" Pn:{''.join(sorted(unit.pins))}"
                                             if unit.pins else "")
            if cmd == "fault" and args:
                return self._fault(args[0].lower(), args[1:], t)
        except (ValueError, UserError) as exc:
            return f"error: {exc}"
        except Exception as exc:  # noqa: BLE001 - a request never stops the emulator
            return f"error: {type(exc).__name__}: {exc}"
        return f"error: cannot parse {line.strip()[:80]!r}; {HELP}"

    def _fault(self, kind: str, args: list[str], t: float) -> str:
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
        if kind in ("lose", "garble"):
            if not (0 <= x <= 1_000_000 and x == int(x)):
                raise ValueError(f"fault {kind} {args[0]}: expected a count 0..1000000")
            setattr(f, f"{kind}_next", int(x))
            return f"ok the next {int(x)} answer(s) will be {'lost' if kind == 'lose' else 'garbled'}"
        if kind == "unplug":
            if not 0 < x <= 3600:
                raise ValueError(f"fault unplug {args[0]}: expected 0..3600 seconds")
            f.unplug(t, x)
            return f"ok cable pulled for {x:g} s"
        raise ValueError(f"unknown fault {kind!r} (lose, garble, unplug, line)")
