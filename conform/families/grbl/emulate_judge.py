"""How ``conform emulate judge`` compares grbl's answers with a recording of the real firmware.

The engine (conform/emulator/judge.py) plays the recording's host writes into the reference
unit and compares the answer lines; grbl tells it which lines close an answer (``ok`` and
``error:N``, what a streaming sender counts), which lines are the same within the motion
model's tolerance (:func:`near`: status reports while the machine moves) and where to place
the reference after a moment-dependent stop (:class:`Follow`). grbl prints nothing that
differs between two runs of one build at rest, so no line is masked.
"""

from __future__ import annotations

import re

from conform.families.grbl.unit.planner import TIMING_TOLERANCE

_ANSWER = re.compile(r"^(ok|error:\d+)$")
_STATUS = re.compile(r"^<([A-Za-z]+(?::\d)?)\|(.*)>(\r?\n)?$")
_MOVING = ("Run", "Jog", "Home", "Hold:1")
_POSITIONS = ("MPos", "WPos")


def is_answer(line: str) -> bool:
    """``ok`` or ``error:N``: the end of the answer to one line (protocol.c,
    report_status_message)."""
    return _ANSWER.match(line) is not None


class Follow:
    """Where the recording's state is given to the reference (``Family.judge_follow``): places
    a machine reached by the moment something happened rather than by the model.

    - A homing cycle cut by a reset (``ALARM:6``) leaves the machine wherever the cycle had
      got to. In the recordings that is where grbl-sim's switchless seek travelled by the
      simulator's own clock (its input pins read high: the recordings' README names this
      artefact), which no model of a machine reproduces; the reference is put where the first
      status report after the alarm shows the recorded machine.
    - A reset during motion (``ALARM:3``) and a feed hold (``Hold:0``, ``Door:0``) stop a
      moving machine where it was at that moment: positions while moving depend on the
      timing (README), so the reference, when it stands within the motion model's stated
      tolerance of the recorded machine (planner.TIMING_TOLERANCE at the fastest axis' rate),
      is put exactly there; farther away, it is left where it is and the difference shows.

    The status reports themselves, and everything after, are still compared."""

    def __init__(self) -> None:
        self.homing_cut = False
        self.stopped = False

    def __call__(self, unit: object, line: str) -> None:
        if line == "ALARM:6":
            self.homing_cut = True
            return
        if line == "ALARM:3":
            self.stopped = True
            return
        got = _fields(line + "\r\n")
        if got is None or "MPos" not in got[1]:
            return
        held = got[0] in ("Hold:0", "Door:0")
        if not (self.homing_cut or self.stopped or held):
            return
        free = self.homing_cut
        self.homing_cut = self.stopped = False
        try:
            where = [float(x) for x in got[1]["MPos"].split(",")]
        except ValueError:
            return
        place = getattr(unit, "place", None)
        if place is None:
            return
        if not free:
            settings = getattr(unit, "settings", {})
            rate = max((settings.get(110 + i, 0.0) for i in range(3)), default=0.0) / 60.0
            now = getattr(unit, "position", where)
            if len(now) != len(where) or any(
                    abs(a - b) > rate * TIMING_TOLERANCE + 0.001 for a, b in zip(
                        now, where, strict=True)):
                return
        place(where)


def _fields(line: str) -> tuple[str, dict[str, str]] | None:
    """A status report's state and its fields by name; None for any other line."""
    m = _STATUS.match(line)
    if m is None:
        return None
    fields = {}
    for part in m[2].split("|"):
        name, _, value = part.partition(":")
        fields[name] = value
    return m[1], fields


def near(recorded: str, reference: str, accel: float = 10.0) -> bool:
    """Two status reports taken while the machine moves (Run, Jog, Home, a hold still
    decelerating) are the same when their state, line ending and fields agree, and their
    positions and feed differ by no more than the motion model's stated timing tolerance
    (planner.TIMING_TOLERANCE) explains: where a moving machine is when the report is taken
    depends on the timing of the run. ``accel``: the fastest acceleration of the axes, mm/s²
    (the $120-$122 default). Reports at rest are compared exactly."""
    a, b = _fields(recorded), _fields(reference)
    if a is None or b is None or a[0] != b[0] or a[0] not in _MOVING:
        return False
    if recorded[-2:] != reference[-2:] or list(a[1]) != list(b[1]):
        return False
    try:
        fa = [float(x) for x in a[1].get("FS", a[1].get("F", "0")).split(",")]
        fb = [float(x) for x in b[1].get("FS", b[1].get("F", "0")).split(",")]
    except ValueError:
        return False
    dt = TIMING_TOLERANCE
    if fa[1:] != fb[1:] or abs(fa[0] - fb[0]) > accel * dt * 60:
        return False
    span = max(fa[0], fb[0]) / 60 * dt + 0.001
    for name, value in a[1].items():
        other = b[1][name]
        if name in _POSITIONS:
            try:
                xs = [float(x) for x in value.split(",")]
                ys = [float(x) for x in other.split(",")]
            except ValueError:
                return False
            if len(xs) != len(ys) or any(abs(x - y) > span for x, y in zip(xs, ys, strict=True)):
                return False
        elif name not in ("FS", "F") and value != other:
            return False
    return True
