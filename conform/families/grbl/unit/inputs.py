"""grbl's input pins on the reference unit: limit switches, the probe, the safety door and the
feed-hold / cycle-start / reset buttons, as the emulator's control socket drives them.

What each does follows gnea/grbl: a limit switch with hard limits on (``$21=1``) in any state
but Alarm kills motion and raises ``ALARM:1`` with ``[MSG:Reset to continue]`` (limits.c,
interface.md §Alarm Message: critical, only a reset is taken); with ``$21=0`` it only shows in
``Pn:``. The probe ends a G38.x move when it reaches the state the command seeks (G38.2/.3:
contact, G38.4/.5: loss of contact) and grbl prints ``[PRB:…:1]`` (probe.c, motion_control.c
``mc_probe_cycle``, MESSAGE_PROBE_COORDINATES on by default); a probe already in that state
when the move starts is ``ALARM:4``. The door opens into the Door state (a hold), and
``~``/cycle start cannot resume while it is open (``Door:1``; ``Door:2`` while decelerating;
realtime_cmds.md 0x84, interface.md §Machine State). Feed hold, cycle start and reset act
like ``!``, ``~`` and Ctrl-X (system.c ``system_control_get_state``). Every triggered pin
shows in the status report's ``Pn:`` field, letters in report.c's order: P X Y Z D R H S.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from conform.families.grbl.unit import replies as rp

if TYPE_CHECKING:
    from conform.families.grbl.unit.model import GrblUnit

# control name -> Pn: letter
PINS = {"probe": "P", "limit-x": "X", "limit-y": "Y", "limit-z": "Z", "door": "D",
        "reset": "R", "hold": "H", "start": "S"}
ORDER = "PXYZDRHS"


def pin_field(u: GrblUnit) -> str | None:
    """``Pn:…`` when a pin is triggered, else None (the field is left out)."""
    if not u.pins:
        return None
    return "Pn:" + "".join(c for c in ORDER if c in u.pins)


def set_input(u: GrblUnit, name: str, on: bool, t: float) -> None:
    """Trigger (``on``) or release input ``name`` (one of :data:`PINS`) at time ``t``."""
    if name not in PINS:
        raise ValueError(f"unknown input {name!r} (inputs: {', '.join(PINS)})")
    u._advance(max(t, u.now))
    t = u.now
    letter = PINS[name]
    was = letter in u.pins
    (u.pins.add if on else u.pins.discard)(letter)
    if on == was:
        return
    if name.startswith("limit-"):
        if on and u.settings[21] and u.state not in ("Alarm", "Home"):
            inside_line = u._pending is not None or u._busy is not None
            u._hard_stop(t)
            u.state = "Alarm"
            u._critical = True
            u._owed = inside_line     # that line's ok comes after the reset, before the banner
            u._alarm(t, 1)
            u._say(t, rp.MSG["reset"])
    elif name == "probe":
        _probe_edge(u, on, t)
    elif name == "door":
        u.door_open = on
        if on:
            u._realtime(0x84, t)
    elif on:
        u._realtime({"reset": 0x18, "hold": 0x21, "start": 0x7E}[name], t)


def probe_blocks_start(u: GrblUnit, probe: str) -> bool:
    """A G38.x that starts with the probe already where it is meant to end: ALARM:4."""
    touching = "P" in u.pins
    return touching if probe in ("38.2", "38.3") else not touching


def _probe_edge(u: GrblUnit, on: bool, t: float) -> None:
    pl = u.planner
    if not (pl.blocks and pl.running and pl.blocks[0].kind == "probe"):
        return
    head = pl.blocks[0]
    if on != (head.tag.probe in ("38.2", "38.3")):
        return
    pos = pl.where(t)[0]
    busy = u._busy
    u._hard_stop(t)
    pl.clear(pos)
    u.prb, u.prb_ok = list(pos), True
    u.state = "Idle"
    u._say(t, f"[PRB:{rp.axes(pos, bool(u.settings[13]))}:1]")
    u._finish(t, 0, busy[1] if busy else None)
