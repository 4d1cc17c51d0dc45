"""Judging a reference unit by what a real unit answered: a session recorded from real
firmware (an MCAP capture made by ``conform proxy``, or a text transcript) is played into the
family's reference unit at the recorded times, and the unit's lines are compared with the
real ones. The model is then held to recorded answers, not to itself.

A text transcript has one event per line::

    # comments and blank lines are ignored
    0.000 > N1 M105*39            the host wrote this line (a newline is added)
    0.012 < ok T:21.50 /0.00      the unit answered this line
    > M105*99                     the time may be left out: GAP seconds after the last event
    0.5 >! \\x18                   ``>!``: these bytes exactly, no newline (escapes as in Python)

What varies from one run of the same firmware to the next (temperatures, build dates) is
masked by the family (``Family.judge_mask``) before lines are compared.
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from conform.errors import UserError

if TYPE_CHECKING:
    from conform.emulator.serve import SansIOUnit

GAP = 0.2
"""Seconds between events whose transcript line gives no time."""

SETTLE = 3.0
"""Seconds the reference unit is given after the last host write to say what it still has."""


@dataclass(frozen=True)
class Event:
    t: float
    host: bool          # True: the host wrote ``data``; False: the unit answered it
    data: bytes
    where: str          # the transcript line or capture record that holds it


@dataclass
class Transcript:
    events: list[Event]
    variant: str = ""   # the variant the recording names, if any
    source: str = ""

    @property
    def host_events(self) -> list[Event]:
        return [e for e in self.events if e.host]

    def unit_bytes(self) -> bytes:
        return b"".join(e.data for e in self.events if not e.host)


_TEXT_LINE = re.compile(r"^(?:(?P<t>[0-9]+(?:\.[0-9]*)?)\s+)?(?P<dir>>!|>|<)(?: (?P<text>.*))?$")


def _unescape(text: str, where: str) -> bytes:
    try:
        return text.encode("latin-1").decode("unicode_escape").encode("latin-1")
    except (UnicodeDecodeError, UnicodeEncodeError) as exc:
        raise UserError(f"{where}: bad escape in {text!r}: {exc.reason}") from None


def parse_text(text: str, source: str = "transcript") -> Transcript:
    """A text transcript (see the module docstring); a bad line is a one-line error naming it."""
    events: list[Event] = []
    t = 0.0
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.rstrip("\r")
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        where = f"{source}:{number}"
        m = _TEXT_LINE.match(line)
        if m is None:
            raise UserError(f"{where}: expected '[SECONDS] > LINE', '[SECONDS] >! BYTES' or "
                            f"'[SECONDS] < LINE', not {line[:60]!r}")
        if m["t"] is not None:
            stamp = float(m["t"])
            if stamp < t:
                raise UserError(f"{where}: time {stamp} is before the previous event's {t}")
            t = stamp
        elif events:
            t += GAP
        body = m["text"] or ""
        if m["dir"] == ">!":
            events.append(Event(t, True, _unescape(body, where), where))
        elif m["dir"] == ">":
            events.append(Event(t, True, body.encode("latin-1", "replace") + b"\n", where))
        else:
            events.append(Event(t, False, body.encode("latin-1", "replace") + b"\n", where))
    if not any(e.host for e in events):
        raise UserError(f"{source}: no host line ('>') in the transcript")
    return Transcript(events, source=source)


def read_capture(path: Path) -> Transcript:
    """Both directions of an MCAP capture, in the order they were read, with their times."""
    from conform.capture.reader import open_capture

    cap = open_capture(path)
    events: list[Event] = []
    t0: float | None = None
    for i, chunk in enumerate(cap.raw_chunks()):
        stamp = chunk.get("t_read")
        t = float(stamp) if isinstance(stamp, (int, float)) else chunk["log_time"] / 1e9
        if t0 is None:
            t0 = t
        events.append(Event(max(0.0, t - t0), chunk.get("direction") == "host",
                            bytes(chunk["bytes"]), f"{path.name}: read {i}"))
    if not any(e.host for e in events):
        raise UserError(f"{path}: the capture holds no host bytes to play")
    session = cap.metadata.get("conform.session", {})
    return Transcript(events, variant=str(session.get("variant", "") or ""), source=str(path))


def read_transcript(path: str | Path) -> Transcript:
    """An MCAP capture or a text transcript, told apart by the file's first bytes."""
    p = Path(path)
    try:
        head = p.read_bytes()[:8]
    except OSError as exc:
        raise UserError(f"{p}: cannot read: {exc.strerror or exc}") from None
    if head.startswith(b"\x89MCAP"):
        return read_capture(p)
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise UserError(f"{p}: not an MCAP capture nor a UTF-8 transcript "
                        f"(byte {exc.start} cannot be decoded)") from None
    return parse_text(text, p.name)


def play(unit: SansIOUnit, transcript: Transcript, settle: float = SETTLE) -> list[tuple[float, bytes]]:
    """Every host event written into ``unit`` at its time; what the unit wrote, with times.

    What the unit says before the first host event (its banner) is dropped when the recording
    starts with the host: the recording joined a unit that was already running."""
    out: list[tuple[float, bytes]] = []
    hosts = transcript.host_events
    if transcript.events[0].host:       # the recording joined a running unit: no banner
        _until(unit, hosts[0].t, [])
    for e in hosts:
        _until(unit, e.t, out)
        unit.receive(e.data, e.t)
        out.extend(unit.poll(e.t))
    _until(unit, hosts[-1].t + settle, out)
    return out


def _until(unit: SansIOUnit, t: float, out: list[tuple[float, bytes]]) -> None:
    for _ in range(100_000):
        nxt = unit.next_deadline()
        if nxt is None or nxt > t or not math.isfinite(nxt):
            break
        out.extend(unit.poll(nxt))
    out.extend(unit.poll(t))


_LINE = re.compile(r"[^\r\n]*(?:\r\n|\r|\n)|[^\r\n]+$")


def lines_of(data: bytes) -> list[str]:
    """The answer lines, each with its terminator (CR, LF or CR LF) kept: a unit that ends its
    lines differently from the recorded one disagrees."""
    return _LINE.findall(data.decode("latin-1"))


@dataclass
class Difference:
    """One place where the two disagree: what the real unit wrote there, what the reference
    wrote, and the last host line written before it."""
    recorded: list[str]
    reference: list[str]
    after_host: str
    at: int             # index of the first recorded line concerned


@dataclass
class Verdict:
    source: str
    variant: str
    host_lines: int
    recorded_lines: int
    reference_lines: int
    same: int
    differences: list[Difference] = field(default_factory=list)

    @property
    def agrees(self) -> bool:
        return not self.differences

    def to_dict(self) -> dict[str, object]:
        return {"source": self.source, "variant": self.variant, "agrees": self.agrees,
                "host_lines": self.host_lines, "recorded_lines": self.recorded_lines,
                "reference_lines": self.reference_lines, "same": self.same,
                "differences": [d.__dict__ for d in self.differences]}


def _host_before(transcript: Transcript, t: float) -> str:
    """The last host write at or before time ``t``."""
    before = [e for e in transcript.host_events if e.t <= t]
    return before[-1].data.decode("latin-1").rstrip("\n") if before else ""


def _timed_lines(chunks: Iterable[tuple[float, bytes]]) -> tuple[list[str], list[float]]:
    """The lines of a stream read in chunks, each timed by the read that ended it (a line
    split over two reads is one line; a CR at a read's end waits for a possible LF)."""
    lines: list[str] = []
    times: list[float] = []
    buf, last = "", 0.0
    for t, data in chunks:
        buf += data.decode("latin-1")
        last = t
        cut = len(buf) - 1 if buf.endswith("\r") else len(buf)
        done = _LINE.findall(buf[:cut])
        rest = buf[cut:]
        if done and not done[-1].endswith(("\r", "\n")):
            rest = done.pop() + rest
        buf = rest
        lines.extend(done)
        times.extend([t] * len(done))
    if buf:
        lines.append(buf)
        times.append(last)
    return lines, times


def compare(transcript: Transcript, reference_out: Iterable[tuple[float, bytes]],
            mask: Callable[[str], str], variant: str) -> Verdict:
    """Recorded unit lines against the reference unit's, after ``mask``, in order."""
    recorded, rec_t = _timed_lines((e.t, e.data) for e in transcript.events if not e.host)
    reference, ref_t = _timed_lines(reference_out)
    a = [mask(x) for x in recorded]
    b = [mask(x) for x in reference]
    matcher = difflib.SequenceMatcher(a=a, b=b, autojunk=False)
    diffs: list[Difference] = []
    same = 0
    for op, i1, i2, j1, j2 in matcher.get_opcodes():
        if op == "equal":
            same += i2 - i1
            continue
        t = min(rec_t[i1] if i1 < i2 else math.inf, ref_t[j1] if j1 < j2 else math.inf)
        diffs.append(Difference(recorded[i1:i2], reference[j1:j2],
                                _host_before(transcript, t), i1))
    return Verdict(transcript.source, variant, len(transcript.host_events), len(recorded),
                   len(reference), same, diffs)


def judge(transcript: Transcript, unit: SansIOUnit, mask: Callable[[str], str], variant: str,
          settle: float = SETTLE) -> Verdict:
    return compare(transcript, play(unit, transcript, settle), mask, variant)


def _shown(line: str, width: int = 100) -> str:
    text = repr(line)
    return text if len(text) <= width else text[:width - 1] + "…"


def render(v: Verdict, limit: int = 20, lines: int = 6) -> list[str]:
    """The terminal lines: the verdict first, then each difference with its host line."""
    head = (f"{v.source}: {'AGREES' if v.agrees else 'DIFFERS'} with the reference "
            f"{v.variant}: {v.same} of {v.recorded_lines} recorded answer lines matched "
            f"({v.reference_lines} from the reference, {v.host_lines} host writes played)")
    out = [head]
    for d in v.differences[:limit]:
        out.append(f"  after host {_shown(d.after_host.rstrip(), 60)} "
                   f"(recorded line {d.at + 1}):")
        for side, got in (("recorded ", d.recorded), ("reference", d.reference)):
            out.extend(f"    {side}: {_shown(x)}" for x in got[:lines])
            if len(got) > lines:
                out.append(f"    {side}: … {len(got) - lines} more lines")
            if not got:
                out.append(f"    {side}: (nothing)")
    if len(v.differences) > limit:
        out.append(f"  … and {len(v.differences) - limit} more differences (--json lists all)")
    return out
