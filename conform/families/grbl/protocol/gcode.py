"""The g-code parser of grbl 1.1f as a pure function: a stripped line and the modal state in,
an error code or a block to execute out.

It follows the order in which grbl checks a block (gnea/grbl grbl/gcode.c ``gc_execute_line``):
words are read and grouped first (errors 1, 2, 4, 20, 21, 23, 24, 25, 38), then the block is
checked against the modal state (22, 26–37), then leftover words give 36. The returned
:class:`Block` carries the new modal state and the motion to plan; the caller applies it only
when the code is 0, so a rejected line changes nothing (interface.md: "did not execute
anything inside that message").
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace

AXES = "XYZ"
VALUE_LETTERS = set("FIJKLNPRSTXYZ")
MM_PER_INCH = 25.4
_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)")

# modal groups (gcode.h): the key a G or M code occupies in one block
G_GROUPS: dict[str, str] = {
    **{k: "motion" for k in ("0", "1", "2", "3", "38.2", "38.3", "38.4", "38.5", "80")},
    **{k: "nonmodal" for k in ("4", "10", "28", "28.1", "30", "30.1", "53", "92", "92.1")},
    **{k: "plane" for k in ("17", "18", "19")},
    **{k: "distance" for k in ("90", "91")},
    "91.1": "arc_distance",
    **{k: "feed_mode" for k in ("93", "94")},
    **{k: "units" for k in ("20", "21")},
    "40": "cutter",
    **{k: "tlo" for k in ("43.1", "49")},
    **{k: "coord" for k in ("54", "55", "56", "57", "58", "59")},
    "61": "path",
}
M_GROUPS: dict[int, str] = {0: "program", 1: "program", 2: "program", 30: "program",
                            3: "spindle", 4: "spindle", 5: "spindle",
                            7: "coolant", 8: "coolant", 9: "coolant"}
AXIS_COMMANDS = {"0", "1", "2", "3", "38.2", "38.3", "38.4", "38.5", "10", "28", "30", "92"}
PLANES = {"17": (0, 1, 2), "18": (2, 0, 1), "19": (1, 2, 0)}


@dataclass
class Modal:
    """The parser state ``$G`` prints, plus the offsets ``$#`` prints (all in mm)."""

    motion: str = "0"
    coord: int = 0
    plane: str = "17"
    units: str = "21"
    distance: str = "90"
    feed_mode: str = "94"
    program: int | None = None
    spindle: int = 5
    coolant: frozenset[int] = frozenset()
    tool: int = 0
    feed: float = 0.0      # mm/min (G94) as programmed
    speed: float = 0.0
    tlo: float = 0.0
    coords: list[list[float]] = field(default_factory=lambda: [[0.0] * 3 for _ in range(6)])
    g28: list[float] = field(default_factory=lambda: [0.0] * 3)
    g30: list[float] = field(default_factory=lambda: [0.0] * 3)
    g92: list[float] = field(default_factory=lambda: [0.0] * 3)
    line_number: int = 0

    def copy(self) -> Modal:
        return replace(self, coords=[list(c) for c in self.coords], g28=list(self.g28),
                       g30=list(self.g30), g92=list(self.g92))

    def wco(self) -> list[float]:
        """The work coordinate offset: coordinate system + G92 + tool length (Z)."""
        w = [c + g for c, g in zip(self.coords[self.coord], self.g92, strict=True)]
        w[2] += self.tlo
        return w

    def gc_line(self) -> str:
        """The ``[GC:...]`` body (report.c report_gcode_modes)."""
        parts = [f"G{self.motion}", f"G{54 + self.coord}", f"G{self.plane}", f"G{self.units}",
                 f"G{self.distance}", f"G{self.feed_mode}"]
        if self.program is not None:
            parts.append(f"M{self.program}")
        parts.append(f"M{self.spindle}")
        if self.coolant:
            parts.extend(f"M{c}" for c in sorted(self.coolant))
        else:
            parts.append("M9")
        feed = self.feed / MM_PER_INCH if self.units == "20" else self.feed
        parts += [f"T{self.tool}", f"F{feed:.0f}", f"S{self.speed:.0f}"]
        return " ".join(parts)


@dataclass
class Block:
    """A checked block: the modal state after it and what it asks the machine to do."""

    modal: Modal
    kind: str = "none"   # none | line | arc | probe | dwell | home28 | home30
    target: list[float] | None = None     # machine coordinates, mm
    via: list[float] | None = None        # G28/G30 intermediate point
    rapid: bool = False
    feed: float = 0.0                     # mm/min along the path
    inverse_time: bool = False
    dwell: float = 0.0
    arc_length: float = 0.0
    probe: str = ""
    sync: bool = False                    # grbl waits for the planner to empty first
    program_end: bool = False
    pause: bool = False
    coord_write: bool = False


class GcodeError(Exception):
    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


def _fail(code: int) -> GcodeError:
    return GcodeError(code)


def strip_line(raw: bytes) -> tuple[str, bool]:
    """grbl's input filter: drop spaces, control bytes, ``( )`` and ``;`` comments; upper-case.

    Returns (line, inside a comment at the end). Used by the reference unit as it reads.
    """
    out = []
    paren = semi = False
    for b in raw:
        c = chr(b)
        if paren:
            if c == ")":
                paren = False
            continue
        if semi:
            continue
        if c == "(":
            paren = True
        elif c == "/":
            continue  # block delete is not supported: the character is dropped
        elif c == ";":
            semi = True
        elif c <= " " or b == 0x7F:
            continue
        else:
            out.append(c.upper() if "a" <= c <= "z" else c)
    return "".join(out), paren


def words(line: str) -> list[tuple[str, float, str]]:
    """(letter, value, value text) for each word; raises GcodeError 1 or 2."""
    out = []
    i = 0
    while i < len(line):
        letter = line[i]
        if not "A" <= letter <= "Z":
            raise _fail(1)
        m = _NUMBER.match(line, i + 1)
        if m is None:
            raise _fail(2)
        out.append((letter, float(m.group(0)), m.group(0)))
        i = m.end()
    return out


def _gcode_key(value: float) -> tuple[str, int]:
    """G word value → ('38.2', mantissa) with grbl's rounding of the fraction to 1/100."""
    whole = int(math.trunc(value))
    mantissa = int(round(100 * (value - whole)))
    key = f"{whole}.{mantissa // 10}" if mantissa else str(whole)
    return key, mantissa


def parse(line: str, state: Modal, position: list[float], *, jog: bool = False,
          tool_max: int = 255, line_number_max: int = 9999999) -> Block:
    """Check one stripped, non-empty line against ``state``; raises GcodeError(code)."""
    ws = words(line)
    groups: dict[str, str] = {}
    m_groups: dict[str, int] = {}
    values: dict[str, float] = {}
    axis_command: str | None = None
    for letter, value, _text in ws:
        if letter == "G":
            key, mantissa = _gcode_key(value)
            if key in G_GROUPS:
                group = G_GROUPS[key]
            elif str(int(value)) in G_GROUPS and mantissa:
                raise _fail(23)           # e.g. G1.5, G59.1: known code, fraction not allowed
            else:
                raise _fail(20)
            if key in AXIS_COMMANDS:
                if axis_command is not None:
                    raise _fail(24)
                axis_command = key
            if group in groups:
                raise _fail(21)
            groups[group] = key
        elif letter == "M":
            if value != int(value):
                raise _fail(23)
            code = int(value)
            if code not in M_GROUPS:
                raise _fail(20)
            group = M_GROUPS[code]
            if group in m_groups:
                raise _fail(21)
            m_groups[group] = code
        else:
            if letter not in VALUE_LETTERS:
                raise _fail(20)
            if letter in values:
                raise _fail(25)
            if letter in "FNPST" and value < 0:
                raise _fail(4)
            if letter == "T" and value > tool_max:
                raise _fail(38)
            values[letter] = value
    return _check(groups, m_groups, values, axis_command, state, position, jog,
                  line_number_max)


def _jog_words(groups: dict[str, str], m_groups: dict[str, int], values: dict[str, float]
               ) -> None:
    """A jog carries only G20/G21, G90/G91, G53, N, F and axis words (jogging.md)."""
    allowed = {"distance", "units", "nonmodal"}
    if m_groups or any(g not in allowed for g in groups) or (
            "nonmodal" in groups and groups["nonmodal"] != "53"):
        raise _fail(16)
    if set(values) - set("FNXYZ"):
        raise _fail(16)


def _check(groups: dict[str, str], m_groups: dict[str, int], values: dict[str, float],
           axis_command: str | None, state: Modal, position: list[float], jog: bool,
           line_number_max: int) -> Block:
    new = state.copy()
    axis_words = {a: values[a] for a in AXES if a in values}
    used = set("NFST") | set(AXES)
    if "N" in values:
        if values["N"] > line_number_max:
            raise _fail(27)
        new.line_number = int(values["N"])
    if axis_words and axis_command is None:
        axis_command = "motion"
    elif axis_command in ("0", "1", "2", "3", "38.2", "38.3", "38.4", "38.5"):
        axis_command = "motion"
    motion = groups.get("motion", state.motion)
    if jog:
        motion = "1"
    new.units = groups.get("units", state.units)
    scale = MM_PER_INCH if new.units == "20" else 1.0
    new.feed_mode = groups.get("feed_mode", state.feed_mode)
    inverse = new.feed_mode == "93" and not jog
    # feed rate
    feed = state.feed
    if jog:
        if "F" not in values:
            raise _fail(22)       # gcode.c checks the jog's F before its words
        _jog_words(groups, m_groups, values)
        feed = values["F"] * scale
    elif inverse:
        if axis_command == "motion" and motion not in ("0", "80") and "F" not in values:
            raise _fail(22)
        feed = values.get("F", 0.0)
    elif "F" in values:
        feed = values["F"] * scale
    if not jog:
        new.feed = feed if not inverse else state.feed
    if "S" in values:
        new.speed = values["S"]
    if "T" in values:
        new.tool = int(values["T"])
    if "spindle" in m_groups:
        new.spindle = m_groups["spindle"]
    if "coolant" in m_groups:
        c = m_groups["coolant"]
        new.coolant = frozenset() if c == 9 else (new.coolant | {8} if c == 8 else new.coolant)
    block = Block(new)
    nonmodal = groups.get("nonmodal")
    if nonmodal == "4":
        if "P" not in values:
            raise _fail(28)
        block.kind, block.dwell, block.sync = "dwell", values["P"], True
        used.add("P")
    new.plane = groups.get("plane", state.plane)
    if groups.get("tlo") == "43.1":
        if set(axis_words) != {"Z"}:
            raise _fail(37)
        new.tlo = axis_words["Z"] * scale
        axis_words = {}
        axis_command = None if axis_command == "motion" and "motion" not in groups else axis_command
    elif groups.get("tlo") == "49":
        new.tlo = 0.0
    if "coord" in groups:
        new.coord = int(groups["coord"]) - 54
    new.distance = groups.get("distance", state.distance)
    if nonmodal == "10":
        if not axis_words:
            raise _fail(26)
        if "P" not in values and "L" not in values:
            raise _fail(28)
        p = int(values.get("P", 0))
        if p > 6:
            raise _fail(29)
        l_value = int(values.get("L", 0))
        if l_value not in (2, 20) or (l_value == 2 and "R" in values):
            raise _fail(20)
        idx = state.coord if p == 0 else p - 1
        row = list(new.coords[idx])
        for i, a in enumerate(AXES):
            if a in axis_words:
                v = axis_words[a] * scale
                if l_value == 20:
                    # make the current position read v in that system
                    row[i] = position[i] - new.g92[i] - (new.tlo if i == 2 else 0.0) - v
                else:
                    row[i] = v
        new.coords[idx] = row
        used |= {"P", "L"}
        block.sync = block.coord_write = True
        axis_command = "nonmodal"
    elif nonmodal in ("28.1", "30.1"):
        (new.g28 if nonmodal == "28.1" else new.g30)[:] = list(position)
        block.sync = block.coord_write = True
    elif nonmodal == "92":
        if not axis_words:
            raise _fail(26)
        for i, a in enumerate(AXES):
            if a in axis_words:
                new.g92[i] = position[i] - new.coords[new.coord][i] - (
                    new.tlo if i == 2 else 0.0) - axis_words[a] * scale
        block.sync = True
        axis_command = "nonmodal"
    elif nonmodal == "92.1":
        new.g92 = [0.0] * 3
        block.sync = True
    elif nonmodal == "53" and motion not in ("0", "1"):
        raise _fail(30)
    if nonmodal in ("28", "30"):
        via = None
        if axis_words:
            via = _target(axis_words, new, position, scale, nonmodal == "53")
        block.kind, block.via, block.rapid = ("home28" if nonmodal == "28" else "home30"), via, True
        block.target = list(new.g28 if nonmodal == "28" else new.g30)
        axis_command = "nonmodal"
    new.motion = state.motion if jog else motion
    # motion modes
    if motion == "80":
        if axis_words and axis_command == "motion":
            raise _fail(31)
    elif axis_command == "motion":
        target = _target(axis_words, new, position, scale, nonmodal == "53")
        if motion == "0":
            if axis_words:
                block.kind, block.target, block.rapid = "line", target, True
        else:
            f_eff = feed if not inverse else values.get("F", 0.0)
            if f_eff == 0.0:
                raise _fail(22)
            if motion == "1":
                if axis_words:
                    block.kind, block.target, block.feed = "line", target, f_eff
            elif motion in ("2", "3"):
                _arc(block, motion, new, axis_words, values, position, target, scale, used)
                block.feed = f_eff
            else:
                if target == list(position):
                    raise _fail(33)
                block.kind, block.target, block.feed, block.probe = "probe", target, f_eff, motion
                block.sync = True
            block.inverse_time = inverse
    prog = m_groups.get("program")
    if prog is not None:
        block.sync = True
        if prog in (0, 1):
            block.pause = True
        else:
            block.program_end = True
    unused = set(values) - used
    if unused:
        raise _fail(36)
    return block


def _target(axis_words: dict[str, float], m: Modal, position: list[float], scale: float,
            absolute_machine: bool) -> list[float]:
    wco = m.wco()
    out = list(position)
    for i, a in enumerate(AXES):
        if a not in axis_words:
            continue
        v = axis_words[a] * scale
        if absolute_machine:
            out[i] = v
        elif m.distance == "91":
            out[i] = position[i] + v
        else:
            out[i] = v + wco[i]
    return out


def _arc(block: Block, motion: str, m: Modal, axis_words: dict[str, float],
         values: dict[str, float], position: list[float], target: list[float], scale: float,
         used: set[str]) -> None:
    a0, a1, _lin = PLANES[m.plane]
    if AXES[a0] not in axis_words and AXES[a1] not in axis_words:
        raise _fail(32)
    x = target[a0] - position[a0]
    y = target[a1] - position[a1]
    ijk = "IJK"
    if "R" in values:
        used.add("R")
        if target == list(position):
            raise _fail(33)
        r = values["R"] * scale
        h2 = 4.0 * r * r - x * x - y * y
        if h2 < 0:
            raise _fail(34)
        radius = abs(r)
        chord = math.hypot(x, y)
        angle = 2 * math.asin(min(1.0, chord / (2 * radius))) if radius else 0.0
        if r < 0:
            angle = 2 * math.pi - angle
    else:
        if ijk[a0] not in values and ijk[a1] not in values:
            raise _fail(35)
        i_off = values.get(ijk[a0], 0.0) * scale
        j_off = values.get(ijk[a1], 0.0) * scale
        used |= {ijk[a0], ijk[a1]}
        radius = math.hypot(i_off, j_off)
        cx, cy = position[a0] + i_off, position[a1] + j_off
        target_r = math.hypot(target[a0] - cx, target[a1] - cy)
        delta = abs(target_r - radius)
        if delta > 0.005 and (delta > 0.5 or delta > 0.001 * radius):
            raise _fail(33)
        a_start = math.atan2(position[a1] - cy, position[a0] - cx)
        a_end = math.atan2(target[a1] - cy, target[a0] - cx)
        angle = (a_end - a_start) if motion == "3" else (a_start - a_end)
        angle %= 2 * math.pi
        if angle == 0.0:
            angle = 2 * math.pi
    block.kind, block.target = "arc", target
    block.arc_length = max(radius * angle, math.dist(position, target))
