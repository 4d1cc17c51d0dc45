"""How ``conform emulate judge`` compares grbl's answers with a recording of the real firmware.

The engine (conform/emulator/judge.py) plays the recording's host writes into the reference
unit and compares the answer lines; grbl tells it which lines close an answer (``ok`` and
``error:N``, what a streaming sender counts), what may differ between two runs of the same
build (:func:`mask`), and which lines are the same within the motion model's tolerance
(:func:`near`: status reports while the machine moves).
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


def mask(line: str) -> str:
    """grbl prints nothing that differs from one run of a build to the next at rest: the line
    is compared whole."""
    return line


def _fields(line: str) -> tuple[str, dict[str, str]] | None:
    m = _STATUS.match(line)
    if m is None or m[3] != _STATUS.match(line)[3]:
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
