"""A small G-code subset turned into GVE vectors: G0/G1/G2/G3, F, G90/G91, G20/G21, G17.

Moves become relative ``C`` vectors in pulses (``steps_per_mm`` per axis, rounding carried
so no error accumulates); arcs are cut into chords within ``chord_tolerance`` mm. Before
every vector whose end is a junction with the next one, a ``B`` sets the speed the unit may
keep through that junction (GVE64 §13.5.3), chosen like the CNC8x9 continuity criteria
(seed 004): with ``alpha`` the angle between the two directions, ``T`` the interpolation
period and ``a`` the acceleration,

* accuracy: ``v = L / (T * tan(alpha / 2))`` with ``L`` the allowed path error;
* dynamics: ``v = a * T / (2 * sin(alpha / 2))``;
* above ``stop_angle`` the motion stops (``B`` at its minimum);

and never more than the programmed feed. ``F`` (mm/min) becomes ``V`` in pulses/s of the X
axis's resolution (exact for moves along one axis; the unit's VN mode makes diagonal moves
the speed of their dominant axis).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from conform.errors import UserError
from conform.families.gve.protocol import CommandParser
from conform.families.gve.sender.items import Item, parse_item
from conform.families.gve.spec.model import Dialect, Variant

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")
SUPPORTED = "GFXYZIJN"  # N (a line number) is read and ignored


@dataclass(frozen=True)
class GcodeOptions:
    steps_per_mm: tuple[float, ...] = (100.0, 100.0, 100.0)
    feed: float = 600.0  # mm/min until an F word
    rapid: float = 3000.0  # mm/min for G0
    accel: float = 500.0  # mm/s², for the dynamic criterion and the A command
    period: float = 0.001  # interpolation period T, s
    path_error: float = 0.01  # L, mm
    stop_angle: float = 120.0  # degrees: sharper junctions stop
    lenient: bool = False  # skip what cannot be read and words outside the subset
    chord_tolerance: float = 0.002  # mm
    b_min: int = 100  # pulses/s: the "stop" speed at a junction too sharp to pass
    short: int = 16  # the $ threshold: only vectors shorter than this run at the B speed


@dataclass
class Segment:
    d: tuple[int, int, int]  # pulses
    mm: tuple[float, float, float]
    feed: float  # mm/min
    rapid: bool
    where: str


def _blank_comments(line: str, where: str) -> str:
    """Parenthesised comments become spaces (columns stay right); ``;`` ends the line."""
    out = []
    depth_start = -1
    for k, ch in enumerate(line):
        if depth_start >= 0:
            out.append(" ")
            if ch == ")":
                depth_start = -1
        elif ch == "(":
            depth_start = k
            out.append(" ")
        elif ch == ";":
            break
        else:
            out.append(ch)
    if depth_start >= 0:
        raise UserError(f"{where}:{depth_start + 1}: comment not closed with ')'")
    return "".join(out)


def _parse_words(line: str, where: str = "", lenient: bool = False) -> list[tuple[str, float]]:
    """The words of one line; anything that is not a letter and a number is an error naming
    ``file:line:column`` (``X1O``: the ``O``), as is a word outside the subset, unless
    ``lenient`` (then it is skipped)."""
    if lenient:
        line = re.sub(r"\(.*?\)", " ", line).split(";", 1)[0]
        return [(m.group(1).upper(), float(m.group(2))) for m in _WORD.finditer(line)
                if m.group(1).upper() in SUPPORTED + "MST"]
    text = _blank_comments(line, where)
    if text.strip() == "%":
        return []  # program start/end marker
    words: list[tuple[str, float]] = []
    pos = 0
    while pos < len(text):
        if text[pos].isspace():
            pos += 1
            continue
        m = _WORD.match(text, pos)
        if m is None:
            shown = text[pos:pos + 10].rstrip()
            raise UserError(f"{where}:{pos + 1}: cannot read {shown!r} (a word is a letter and "
                            "a number; --lenient skips what it cannot read)")
        letter, value = m.group(1).upper(), float(m.group(2))
        if letter not in SUPPORTED:
            raise UserError(f"{where}:{pos + 1}: word {letter}{m.group(2)} is not in the supported "
                            "subset (G0-G3, G17, G20/G21, G90/G91, F, X, Y, Z, I, J, N); "
                            "--lenient skips it")
        if abs(value) > 1e6:
            raise UserError(f"{where}:{pos + 1}: {letter}{m.group(2)} is too large")
        words.append((letter, value))
        pos = m.end()
    return words


def gcode_segments(text: str, opts: GcodeOptions, source: str = "") -> list[Segment]:
    spm = tuple(opts.steps_per_mm) + (opts.steps_per_mm[-1],) * (3 - len(opts.steps_per_mm))
    pos = [0.0, 0.0, 0.0]
    pulses = [0, 0, 0]
    absolute, scale, motion, feed = True, 1.0, 0, opts.feed
    segs: list[Segment] = []
    for no, raw in enumerate(text.splitlines(), 1):
        where = f"{source}:{no}"
        words = _parse_words(raw, where, opts.lenient)
        if not words:
            continue
        target: dict[str, float] = {}
        ij: dict[str, float] = {}
        for letter, value in words:
            if letter == "G":
                g = int(value) if value == int(value) else value
                if g in (0, 1, 2, 3):
                    motion = int(g)
                elif g == 90:
                    absolute = True
                elif g == 91:
                    absolute = False
                elif g == 20:
                    scale = 25.4
                elif g == 21:
                    scale = 1.0
                elif g in (17, 94, 54, 40, 49, 80):
                    pass
                else:
                    raise UserError(f"{where}: G{value:g} is not in the supported subset")
            elif letter == "F":
                if value <= 0:
                    raise UserError(f"{where}: feed F{value:g} must be positive")
                feed = value * scale
            elif letter in "XYZ":
                target[letter] = value * scale
            elif letter in "IJ":
                ij[letter] = value * scale
            elif letter in "NMST":
                pass
            else:
                raise UserError(f"{where}: word {letter}{value:g} is not supported")
        if not target:
            continue
        end = list(pos)
        for k, axis in enumerate("XYZ"):
            if axis in target:
                end[k] = target[axis] if absolute else pos[k] + target[axis]
        points: list[list[float]]
        if motion in (2, 3):
            points = _arc(pos, end, ij, motion == 2, opts.chord_tolerance, where)
        else:
            points = [end]
        for p in points:
            new = [round(p[k] * spm[k]) for k in range(3)]
            d = (new[0] - pulses[0], new[1] - pulses[1], new[2] - pulses[2])
            mm = (p[0] - pos[0], p[1] - pos[1], p[2] - pos[2])
            pulses = new
            pos = list(p)
            if any(d):
                segs.append(Segment(d, mm, opts.rapid if motion == 0 else feed, motion == 0,
                                    where))
    return segs


def _arc(start: list[float], end: list[float], ij: dict[str, float], cw: bool, tol: float,
         where: str) -> list[list[float]]:
    if "I" not in ij and "J" not in ij:
        raise UserError(f"{where}: arc without I/J (R arcs are not supported)")
    cx, cy = start[0] + ij.get("I", 0.0), start[1] + ij.get("J", 0.0)
    r = math.hypot(start[0] - cx, start[1] - cy)
    if r <= 0:
        raise UserError(f"{where}: arc of zero radius")
    a0 = math.atan2(start[1] - cy, start[0] - cx)
    a1 = math.atan2(end[1] - cy, end[0] - cx)
    sweep = a1 - a0
    if cw and sweep >= 0:
        sweep -= 2 * math.pi
    elif not cw and sweep <= 0:
        sweep += 2 * math.pi
    step = 2 * math.acos(max(-1.0, min(1.0, 1 - tol / r))) if tol < r else math.pi / 2
    n = max(1, math.ceil(abs(sweep) / max(step, 1e-6)))
    pts = []
    for k in range(1, n + 1):
        a = a0 + sweep * k / n
        z = start[2] + (end[2] - start[2]) * k / n
        pts.append([cx + r * math.cos(a), cy + r * math.sin(a), z])
    pts[-1] = list(end)
    return pts


def junction_speed(u: tuple[float, ...], w: tuple[float, ...], v: float, opts: GcodeOptions,
                   spm: float) -> float:
    """Speed (pulses/s) allowed through the junction of directions ``u`` then ``w``."""
    nu, nw = math.hypot(*u), math.hypot(*w)
    if nu == 0 or nw == 0:
        return v
    cos = max(-1.0, min(1.0, sum(a * b for a, b in zip(u, w, strict=True)) / (nu * nw)))
    alpha = math.acos(cos)
    if alpha < 1e-9:
        return v
    if math.degrees(alpha) > opts.stop_angle:
        return 0.0
    err = opts.path_error * spm
    acc = opts.accel * spm
    v_acc = err / (opts.period * math.tan(alpha / 2))
    v_dyn = acc * opts.period / (2 * math.sin(alpha / 2))
    return min(v, v_acc, v_dyn)


def gcode_to_items(text: str, variant: Variant, dialect: Dialect, opts: GcodeOptions,
                   source: str = "") -> list[Item]:
    segs = gcode_segments(text, opts, source)
    if not segs:
        raise UserError(f"{source}: no moves in the G-code")
    parser = CommandParser(variant, dialect)
    spm = float(opts.steps_per_mm[0])
    vmax = int(variant.range("V")[1])
    bmin, bmax = variant.range("B")
    items: list[Item] = []
    lines: list[tuple[str, str]] = []
    accel_k = max(1, min(1000, round(opts.accel * spm / 1000)))
    lines.append((f"A{accel_k}", source))
    lines.append((f"${max(1, int(opts.short))}", source))
    last_v = last_b = None
    naxes = len(variant.axes)
    for i, s in enumerate(segs):
        v = int(max(10, min(vmax, round(s.feed / 60.0 * spm))))
        if v != last_v:
            lines.append((f"V{v}", s.where))
            last_v = v
        nxt = segs[i + 1] if i + 1 < len(segs) else None
        if nxt is not None:
            v_next = max(10, min(vmax, round(nxt.feed / 60.0 * spm)))
            vj = junction_speed(s.mm, nxt.mm, min(v, v_next), opts, spm)
            if s.rapid != nxt.rapid:
                vj = 0.0
            b = int(max(bmin, opts.b_min, min(bmax, round(vj))))
            if b != last_b:
                lines.append((f"B{b}", s.where))
                last_b = b
        args = ",".join(str(x) for x in (s.d + (0,) * naxes)[:naxes])
        lines.append((f"C{args}", s.where))
    for text_line, where in lines:
        items.append(parse_item(text_line, variant, parser, where))
    return items
