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
from collections.abc import Iterator
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

    def gc_line(self, inches: bool = False) -> str:
        """The ``[GC:...]`` body (report.c report_gcode_modes). The feed is printed as stored
        (mm/min after G20 G94, inverse time as given after G93) and converted only by $13
        (printFloat_RateValue), so the recorded firmware shows ``F250`` for G20 G93 F250."""
        from conform.families.grbl.spec.load import print_float

        parts = [f"G{self.motion}", f"G{54 + self.coord}", f"G{self.plane}", f"G{self.units}",
                 f"G{self.distance}", f"G{self.feed_mode}"]
        if self.program is not None:
            parts.append(f"M{self.program}")
        parts.append(f"M{self.spindle}")
        if self.coolant:
            parts.extend(f"M{c}" for c in sorted(self.coolant))
        else:
            parts.append("M9")
        feed = print_float(self.feed / MM_PER_INCH, 1) if inches else print_float(self.feed, 0)
        parts += [f"T{self.tool}", f"F{feed}", f"S{print_float(self.speed, 0)}"]
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
    wco: bool = False      # G92, G92.1, G10 on the active system: the WCO: refresh is forced


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


def read_float(line: str, i: int) -> tuple[float, int] | None:
    """grbl's ``read_float`` (nuts_bolts.c): an optional sign, digits with at most one '.';
    digits past the eighth only scale the value (MAX_INT_DIGITS 8). None when no digit is read
    (error 2); else the value and the index after it."""
    j = i
    neg = False
    if j < len(line) and line[j] in "+-":
        neg = line[j] == "-"
        j += 1
    intval = exp = ndigit = 0
    decimal = False
    while j < len(line):
        c = line[j]
        if "0" <= c <= "9":
            ndigit += 1
            if ndigit <= 8:
                exp -= decimal
                intval = intval * 10 + (ord(c) - 48)
            elif not decimal:
                exp += 1
        elif c == "." and not decimal:
            decimal = True
        else:
            break
        j += 1
    if not ndigit:
        return None
    value = intval * 10.0 ** exp
    return (-value if neg else value), j


def iter_words(line: str, start: int = 0) -> Iterator[tuple[str, float, str]]:
    """(letter, value, value text) for each word, read lazily as gcode.c STEP 2 reads them:
    GcodeError 1 or 2 is raised when the bad word is reached, after the words before it."""
    i = start
    while i < len(line):
        letter = line[i]
        if not "A" <= letter <= "Z":
            raise _fail(1)
        got = read_float(line, i + 1)
        if got is None:
            raise _fail(2)
        yield letter, got[0], line[i + 1:got[1]]
        i = got[1]


def words(line: str, start: int = 0) -> list[tuple[str, float, str]]:
    """Every word of ``line``; raises GcodeError 1 or 2."""
    return list(iter_words(line, start))


# STEP 2 of gc_execute_line (gcode.c): G words by their whole part; the group each belongs to
_G_MOTION = {0, 1, 2, 3, 38, 80}
_G_SIMPLE = {17: "plane", 18: "plane", 19: "plane", 93: "feed_mode", 94: "feed_mode",
             20: "units", 21: "units", 40: "cutter", 54: "coord", 55: "coord", 56: "coord",
             57: "coord", 58: "coord", 59: "coord"}


def _g_word(value: float, axis_command: str | None) -> tuple[str, str, str | None]:
    """One G word as gcode.c STEP 2 reads it: (group, key, axis command after it), raising the
    code gcode.c fails with, in its order: 24 (an axis command twice), 20 (unsupported, also
    G28.2, G38.1, G43, G61.1, G90.1, G92.2), then 23 (a fraction left over: G1.5, G59.1)."""
    whole = int(math.trunc(value)) & 0xFF          # int_value is a uint8_t
    mantissa = int(round(100 * (value - math.trunc(value))))
    if whole in (10, 28, 30, 92, 4, 53):
        if whole in (10, 28, 30, 92) and mantissa == 0:
            if axis_command is not None:
                raise _fail(24)
            axis_command = "nonmodal"
        key = str(whole)
        if whole in (28, 30, 92):
            if mantissa not in (0, 10):
                raise _fail(20)
            key, mantissa = (f"{whole}.1" if mantissa else key), 0
        group = "nonmodal"
    elif whole in _G_MOTION:
        if whole != 80:
            if axis_command is not None:
                raise _fail(24)
            axis_command = "motion"
        key = str(whole)
        if whole == 38:
            if mantissa not in (20, 30, 40, 50):
                raise _fail(20)
            key, mantissa = f"38.{mantissa // 10}", 0
        group = "motion"
    elif whole in (90, 91):
        if mantissa == 0:
            group, key = "distance", str(whole)
        else:
            if mantissa != 10 or whole == 90:
                raise _fail(20)
            group, key, mantissa = "arc_distance", "91.1", 0
    elif whole in (43, 49):
        if axis_command is not None:
            raise _fail(24)
        axis_command = "tlo"
        if whole == 49:
            key = "49"
        elif mantissa == 10:
            key = "43.1"
        else:
            raise _fail(20)
        group, mantissa = "tlo", 0
    elif whole == 61:
        if mantissa:
            raise _fail(20)
        group, key = "path", "61"
    elif whole in _G_SIMPLE:
        group, key = _G_SIMPLE[whole], str(whole)
    else:
        raise _fail(20)
    if mantissa > 0:
        raise _fail(23)
    return group, key, axis_command


def _m_word(value: float, mist: bool) -> tuple[str, int]:
    """One M word (gcode.c STEP 2): 23 for a fraction first, then 20 for an unsupported code
    (M7 without the ENABLE_M7 build option, config.h: off by default)."""
    whole = int(math.trunc(value)) & 0xFF
    if int(round(100 * (value - math.trunc(value)))) > 0:
        raise _fail(23)
    if whole in (0, 1, 2, 30):
        return "program", whole
    if whole in (3, 4, 5):
        return "spindle", whole
    if whole in (8, 9) or (whole == 7 and mist):
        return "coolant", whole
    raise _fail(20)


def parse(line: str, state: Modal, position: list[float], *, jog: bool = False,
          tool_max: int = 255, line_number_max: int = 10000000, mist: bool = False) -> Block:
    """Check one stripped line against ``state`` in gc_execute_line's order; raises
    GcodeError(code). ``jog``: ``line`` is the part after ``$J=``."""
    groups: dict[str, str] = {}
    m_groups: dict[str, int] = {}
    values: dict[str, float] = {}
    axis_command: str | None = None
    for letter, value, _text in iter_words(line):   # STEP 2: each word checked as read
        if letter == "G":
            group, key, axis_command = _g_word(value, axis_command)
            if group in groups:
                raise _fail(21)
            groups[group] = key
        elif letter == "M":
            group, code = _m_word(value, mist)
            if group in m_groups:
                raise _fail(21)
            m_groups[group] = code
        else:
            if letter not in VALUE_LETTERS:
                raise _fail(20)
            if letter == "T" and value > tool_max:
                raise _fail(38)            # checked as T is read, before the repeat check
            if letter in values:
                raise _fail(25)
            if letter in "FNPST" and value < 0:
                raise _fail(4)
            values[letter] = value
    return _check(groups, m_groups, values, axis_command, state, position, jog,
                  line_number_max)


def _check(groups: dict[str, str], m_groups: dict[str, int], values: dict[str, float],
           axis_command: str | None, state: Modal, position: list[float], jog: bool,
           line_number_max: int) -> Block:
    """gc_execute_line STEP 3 (error checks in its numbered order [0]..[21], then unused
    words) and the jog checks at the start of STEP 4."""
    new = state.copy()
    axis_words = {a: values[a] for a in AXES if a in values}
    used = set("NF") if jog else set("NFST")   # single-meaning words; a jog has no S or T
    if axis_words and axis_command is None:
        axis_command = "motion"                # [0] implicit motion mode
    if "N" in values and math.trunc(values["N"]) > line_number_max:
        raise _fail(27)                        # [0] MAX_LINE_NUMBER with '>' (gcode.c:27, :376)
    new.line_number = int(math.trunc(values.get("N", 0.0)))
    motion = "1" if jog else state.motion
    motion = groups.get("motion", motion)
    new.units = groups.get("units", state.units)
    scale = MM_PER_INCH if new.units == "20" else 1.0
    new.feed_mode = "94" if jog else groups.get("feed_mode", state.feed_mode)
    inverse = new.feed_mode == "93"
    # [2]/[3] feed rate mode and feed rate
    if jog:
        if "F" not in values:
            raise _fail(22)
        feed = values["F"] * scale
    elif inverse:
        if axis_command == "motion" and motion not in ("0", "80") and "F" not in values:
            raise _fail(22)
        feed = values.get("F", 0.0)
    elif state.feed_mode == "94":
        feed = values["F"] * scale if "F" in values else state.feed
    else:
        feed = values.get("F", 0.0)      # G93 -> G94: the F word as given, else undefined
    # [4] spindle speed, [5] tool: T is only tracked, and a block without T sets it to 0
    speed = values.get("S", state.speed) if not jog else state.speed
    tool = int(math.trunc(values.get("T", 0.0))) if not jog else state.tool
    nonmodal = groups.get("nonmodal")
    block = Block(new)
    if nonmodal == "4":                        # [10] dwell
        if "P" not in values:
            raise _fail(28)
        block.kind, block.dwell, block.sync = "dwell", values["P"], True
        used.add("P")
    new.plane = groups.get("plane", state.plane)
    a0, a1, _lin = PLANES[new.plane]
    tlo_key = groups.get("tlo")
    if axis_command == "tlo" and tlo_key == "43.1" and set(axis_words) != {"Z"}:
        raise _fail(37)                        # [14]
    new.coord = int(groups["coord"]) - 54 if "coord" in groups else state.coord
    new.distance = groups.get("distance", state.distance)
    block_coords = new.coords[new.coord]
    # [19] non-modal commands that use axis words
    target = list(position)
    if nonmodal == "10":
        if not axis_words:
            raise _fail(26)
        if "P" not in values and "L" not in values:
            raise _fail(28)
        p = int(math.trunc(values.get("P", 0.0))) & 0xFF
        if p > len(new.coords):
            raise _fail(29)
        l_value = int(math.trunc(values.get("L", 0.0))) & 0xFF
        if l_value != 20 and (l_value != 2 or "R" in values):
            raise _fail(20)
        used |= {"P", "L"}
        idx = p - 1 if p > 0 else new.coord
        row = list(new.coords[idx])
        for k, a in enumerate(AXES):
            if a in axis_words:
                v = axis_words[a] * scale
                row[k] = v if l_value == 2 else (
                    position[k] - state.g92[k] - v - (state.tlo if k == 2 else 0.0))
        new.coords[idx] = row
        block.sync = block.coord_write = True
        block.wco = idx == new.coord           # gcode.c [19]: only the active system
    elif nonmodal == "92":
        if not axis_words:
            raise _fail(26)
        for k, a in enumerate(AXES):
            if a in axis_words:
                new.g92[k] = position[k] - block_coords[k] - axis_words[a] * scale - (
                    state.tlo if k == 2 else 0.0)
        block.sync = block.wco = True
    else:
        if axis_command != "tlo" and axis_words:
            target = _target(axis_words, new, state, position, scale, nonmodal == "53")
        if nonmodal in ("28", "30"):
            home = list(new.g28 if nonmodal == "28" else new.g30)
            if axis_words:                     # only the axes named go home, via the target
                home = [home[k] if a in axis_words else position[k] for k, a in enumerate(AXES)]
                block.via = target
            else:
                axis_command = None
            block.kind, block.target, block.rapid = ("home28" if nonmodal == "28" else
                                                     "home30"), home, True
        elif nonmodal in ("28.1", "30.1"):
            (new.g28 if nonmodal == "28.1" else new.g30)[:] = list(position)
            block.sync = block.coord_write = True
        elif nonmodal == "92.1":
            new.g92 = [0.0] * 3
            block.sync = block.wco = True
        elif nonmodal == "53" and motion not in ("0", "1"):
            raise _fail(30)
    # [20] motion modes
    if motion == "80":
        if axis_words:
            raise _fail(31)                    # strict: even for G10/G28/G92/G43.1 words
    elif axis_command == "motion":
        if motion != "0" and feed == 0.0:
            raise _fail(22)
        if motion in ("0", "1"):
            if axis_words:
                block.kind, block.target, block.rapid = "line", target, motion == "0"
        elif motion in ("2", "3"):
            if not axis_words:
                raise _fail(26)
            if AXES[a0] not in axis_words and AXES[a1] not in axis_words:
                raise _fail(32)
            _arc(block, motion, new, values, position, target, scale, used)
        else:
            if not axis_words:
                raise _fail(26)
            if target == list(position):
                raise _fail(33)
            block.kind, block.target, block.probe = "probe", target, motion
            block.sync = True
        block.feed = feed
        block.inverse_time = inverse
    # [0] unused words (gcode.c: N F S T removed, axis words when an axis command used them)
    if axis_command is not None:
        used |= set(AXES)
    if set(values) - used:
        raise _fail(36)
    if jog:                                    # STEP 4: only G20/21, G90/91, G53 in a jog
        if m_groups or set(groups) - {"distance", "units", "nonmodal"} or nonmodal not in (
                None, "53"):
            raise _fail(16)
        new.motion = state.motion
        block.kind = "line" if block.target is not None else "none"
        return block
    new.motion = motion
    new.feed = feed                          # gc_state.feed_rate = gc_block.values.f, always
    new.speed, new.tool = speed, tool
    if tlo_key == "49":
        new.tlo = 0.0
    elif tlo_key == "43.1":
        new.tlo = axis_words["Z"] * scale
    if "spindle" in m_groups:
        new.spindle = m_groups["spindle"]
    if "coolant" in m_groups:
        c = m_groups["coolant"]
        new.coolant = frozenset() if c == 9 else new.coolant | {c}
    if new.spindle != state.spindle or new.coolant != state.coolant or (
            new.speed != state.speed and state.spindle != 5):
        block.sync = True                      # spindle_sync / coolant_sync wait for motion
    prog = m_groups.get("program")
    if prog is not None and prog != 1:         # M1 (optional stop) is ignored
        block.sync = True
        block.pause = prog == 0
        block.program_end = prog != 0
    return block


def _target(axis_words: dict[str, float], new: Modal, state: Modal, position: list[float],
            scale: float, absolute_machine: bool) -> list[float]:
    """gcode.c [19] default: the axis words as machine coordinates: G53 as given, G91 added to
    the position, G90 plus the block's coordinate system, the G92 offset and (Z) the tool
    length offset of the state."""
    coords = new.coords[new.coord]
    out = list(position)
    for i, a in enumerate(AXES):
        if a not in axis_words:
            continue
        v = axis_words[a] * scale
        if absolute_machine:
            out[i] = v
        elif new.distance == "91":
            out[i] = position[i] + v
        else:
            out[i] = v + coords[i] + state.g92[i] + (state.tlo if i == 2 else 0.0)
    return out


def _arc(block: Block, motion: str, m: Modal, values: dict[str, float], position: list[float],
         target: list[float], scale: float, used: set[str]) -> None:
    """gcode.c [20] G2/G3: radius mode (33 same point, 34 radius too small) or offset mode
    (35 no offset in the plane, 33 the two radii differ)."""
    a0, a1, _lin = PLANES[m.plane]
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
