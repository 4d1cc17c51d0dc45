"""Judging a reference unit by what a real unit answered: a session recorded from real
firmware (an MCAP capture made by ``conform proxy``, or a text transcript) is played into the
family's reference unit as the recorded sender paced it (by the answers it waited for, not by
the clock: :func:`play`), and the unit's lines are compared with the real ones. The model is
then held to recorded answers, not to itself.

A text transcript has one event per line::

    # comments and blank lines are ignored
    0.000 > N1 M105*39            the host wrote this line (a newline is added)
    0.012 < ok T:21.50 /0.00      the unit answered this line
    > M105*99                     the time may be left out: GAP seconds after the last event
    0.5 >! \\x18                   ``>!``: these bytes exactly, no newline (escapes as in Python)

The text form cannot hold a CR: its unit lines are given the family's ``line_ending``.
What varies from one run of the same firmware to the next (temperatures, build dates) is
masked by the family (``Family.judge_mask``) before lines are compared, and lines the family
finds the same within its stated tolerance (``Family.judge_near``) count as the same. A
recording another family recognises better is refused (:func:`foreign`).
"""

from __future__ import annotations

import bisect
import difflib
import math
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from conform.errors import UserError

if TYPE_CHECKING:
    from conform.emulator.serve import SansIOUnit
    from conform.families import Family

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
    text: bool = False  # a text transcript: its unit lines end in a bare LF (no CR kept)

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
    return Transcript(events, source=source, text=True)


def with_line_ending(transcript: Transcript, ending: str) -> Transcript:
    """A text transcript's unit lines given the unit's line ending (the text form cannot hold
    a CR); a capture holds the bytes as they were and is returned as it is."""
    if not transcript.text or ending == "\n":
        return transcript
    end = ending.encode("latin-1")
    events = [e if e.host or not e.data.endswith(b"\n") else
              Event(e.t, False, e.data[:-1] + end, e.where) for e in transcript.events]
    return Transcript(events, transcript.variant, transcript.source, text=False)


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


_LINE = re.compile(r"[^\r\n]*(?:\r\n|\r|\n)|[^\r\n]+$")


def lines_of(data: bytes) -> list[str]:
    """The answer lines, each with its terminator (CR, LF or CR LF) kept: a unit that ends its
    lines differently from the recorded one disagrees."""
    return _LINE.findall(data.decode("latin-1"))


WAIT_FACTOR = 1.5
WAIT_EXTRA = 2.0
"""A write paced by an answer waits for the reference's answer at most the recorded gap since
the previous write times ``WAIT_FACTOR`` plus ``WAIT_EXTRA`` seconds: a reference that never
answers gives a difference, not a hang."""


def _every_line(line: str) -> bool:
    return True


_TERMINATOR = re.compile(rb"\r\n|\r|\n")


def _line_count(data: bytes) -> int:
    return len(_TERMINATOR.findall(data))


class _Lines:
    """Lines of a stream read in chunks, each timed by the read that ended it (a line split
    over two reads is one line; a CR at a read's end waits for a possible LF)."""

    def __init__(self) -> None:
        self.buf = ""
        self.last = 0.0

    def feed(self, t: float, data: bytes) -> list[tuple[float, str]]:
        self.buf += data.decode("latin-1")
        self.last = t
        cut = len(self.buf) - 1 if self.buf.endswith("\r") else len(self.buf)
        done = _LINE.findall(self.buf[:cut])
        rest = self.buf[cut:]
        if done and not done[-1].endswith(("\r", "\n")):
            rest = done.pop() + rest
        self.buf = rest
        return [(t, x) for x in done]

    def end(self) -> list[tuple[float, str]]:
        rest, self.buf = self.buf, ""
        return [(self.last, rest)] if rest else []


@dataclass(frozen=True)
class Pace:
    """How the recorded sender timed one host write. ``answered``: it wrote after an answer
    that came since its previous write (an ok-paced sender, or a counting one given room), with
    ``owed`` of its lines still unanswered then and ``since`` seconds after that answer;
    otherwise (put in at once, a realtime byte, bytes in flight) ``since`` seconds after its
    previous write."""

    answered: bool
    owed: int
    since: float


def pacing(transcript: Transcript, is_answer: Callable[[str], bool] = _every_line) -> list[Pace]:
    """The pace of every host write of the recording (see :class:`Pace`). A line is owed
    from its write to the next answer; an answer when nothing is owed (a unit that answers
    a line twice, or unasked) owes the host nothing back."""
    reader = _Lines()
    owed = 0
    answer_t: float | None = None
    prev_t = 0.0
    paces: list[Pace] = []
    for e in transcript.events:
        if not e.host:
            for _, line in reader.feed(e.t, e.data):
                if is_answer(line.rstrip("\r\n")):
                    owed = max(0, owed - 1)
                    answer_t = e.t
            continue
        if answer_t is not None and (not paces or answer_t >= prev_t):
            paces.append(Pace(True, owed, e.t - answer_t))
        else:
            paces.append(Pace(False, owed, e.t - (prev_t if paces else 0.0)))
        owed += _line_count(e.data)
        prev_t = e.t
    return paces


def _follower(transcript: Transcript, follow: Callable[[Any, str], None] | None, unit: SansIOUnit
              ) -> Callable[[Event], None]:
    """A function that, given host write ``e``, shows ``follow`` the recorded answer lines
    before the next host write (those not shown yet)."""
    if follow is None:
        return lambda e: None
    reader = _Lines()
    after: dict[int, list[str]] = {}
    current = -1
    for e in transcript.events:
        if e.host:
            current += 1
        else:
            after.setdefault(current, []).extend(x for _, x in reader.feed(e.t, e.data))
    index = {id(e): i for i, e in enumerate(transcript.host_events)}
    pending = after.get(-1, [])

    def show(e: Event) -> None:
        nonlocal pending
        for line in pending + after.get(index[id(e)], []):
            follow(unit, line.rstrip("\r\n"))
        pending = []

    return show


class _Player:
    """The reference unit driven through a recording's host writes, its answer lines counted
    as they come."""

    def __init__(self, unit: SansIOUnit, is_answer: Callable[[str], bool]) -> None:
        self.unit = unit
        self.is_answer = is_answer
        self.out: list[tuple[float, bytes]] = []
        self.reader = _Lines()
        self.owed = 0           # host lines written to the reference and not yet answered
        self.answer_t = 0.0     # the time of its last answer line

    def take(self, chunks: list[tuple[float, bytes]]) -> None:
        for t, data in chunks:
            self.out.append((t, data))
            for _, line in self.reader.feed(t, data):
                if self.is_answer(line.rstrip("\r\n")):
                    self.owed = max(0, self.owed - 1)
                    self.answer_t = t

    def until(self, t: float, done: Callable[[], bool] | None = None) -> bool:
        """Run the unit to ``t``, or until ``done()`` holds (then True)."""
        for _ in range(1_000_000):
            if done is not None and done():
                return True
            nxt = self.unit.next_deadline()
            if nxt is None or nxt > t or not math.isfinite(nxt):
                break
            self.take(self.unit.poll(nxt))
        self.take(self.unit.poll(t))
        return done is not None and done()

    def write(self, data: bytes, t: float) -> None:
        self.unit.receive(data, t)
        self.owed += _line_count(data)
        self.take(self.unit.poll(t))


def play(unit: SansIOUnit, transcript: Transcript, settle: float = SETTLE,
         is_answer: Callable[[str], bool] = _every_line, played: list[float] | None = None,
         follow: Callable[[Any, str], None] | None = None) -> list[tuple[float, bytes]]:
    """Every host write played into ``unit`` as the recorded sender paced it; what the unit
    wrote, with times (``played``, when given, gets the time each host write was played).

    A write that followed an answer in the recording (:func:`pacing`) is played once the
    reference has no more of its lines unanswered than the recorded sender had (its answer
    then, plus the recorded delay after it), waiting at most the bound ``WAIT_FACTOR`` /
    ``WAIT_EXTRA``, and never sooner after the previous write than in the recording (a
    reference that answers faster than the recorded link does not move the host's writes
    earlier against what the unit is doing); a write that came before any answer keeps its
    recorded delay after the previous write. A reference that answers a line the firmware
    did not, or not at all, shifts the count once (a timeout resets it), so one difference
    stays one difference.

    What the unit says before the first host event (its banner) is dropped when the recording
    starts with the host: the recording joined a unit that was already running.

    ``follow`` (the family's ``judge_follow``) is shown the recorded answer lines up to the
    next host write before each write is played."""
    hosts = transcript.host_events
    shown = _follower(transcript, follow, unit)
    player = _Player(unit, is_answer)
    if transcript.events[0].host:       # the recording joined a running unit: no banner
        player.until(hosts[0].t)
        player.out.clear()
        player.reader = _Lines()
        player.owed, player.answer_t = 0, 0.0
    t_prev, rec_prev = 0.0, 0.0
    slack = 0           # lines the reference owes beyond the recording, after a timeout
    for pace, e in zip(pacing(transcript, is_answer), hosts, strict=True):
        gap = e.t - rec_prev
        if pace.answered:
            need = pace.owed + slack
            bound = t_prev + gap * WAIT_FACTOR + WAIT_EXTRA
            def answered(need: int = need) -> bool:
                return player.owed <= need

            if player.until(bound, answered):
                slack = max(0, min(slack, player.owed - pace.owed))
                t = max(t_prev + gap, player.answer_t + pace.since, player.unit.now)
            else:
                slack = player.owed - pace.owed
                t = bound
        else:
            t = t_prev + pace.since
        player.until(t)
        t = max(t, player.unit.now)
        shown(e)
        player.write(e.data, t)
        if played is not None:
            played.append(t)
        t_prev, rec_prev = t, e.t
    player.until(t_prev + settle)
    return player.out


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


def _host_before(transcript: Transcript, t: float, times: list[float] | None = None) -> int:
    """The index of the last host write at or before time ``t`` (-1: none), on the
    recording's clock, or on the reference's when ``times`` are the writes' played times."""
    stamps = times if times is not None else [e.t for e in transcript.host_events]
    return bisect.bisect_right(stamps, t) - 1


def _timed_lines(chunks: Iterable[tuple[float, bytes]]) -> tuple[list[str], list[float]]:
    """The lines of a stream read in chunks, each timed by the read that ended it."""
    reader = _Lines()
    timed = [x for t, data in chunks for x in reader.feed(t, data)] + reader.end()
    return [x for _, x in timed], [t for t, _ in timed]


def _near_pairs(a: list[str], b: list[str], near: Callable[[str, str], bool]
                ) -> list[tuple[int, int]]:
    """The longest run of pairs (i, j), in order, with ``near(a[i], b[j])``."""
    if len(a) * len(b) > NEAR_CELLS:
        return [(i, i) for i in range(min(len(a), len(b))) if near(a[i], b[i])]
    n, m = len(a), len(b)
    best = [[0] * (m + 1) for _ in range(n + 1)]
    for i in range(n - 1, -1, -1):
        for j in range(m - 1, -1, -1):
            best[i][j] = (best[i + 1][j + 1] + 1 if near(a[i], b[j])
                          else max(best[i + 1][j], best[i][j + 1]))
    pairs, i, j = [], 0, 0
    while i < n and j < m:
        if near(a[i], b[j]) and best[i][j] == best[i + 1][j + 1] + 1:
            pairs.append((i, j))
            i, j = i + 1, j + 1
        elif best[i + 1][j] >= best[i][j + 1]:
            i += 1
        else:
            j += 1
    return pairs


NEAR_CELLS = 250_000
"""A block of differing lines larger than this (recorded × reference) is paired line by line
rather than searched for its best pairing."""


def _opcodes(a: list[str], b: list[str], near: Callable[[str, str], bool] | None
             ) -> list[tuple[str, int, int, int, int]]:
    """difflib's opcodes of the two line lists, the differing blocks split further where
    ``near`` pairs their lines."""
    ops: list[tuple[str, int, int, int, int]] = list(
        difflib.SequenceMatcher(a=a, b=b, autojunk=False).get_opcodes())
    if near is None:
        return ops
    out: list[tuple[str, int, int, int, int]] = []
    for op, i1, i2, j1, j2 in ops:
        if op == "equal" or i1 == i2 or j1 == j2:
            out.append((op, i1, i2, j1, j2))
            continue
        i, j = i1, j1
        for pi, pj in _near_pairs(a[i1:i2], b[j1:j2], near):
            if (i, j) != (i1 + pi, j1 + pj):
                out.append(("replace", i, i1 + pi, j, j1 + pj))
            out.append(("equal", i1 + pi, i1 + pi + 1, j1 + pj, j1 + pj + 1))
            i, j = i1 + pi + 1, j1 + pj + 1
        if (i, j) != (i2, j2):
            out.append(("replace", i, i2, j, j2))
    return out


def compare(transcript: Transcript, reference_out: Iterable[tuple[float, bytes]],
            mask: Callable[[str], str], variant: str,
            near: Callable[[str, str], bool] | None = None,
            played: list[float] | None = None) -> Verdict:
    """Recorded unit lines against the reference unit's, after ``mask``, in order; lines
    ``near`` pairs (the family's tolerance) count as the same. ``played``: when each host
    write was played into the reference (its lines are then placed after the right one)."""
    recorded, rec_t = _timed_lines((e.t, e.data) for e in transcript.events if not e.host)
    reference, ref_t = _timed_lines(reference_out)
    a = [mask(x) for x in recorded]
    b = [mask(x) for x in reference]
    diffs: list[Difference] = []
    hosts = transcript.host_events
    same = 0
    for op, i1, i2, j1, j2 in _opcodes(a, b, near):
        if op == "equal":
            same += i2 - i1
            continue
        where = min(_host_before(transcript, rec_t[i1]) if i1 < i2 else len(hosts),
                    _host_before(transcript, ref_t[j1], played) if j1 < j2 else len(hosts))
        after = hosts[where].data.decode("latin-1").rstrip("\n") if 0 <= where < len(hosts) \
            else ""
        diffs.append(Difference(recorded[i1:i2], reference[j1:j2], after, i1))
    return Verdict(transcript.source, variant, len(transcript.host_events), len(recorded),
                   len(reference), same, diffs)


def judge(transcript: Transcript, unit: SansIOUnit, mask: Callable[[str], str], variant: str,
          settle: float = SETTLE, *, is_answer: Callable[[str], bool] = _every_line,
          near: Callable[[str, str], bool] | None = None,
          follow: Callable[[Any, str], None] | None = None) -> Verdict:
    played: list[float] = []
    out = play(unit, transcript, settle, is_answer, played, follow)
    return compare(transcript, out, mask, variant, near, played)


def foreign(transcript: Transcript, fam: Family) -> str | None:
    """Why the recording is another family's, or None when it may be ``fam``'s: another
    family's detector recognises its traffic better than ``fam``'s does, surely (0.5 or more)
    or where ``fam``'s recognises none of it."""
    from conform.families import families

    host = b"".join(e.data for e in transcript.events if e.host)
    unit = transcript.unit_bytes()
    own = fam.detect(host, unit, {}).score
    others = [(f, f.detect(host, unit, {})) for f in families() if f.name != fam.name]
    if not others:
        return None
    other, best = max(others, key=lambda x: x[1].score)
    if best.score <= own or (best.score < 0.5 and own > 0):
        return None
    names = ", ".join(v.id for v in other.variants())
    return (f"a {other.name} recording ({best.why}), not {fam.name}'s: judge it with a "
            f"{other.name} variant ({names})")


def judge_recording(transcript: Transcript, fam: Family, variant: str,
                    settle: float = SETTLE) -> Verdict:
    """``conform emulate judge``: the recording played into ``fam``'s reference unit and
    compared with the family's ending, answers, mask and tolerance; a recording of another
    family is refused in one line."""
    why = foreign(transcript, fam)
    if why is not None:
        raise UserError(f"{transcript.source}: {why}, not {variant}")
    transcript = with_line_ending(transcript, fam.line_ending)
    return judge(transcript, fam.judge_unit(variant), fam.judge_mask(variant), variant, settle,
                 is_answer=fam.judge_answers(variant), near=fam.judge_near(variant),
                 follow=fam.judge_follow(variant))


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
