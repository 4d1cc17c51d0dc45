"""Random sequences for grbl: a hypothesis ``RuleBasedStateMachine`` that drives the target
and the reference unit side by side with g-code lines, ``$`` commands, setting writes and
realtime bytes drawn from the tables, compares every answer, shrinks a difference to the
shortest sequence that still shows it and prints that sequence as the replay.

The lines are made of words grbl knows and some it does not (codes.toml's provoking lines,
G/M codes with and without fractions, value words with edge values), so the parser's order
of checks is exercised far beyond the directed checks. Answers are compared line by line;
on a unit behind a link, status reports are compared by their state only (positions and
feeds there follow real time), on an emulated one exactly.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, rule, run_state_machine_as_test

from conform.families.grbl.spec.load import GrblSpec, Variant

PROFILES = {"quick": (60, 15), "full": (300, 30)}   # examples, steps per example
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


def compare_step(target_session: Any, reference_session: Any, data: bytes,
                 normalize: Callable[[list[str]], list[str]]) -> str:
    """Send ``data`` to both; how their answers differ ("" when they agree)."""
    lines = data.count(b"\n")
    status = data.count(b"?") if not lines else 0
    # the reference says how many answers to wait for: a held unit (feed hold, M0) answers its
    # lines only after '~', which then answers them all, so waiting for one answer per line
    # sent would cost the target's whole timeout at every step of a hold
    ref = reference_session.talk(data, answers=lines, status=status, timeout=3.0, linger=0.05)
    answers = sum(1 for x in ref.lines if x == "ok" or x.startswith("error:"))
    tgt = target_session.talk(data, answers=answers, status=status, timeout=3.0, linger=0.05)
    got = [normalize(tgt.lines), normalize(ref.lines)]
    if got[0] == got[1]:
        return ""
    return (f"after {data!r}: the target answered {' | '.join(got[0]) or '-'}, "
            f"the reference {' | '.join(got[1]) or '-'}")


def _replay(target_session: Any, reference_session: Any, steps: list[bytes],
            normalize: Callable[[list[str]], list[str]]) -> str:
    for s in (target_session, reference_session):
        s.fresh()
    for data in steps:
        why = compare_step(target_session, reference_session, data, normalize)
        if why:
            return why
    return ""


def _minimize(target_session: Any, reference_session: Any, out: Outcome,
              normalize: Callable[[list[str]], list[str]]) -> None:
    """Drop steps one at a time while the difference stays (after hypothesis's shrinking,
    which keeps steps a deletion would not have changed)."""
    i = 0
    while i < len(out.steps) and len(out.steps) > 1:
        trial = out.steps[:i] + out.steps[i + 1:]
        why = _replay(target_session, reference_session, trial, normalize)
        if why:
            out.steps, out.why = trial, why
        else:
            i += 1


def build_machine(target_session: Any, reference_session: Any, spec: GrblSpec, v: Variant,
                  normalize: Callable[[list[str]], list[str]], out: Outcome) -> type:
    provoking = tuple(c.send.decode("latin-1").strip() for c in spec.errors.values()
                      if c.send is not None and not c.setup and not c.send.startswith(b"$"))
    settings_rows = [(n, s) for n, s in spec.settings.items()]
    realtime = tuple(b for b, r in spec.realtime.items() if r.effect != "reset")

    class GrblSequences(RuleBasedStateMachine):
        def __init__(self) -> None:
            super().__init__()
            self.steps: list[bytes] = []
            for s in (target_session, reference_session):
                s.restore()   # a real unit keeps an example's setting writes (EEPROM): undo them
                s.fresh()
            out.examples += 1

        def _both(self, data: bytes) -> None:
            self.steps.append(data)
            why = compare_step(target_session, reference_session, data, normalize)
            if why:
                out.steps, out.why = list(self.steps), why
                raise AssertionError(why)

        @rule(line=gcode_lines(provoking))
        def gcode(self, line: str) -> None:
            self._both(line.encode("latin-1") + b"\n")

        @rule(word=st.one_of(st.sampled_from([f"G{g}" for g in G_WORDS]),
                             st.sampled_from([f"M{m}" for m in M_WORDS])),
              value=st.sampled_from(("", "T5", "F100", "S200", "N5", "P0.1")))
        def modal(self, word: str, value: str) -> None:
            """One G or M word, perhaps with one value word: mostly lines grbl takes."""
            self._both(f"{word}{value}\n".encode())

        @rule(cmd=st.sampled_from(SAFE_COMMANDS))
        def command(self, cmd: str) -> None:
            self._both(cmd.encode() + b"\n")

        @rule(jog=st.tuples(st.sampled_from(("", "G91", "G90", "G20", "G53", "G2", "M3")),
                            st.sampled_from(("X-1", "Y-0.5", "Z-1", "")),
                            st.sampled_from(("F100", "F0", "", "S100", "T1"))))
        def jog(self, jog: tuple[str, str, str]) -> None:
            self._both(("$J=" + "".join(jog)).encode() + b"\n")

        @rule(row=st.sampled_from(settings_rows),
              value=st.sampled_from(("-1", "0", "1", "2", "3", "2.5", "255", "256", "5x", "x")))
        def setting(self, row: tuple[int, Any], value: str) -> None:
            self._both(f"${row[0]}={value}\n".encode())

        @rule(byte=st.sampled_from(realtime))
        def realtime_byte(self, byte: int) -> None:
            self._both(bytes([byte]))

    return GrblSequences


def run_sequences(target_session: Any, reference_session: Any, spec: GrblSpec, v: Variant, *,
                  emulated: bool, profile: str = "quick", seed: int = 0) -> Outcome:
    """Run the machine; an Outcome whose ``steps`` is empty when every example agreed."""
    examples, steps = PROFILES.get(profile, PROFILES["quick"])
    out = Outcome()

    def normalize(lines: list[str]) -> list[str]:
        if emulated:
            return lines
        return [x.split("|", 1)[0] + ">" if x.startswith("<") else x for x in lines]

    machine = build_machine(target_session, reference_session, spec, v, normalize, out)
    machine.TestCase.settings = settings(
        max_examples=examples, stateful_step_count=steps, deadline=None, database=None,
        derandomize=True, suppress_health_check=list(HealthCheck),
        phases=(Phase.generate, Phase.shrink), print_blob=False)
    random.seed(seed)
    try:
        run_state_machine_as_test(machine, settings=machine.TestCase.settings)
    except AssertionError:
        pass                     # out holds the shrunk sequence (the last failing run)
    if out.steps:
        _minimize(target_session, reference_session, out, normalize)
    return out


def replay_text(steps: list[bytes]) -> str:
    """The sequence as one line a reader can paste: each step's bytes, in order."""
    return " ".join(repr(s)[1:] for s in steps)
