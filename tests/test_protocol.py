"""The codec reproduces the manuals' worked examples byte for byte and round-trips every command."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conform.families.gve.protocol import (
    Answer,
    CommandParser,
    Garbled,
    LineSplitter,
    Rejection,
    append_checksum,
    build_packet,
    checksum,
    encode_answer,
    encode_command,
    parse_answer,
    split_checksum,
    verify,
)
from conform.families.gve.spec import load_spec
from conform.families.gve.testing.strategies import command_args

SPEC = load_spec()
DIALECT = SPEC.dialect()
PARSERS = {vid: CommandParser(v, DIALECT) for vid, v in SPEC.variants.items()}
CASES = [(vid, cid) for vid, v in SPEC.variants.items() for cid in v.commands]


# --- golden examples (GVE64 §13.3.2, §13.3.3, §13.7) ----------------------------------------

def test_checksum_worked_example():
    ex = next(e for e in SPEC.examples if e.kind == "checksum")
    assert sum(b"!0A100,") == 0x14F
    assert append_checksum(ex.body.encode()) == ex.line.encode() == b"!0A100,4F"
    v = SPEC.variant("gve64-v19")
    assert encode_command(v, v.command("A"), [100], checksum_on=True) == b"!0A100,4F\r"


def test_checksum_on_off_answers():
    assert encode_answer(0, checksum_on=True) == b"0,5C\r"
    assert encode_answer(0) == b"0\r"
    v = SPEC.variant("gve64-v19")
    assert encode_command(v, v.command("%"), ["+"]) == b"!0%+\r"
    assert encode_command(v, v.command("%"), ["-"], checksum_on=True) == b"!0%-,CF\r"
    a = parse_answer(b"0,5C", checksum_on=True)
    assert isinstance(a, Answer) and a.checksum_ok and a.fields == () and a.code == 0


def test_packet_worked_example():
    ex = next(e for e in SPEC.examples if e.kind == "packet")
    v = SPEC.variant("gve64-v19")
    vectors = [PARSERS["gve64-v19"].parse(line.encode(), True) for line in ex.send[1:-1]]
    assert all(c.name == "C" and c.checksum for c in vectors)
    lines = [encode_command(v, v.command("C"), c.args[:3], checksum_on=True) for c in vectors]
    packet = build_packet(lines, checksum_on=True)
    assert [p.rstrip(b"\r").decode() for p in packet] == list(ex.send)
    assert encode_answer(0, fields=[10], checksum_on=True) == b"0,10,E9\r" == (ex.expect[0] + "\r").encode()
    a = parse_answer(b"0,10,E9", checksum_on=True)
    assert a.fields == ("10",) and a.checksum == 0xE9 and a.checksum_ok


def test_answer_table_13_7_parses():
    rows = {e.id: e for e in SPEC.examples if e.id.startswith("13.7/")}
    parser = PARSERS["gve64-v19"]
    for ex in rows.values():
        cmd = parser.parse(ex.send[0].encode(), False)
        answer = parse_answer(ex.expect[0].encode(), False)
        assert isinstance(answer, Answer)
        if ex.id == "13.7/status-range":
            assert isinstance(cmd, Rejection) and cmd.code == answer.code == 5
        else:
            assert not isinstance(cmd, Rejection), ex.id
    assert parse_answer(b"8", False) == Answer(0, True, (), None, None, b"8")
    assert parse_answer(b"0,-1000,2000,50", False).fields == ("-1000", "2000", "50")
    assert parse_answer(b"0,2B", False).fields == ("2B",)
    assert parse_answer(b"1", False).code == 1


def test_l_with_three_fields_on_four_axes():
    """`!0L1000,0,0` → `0` on the 4-axis GVE64 (§13.7): three fields are accepted."""
    cmd = PARSERS["gve64-v19"].parse(b"!0L1000,0,0", False)
    assert cmd.name == "L" and cmd.args == (1000, 0, 0, 0)
    assert isinstance(PARSERS["gve64-v19"].parse(b"!0L1000,0", False), Rejection)
    assert isinstance(PARSERS["gve124"].parse(b"!0L1,2,3,4", False), Rejection)


@pytest.mark.parametrize(
    ("variant", "line", "kind", "code"),
    [
        ("gve64-v10", b"!0VL1,2,3,4", "absent", 3),
        ("gve64-v10", b"!0VK", "absent", 3),
        ("gve64-v10", b"!0XM100", "absent", 3),
        ("gve64-v10", b"!0NX100", "absent", 3),
        ("gve124", b"!0P4", "absent", 3),
        ("gve124", b"!0Y-", "absent", 3),
        ("gve124", b"!0I2", "absent", 3),
        ("gve64-v19", b"!0Z", "unknown", 3),
        ("gve64-v19", b"!0S512", "unknown", 3),
        ("gve64-v19", b"!0V9", "range", 5),
        ("gve64-v19", b"!0V125001", "range", 5),
        ("gve64-phantom", b"!0V200001", "range", 5),
        ("gve64-v19", b"!0V+100", "syntax", 4),
        ("gve64-v19", b"!0T25", "range", 5),
        ("gve64-v19", b"!0T", "syntax", 4),
        ("gve64-v19", b"!0SW8,F1", "range", 5),
        ("gve64-v19", b"!0NQ100", "range", 5),
        ("gve124", b"!0NA100", "range", 5),
        ("gve64-v19", b"!0L1,2,3,4,5", "syntax", 4),
        ("gve64-v19", b"!3V100", "address", None),
        ("gve64-v19", b"hello", "garbage", None),
        ("gve64-v19", b"!7L1,2,3", "unknown", 3),
    ],
)
def test_rejections(variant, line, kind, code):
    r = PARSERS[variant].parse(line, False)
    assert isinstance(r, Rejection), r
    assert (r.kind, r.code) == (kind, code), r.detail


def test_checksum_rejections():
    parser = PARSERS["gve64-v19"]
    assert parser.parse(b"!0A100,4E", True).kind == "checksum"
    assert parser.parse(b"!0A100,4E", True).code == 4
    assert parser.parse(b"!0A100", True).code == 4  # A11 default: no checksum while on → 4
    lenient = CommandParser(SPEC.variant("gve64-v19"), SPEC.dialect({"A11": "lenient"}))
    assert lenient.parse(b"!0A100", True).name == "A"
    assert parser.parse(b"!0A100,4F", False).code == 4  # a checksum while off is a second field


def test_dialect_choices_change_parsing():
    v = SPEC.variant("gve64-v19")
    assert CommandParser(v, SPEC.dialect({"A2": "s-too"})).parse(b"!0S512", False).name == "$"
    assert CommandParser(v, SPEC.dialect({"A3": "zero-too"})).parse(b"!000,FB", False).name == "O"
    assert CommandParser(v, SPEC.dialect({"A21": "any-case"})).parse(b"!0pf", False).name == "PF"
    assert PARSERS["gve64-v19"].parse(b"!0pf", False).code == 3
    assert CommandParser(v, SPEC.dialect({"A6": "1-65535"})).parse(b"!0A5000", False).name == "A"
    assert PARSERS["gve64-v19"].parse(b"!0A5000", False).code == 5
    lenient = CommandParser(v, SPEC.dialect({"A22": "lenient"}))
    assert lenient.parse(b"!0L+100, 0,,5", False).args == (100, 0, 0, 5)
    assert lenient.parse(b"!0%+", False).args == ("+",)
    assert lenient.parse(b"!0Y-", False).args == ("-",)
    assert CommandParser(v, SPEC.dialect({"A23": "error-3"})).parse(b"!3V1", False).code == 3


# --- round trips drawn from the tables -------------------------------------------------------

@pytest.mark.parametrize(("variant_id", "command_id"), CASES)
@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), checksum_on=st.booleans())
def test_encode_parse_round_trip(variant_id, command_id, data, checksum_on):
    v = SPEC.variant(variant_id)
    cmd = v.command(command_id)
    args = data.draw(command_args(cmd, v))
    address = 7 if cmd.addresses == (7,) else data.draw(st.sampled_from(cmd.addresses))
    line = encode_command(v, cmd, args, address=address, checksum_on=checksum_on)
    assert line.endswith(b"\r")
    parsed = PARSERS[variant_id].parse(line[:-1], checksum_on)
    assert not isinstance(parsed, Rejection), (line, parsed)
    assert parsed.name == command_id and parsed.address == address
    expected = list(args)
    per_axis = [p for p in cmd.params if p.per_axis]
    if per_axis:
        expected += [0] * (len(v.axes) - len(args))
    if cmd.params and cmd.params[0].kind == "float" or any(p.kind == "float" for p in cmd.params):
        assert parsed.args[0] == expected[0] and parsed.args[1] == pytest.approx(expected[1])
    else:
        assert list(parsed.args) == expected
    if checksum_on:
        assert verify(line[:-1])


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=60).filter(lambda b: b"\r" not in b))
def test_checksum_of_any_line_verifies(body):
    line = append_checksum(body)
    assert verify(line)
    head, value = split_checksum(line)
    assert head == body and value == checksum(body + b",")
    if body:  # flipping one byte breaks it unless the sum happens to be the same
        broken = bytes([body[0] ^ 0x01]) + body[1:]
        assert verify(broken + line[len(body):]) is False


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=40), st.booleans())
def test_parsers_never_raise(data, checksum_on):
    for parser in PARSERS.values():
        result = parser.parse(data, checksum_on)
        assert hasattr(result, "raw")
    assert isinstance(parse_answer(data, checksum_on), Answer | Garbled)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(min_size=1, max_size=20).filter(lambda b: b"\r" not in b and b"\n" not in b),
                max_size=6), st.data())
def test_line_splitter_reassembles_any_chunking(lines, data):
    stream = b"".join(line + b"\r" for line in lines)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=5)))
    splitter = LineSplitter("cr")
    out = []
    prev = 0
    for cut in [*cuts, len(stream)]:
        out += splitter.feed(stream[prev:cut])
        prev = cut
    assert out == lines and splitter.pending == b""


def test_line_splitter_modes():
    assert LineSplitter("cr").feed(b"!0P\r\n!0F\r") == [b"!0P", b"!0F"]
    assert LineSplitter("cr-or-lf").feed(b"!0P\n!0F\r\n") == [b"!0P", b"!0F"]
    assert LineSplitter("crlf").feed(b"!0P\r!0F\r\n") == [b"!0P\r!0F"]
