"""A fuzz campaign against the reference unit, in-process on virtual time.

Frames are valid command lines drawn from the tables (every command of the variant, with and
without checksums, values at and beyond their bounds), mutations of them (bit flips, cut,
doubled and spliced lines, lone CR/LF, over-long numbers and lines), random bytes, packets,
checksum toggles and resets. Every variant is run under the default dialect and under each
single alternative of every open question, then under random mixes.

Each answer is judged by :class:`conform.families.gve.protocol.grammar.AnswerGrammar` (from the tables, not
from the unit): the harness tracks what the protocol says the state is (checksums on/off, inside
a packet, deaf after ``J``) from the lines it sent; when a frame leaves that state unknown
(several lines, a cut line) answers are judged line by line until the harness resynchronises
the way a host would (end the line, close a packet, ``J``, wait the deaf time) and checks that
the unit answers ``?`` again. Exceptions, frames that take longer than ``hang_s`` seconds
and malformed answers are counted, with the first few examples kept (a frame's time is the CPU
time it took, which a loaded machine does not stretch).
"""

from __future__ import annotations

import gc
import random
import re
import time
from dataclasses import dataclass, field
from typing import Any

from conform.families.gve.protocol.checksum import append_checksum
from conform.families.gve.protocol.commands import Command, CommandParser, Rejection, encode_command
from conform.families.gve.protocol.grammar import AnswerGrammar
from conform.families.gve.protocol.lines import MAX_LINE, LineSplitter
from conform.families.gve.spec.model import CommandSpec, Dialect, Spec, Variant
from conform.families.gve.unit.model import Unit

_cpu = time.thread_time  # a frame's time: CPU seconds, which a loaded machine does not stretch
_STEPS = (0.0, 0.0005, 0.002, 0.02, 0.3)  # seconds between frames
ALPHABET = b"!0123456789,.-+ \r\n*%@>?$&CLVABTNPWYKRHDGEFUOISJXZQabcxyz\x00\xff"
_TO_ALPHABET = bytes(ALPHABET[i % len(ALPHABET)] for i in range(256))
_IN_LINE = ALPHABET.replace(b"\r", b"").replace(b"\n", b"")
_TO_IN_LINE = bytes(_IN_LINE[i % len(_IN_LINE)] for i in range(256))


def _noise(rng: random.Random, n: int, one_line: bool = False) -> bytes:
    """``n`` random bytes, mostly protocol characters (no line ends with ``one_line``)."""
    return rng.randbytes(n).translate(_TO_IN_LINE if one_line else _TO_ALPHABET)


@dataclass
class Figures:
    """What a campaign found."""

    frames: int = 0
    judged: int = 0  # frames whose answer was judged against the command the line is
    configs: int = 0
    resyncs: int = 0
    exceptions: int = 0
    hangs: int = 0
    malformed: int = 0
    max_frame_s: float = 0.0
    seconds: float = 0.0
    cpu_seconds: float = 0.0
    examples: list[str] = field(default_factory=list)

    @property
    def failures(self) -> int:
        return self.exceptions + self.hangs + self.malformed

    @property
    def rate(self) -> float:
        return self.frames / self.seconds if self.seconds else 0.0

    def note(self, what: str) -> None:
        if len(self.examples) < 10:
            self.examples.append(what)


def dialects(spec: Spec, rng: random.Random, mixes: int) -> list[dict[str, str]]:
    """The default, each single alternative of every open question, then ``mixes`` random mixes."""
    out: list[dict[str, str]] = [{}]
    for q in spec.questions.values():
        out.extend({q.id: alt} for alt in q.alternatives if alt != q.default)
    for _ in range(mixes):
        out.append({q.id: rng.choice(list(q.alternatives)) for q in spec.questions.values()})
    return out


def _value(rng: random.Random, kind: str, lo: Any, hi: Any, variant: Variant, choices: tuple) -> Any:
    r = rng.random()
    if kind in ("int", "uint", "hex"):
        lo, hi = int(lo), int(hi)
        if r < 0.1:
            return lo
        if r < 0.2:
            return hi
        if r < 0.25:
            return hi + 1
        if r < 0.28:
            return lo - 1 if kind == "int" else lo
        if r < 0.7:
            return rng.randint(max(lo, -1000), min(hi, 1000)) if lo <= 1000 and hi >= -1000 else lo
        return rng.randint(lo, hi)
    if kind == "float":
        return rng.choice((0.0, 1.5, -2.25, 3.4e38, 1e39, float(rng.randint(-10**6, 10**6)) / 8))
    if kind == "axis":
        return rng.choice(variant.axes) if r < 0.9 else rng.choice("XYZAQ")
    return rng.choice(choices) if r < 0.95 else "?"


def _args(rng: random.Random, cmd: CommandSpec, variant: Variant, dialect: Dialect) -> list[Any]:
    out: list[Any] = []
    for p in cmd.params:
        lo, hi = dialect.ranges.get(p.range_name or "", (p.lo, p.hi))
        if lo is None:
            lo, hi = 0, 255
        count = 1
        if p.per_axis:
            count = rng.randint(p.min_count or len(variant.axes), len(variant.axes))
        out.extend(_value(rng, p.kind, lo, hi, variant, p.choices) for _ in range(count))
    return out


def line_pool(spec: Spec, variant: Variant, dialect: Dialect, rng: random.Random,
              size: int = 1500) -> list[bytes]:
    """Command lines (no terminator, no checksum) for every command the tables list, at the
    addresses the variant answers; commands of other variants give "absent" lines."""
    roles = {0: variant.interpolator_address, 7: variant.spindle_address}
    specs = list(variant.commands.values()) + [
        c for cid, c in spec.commands.items() if cid not in variant.commands]
    out: list[bytes] = []
    while len(out) < size:
        cmd = rng.choice(specs)
        resolved = variant.commands.get(cmd.id, cmd)
        if any(p.lo is None and p.kind in ("int", "uint", "hex", "float") for p in resolved.params):
            continue  # a range this variant does not define
        address = roles.get(rng.choice(cmd.addresses), rng.randint(0, 9))
        if cmd.id in ("J", "%") or cmd.id == "*S":
            continue  # sent on purpose only (see Campaign)
        try:
            line = encode_command(variant, resolved, _args(rng, resolved, variant, dialect),
                                  address=address, terminator=b"")
        except (ValueError, TypeError, UnicodeEncodeError):
            continue
        out.append(line)
    out.extend([b"!0", b"!", b"!0Z", b"!3V1", b"!0v1", b"!9?", b"!0" + b"C" * 8])
    return out


def recovery_frames(variant: Variant, dialect: Dialect) -> list[bytes]:
    """What a host sends to a unit in an unknown state, in order: a terminator (ends a cut
    line; the host then waits for whatever answer is still due), ``*E0`` to close a packet and
    ``J`` to reset, each with and without a checksum. Once the deaf time after ``J``
    (``ready_after_s`` of the reset table) has passed, the unit is in its reset state."""
    term = b"\r\n" if dialect["A1"] == "crlf" else b"\r"
    addr = b"!%d" % variant.interpolator_address
    out = [term]
    for body in (addr + b"*E0", addr + b"J"):
        out += [body + term, append_checksum(body) + term]
    return out


# lines after which the harness no longer knows the state when it cannot tell their answers apart
_STATEFUL = frozenset(("%", "*S", "*E", "J", "H", "W"))
_MAY_BE_STATEFUL = re.compile(rb"[%*JjHhWw]")


_KEEP = {"parser": 8, "grammar": 512}  # kept by a campaign (parsers hold verdict caches)
_RANGES = " ranges"  # a read of the dialect's ranges (not a question id)


class _Reader:
    """A dialect that records which questions are read (to tell which dialects read alike)."""

    def __init__(self, dialect: Dialect) -> None:
        self.dialect = dialect
        self.read: set[str] = set()

    @property
    def ranges(self) -> Any:
        self.read.add(_RANGES)
        return self.dialect.ranges

    def __getitem__(self, question_id: str) -> str:
        self.read.add(question_id)
        return self.dialect[question_id]


def _answers(dialect: Dialect, reads: set[str]) -> tuple:
    return (tuple(sorted((q, dialect[q]) for q in reads if q != _RANGES)),
            tuple(sorted(dialect.ranges.items())) if _RANGES in reads else ())


class Campaign:
    """Run ``frames`` frames over every variant and dialect (see the module docstring)."""

    def __init__(self, spec: Spec, seed: int = 1, hang_s: float = 0.5, mixes: int = 40,
                 unit_class: type[Unit] = Unit) -> None:
        self.spec = spec
        self.unit_class = unit_class
        self.rng = random.Random(seed)
        self.hang_s = hang_s
        self.configs = [(v, d) for d in dialects(spec, self.rng, mixes) for v in spec.variants]
        self.rng.shuffle(self.configs)
        self._pools: dict[str, list[bytes]] = {}
        self._built: dict[tuple, Any] = {}
        self._reads: dict[tuple[str, str], set[str]] = {}
        self._framed: dict[tuple[str, bytes], tuple[list[bytes], list[bytes]]] = {}

    def _shared(self, kind: str, build: Any, variant: Variant, dialect: Dialect) -> Any:
        """``build(variant, dialect)``, made once for all dialects that agree on what it read.

        A build is recorded with the questions (and ranges) it read; a later dialect with the
        same answers to those gets the same object. Configurations are visited in shuffled
        order, so the most recent builds of each kind are kept (``_KEEP``)."""
        reads = self._reads.setdefault((kind, variant.id), set())
        key = (kind, variant.id, _answers(dialect, reads))
        made = self._built.get(key)
        if made is not None:
            self._built[key] = self._built.pop(key)  # most recently used last
            return made
        reader = _Reader(dialect)
        made = build(variant, reader)
        reads.update(reader.read)
        self._built[(kind, variant.id, _answers(dialect, reads))] = made
        kept = [k for k in self._built if k[0] == kind]
        for old in kept[: max(0, len(kept) - _KEEP[kind])]:
            del self._built[old]
        return made

    def parser(self, variant: Variant, dialect: Dialect) -> tuple[CommandParser, tuple[dict, dict]]:
        """The tables' reading of a line for this variant and dialect, with a cache of its
        verdicts with checksums off and on (shared by the dialects the parser reads alike)."""
        commands = dict(self.spec.commands)
        return self._shared("parser", lambda v, d: (CommandParser(v, d, commands), ({}, {})),
                            variant, dialect)

    def grammar(self, variant: Variant, dialect: Dialect) -> AnswerGrammar:
        """The answer grammar for this variant and dialect (shared likewise)."""
        return self._shared("grammar", lambda v, d: AnswerGrammar(self.spec, v, d),
                            variant, dialect)

    def framed(self, variant: Variant, term: bytes) -> tuple[list[bytes], list[bytes]]:
        """The pool's lines with ``term``, without and with a checksum (made once)."""
        key = (variant.id, term)
        framed = self._framed.get(key)
        if framed is None:
            pool = self.pool(variant)
            framed = self._framed[key] = ([x + term for x in pool],
                                          [append_checksum(x) + term for x in pool])
        return framed

    def pool(self, variant: Variant) -> list[bytes]:
        """The lines of one variant (made once; values beyond a dialect's ranges are wanted)."""
        pool = self._pools.get(variant.id)
        if pool is None:
            pool = self._pools[variant.id] = line_pool(self.spec, variant, self.spec.dialect(),
                                                       self.rng, 4000)
        return pool

    def run(self, frames: int, per_config: int | None = None) -> Figures:
        fig = Figures()
        per = per_config or max(200, frames // len(self.configs) + 1)
        start, cpu = time.perf_counter(), time.process_time()
        i = 0
        while fig.frames < frames:
            vid, choices = self.configs[i % len(self.configs)]
            i += 1
            fig.configs += 1
            _Run(self, self.spec.variant(vid), self.spec.dialect(choices), fig).go(
                min(per, frames - fig.frames))
        fig.seconds = time.perf_counter() - start
        fig.cpu_seconds = time.process_time() - cpu
        return fig


class _Run:
    """One variant under one dialect: one unit, the harness's view of its state."""

    def __init__(self, campaign: Campaign, variant: Variant, dialect: Dialect, fig: Figures) -> None:
        self.c = campaign
        self.rng = campaign.rng
        self.fig = fig
        self.variant = variant
        self.dialect = dialect
        self.label = f"{variant.id} {dict(dialect.changed())}"
        self.unit = campaign.unit_class(variant, dialect)
        self.grammar = campaign.grammar(variant, dialect)
        self.parser, self._verdicts = campaign.parser(variant, dialect)
        self.splitter = LineSplitter(dialect["A1"])
        self.term = b"\r\n" if dialect["A1"] == "crlf" else b"\r"
        self.mode = dialect["A1"]
        self._cut = -len(self.term)
        self.pool = campaign.pool(variant)
        self.framed = campaign.framed(variant, self.term)
        self.addr = b"!%d" % variant.interpolator_address
        self.reset_cs = bool(variant.reset.get("checksum", False))
        self.ready_after = float(variant.reset.get("ready_after_s", 2.0))
        self.cs: bool | None = self.reset_cs
        self.packet: bool | None = False
        self.deaf_until = -1.0
        self.t = 0.0
        self.known = True
        self.unknown_left = 0
        self.queue: list[bytes] = []
        self.watchdog = dialect["A13"] != "off"
        self.hex_floats = dialect["A18"] == "hex-bytes"

    # frames ------------------------------------------------------------------------------
    def _with_sum(self, body: bytes) -> bytes:
        on = self.cs if self.cs is not None else self.rng.random() < 0.5
        if on and self.rng.random() < 0.92:
            return append_checksum(body)
        return body

    def _mutate(self, frame: bytes) -> bytes:
        rng = self.rng
        kind = rng.randrange(9)
        n = len(frame)
        i = rng.randrange(n) if n else 0
        if kind == 0 and n:
            b = bytearray(frame)
            b[i] ^= 1 << rng.randrange(8)
            return bytes(b)
        if kind == 1:
            return frame[:i] + bytes((rng.choice(ALPHABET),)) + frame[i:]
        if kind == 2:
            return frame[:i] + frame[i + 1:]
        if kind == 3:
            return frame[:i]
        if kind == 4:
            return frame + frame
        if kind == 5:
            return frame[:i] + rng.choice(self.pool) + self.term
        if kind == 6:  # over-long number
            digits = b"9" * rng.choice((21, 41, 4301, 5000)) if rng.random() < 0.7 else \
                b"0" * 5000 + b"1"
            return frame[:i] + digits + frame[i:]
        if kind == 7:  # a lone CR or LF inside the line
            return frame[:i] + rng.choice((b"\r", b"\n")) + frame[i:]
        return frame.replace(b",", b" ,  ", 1)

    def _frame(self) -> bytes:
        rng = self.rng
        r = rng.random()
        if r < 0.82:
            on = self.cs if self.cs is not None else r < 0.4
            framed = self.framed[1 if on and rng.random() < 0.92 else 0]
            frame = framed[int(rng.random() * len(framed))]
            return frame if r < 0.58 else self._mutate(frame)
        if r < 0.92:
            return _noise(rng, rng.randrange(24))
        if r < 0.95:  # a packet: *S, C/B lines (or anything), *E with the right count or not
            lines = [rng.choice(self.pool) if rng.random() < 0.3 else
                     self.addr + b"C%d,%d,%d" % (rng.randint(-50, 50), rng.randint(-50, 50), 0)
                     for _ in range(rng.randrange(6))]
            count = len(lines) if rng.random() < 0.8 else rng.randrange(9)
            body = [self.addr + b"*S", *lines, self.addr + b"*E%d" % count]
            self.queue.extend(self._with_sum(x) + self.term for x in body[1:])
            return self._with_sum(body[0]) + self.term
        if r < 0.965:  # an over-long line
            return self.addr + b"C" + _noise(rng, 5000, one_line=True) + self.term
        if r < 0.99:
            sign = b"+" if rng.random() < 0.5 else b"-"
            return self._with_sum(self.addr + b"%" + sign) + self.term
        if r < 0.995:
            return self._with_sum(self.addr + b"J") + self.term
        return self._with_sum(self.addr + b"H") + self.term

    # one frame ---------------------------------------------------------------------------
    def go(self, n: int) -> None:
        fig = self.fig
        rng = self.rng
        send = self.send
        end = fig.frames + n
        while fig.frames < end:
            if not self.known:
                if self.unknown_left <= 0:
                    self.resync()
                    continue
                self.unknown_left -= 1
            send(self.queue.pop(0) if self.queue else self._frame())
            self.t += _STEPS[int(rng.random() * 5)]

    def _exchange(self, frame: bytes) -> bytes | None:
        """The unit's answer to ``frame`` (None after an exception, counted), its time checked.

        A frame's time is the CPU time of the unit's exchange alone, with the garbage collector
        held off meanwhile: a collection of the harness's heap, or the harness's own work
        between frames, is not the unit hanging (a loaded machine once stretched those past
        ``hang_s``)."""
        fig = self.fig
        fig.frames += 1
        collecting = gc.isenabled()
        gc.disable()
        start = _cpu()
        try:
            t_ans, out = self.unit.exchange(frame, self.t)
        except Exception as exc:  # noqa: BLE001 - counting them is the point
            fig.exceptions += 1
            fig.note(f"{self.label}: {frame[:60]!r}: {type(exc).__name__}: {exc}")
            self.unit = self.c.unit_class(self.variant, self.dialect, t0=self.t)
            self._reset_state()
            return None
        finally:
            dt = _cpu() - start
            if collecting:
                gc.enable()
        if dt > fig.max_frame_s:
            fig.max_frame_s = dt
            if dt > self.c.hang_s:
                fig.hangs += 1
                fig.note(f"{self.label}: {frame[:60]!r}: took {dt:.2f} s")
        now = self.unit.now  # a silent exchange may still have run virtual time (watchdog)
        self.t = t_ans if t_ans > now else now
        return out

    def _reset_state(self) -> None:
        self.cs = self.reset_cs
        self.packet = False
        self.known = True
        self.splitter.clear()
        self.queue.clear()

    def _bad(self, frame: bytes, out: bytes, problem: str) -> None:
        self.fig.malformed += 1
        self.fig.note(f"{self.label}: {frame[:60]!r} -> {out[:60]!r}: {problem}")

    def send(self, frame: bytes) -> None:
        t = self.t
        deaf = t < self.deaf_until
        single = None
        if deaf or not self.known:
            lines: list[bytes] = []
        elif self._one_line(frame):
            single = frame[: self._cut]
            lines = [single]
        else:
            had_pending = bool(self.splitter._buf)
            lines = self.splitter.feed(frame)
            if (len(lines) == 1 and not had_pending and not self.splitter._buf
                    and len(frame) == len(lines[0]) + len(self.term)):
                single = lines[0]
        out = self._exchange(frame)
        if out is None:
            return
        if single is not None and not deaf:
            if abs(t - self.deaf_until) < 1e-6:
                self.known = False  # too close to call
                return
            problem = self._judge(single, out, t)
        elif not self.known:
            problem = self.grammar.check(out, None, None)
        elif abs(t - self.deaf_until) < 1e-6:
            self.known = False  # too close to call
            return
        elif deaf:
            problem = self.grammar.check(out, self.cs, None, silent=True)
        else:
            problem = self._several(lines, out)
        if problem is not None:
            self._bad(frame, out, problem)

    def _one_line(self, frame: bytes) -> bool:
        """``frame`` is exactly one whole line and nothing is pending (the common case, told
        without the splitter; the splitter's rules otherwise)."""
        if self.splitter._buf or len(frame) > MAX_LINE or not frame.endswith(self.term):
            return False
        mode = self.mode
        if mode == "cr":
            return frame.count(b"\r") == 1 and frame[:1] != b"\n"
        if mode == "crlf":
            return frame.count(b"\r\n") == 1
        return frame.count(b"\r") == 1 and b"\n" not in frame and len(frame) > 1

    def _several(self, lines: list[bytes], out: bytes) -> str | None:
        """A frame of several lines, or a cut one: judge each answer line on its own; the
        state stays known unless one of the lines may have changed it."""
        if self.splitter.pending and self.watchdog and b"!" in self.splitter.pending:
            self.splitter.clear()  # the watchdog ran out within the exchange
        if self.packet:
            self._lose_track()
        else:
            for line in lines:
                if _MAY_BE_STATEFUL.search(line) is None:
                    continue
                verdict = self._verdict(line)
                if verdict.__class__ is Command and verdict.name in _STATEFUL:
                    self._lose_track()
                    break
        return self.grammar.check(out, self.cs, None)

    def _lose_track(self) -> None:
        self.known = False
        self.unknown_left = self.rng.randrange(1, 12)

    def _judge(self, line: bytes, out: bytes, t: float) -> str | None:
        """One complete line: its answer must be the one its command (or rejection) has."""
        self.fig.judged += 1
        verdict = self._verdict(line)
        name = verdict.name
        if (name in ("EFW", "EUW") and self.hex_floats
                and (verdict.__class__ is Command or verdict.kind in ("syntax", "range"))):
            verdict = Command(0, name, (), False, line)  # the unit reads these itself (A18)
        if self.packet:
            return self._in_packet(verdict, out, t)
        problem = self.grammar.check(out, self.cs, verdict)
        self._after(verdict, out, t)
        return problem

    def _verdict(self, line: bytes) -> Command | Rejection:
        cache = self._verdicts[1 if self.cs else 0]
        v = cache.get(line)
        if v is None:
            if len(cache) > 200_000:
                cache.clear()
            v = cache[line] = self.parser.parse(line, bool(self.cs))
        return v

    def _in_packet(self, verdict: Command | Rejection, out: bytes, t: float) -> str | None:
        name = verdict.name
        if name == "*E" and (verdict.__class__ is Command or verdict.code is not None):
            self.packet = False
            return self.grammar.check(out, self.cs, verdict)
        if (verdict.__class__ is Command and self.dialect["A12"] == "accept-any"
                and name in ("J", "%", "*S")):
            self._lose_track()  # executed unless an earlier line of the packet failed (A12)
        return self.grammar.check(out, self.cs, None, silent=True)

    def _after(self, verdict: Command | Rejection, out: bytes, t: float) -> None:
        """The protocol state after a judged line (from the line and its answer code)."""
        if verdict.__class__ is not Command:
            return
        name = verdict.name
        code = (out[0] - 0x30) & 7 if out[:1].isdigit() else (None if not out else -1)
        if name == "%" and code == 0:
            self.cs = verdict.args[0] == "+"
        elif name == "*S" and not out:
            self.packet = True
        elif name == "J" and (code == 0 if self.grammar.j_answers else not out):
            self.deaf_until = t + self.ready_after
            self.cs, self.packet = self.reset_cs, False

    def resync(self) -> None:
        """Regain a known state as a host would: end the line, close a packet, reset, wait;
        then the unit must answer ``?``."""
        self.fig.resyncs += 1
        for frame in recovery_frames(self.variant, self.dialect):
            out = self._exchange(frame)
            if out is not None:
                problem = self.grammar.check(out, None, None)
                if problem is not None:
                    self._bad(frame, out, problem)
        self.t += self.ready_after + 0.01
        self._reset_state()
        self.deaf_until = -1.0
        probe = self.addr + b"?"
        frame = (append_checksum(probe) if self.cs else probe) + self.term
        out = self._exchange(frame)
        if out is None:
            return
        verdict = self.parser.parse(probe if not self.cs else append_checksum(probe), bool(self.cs))
        problem = self.grammar.check(out, self.cs, verdict)
        if problem is None and not out:
            problem = "no answer after the reset and its deaf time"
        if problem is not None:
            self._bad(frame, out, "after resync: " + problem)
