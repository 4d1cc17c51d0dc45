"""The GVE emulator's control commands: change inputs while it runs, read its state.

One text line per request, one line back (``ok ...`` or ``error: ...``)::

    input 1 7 off          set the electrical level of I1 bit 7 (what I1 reads)
    press stop             assert an input per the current polarity (ST2/ST3): may interrupt
    release stop           the opposite level
    state                  JSON: position, queue, ST0..ST6, INTA/RUN, inputs, outputs, ...
    help

Names for ``press``/``release`` follow the Gravos wiring of GVE64 §13.5.12 (``stop`` is IN7,
``refx`` IN0, ``sensor`` I2 bit 7...); ``PORT.BIT`` (``1.7``) works too. :func:`run_control`
is pure (no sockets): the ``commands`` hook of :class:`conform.emulator.serve.Emulator`, which
serves it on a unix socket; :func:`conform.emulator.control.send_control` is the client
``conform emulate control`` uses.
"""

from __future__ import annotations

import json

from conform.families.gve.unit.model import Unit

INPUT_NAMES: dict[str, tuple[int, int]] = {
    "refx": (1, 0), "refy": (1, 1), "refz": (1, 2), "start": (1, 3), "endz": (1, 4),
    "endy": (1, 5), "endx": (1, 6), "stop": (1, 7), "sensor-button": (2, 6), "sensor": (2, 7),
}

HELP = ("commands: input PORT BIT on|off | press NAME | release NAME | state | help; "
        f"names: {', '.join(INPUT_NAMES)} or PORT.BIT")


def _input(name: str) -> tuple[int, int]:
    if name in INPUT_NAMES:
        return INPUT_NAMES[name]
    port, dot, bit = name.partition(".")
    if dot and port.isdigit() and bit.isdigit():
        return int(port), int(bit)
    raise ValueError(f"unknown input {name!r}")


def state(unit: Unit) -> dict[str, object]:
    """The unit's state as plain data (for ``state`` and tests)."""
    return {
        "variant": unit.variant.id, "time": unit.now, "position": list(unit.position),
        "queue": unit.queue_len, "status": ["%02X" % unit.status(n) for n in range(7)],
        "inta": unit.inta, "run": unit.run, "inputs": {"I1": "%02X" % unit.input_level(1),
                                                       "I2": "%02X" % unit.input_level(2)},
        "outputs": "%02X" % unit.outputs, "spindle": unit.spindle, "checksum": unit.checksum_on,
        "index": unit.index, "mpg": unit.mpg, "deaf": unit.deaf, "modal": {
            k: list(v) if isinstance(v, tuple) else v for k, v in unit.modal.items()},
    }


def run_control(unit: Unit, line: str, t: float) -> str:
    """Execute one control line at time ``t``; return the reply line."""
    words = line.strip().lower().split()
    if not words:
        return "error: empty command"
    cmd, args = words[0], words[1:]
    try:
        if cmd == "help":
            return "ok " + HELP
        if cmd == "state":
            return "ok " + json.dumps(state(unit), separators=(",", ":"))
        if cmd == "input" and len(args) == 3:
            port, bit = int(args[0]), int(args[1])
            if args[2] not in ("on", "off", "1", "0", "high", "low"):
                return f"error: level {args[2]!r} is not on/off"
            unit.set_level(port, bit, args[2] in ("on", "1", "high"), t)
        elif cmd in ("press", "release") and len(args) == 1:
            port, bit = _input(args[0])
            unit.set_input(port, bit, cmd == "press", t)
        else:
            return f"error: cannot parse {line.strip()!r}; {HELP}"
    except ValueError as exc:
        return f"error: {exc}"
    return "ok I1=%02X I2=%02X INTA=%d ST4=%02X ST5=%02X" % (
        unit.input_level(1), unit.input_level(2), unit.inta, unit.status(4), unit.status(5))
