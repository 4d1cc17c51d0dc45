"""What a line does to a real machine, and the guard that keeps a run inside what it may use.

``hazards(line)`` names the risks of one command line: ``motion`` (L, C, W, Y+/Y&, G, a packet
holding vectors), ``actuator`` (outputs switched on, spindle speed), ``eeprom`` (EEPROM writes),
``reset`` (J). Against a real unit a check whose script carries a hazard the run did not allow is
SKIPPED; the guard refuses such a line outright as a last line of defence, and bounds every axis
move by ``max_steps``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from conform.errors import UserError

_LINE = re.compile(rb"^!(\d)([^\r\n]*)")
_VECTOR = re.compile(r"^[LC](-?\d+(?:,-?\d+)*)")
_WREF = re.compile(r"^W([A-Za-z]),(-?\d+),(\d+),(\d+),(\d+)")

# the answer to H, D and O0,FF when a run is interrupted (GVE64 §13.5.9, §13.5.11)
STOP_SEQUENCE = ("H", "D", "O0,FF")


class SafetyRefusal(UserError):
    """The guard refused to send a line (a harness decision, not the unit's fault)."""


def _bodies(body: str) -> list[str]:
    """The command text with and without a trailing ``,XX`` (which may be a checksum or a
    last parameter): the guard considers both readings."""
    m = re.search(r",([0-9A-Fa-f]{2})$", body)
    return [body, body[: m.start()]] if m else [body]


_NO_COUNT = re.compile(r"[^1-9]*")  # no reading of such a field gives a count other than 0
_LETTER_TAIL = re.compile(r"[A-Fa-f][0-9A-Fa-f]")  # a checksum no decimal reading takes for one
_W_STILL = re.compile(r"^W[A-Za-z],-?0+,\d+,0+(?:,\d+)?(?:,[0-9A-Fa-f]{2})?$")


def _zero_vector(body: str) -> bool:
    """``L0,0,0`` / ``C00,-0,0`` / ``C0#,0,0`` / ``C0,0,0,A8``: no field holds a digit 1-9
    (a checksum tail that reads as a fourth field starts with a letter): whatever a unit makes
    of the line, no axis gets a pulse (GVE64 §13.5.2: L0,0,0 has no motion effect)."""
    if body[:1] not in ("L", "C"):
        return False
    fields = body[1:].split(",")
    return all(_NO_COUNT.fullmatch(f) or (i == len(fields) - 1 and i >= 3
                                          and _LETTER_TAIL.fullmatch(f))
               for i, f in enumerate(fields))


def _w_still(body: str) -> bool:
    """``WX,0,1000,0,500``: a reference move of no length either way (GVE64 §13.5.7: n2 and
    n4 are the longest travel to and from the switch): nothing moves."""
    return _W_STILL.match(body) is not None


def hazards(line: bytes, idle: bool = False) -> set[str]:
    """The risks a command line carries for a real machine (empty for a harmless line).

    ``idle``: the host knows the queue is empty and nothing moves (read back with F after the
    state was reached, nothing that moves sent since), so ``G`` has nothing to start."""
    m = _LINE.match(line)
    if m is None:
        return set()
    address = int(m.group(1))
    try:
        text = m.group(2).decode("ascii")
    except UnicodeDecodeError:
        return set()
    out: set[str] = set()
    for body in _bodies(text):
        if address == 7:
            if body.startswith("V") and not _NO_COUNT.fullmatch(body[1:]):
                out.add("actuator")  # a spindle speed other than 0 (GVE64 §13.6)
        elif address == 0:
            if _zero_vector(body) or (body[:1] == "G" and idle) or _w_still(body):
                pass
            elif body[:1] in ("L", "C", "G", "W") or body.startswith(("Y+", "Y&")):
                out.add("motion")
            elif body.startswith("O") and body.upper() != "O0,FF":
                out.add("actuator")
        if address in (0, 7):
            if body.startswith(("EW", "EFW", "EUW")):
                out.add("eeprom")
            elif body.startswith("J"):
                out.add("reset")
    if "actuator" in out and address == 0 and any(b.upper() == "O0,FF" for b in _bodies(text)):
        out.discard("actuator")  # O0,FF with its checksum: all outputs off
    if "actuator" in out and address == 7 and any(b == "V0" or b.lstrip("V0") == ""
                                                  for b in _bodies(text)):
        out.discard("actuator")
    return out


def axis_moves(line: bytes) -> list[int]:
    """The pulse counts a line may ask any axis to travel (vectors, W travels)."""
    m = _LINE.match(line)
    if m is None or m.group(1) != b"0":
        return []
    out: list[int] = []
    for body in _bodies(m.group(2).decode("ascii", "replace")):
        v = _VECTOR.match(body)
        if v:
            out += [int(x) for x in v.group(1).split(",")]
        w = _WREF.match(body)
        if w:
            out += [int(w.group(2)), int(w.group(4))]
    return out


@dataclass(frozen=True)
class Guard:
    """What a run may do to the machine behind the target."""

    allow_motion: bool = True
    max_steps: int | None = None
    allow_eeprom: bool = True

    @staticmethod
    def emulated() -> Guard:
        return Guard(True, None, True)

    def blocked(self, risks: set[str]) -> set[str]:
        """The risks this guard does not allow."""
        allowed = {"reset"}
        if self.allow_motion:
            allowed |= {"motion", "actuator"}
        if self.allow_eeprom:
            allowed.add("eeprom")
        return risks - allowed

    def moves(self, line: bytes) -> bool:
        """Does ``line`` set axes moving (the host no longer knows the unit idle)?"""
        return "motion" in hazards(line)

    def check(self, line: bytes, idle: bool = False) -> None:
        bad = self.blocked(hazards(line, idle))
        if bad:
            raise SafetyRefusal(f"refused to send {line!r}: {', '.join(sorted(bad))} not allowed "
                                "(use --allow-motion with --max-steps)")
        if self.max_steps is not None:
            for n in axis_moves(line):
                if abs(n) > self.max_steps:
                    raise SafetyRefusal(f"refused to send {line!r}: a move of {abs(n)} steps "
                                        f"exceeds --max-steps {self.max_steps}")


# why a check was not run on this target; the text before " (" groups them (not_verified)
INPUTS_SKIP = ("needs inputs driven (a real unit's inputs are switched by hand; with `conform "
               "emulate serve` behind the link: enable with --inputs-control PATH)")
_ENABLE = {"motion": "--allow-motion --max-steps N", "actuator": "--allow-motion --max-steps N",
           "eeprom": "--allow-eeprom"}


def blocked_reason(blocked: set[str]) -> str:
    how = " ".join(dict.fromkeys(_ENABLE.get(r, r) for r in sorted(blocked)))
    return f"needs {', '.join(sorted(blocked))} (not allowed in this run: enable with {how})"


def envelope_reason(pulses: int, max_steps: int) -> str:
    return (f"outside the envelope (a move of {pulses} pulses cannot be done inside "
            f"--max-steps {max_steps}: enable with --max-steps {pulses})")


def not_verified(results: Iterable[Any]) -> list[dict[str, Any]]:
    """SKIPPED checks grouped by why, with how to enable them: what a run did not verify."""
    groups: dict[str, dict[str, Any]] = {}
    for r in results:
        if getattr(r.grade, "value", r.grade) != "SKIPPED":
            continue
        reason, _, rest = r.detail.partition(" (")
        how = rest.rsplit("enable with ", 1)[-1].rstrip(")") if "enable with" in rest else ""
        if reason.startswith("outside the envelope"):
            g = groups.setdefault("outside the envelope (--max-steps)", {
                "reason": "outside the envelope (--max-steps)", "how": "", "count": 0,
                "checks": [], "needs_pulses": 0})
            pulses = int(rest.split(" pulses", 1)[0].rsplit(" ", 1)[-1])
            g["needs_pulses"] = max(g["needs_pulses"], pulses)
            g["how"] = f"--max-steps {g['needs_pulses']}"
        else:
            g = groups.setdefault(reason, {"reason": reason, "how": how, "count": 0,
                                           "checks": []})
        g["count"] += 1
        g["checks"].append(r.id)
    return sorted(groups.values(), key=lambda g: -g["count"])


def run_guard(emulated: bool, allow_motion: bool, max_steps: int | None,
              allow_eeprom: bool) -> Guard:
    """The guard of a run: a real unit gets what the options allow; the emulator everything,
    inside ``--max-steps`` when given (so it plans the same checks as a real unit would)."""
    if emulated:
        return Guard(True, max_steps, True)
    return Guard(allow_motion, max_steps, allow_eeprom)
