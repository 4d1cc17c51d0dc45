"""Issue 24's bug classes: the queue's edge, every open question asked in a run, answers judged
whole, and what a default run (no opt-in) verifies without moving an axis; each class with its
project mutant, killed by the check meant for it — over a real pty where the class is about
what a link shows."""

from __future__ import annotations

import re

import pytest
from test_conformance_link import served  # conform emulate serve (or a mutant) on a pty

from conform.conformance.results import Grade
from conform.conformance.runner import RunOptions
from conform.families.gve.conformance.checks import generate, select
from conform.families.gve.conformance.expect import moving_tolerance, reply_mismatch
from conform.families.gve.conformance.motion_free import zero_line
from conform.families.gve.conformance.runner import Runner
from conform.families.gve.conformance.safety import Guard, hazards
from conform.families.gve.conformance.script import Step, skip_reason
from conform.families.gve.conformance.suite import suite
from conform.families.gve.conformance.target import (
    GveEmuTarget,
    GveLinkTarget,
    GveReply,
    emulator_factory,
)
from conform.families.gve.protocol.checksum import append_checksum
from conform.link import open_port

NO_OPT_IN = Guard(False, None, False)
VARIANTS = ("gve64-v10", "gve64-v19", "gve64-phantom", "gve124")


def _emu_run(spec, variant, patterns, *, mutant=None, dialect=None, guard=None):
    target = GveEmuTarget(emulator_factory(spec, variant, dialect, mutant), "emu", guard)
    checks = suite(spec, variant, patterns=patterns, guard=guard, machine=False)
    return {c.key: c for c in Runner(spec, target, variant, options=RunOptions()).run(checks).checks}


def _link_run(spec, port, variant, patterns, guard=NO_OPT_IN):
    target = GveLinkTarget(open_port(port, 115200, 0.1), port, guard, 115200)
    try:
        checks = suite(spec, variant, patterns=patterns, guard=guard, machine=False)
        run = Runner(spec, target, variant, options=RunOptions()).run(checks)
    finally:
        target.close()
    return {c.key: c for c in run.checks}


# -- 1. the queue's edge ----------------------------------------------------------------------

def test_a_vector_answered_0_beyond_capacity_and_lost_fails(spec):
    got = _emu_run(spec, "gve64-v19", ["C/queue-full", "C/queue-zero", "*/13.7/queue-full"],
                   mutant="queue-edge-drop")
    for key in ("C/queue-full", "C/queue-zero", "queue-full"):
        assert got[key].grade is Grade.FAIL, (key, got[key].grade, got[key].detail)
        assert got[key].question is None  # no open question explains a lost vector


def test_a5_is_concluded_once_the_extra_vector_was_seen_executed(spec):
    """A unit that does take capacity + 1 vectors while one runs, and executes the extra one,
    is still the A5 alternative: the position read back after the queue has run shows it."""
    dialect = spec.dialect({"A5": "excludes-running"})
    got = _emu_run(spec, "gve64-v19", ["C/queue-full", "question/A5"], dialect=dialect)
    for key in ("C/queue-full", "question/A5"):
        assert got[key].grade is Grade.DEVIATION, (key, got[key].detail)
        assert (got[key].question, got[key].alternative) == ("A5", "excludes-running")
    script = [s.describe() for s in select(generate(spec, "gve64-v19"), ["C/queue-full"])[0]
              .script]
    assert script[-1] == "!0PF" and script[-3].startswith("(wait")  # read back after the drain


# -- 2. every open question is asked --------------------------------------------------------

@pytest.mark.parametrize("variant", VARIANTS)
def test_every_open_question_has_an_info_check(spec, variant):
    checks = {c.key: c for c in generate(spec, variant)}
    for q in spec.questions:
        c = checks[f"question/{q}"]
        assert c.level == "INFO" and c.questions == (q,)
        # N/A only where the variant lacks the command asked about: XM (v10: A8), EFW (GVE124)
        assert c.na is None or (variant, q) in {("gve64-v10", "A8"), ("gve124", "A18")}, c.na


# the alternatives a probe cannot tell apart on GVE64 v19 (the variant makes them equal)
SAME_ON_V19 = {("A7", "rate-limited"), ("A19", "none"), ("A20", "missing-reads-0")}


def test_each_alternative_is_named_by_its_question_check(spec):
    for q, question in spec.questions.items():
        for alt in question.alternatives:
            if alt == spec.dialect()[q]:
                continue
            got = _emu_run(spec, "gve64-v19", [f"question/{q}"],
                           dialect=spec.dialect({q: alt}))[f"question/{q}"]
            if (q, alt) in SAME_ON_V19:
                assert got.grade is Grade.PASS, (q, alt, got.detail)
            else:
                assert got.grade is Grade.DEVIATION, (q, alt, got.grade, got.detail)
                assert (got.question, got.alternative) == (q, alt)


def test_a_lower_case_answer_no_alternative_lists_fails_the_a21_check(spec):
    got = _emu_run(spec, "gve64-v19", ["question/A21", "unknown-command"],
                   mutant="lower-case-4")
    assert got["question/A21"].grade is Grade.FAIL
    assert got["unknown-command"].grade is Grade.PASS  # what caught nothing before


def test_default_run_asks_all_but_the_motion_and_eeprom_questions(spec):
    asked = {c.questions[0] for c in suite(spec, "gve64-v19", patterns=["question/*"],
                                           guard=NO_OPT_IN, machine=False)
             if skip_reason(c.script, NO_OPT_IN, False) is None}
    assert set(spec.questions) - asked == {"A5", "A16", "A18", "A25", "A26", "A27"}


# -- 3. answers judged whole, over a pty --------------------------------------------------------

def test_bytes_after_the_cr_are_judged_with_the_answer():
    step = Step(line=b"!0F\r")
    ref = GveReply(b"!0F\r", 0.0, [b"0,00"])
    for loose in (False, True):
        assert reply_mismatch(step, ref, GveReply(b"!0F\r", 0.0, [b"0,00"]), loose, 0) is None
        lf = GveReply(b"!0F\r", 0.0, [b"0,00"], trailing=b"\n")
        assert reply_mismatch(step, ref, lf, loose, 0) == "bytes after the answer's CR: '\\n'"
        twice = GveReply(b"!0F\r", 0.0, [b"0,00"], trailing=b"0,00\r")
        assert "after the answer's CR" in reply_mismatch(step, ref, twice, loose, 0)
    late = GveReply(b"!0F\r", 0.0, [b"0,00"], stray=b"\n")  # the LF came after the quiet time
    assert "LF" in reply_mismatch(step, ref, late, True, 0)
    pos = Step(line=b"!0PF\r", kind="position")
    ref = GveReply(b"!0PF\r", 0.0, [b"0,1,2,3"])
    plus = GveReply(b"!0PF\r", 0.0, [b"0,+1,2,3"])
    assert "not an integer" in reply_mismatch(pos, ref, plus, True, 5)


def test_a_position_under_way_may_lie_anywhere_the_reading_could_have_been_taken():
    """At 125 000 pulses/s the reference read X=181 124 with its answer back in 2 ms. A target
    whose answer took 198 ms longer (a loaded emulator, a busy unit) took its reading up to
    198 ms later: 25 000 pulses further is within reach then, and not when it answered as
    promptly as the reference; the gap between the two writes counts the same way."""
    pos = Step(line=b"!0PF\r", kind="position")
    ref = GveReply(b"!0PF\r", 1.565, [b"0,181124,-456,789"], t_rx=1.567, moving=True)
    further = [b"0,206124,-456,789"]
    slow = GveReply(b"!0PF\r", 1.565, further, t_rx=1.765)
    prompt = GveReply(b"!0PF\r", 1.565, further, t_rx=1.567)
    assert moving_tolerance(125000, ref, slow) == pytest.approx(125000 * (0.198 + 0.05))
    assert reply_mismatch(pos, ref, slow, True, moving_tolerance(125000, ref, slow)) is None
    assert moving_tolerance(125000, ref, prompt) == pytest.approx(125000 * 0.05)
    assert "not within 6250 of 181124" in reply_mismatch(pos, ref, prompt, True,
                                                         moving_tolerance(125000, ref, prompt))
    written_later = GveReply(b"!0PF\r", 1.765, further, t_rx=1.767)
    assert reply_mismatch(pos, ref, written_later, True,
                          moving_tolerance(125000, ref, written_later)) is None
    unanswered = GveReply(b"!0PF\r", 1.565, [])
    assert moving_tolerance(125000, ref, unanswered) == pytest.approx(125000 * 0.05)


FRAMING = ["framing/answers", "V/valid", "F/valid", "PF/valid", "SR/word-2", "H/idle"]


@pytest.mark.slow
def test_cr_lf_answers_fail_every_directed_check_over_a_pty(spec):
    with served("gve64-v19", mutant="answer-crlf") as port:
        bad = _link_run(spec, port, "gve64-v19", FRAMING)
    for key, c in bad.items():
        assert c.grade is Grade.FAIL, (key, c.grade, c.detail)
        assert "after the answer's CR" in c.detail or "LF" in c.detail, (key, c.detail)


@pytest.mark.slow
def test_the_reference_over_a_pty_passes_the_framing_checks(spec):
    with served("gve64-v19", "--baud", "115200") as port:
        good = _link_run(spec, port, "gve64-v19", FRAMING)
    assert {k: c.grade for k, c in good.items()} == {k: Grade.PASS for k in good}


# -- 4. verified without opt-in ---------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("mutant", ["queue-edge-drop", "no-queue-full-flag", "queue-one-short"])
def test_queue_mutants_are_killed_without_opt_in_over_a_pty(spec, mutant):
    with served("gve64-v19", mutant=mutant) as port:
        got = _link_run(spec, port, "gve64-v19", ["C/queue-zero", "C/queue-full"])
    assert got["C/queue-full"].grade is Grade.SKIPPED  # moves: needs the opt-in
    assert got["C/queue-zero"].grade is Grade.FAIL, got["C/queue-zero"].detail


@pytest.mark.parametrize("variant", VARIANTS)
def test_what_runs_without_opt_in_sends_no_pulse(spec, variant):
    """Every vector a default run sends holds no digit 1-9 in any field (a checksum tail that
    could read as a field starts with a letter), every W no length: whatever a unit makes of
    the line, nothing moves."""
    checks = suite(spec, variant, guard=NO_OPT_IN, machine=False)
    sent = [s.line for c in checks if c.na is None and skip_reason(c.script, NO_OPT_IN, False)
            is None for s in c.script if s.line]
    vectors = [ln for ln in sent if re.match(rb"^!0[LC]", ln)]
    assert len(vectors) > spec.variant(variant).queue  # the queue fill among them
    for ln in vectors:
        fields = ln[3:].rstrip(b"\r").split(b",")
        assert all(not re.search(rb"[1-9]", f) or (i >= 3 and re.fullmatch(rb"[A-F][0-9A-F]", f))
                   for i, f in enumerate(fields)), ln
    for ln in sent:
        if re.match(rb"^!0W", ln):
            assert re.match(rb"^!0W[A-Z],-?0+,\d+,0+", ln), ln


def test_zero_lines_with_checksums_are_motion_free():
    for mnemonic in ("C", "L"):
        text = zero_line(True, mnemonic)
        line = append_checksum(text.encode()) + b"\r"
        assert not hazards(line) and not re.search(rb"[1-9]", line[3:-4]), line
    assert hazards(b"!0C0,0,0,38\r") == {"motion"}  # a tail that reads as 38 pulses on A
    assert hazards(b"!0WX#,0,1000,0,500\r") == {"motion"}  # '#' might shift a speed into a length


def test_default_run_skips_fewer_checks(spec):
    """107 were SKIPPED for gve64-v19 without opt-in before these motion-free forms."""
    checks = suite(spec, "gve64-v19", guard=NO_OPT_IN, machine=False)
    skipped = [c for c in checks if c.na is None and skip_reason(c.script, NO_OPT_IN, False)]
    # a command's from-state form is skipped exactly where its valid form is (EEPROM writes)
    valid_skipped = {c.key.rsplit("/", 1)[0] for c in skipped if c.key.endswith("/valid")}
    from_state = [c for c in skipped if c.key.endswith("/from-state")]
    assert {c.key.rsplit("/", 1)[0] for c in from_state} <= valid_skipped
    assert len(skipped) - len(from_state) <= 86, len(skipped)
    assert not [c.key for c in skipped if c.key.endswith(("/valid", "/checksum"))
                and c.key.split("/")[0] in ("L", "C", "G", "*S", "*E", "W")]


# -- 5. alternatives scoped to their question; values at rest judged strictly on a link --------

@pytest.mark.slow
def test_a_position_wrong_at_rest_fails_over_a_pty_and_no_alternative_excuses_it(spec):
    """A14's reset-blocks sets RUN at rest; it once made a link run read "moving", widen the
    position tolerance and excuse a position 300 steps off as that alternative."""
    patterns = ["P/valid", "PF/valid", "P4/valid", "*/13.7/position"]
    with served("gve64-v19", mutant="position-off-at-rest") as port:
        got = _link_run(spec, port, "gve64-v19", patterns)
    assert got, "no check ran"
    for key, c in got.items():
        assert c.grade is Grade.FAIL, (key, c.grade, c.detail)
        assert c.question is None and "position" in c.detail, (key, c.question, c.detail)


@pytest.mark.slow
def test_the_a14_alternative_still_reads_as_a14_over_a_pty(spec):
    with served("gve64-v19", "--dialect", "A14=reset-blocks") as port:
        got = _link_run(spec, port, "gve64-v19", ["question/A14", "P/valid"])
    assert got["question/A14"].grade is Grade.DEVIATION
    assert (got["question/A14"].question, got["question/A14"].alternative) == ("A14", "reset-blocks")
    assert got["P/valid"].grade is Grade.PASS, got["P/valid"].detail  # A14 does not touch P


def test_an_alternative_explains_only_answers_it_changes(spec):
    """In-process: the alternative must change the failing answer itself, not merely make the
    rest of the transcript tolerant."""
    got = _emu_run(spec, "gve64-v19", ["P/valid", "position"], mutant="position-off-at-rest")
    for key, c in got.items():
        assert c.grade is Grade.FAIL and c.question is None, (key, c.grade, c.detail)
