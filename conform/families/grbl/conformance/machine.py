"""Random sequences for grbl: hypothesis draws each example whole (g-code lines, ``$``
commands, setting writes and realtime bytes from the tables), then it is sent to the target
and to the reference unit side by side and every answer compared; a difference is shrunk to
the shortest sequence that still shows it and printed as the replay.

Nothing drawn depends on what the target answers, so an example replays the same on any
target, a serial port too. Every example starts from a soft reset, with the reference put in
the state the target is really in (its position, offsets, modal state and settings read back:
:class:`Pair`), and a difference counts only when a replay shows it again.

The lines are made of words grbl knows and some it does not (codes.toml's provoking lines,
G/M codes with and without fractions, value words with edge values), so the parser's order
of checks is exercised far beyond the directed checks. Answers are compared line by line;
on a unit behind a link, status reports are compared by their state only (positions and
feeds there follow real time), on an emulated one exactly.

With ``--max-steps N`` no random line moves an axis further than N steps: each step goes to
the reference unit first, and when a block it planned would take an axis more than N whole
steps ($100-$102 in force, planner.c's lround of each end) -- or its arc's length more than
N steps -- or the reference still holds a line it could not plan yet (a pause, a hold), the
example ends there and that step never reaches the target.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import hypothesis
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from hypothesis.errors import HypothesisException

from conform.conformance.target import HarnessError
from conform.families.grbl.conformance.readback import read_eeprom, read_state
from conform.families.grbl.spec.load import GrblSpec, Variant
from conform.families.grbl.unit.adopt import UnitState, start_from
from conform.families.grbl.unit.model import GrblUnit

PROFILES = {"quick": (60, 15), "full": (300, 30)}   # examples, steps per example
LINK_BUDGET = {"quick": 45.0, "full": 900.0}      # s of examples on a link
SHRINK_SECONDS = {"quick": 25.0, "full": 120.0}    # s of shrinking a difference on a link
SETTLE = 0.25       # s: on a link, no step goes out this close before a change the reference
SETTLE_GAP = 0.05   # expects; the wait runs this far past the change
SETTLE_MAX = 2.0    # s of settling at most before one step
SAFE_COMMANDS = ("$", "$$", "$#", "$G", "$I", "$N", "$C", "$X")
G_WORDS = ("0", "1", "2", "3", "4", "10", "17", "18", "19", "20", "21", "28", "28.1", "28.2",
           "30", "38.2", "38.3", "40", "43", "43.1", "49", "53", "54", "55", "59", "59.1",
           "61", "61.1", "80", "90", "90.1", "91", "91.1", "92", "92.1", "93", "94", "1.5", "5")
M_WORDS = ("0", "1", "2", "3", "4", "5", "7", "8", "9", "30", "3.5", "6")
VALUE_LETTERS = "XYZFIJKLNPRST"
VALUES = ("0", "1", "-1", "2.5", "-0.5", "10", "255", "256", "9999999", "10000000", "10000001",
          "", ".", "-")


def _word(letter: str, value: str) -> str:
    return f"{letter}{value}"


@st.composite
def gcode_lines(draw: Any, provoking: tuple[str, ...]) -> str:
    """A g-code line: one of the tables' provoking lines, or 1-5 words drawn from G/M codes
    (supported, unsupported, fractional) and value words with edge values, sometimes a
    comment or a stray character."""
    if provoking and draw(st.booleans()) and draw(st.booleans()):
        return draw(st.sampled_from(provoking))
    parts = []
    for _ in range(draw(st.integers(1, 5))):
        kind = draw(st.sampled_from("GGMVVV"))
        if kind == "G":
            parts.append(_word("G", draw(st.sampled_from(G_WORDS))))
        elif kind == "M":
            parts.append(_word("M", draw(st.sampled_from(M_WORDS))))
        else:
            parts.append(_word(draw(st.sampled_from(VALUE_LETTERS)), draw(st.sampled_from(VALUES))))
    extra = draw(st.sampled_from(("", "", "", " (note)", ";end", ")", "A1", "g1 x1 f100")))
    return " ".join(parts) + extra


@dataclass
class Outcome:
    steps: list[bytes] = field(default_factory=list)   # the shortest failing sequence
    why: str = ""
    examples: int = 0
    cut: int = 0                                        # examples left out by the time budget
    unconfirmed: list[str] = field(default_factory=list)   # differences no replay showed again
    error: HarnessError | None = None                   # the link failed: the run stops
    note: str = ""                                      # what the run left changed on the unit
    beyond: int = 0                # examples ended before a step beyond --max-steps
    first_beyond: str = ""         # the first such step, and why


class Beyond(Exception):
    """A step the target must not get: it would move further than the run's bound."""


def compare_step(target_session: Any, reference_session: Any, data: bytes,
                 normalize: Callable[[list[str]], list[str]],
                 guard: Callable[[], str] | None = None) -> str:
    """Send ``data`` to both; how their answers differ ("" when they agree). ``guard``, asked
    after the reference has taken the step, names why the target must not (:class:`Beyond`)."""
    lines = data.count(b"\n")
    status = data.count(b"?") if not lines else 0
    # the reference says how many answers to wait for: a held unit (feed hold, M0) answers its
    # lines only after '~', which then answers them all, so waiting for one answer per line
    # sent would cost the target's whole timeout at every step of a hold
    ref = reference_session.talk(data, answers=lines, status=status, timeout=3.0, linger=0.05)
    answers = sum(1 for x in ref.lines if x == "ok" or x.startswith("error:"))
    stop = guard() if guard is not None else ""
    if stop:
        raise Beyond(stop)
    tgt = target_session.talk(data, answers=answers, status=status, timeout=3.0, linger=0.05)
    got = [normalize(tgt.lines), normalize(ref.lines)]
    if got[0] == got[1]:
        return ""
    return (f"after {data!r}: the target answered {' | '.join(got[0]) or '-'}, "
            f"the reference {' | '.join(got[1]) or '-'}")


class Pair:
    """The target and the reference unit side by side. Each example starts with both reset
    and the reference put in the state the target is really in (:mod:`.readback`: position,
    offsets, modal state, settings — a grbl keeps its position across a soft reset); on a link
    the reference then keeps the target's clock, and no step is sent just before a change the
    reference expects (a block's end, a dwell's, an alarm's delay), where the wall clock's
    jitter would decide which side of it each unit answers from."""

    def __init__(self, target_session: Any, reference_session: Any,
                 normalize: Callable[[list[str]], list[str]], max_steps: int | None = None
                 ) -> None:
        self.t, self.r, self.normalize = target_session, reference_session, normalize
        self.max_steps = max_steps
        self.planned: list[Any] = []   # the reference's blocks not yet weighed against it
        self.beyond, self.first_beyond = 0, ""
        self.linked = not target_session.target.emulated
        self.known: UnitState | None = None
        self.first: UnitState | None = None   # the target's state before the first example
        self.offset = 0.0

    def start(self) -> None:
        """Both fresh, the reference in the target's state (HarnessError when it cannot be)."""
        t, r = self.t, self.r
        dirty = t.dirty
        t.restore()   # a real unit keeps an example's setting writes (EEPROM): undo them
        t.fresh()
        if self.known is None or dirty:
            self.known = read_eeprom(t)
            t.dirty = False
        state, said = read_state(t, self.known)
        if self.first is None:
            self.first = state
        r.fresh()
        start_from(r.target.unit, state)
        for data, lines in said:   # the same questions: the reference took the state, and its
            theirs = r.talk(data, status=data.count(b"?")).lines   # report counters match
            if self.normalize(theirs) != self.normalize(lines):
                raise HarnessError(
                    f"the reference could not start from the target's state: after {data!r} "
                    f"the target answered {' | '.join(lines)}, the reference {' | '.join(theirs)}")
        self.offset = t.target.now() - r.target.now()
        if self.max_steps is not None:
            self._record(r.target.unit.planner)

    def _record(self, planner: Any) -> None:
        """Keep every block the reference plans from now on in ``planned``."""
        push, planned = planner.push, self.planned
        planned.clear()

        def record(move: Any) -> None:
            planned.append(move)
            push(move)
        planner.push = record

    def _too_far(self) -> str:
        """Why the step the reference just took must not reach the target ("" if it may)."""
        unit = self.r.target.unit
        moves = list(self.planned)
        self.planned.clear()
        for mv in moves:
            axis, steps = block_steps(unit, mv)
            if steps > (self.max_steps or 0):
                return f"{axis} {steps} steps"
        if unit.rx or unit._pending is not None:
            return "a line the reference could not plan yet"
        return ""

    def put_back(self) -> str:
        """A unit behind a link keeps the G54-G59 offsets the examples wrote (EEPROM): write
        the first ones back (G10 L2). G28/G30 can be stored only where the machine stands
        (G28.1/G30.1): changed ones are said, not moved to."""
        if not self.linked or self.first is None:
            return ""
        t = self.t
        t.restore()   # the settings first: $13 decides how $# reads
        t.fresh()
        now, _said = read_state(t, self.known or UnitState())
        for i, (was, got) in enumerate(zip(self.first.coords, now.coords, strict=True)):
            if was != got:
                words = "".join(f"{a}{x:.4f}" for a, x in zip("XYZ", was, strict=True))
                # G21: in mm, whatever units the unit's startup lines left it in
                t.talk(f"G21G10L2P{i + 1}{words}\n".encode())
        moved = [f"{name} {', '.join(f'{x:.3f}' for x in getattr(now, name.lower()))} (was "
                 f"{', '.join(f'{x:.3f}' for x in getattr(self.first, name.lower()))})"
                 for name in ("G28", "G30")
                 if getattr(now, name.lower()) != getattr(self.first, name.lower())]
        return "; the examples left stored positions changed: " + ", ".join(moved) if moved \
            else ""

    def _catch_up(self) -> None:
        lag = self.t.target.now() - self.offset - self.r.target.now()
        if lag > 0:
            self.r.target.wait(lag)

    def _settle(self) -> None:
        """Wait on both while the reference expects a change within SETTLE seconds."""
        waited = 0.0
        while waited < SETTLE_MAX:
            self._catch_up()
            ref = self.r.target
            due = ref.unit.next_deadline()
            if due is None or due - ref.now() > SETTLE:
                return
            d = max(0.0, due - ref.now()) + SETTLE_GAP
            self.t.target.wait(d)
            waited += d
        self._catch_up()

    def run(self, steps: Sequence[bytes]) -> tuple[str, int]:
        """Start, then send ``steps``: the first difference and its step ("", -1 if none)."""
        self.start()
        guard = self._too_far if self.max_steps is not None else None
        for i, data in enumerate(steps):
            if self.linked:
                self._settle()
            try:
                why = compare_step(self.t, self.r, data, self.normalize, guard)
            except Beyond as exc:
                self.beyond += 1
                self.first_beyond = self.first_beyond or f"{data!r} ({exc})"
                return "", -1
            if why:
                return why, i
        return "", -1


def _lround(x: float) -> int:
    """C's lround: half away from zero (planner.c plan_buffer_line's target steps)."""
    return int(math.copysign(math.floor(abs(x) + 0.5), x))


def block_steps(unit: Any, move: Any) -> tuple[str, int]:
    """The axis a planner block takes furthest and by how many whole steps ($100-$102 in
    force, each end as planner.c rounds it); an arc's every point lies within its length."""
    arc = getattr(move.tag, "kind", "") == "arc"
    best = ("X", 0)
    for i, (a, b) in enumerate(zip(move.start, move.end, strict=True)):
        per_mm = max(unit.settings.get(100 + i, 0.0), 0.0)
        steps = abs(_lround(b * per_mm) - _lround(a * per_mm))
        if arc:
            steps = max(steps, math.ceil(move.length * per_mm))
        if steps > best[1]:
            best = ("XYZ"[i], steps)
    return best


class Weighed(GrblUnit):
    """The reference unit keeping the most whole steps any block it plans takes an axis,
    across its resets (a check's own ``farthest`` move)."""

    farthest = 0

    def _reset(self, t: float, power_up: bool = False, announce: float | None = None) -> None:
        super()._reset(t, power_up, announce)
        push = self.planner.push

        def weigh(move: Any) -> None:
            if move.kind not in ("dwell", "pause", "end", "marker"):
                self.farthest = max(self.farthest, block_steps(self, move)[1])
            push(move)
        self.planner.push = weigh  # type: ignore[method-assign]


def _minimize(pair: Pair, out: Outcome, until: float | None) -> None:
    """Drop steps one at a time while the difference stays (after hypothesis's shrinking,
    which keeps steps a deletion would not have changed)."""
    i = 0
    while i < len(out.steps) and len(out.steps) > 1:
        if until is not None and time.perf_counter() > until:
            return
        trial = out.steps[:i] + out.steps[i + 1:]
        why, n = pair.run(trial)
        if why:
            out.steps, out.why = trial[:n + 1], why
        else:
            i += 1


def step_strategy(spec: GrblSpec, v: Variant) -> st.SearchStrategy[bytes]:
    """One step: a g-code line, one modal word, a safe ``$`` command, a jog, a setting write
    or a realtime byte (never a reset: each example starts from one)."""
    provoking = tuple(c.send.decode("latin-1").strip() for c in spec.errors.values()
                      if c.send is not None and not c.setup and not c.send.startswith(b"$"))
    settings_rows = sorted(spec.settings)
    realtime = tuple(b for b, r in spec.realtime.items() if r.effect != "reset")
    modal = st.tuples(st.one_of(st.sampled_from([f"G{g}" for g in G_WORDS]),
                                st.sampled_from([f"M{m}" for m in M_WORDS])),
                      st.sampled_from(("", "T5", "F100", "S200", "N5", "P0.1")))
    jog = st.tuples(st.sampled_from(("", "G91", "G90", "G20", "G53", "G2", "M3")),
                    st.sampled_from(("X-1", "Y-0.5", "Z-1", "")),
                    st.sampled_from(("F100", "F0", "", "S100", "T1")))
    setting = st.tuples(st.sampled_from(settings_rows),
                        st.sampled_from(("-1", "0", "1", "2", "3", "2.5", "255", "256", "5x",
                                         "x")))
    return st.one_of(
        gcode_lines(provoking).map(lambda line: line.encode("latin-1") + b"\n"),
        modal.map(lambda wv: f"{wv[0]}{wv[1]}\n".encode()),
        st.sampled_from(SAFE_COMMANDS).map(lambda cmd: cmd.encode() + b"\n"),
        jog.map(lambda j: ("$J=" + "".join(j)).encode() + b"\n"),
        setting.map(lambda nv: f"${nv[0]}={nv[1]}\n".encode()),
        st.sampled_from(realtime).map(lambda b: bytes([b])),
    )


def link_budget(options: Any) -> float:
    """Wall seconds of examples on a link: the run's own budget, else its profile's."""
    return options.machine_budget or LINK_BUDGET.get(options.profile, LINK_BUDGET["quick"])


def run_sequences(target_session: Any, reference_session: Any, spec: GrblSpec, v: Variant, *,
                  emulated: bool, profile: str = "quick", seed: int = 0,
                  budget: float | None = None, max_steps: int | None = None) -> Outcome:
    """Random examples, each drawn whole before it is sent (what the target answers never
    changes what is drawn, so hypothesis can replay and shrink an example against any
    target); an Outcome whose ``steps`` is empty when every example agreed. A difference
    counts only when a replay of the example shows it again. ``budget``: wall seconds for the
    examples (a link); those left out are counted in ``cut``. ``max_steps``: no step that
    would move an axis further reaches the target (those examples end there, in ``beyond``)."""
    examples, steps = PROFILES.get(profile, PROFILES["quick"])
    out = Outcome()

    def normalize(lines: list[str]) -> list[str]:
        if emulated:
            return lines
        return [x.split("|", 1)[0] + ">" if x.startswith("<") else x for x in lines]

    pair = Pair(target_session, reference_session, normalize, max_steps)
    verdicts: dict[tuple[bytes, ...], str] = {}
    t0 = time.perf_counter()
    ends = {"examples": None if budget is None else t0 + budget, "shrink": None}

    def example(seq: list[bytes]) -> None:
        key = tuple(seq)
        if key not in verdicts:
            end = ends["shrink"] if out.steps else ends["examples"]
            if out.error is not None or (end is not None and time.perf_counter() > end):
                out.cut += 0 if out.steps or out.error else 1
                return
            verdicts[key] = _judge(pair, seq, out)
            if verdicts[key] and ends["shrink"] is None and not emulated:
                ends["shrink"] = time.perf_counter() + SHRINK_SECONDS.get(profile, 20.0)
        if verdicts[key]:
            raise AssertionError(verdicts[key])

    test = given(st.lists(step_strategy(spec, v), min_size=1, max_size=steps))(example)
    test = settings(max_examples=examples, deadline=None, database=None, derandomize=False,
                    suppress_health_check=list(HealthCheck), report_multiple_bugs=False,
                    phases=(Phase.generate, Phase.shrink), print_blob=False)(test)
    test = hypothesis.seed(seed)(test)
    try:
        test()
    except (AssertionError, HypothesisException):
        pass                     # out holds the shortest confirmed failing sequence
    if out.error is not None:
        raise out.error
    if out.steps:
        found = list(out.steps), out.why
        _minimize(pair, out, ends["shrink"])
        why, n = pair.run(out.steps)   # the log shows the sequence reported
        if why:
            out.steps, out.why = out.steps[:n + 1], why
        else:
            out.steps, out.why = found
    out.note = pair.put_back()
    out.beyond, out.first_beyond = pair.beyond, pair.first_beyond
    return out


def _judge(pair: Pair, seq: list[bytes], out: Outcome) -> str:
    """Run one example; a difference that a replay shows again ("" otherwise)."""
    try:
        out.examples += 1
        why, n = pair.run(seq)
        if not why:
            return ""
        again, m = pair.run(seq[:n + 1])
    except HarnessError as exc:
        out.error = exc
        return ""
    if not again:
        out.unconfirmed.append(why)
        return ""
    if not out.steps or m + 1 < len(out.steps):
        out.steps, out.why = list(seq[:m + 1]), again
    return again


def replay_text(steps: list[bytes]) -> str:
    """The sequence as one line a reader can paste: each step's bytes, in order."""
    return " ".join(repr(s)[1:] for s in steps)
