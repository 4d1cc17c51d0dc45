"""Format 2 (batched) captures: same bytes, same frames, same findings as format 1."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from conform.capture.batch import FRAME_KEYS, BatchSession, rows
from conform.capture.reader import open_capture
from conform.capture.recorder import Recorder
from conform.capture.recover import capture_info
from conform.families.gve import decode
from conform.families.gve.analysis import analyze
from conform.families.gve.decode import LineTracker, make_decoder

CAPTURES = Path(__file__).resolve().parent.parent / "captures"


def rewrite_as_format2(src: Path, dst: Path) -> None:
    """Record a format-1 capture's reads again, with their own times, as format 2."""
    cap = open_capture(src)
    meta = dict(cap.metadata.get("conform.session", {}))
    meta.pop("format_version", None)
    rec = Recorder(dst, meta, clock=lambda: 0.0)
    for c in cap.raw_chunks():
        rec.chunk(c["direction"], c["bytes"], c["t_read"], c["t_first"])
    rec.close()


@pytest.mark.parametrize("name", ["good-rs232", "careless-noisy"])
def test_a_sample_rewritten_as_format2_gives_the_same_analysis(tmp_path, name):
    src = CAPTURES / f"{name}.mcap"
    dst = tmp_path / f"{name}.mcap"
    rewrite_as_format2(src, dst)
    old, new = open_capture(src), open_capture(dst)
    for d in ("host", "unit"):
        assert new.stream(d) == old.stream(d)
    assert old.metadata["conform.session"]["format_version"] == "1"
    assert new.metadata["conform.session"]["format_version"] == "2"
    a, b = analyze(src), analyze(dst)
    assert b.kinds() == a.kinds()
    assert b.metrics["exchanges"] == a.metrics["exchanges"]
    assert b.metrics["vectors_accepted"] == a.metrics["vectors_accepted"]
    assert b.metrics["latency"]["rtt"]["median"] == pytest.approx(a.metrics["latency"]["rtt"]["median"])
    # and the recorder decoded the same exchanges as the analyser paired
    ex = list(new.exchanges())
    assert sum(e["status"] == "answered" for e in ex) >= 0.95 * a.metrics["exchanges"]
    assert capture_info(dst).state == "clean"


def test_batches_store_each_byte_once_and_validate_against_their_schemas(tmp_path):
    import base64

    import jsonschema

    path = tmp_path / "b.mcap"
    rec = Recorder(path, {"baud": 115200, "variant": "gve64-v19"})
    t = rec.now()
    for i in range(50):
        rec.chunk("host", b"!0L%d,0,0\r" % i, t + i * 0.01)
        rec.chunk("unit", b"0\r", t + i * 0.01 + 0.002)
    rec.close()
    raw_bytes = 0
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            payload = json.loads(message.data)
            jsonschema.Draft202012Validator(json.loads(schema.data)).validate(payload)
            if channel.topic.startswith("/serial/"):
                assert set(payload) == {"direction", "offset", "count", "t_start", "t_end",
                                        "bytes", "reads", "data"}
                raw_bytes += len(base64.b64decode(payload["data"]))
    assert raw_bytes == 50 * 2 + sum(len(b"!0L%d,0,0\r" % i) for i in range(50))
    cap = open_capture(path)
    chunks = list(cap.raw_chunks())
    assert [c["direction"] for c in chunks[:4]] == ["host", "unit", "host", "unit"]
    ex = list(cap.exchanges())
    assert len(ex) == 50 and all(e["status"] == "answered" for e in ex)
    assert [e["name"] for e in ex[:2]] == ["L", "L"]


def test_batch_columns_round_trip():
    s = BatchSession(baud=115200, decoder=make_decoder("gve64-v19"))
    s.chunk("host", b"!0PF\r", 1.0)
    s.chunk("unit", b"0,1,2,3\r", 1.01)
    recs = s.finish(2.0)
    frames = next(r for r in recs if r.topic == "/frames").payload
    items = rows(frames, FRAME_KEYS)
    assert [f["kind"] for f in items] == ["command", "answer"]
    assert items[1]["fields"] == ["1", "2", "3"]
    with pytest.raises(ValueError):
        rows({"count": 2, "kind": ["x"]}, ("kind",))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(max_size=24).map(lambda b: b.translate(bytes.maketrans(b"\x00\x01\x02", b"\r\n\r"))),
                max_size=6), st.integers(2, 12))
def test_cr_fast_path_cuts_lines_like_the_byte_loop(blocks, max_line):
    old, decode.MAX_LINE = decode.MAX_LINE, max_line
    try:
        a, b = LineTracker("host", "cr"), LineTracker("host", "cr")
        off = 0
        for k, data in enumerate(blocks):
            if not data:
                continue
            assert a._feed_cr(data, off, 10.0 + k, 9.5 + k) == b._feed_bytes(data, off, 10.0 + k, 9.5 + k)
            off += len(data)
        assert a.partial == b.partial
        assert a.rest(20.0) == b.rest(20.0)
    finally:
        decode.MAX_LINE = old


def test_format1_samples_still_match_the_format1_schemas():
    import jsonschema

    from conform.capture.schemas import CHANNELS_V1

    with open(CAPTURES / "usb-packets.mcap", "rb") as f:
        reader = make_reader(f)
        seen = set()
        for schema, channel, message in reader.iter_messages():
            name, want = CHANNELS_V1[channel.topic]
            assert schema.name == name
            jsonschema.Draft202012Validator(want).validate(json.loads(message.data))
            seen.add(channel.topic)
    assert {"/serial/host", "/serial/unit"} <= seen


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(max_size=40).map(lambda b: b.translate(bytes.maketrans(b"\x00\x01\x02", b"\r\n\r"))),
                max_size=8))
def test_cr_spans_split_lines_like_the_byte_loop(blocks):
    a, b = LineTracker("unit", "cr"), LineTracker("unit", "cr")
    off = 0
    for k, data in enumerate(blocks):
        if not data:
            continue
        want = b._feed_bytes(data, off, 10.0 + k, 9.9 + k)
        assert a.spans(data, off, 10.0 + k, 9.9 + k) == [
            (ln.data, ln.offset, ln.length, ln.t_first) for ln in want]
        assert all(ln.t_last == 10.0 + k for ln in want)
        off += len(data)
    assert a.partial == b.partial and a.rest(20.0) == b.rest(20.0)


class _RecordsOnly:
    """A decoder with only the ``Decoder`` protocol (``feed``/``finish``) and the family's
    fields: no rows."""

    def __init__(self) -> None:
        self._d = make_decoder("gve64-v19")
        self.fields = self._d.fields

    def feed(self, *a):  # noqa: ANN002, ANN201
        return self._d.feed(*a)

    def finish(self, t):  # noqa: ANN001, ANN201
        return self._d.finish(t)


def _batch_frames(stream: list[tuple[str, bytes]], rows_decoder: bool = True
                  ) -> tuple[list[dict], list[dict]]:
    """Frames and exchanges as a recorder stores them (rows -> batch columns -> dicts)."""
    from conform.capture.batch import EXCHANGE_KEYS

    s = BatchSession(baud=115200,
                     decoder=make_decoder("gve64-v19") if rows_decoder else _RecordsOnly())
    recs, t = [], 100.0
    for direction, data in stream:
        t += 0.01
        recs += s.chunk(direction, data, t)
    recs += s.finish(t + 1)
    frames = [f for r in recs if r.topic == "/frames" for f in rows(r.payload, FRAME_KEYS)]
    ex = [e for r in recs if r.topic == "/exchanges" for e in rows(r.payload, EXCHANGE_KEYS)]
    return frames, ex


def test_a_repeated_line_decodes_by_the_checksum_mode_of_its_moment():
    from conform.families.gve.protocol.checksum import append_checksum

    summed = append_checksum(b"!0A100") + b"\r"  # !0A100,4F
    frames, ex = _batch_frames([
        ("host", b"!0A100\r"), ("unit", b"0\r"),
        ("host", b"!0%+\r"), ("unit", b"0,5C\r"),
        ("host", b"!0A100\r"), ("unit", b"4,60\r"),  # checksums on: this one lacks its sum
        ("host", summed), ("unit", b"0,5C\r"),
        ("host", b"!0%-,CF\r"), ("unit", b"0\r"),
        ("host", b"!0A100\r"), ("unit", b"0\r"),  # off again: the same bytes are a command
    ])
    host = [f for f in frames if f["direction"] == "host"]
    assert [(f["kind"], f["checksum_mode"], f["checksum_status"]) for f in host] == [
        ("command", False, "none"), ("command", False, "none"), ("rejection", True, "missing"),
        ("command", True, "ok"), ("command", True, "ok"), ("command", False, "none")]
    assert [e["status"] for e in ex] == ["answered"] * 6


def test_a_line_that_switched_checksums_on_is_a_rejection_once_j_turned_them_off():
    from conform.families.gve.protocol.checksum import append_checksum

    summed = append_checksum(b"!0A100") + b"\r"
    # first seen with the mode unknown (switches it on), then after J (mode known, off: its
    # checksum reads as a parameter too many)
    frames, _ = _batch_frames([("host", summed), ("unit", append_checksum(b"0") + b"\r"),
                               ("host", append_checksum(b"!0J") + b"\r"),
                               ("unit", append_checksum(b"0") + b"\r"),
                               ("host", summed), ("unit", b"1\r")])
    host = [f for f in frames if f["direction"] == "host"]
    assert [(f["kind"], f["checksum_mode"]) for f in host] == [
        ("command", True), ("command", True), ("rejection", False)]


def test_a_decoder_without_rows_gives_the_same_batches():
    """``BatchSession`` takes the records of a decoder that does not collect rows itself."""
    stream = [("host", b"!0PF\r"), ("unit", b"0,1,2,3\r"), ("host", b"!0%+\r"),
              ("unit", b"0,5C\r"), ("host", b"!0A100\r"), ("unit", b"4,60\r"),
              ("host", b"!0*S\r!0L1,2,3\r!0*E\r"), ("unit", b"0,5C\r"), ("host", b"!0PF")]
    assert _batch_frames(stream, rows_decoder=False) == _batch_frames(stream)
