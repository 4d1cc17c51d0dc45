"""Fuzzing the reference unit: arbitrary bytes never raise, and every answer is one the spec
allows (or the silence it prescribes)."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conform.families.gve.protocol import Command, CommandParser, Rejection, append_checksum
from conform.families.gve.spec import load_spec
from conform.families.gve.unit import Unit

SPEC = load_spec()
SETTINGS = settings(max_examples=120, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

TEMPLATES = [
    "!0L{i},{i},{i}", "!0C{i},{i},{i}", "!0C{i},{i},{i},{i}", "!0V{u}", "!0A{u}", "!0B{u}",
    "!0T{u}", "!0${u}", "!0VL{u},{u},{u},{u}", "!0VK", "!0VN", "!0XA", "!0XU", "!0XD", "!0XM{u}",
    "!0P", "!0PF", "!0P4", "!0N", "!0NX{i}", "!0WX,{i},{u},{u},{u}", "!0Y+", "!0Y&", "!0Y-",
    "!0K", "!0R", "!0H", "!0D", "!0G", "!0ER{h}", "!0EW{h},{h}", "!0EFR{h}", "!0EUR{h}",
    "!0EFW{h},{u}.5", "!0EUW{h},{u}", "!0O0,{h}", "!0I1", "!0I2", "!0SR{s}", "!0SW{s},{h}",
    "!0F", "!0@", "!0>", "!0J", "!0%+", "!0%-", "!0*S", "!0*E{s}", "!7V{u}", "!7?", "!0?", "!0Q",
    "!3V{u}", "!0Z", "!0v1",
]
FORMAT = {"i": "%d", "u": "%d", "h": "%X", "s": "%d"}


@st.composite
def lines(draw) -> bytes:
    if draw(st.integers(0, 9)) == 0:
        return draw(st.binary(max_size=24)).replace(b"\r", b"")
    template = draw(st.sampled_from(TEMPLATES))
    values = {
        "i": draw(st.integers(-3000, 3000)), "u": draw(st.sampled_from([0, 1, 10, 500, 20000,
                                                                         200001, 4294967296])),
        "h": draw(st.integers(0, 300)), "s": draw(st.integers(0, 9)),
    }
    text = template
    for key, fmt in FORMAT.items():
        while "{" + key + "}" in text:
            text = text.replace("{" + key + "}", fmt % values[key], 1)
    return text.encode()


dialects = st.fixed_dictionaries({
    qid: st.sampled_from(list(q.alternatives)) for qid, q in SPEC.questions.items()
})


def answer_ok(line: bytes) -> bool:
    """One line the unit sent: an answer digit, fields; or a repeated command (``>``)."""
    if line.startswith(b"!"):
        return True
    if not line or line[:1] not in b"0123456789ABCDEF":
        return False
    return len(line) == 1 or line[1:2] == b","


def allowed_codes(name: str) -> set[int]:
    cmd = SPEC.commands[name]
    codes = {0}
    if cmd.family == "vector":
        codes |= {1, 7}
    if name == "G":
        codes.add(6)
    if not cmd.while_running or cmd.family in ("mpg", "reference", "queue"):
        codes.add(7)
    if name in ("SR", "SW", "EFW") or cmd.params:
        codes.add(5)
    if name == "*E":
        codes.add(4)
    return codes


@given(variant=st.sampled_from(list(SPEC.variants)), dialect=dialects,
       steps=st.lists(st.tuples(lines(), st.floats(0.0, 0.3), st.booleans()), max_size=40))
@SETTINGS
def test_arbitrary_lines_get_allowed_answers(variant, dialect, steps):
    v = SPEC.variant(variant)
    d = SPEC.dialect(dialect)
    unit = Unit(v, d)
    parser = CommandParser(v, d)
    terminator = b"\r\n" if d["A1"] == "crlf" else b"\r"
    t = 0.0
    for body, dt, with_sum in steps:
        t += dt
        checksum_on = unit.checksum_on
        line = append_checksum(body) if (with_sum and checksum_on) else body
        quiet = unit.deaf or unit.executor.running or unit._packet is not None
        t_ans, out = unit.exchange(line + terminator, t)
        assert t_ans >= t
        t = t_ans
        for piece in out.split(b"\r")[:-1]:
            assert answer_ok(piece), (line, out)
        if quiet or not out or unit._packet is not None:
            continue
        verdict = parser.parse(line, checksum_on)
        if verdict.name in ("EFW", "EUW") and d["A18"] == "hex-bytes":
            continue  # the unit parses these values itself (A18)
        first = out.split(b"\r")[0]
        if isinstance(verdict, Rejection):
            if verdict.code is None:
                continue
            assert int(first[:1], 16) & 7 == verdict.code, (line, out, verdict)
        elif isinstance(verdict, Command) and verdict.name not in (">", "*S"):
            if first.startswith(b"!"):
                continue
            code = int(first[:1], 16) & 7
            assert code in allowed_codes(verdict.name), (line, out)
        assert unit.queue_len <= v.queue + 1
        assert all(0 <= unit.status(n) <= 255 for n in range(7))


@given(variant=st.sampled_from(list(SPEC.variants)), dialect=dialects,
       chunks=st.lists(st.tuples(st.binary(max_size=40), st.floats(0.0, 0.5)), max_size=30))
@SETTINGS
def test_arbitrary_bytes_never_raise(variant, dialect, chunks):
    unit = Unit(SPEC.variant(variant), SPEC.dialect(dialect))
    t = 0.0
    sent: list[tuple[float, bytes]] = []
    for data, dt in chunks:
        t += dt
        unit.receive(data, t)
        sent.extend(unit.poll(t))
        nd = unit.next_deadline()
        assert nd is None or nd >= t - 1e-9
    sent.extend(unit.poll(t + 10.0))
    times = [ts for ts, _ in sent]
    assert times == sorted(times)
    for _, data in sent:
        assert data.endswith(b"\r")
        for piece in data.split(b"\r")[:-1]:
            assert answer_ok(piece), data


@given(steps=st.lists(st.tuples(st.sampled_from([b"C", b"L"]),
                                st.lists(st.integers(-2**31, 2**31), min_size=2, max_size=5),
                                st.floats(0.0, 0.05), st.booleans()), max_size=60),
       variant=st.sampled_from(["gve64-v19", "gve124"]))
@SETTINGS
def test_fast_path_equals_parser(steps, variant):
    v = SPEC.variant(variant)
    fast, slow = Unit(v), Unit(v, fast_path=False)
    t = 0.0
    for kind, values, dt, checksum_on in steps:
        t += dt
        if checksum_on != fast.checksum_on:
            toggle = append_checksum(b"!0%-") if fast.checksum_on else b"!0%+"
            assert fast.exchange(toggle + b"\r", t) == slow.exchange(toggle + b"\r", t)
        body = b"!0" + kind + b",".join(b"%d" % x for x in values)
        line = (append_checksum(body) if checksum_on else body) + b"\r"
        assert fast.exchange(line, t) == slow.exchange(line, t)
        assert fast.position == slow.position
        assert fast.queue_len == slow.queue_len and fast.index == slow.index


# ---------------------------------------------------------------- the fuzz campaign

from conform.families.gve.protocol.grammar import AnswerGrammar  # noqa: E402
from conform.families.gve.testing.fuzz import Campaign  # noqa: E402


def test_answer_grammar_rejects_what_the_tables_do_not_allow():
    v = SPEC.variant("gve64-v19")
    d = SPEC.dialect()
    g = AnswerGrammar(SPEC, v, d)
    p = CommandParser(v, d)
    V, Q, ER = p.parse(b"!0V100", False), p.parse(b"!0?", False), p.parse(b"!0ER1F", False)
    assert g.check(b"0\r", False, V) is None and g.check(b"8\r", False, V) is None
    assert g.check(b"0,12\r", False, V)                       # V answers no field
    assert g.check(b"6\r", False, V)                          # 6 is G's alone (errors.toml)
    assert g.check(b"0\r", False, Q)                          # ? answers its version
    assert g.check(b"0,ab\r", False, ER) and g.check(b"0,1FF\r", False, ER)
    assert g.check(b"0,FF\r", False, ER) is None
    assert g.check(b"0,5C\r", True, V) is None and g.check(b"0,5D\r", True, V)
    assert g.check(b"0", False, V)                            # no CR
    assert g.check(b"0\r0\r", False, V)                       # two answers to one line
    assert g.check(b"4\r", False, p.parse(b"!0Vx", False)) is None
    assert g.check(b"5\r", False, p.parse(b"!0Vx", False))    # the tables say 4
    assert g.check(b"0\r", False, p.parse(b"garbage", False))  # ignored lines get silence
    rep = p.parse(b"!0>", False)
    assert g.check(b"!0V1\r0\r", False, rep) is None
    assert g.check(b"!0V1\r2\r0\r", False, rep)               # a cut echo: item 11's symptom
    assert g.check(b"0\r", False, None, silent=True)


class _Deviant(Unit):
    """Answers F with one hex digit too many: the campaign must notice."""

    def _cmd_F(self, args, t):
        code, fields = super()._cmd_F(args, t)
        return code, (fields[0] + "0",)


def test_campaign_finds_a_malformed_answer():
    fig = Campaign(SPEC, seed=5, unit_class=_Deviant, mixes=0).run(4000, per_config=2000)
    assert fig.malformed > 0 and fig.exceptions == 0
    assert any("F" in e for e in fig.examples)


class _Stuck(Unit):
    """Spins on the CPU for 0.2 s the first time it is asked for its position (a unit that
    hangs once)."""

    stuck = False

    def exchange(self, data, t):
        if b"P" in data and not _Stuck.stuck:
            import time

            _Stuck.stuck = True
            end = time.thread_time() + 0.2
            while time.thread_time() < end:
                pass
        return super().exchange(data, t)


def test_campaign_counts_a_unit_that_hangs():
    """The frame's time is the unit's own CPU time: a unit stuck in a loop is counted."""
    _Stuck.stuck = False
    fig = Campaign(SPEC, seed=5, unit_class=_Stuck, mixes=0, hang_s=0.1).run(3000,
                                                                              per_config=1500)
    assert _Stuck.stuck and fig.hangs == 1 and any("took 0.2" in e for e in fig.examples)


def test_campaign_short():
    fig = Campaign(SPEC, seed=11, mixes=2).run(20_000, per_config=300)
    assert fig.frames == 20_000 and fig.judged > 10_000
    assert fig.failures == 0, fig.examples


@pytest.mark.slow
def test_campaign_200k_frames():
    """The CI campaign: 200 000 frames over every variant and dialect (bench/fuzz_unit.py)."""
    fig = Campaign(SPEC, seed=1).run(200_000)
    assert fig.frames == 200_000 and fig.configs >= len(SPEC.variants) * 30
    assert fig.failures == 0, fig.examples


def test_shared_parsers_and_grammars_read_as_fresh_ones():
    """The campaign shares a parser (grammar) between dialects that read alike: each shared one
    reads lines (judges answers) as one built for that very dialect does."""
    campaign = Campaign(SPEC, seed=3, mixes=6)
    probes = [b"0\r", b"8\r", b"0,5C\r", b"4\r", b"0,12\r", b"!0V1\r0\r", b"0,FF\r", b""]
    for vid, choices in campaign.configs[:60]:
        v, d = SPEC.variant(vid), SPEC.dialect(choices)
        parser, _ = campaign.parser(v, d)
        grammar = campaign.grammar(v, d)
        fresh_p, fresh_g = CommandParser(v, d, dict(SPEC.commands)), AnswerGrammar(SPEC, v, d)
        assert grammar.j_answers == fresh_g.j_answers and grammar.echo == fresh_g.echo
        for line in campaign.pool(v)[::97]:
            for cs in (False, True):
                verdict = fresh_p.parse(line, cs)
                assert parser.parse(line, cs) == verdict, (vid, choices, line)
                for out in probes:
                    assert grammar.check(out, cs, verdict) == fresh_g.check(out, cs, verdict)
