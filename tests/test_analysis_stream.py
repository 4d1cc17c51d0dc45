"""Streaming analysis: the findings and metrics do not depend on how the capture is cut.

Reading, decoding and pairing take a bounded number of raw reads at a time
(``reads_per_part``) and decode and pair a bounded number of host lines at a time
(``window_lines``), carrying the line remainder, the checksum mode, open packets and
unanswered commands across the cuts; the findings, positions, queue replay and metrics take
the rows a window at a time with a carried tail. Whatever the cuts, the result is the one
of the default cut; with the tables not kept (``keep_rows=0``, what a long capture does)
too, except the simulated what-if replays, which need the whole table.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from conform.families.gve.analysis import analyze

ROOT = Path(__file__).resolve().parent.parent
CAPTURES = ROOT / "captures"
T0 = 1_750_000_000.0
BAUD = 115200


def outcome(path: Path, **kw: object) -> tuple[list[str], dict]:
    a = analyze(path, **kw)
    found = [json.dumps(f.to_dict(), sort_keys=True, default=str) for f in a.findings]
    return found, json.loads(json.dumps(a.metrics, sort_keys=True, default=str))


def same(path: Path, streamed: bool = False, **kw: object) -> None:
    found, metrics = outcome(path)
    got, got_metrics = outcome(path, **kw)
    if streamed:  # what-if replays need the whole table: a streamed analysis has the
        for row in metrics.get("queue", {}).get("whatif", []):  # scenarios without them
            if row["scenario"] != "as captured":
                row.pop("starvations", None)
                row.pop("job_seconds", None)
    assert got == found
    assert got_metrics == metrics


@pytest.mark.parametrize("name,reads,lines", [
    ("usb-packets", 1, 1), ("usb-latency", 2, 5), ("good-rs232", 7, 5),
    ("proxy-emulator-noisy", 1, 10), ("careless-noisy", 7, 300)])
def test_samples_do_not_depend_on_the_cuts(name: str, reads: int, lines: int) -> None:
    same(CAPTURES / f"{name}.mcap", reads_per_part=reads, window_lines=lines)


@pytest.mark.parametrize("name", ["usb-packets", "usb-latency", "good-rs232",
                                  "proxy-emulator-noisy", "careless-noisy"])
def test_samples_streamed_without_tables(name: str) -> None:
    same(CAPTURES / f"{name}.mcap", streamed=True, keep_rows=0, reads_per_part=3,
         window_lines=200 if name == "careless-noisy" else 7)


@pytest.mark.slow
@pytest.mark.parametrize("reads", [1, 2])
def test_read_by_read(reads: int) -> None:
    same(CAPTURES / "good-rs232.mcap", streamed=True, keep_rows=0, reads_per_part=reads,
         window_lines=3)


def test_synthetic_capture(tmp_path: Path) -> None:
    """The benchmark's session (format 2: checksums on, queue-full runs, `PF` reports)."""
    sys.path.insert(0, str(ROOT / "bench"))
    try:
        from bench_analysis import make_capture
    finally:
        sys.path.remove(str(ROOT / "bench"))
    path = tmp_path / "synthetic.mcap"
    make_capture(path, 1500)
    same(path, reads_per_part=5, window_lines=50)
    same(path, streamed=True, keep_rows=0, reads_per_part=2, window_lines=200)
    a = analyze(path)
    assert a.metrics["exchanges"] == 1500
    assert a.metrics["positions"]["checked"] > 0 and a.kinds().get("position-mismatch") is None


def _cs(body: bytes) -> bytes:
    head = body + b","
    return head + b"%02X" % (sum(head) & 0xFF)


def write_reads(path: Path, reads: list[tuple[str, bytes, float]]) -> None:
    """A format-2 capture of the given reads (direction, bytes, read time)."""
    from conform.capture.batch import raw_batch
    from conform.capture.sink import McapSink

    with open(path, "wb") as f:
        sink = McapSink(f)
        sink.metadata("conform.session", {"variant": "gve64-v19", "baud": BAUD,
                                          "capture_method": "test"})
        for order, (d, data, t) in enumerate(reads):
            # one batch per read, so that a part can end anywhere
            offset = sum(len(x) for dd, x, _ in reads[:order] if dd == d)
            t_first = t - (len(data) - 1) * 10.0 / BAUD
            sink.write(raw_batch(d, offset, bytearray(data), [len(data)], [t], [t_first],
                                 [order]))
        sink.finish()


def conversation() -> list[tuple[str, bytes, float]]:
    """Lines split over reads, answers in later reads, a checksum switch, a packet."""
    t = T0
    reads: list[tuple[str, bytes, float]] = []

    def say(d: str, data: bytes, pieces: int = 1) -> None:
        nonlocal t
        step = max(1, len(data) // pieces)
        for i in range(0, len(data), step):
            piece = data[i : i + step]
            t += 0.0001 + len(piece) * 10.0 / BAUD
            reads.append((d, piece, t))
        t += 0.0003

    say("host", b"!0V2000\r", 3)  # a command cut in three reads
    say("unit", b"0\r")
    say("host", b"!0C100,0,0\r")
    say("unit", b"0", 1)  # an answer whose CR comes in the next read
    say("unit", b"\r")
    say("host", b"!0%+\r", 2)  # checksums on
    say("unit", _cs(b"0") + b"\r", 2)
    say("host", _cs(b"!0C0,100,0") + b"\r", 4)
    say("unit", _cs(b"0") + b"\r")
    say("host", _cs(b"!0*S") + b"\r" + _cs(b"!0C5,5,0")[:5], 1)  # a packet across reads
    say("host", _cs(b"!0C5,5,0")[5:] + b"\r" + _cs(b"!0C6,6,0") + b"\r", 3)
    say("host", _cs(b"!0*E2") + b"\r", 2)
    say("unit", _cs(b"0,2") + b"\r", 3)
    say("host", _cs(b"!0PF") + b"\r")
    say("unit", _cs(b"0,111,111,0") + b"\r", 5)
    say("host", _cs(b"!0%-") + b"\r")  # and off again
    say("unit", b"0\r")
    say("host", b"!0P\r")
    say("unit", b"0,111,111\r", 4)
    return reads


def test_pairing_across_cuts(tmp_path: Path) -> None:
    path = tmp_path / "cuts.mcap"
    write_reads(path, conversation())
    for reads in (1, 2, 7, None):
        a = analyze(path, reads_per_part=reads, window_lines=1 if reads else None)
        ex = a.exchanges
        assert ex["name"].tolist() == ["V", "C", "%", "C", "*S", "C", "C", "*E", "PF", "%", "P"]
        assert ex["status"].tolist() == ["answered", "answered", "answered", "answered",
                                         "in_packet", "in_packet", "in_packet", "answered",
                                         "answered", "answered", "answered"]
        assert ex["cmd_checksum"].tolist() == [0, 0, 0, 1, 1, 1, 1, 1, 1, 1, 0]
        assert ex["answer_checksum"].tolist() == [0, 0, 1, 1, 0, 0, 0, 1, 1, 0, 0]
        assert ex["code"].tolist() == [0, 0, 0, 0, -1, -1, -1, 0, 0, 0, 0]
        assert a.kinds() == {}
        assert a.metrics["vectors_accepted"] == 4
        assert a.metrics["positions"]["checked"] == 1  # P after PF: the last is at rest
    same(path, streamed=True, keep_rows=0, reads_per_part=1, window_lines=1)


def test_streamed_report_and_tables(tmp_path: Path) -> None:
    """A capture too long to keep: the report's plots come from the bounded series and the
    Parquet tables were written as it streamed, with the rows of the whole analysis."""
    import pandas as pd

    from conform.analysis import write_parquet, write_report

    path = CAPTURES / "careless-noisy.mcap"
    whole = analyze(path)
    tables = write_parquet(whole, tmp_path / "whole")
    a = analyze(path, keep_rows=0, parquet=tmp_path / "streamed", window_lines=500)
    assert not a.whole and a.exchanges is None and a.plot is not None
    html = write_report(a, tmp_path / "report")["html"].read_text()
    assert html.count("data:image/png") == 5
    assert write_parquet(a, tmp_path / "ignored") == a.tables
    for name, p in tables.items():
        old, new = pd.read_parquet(p), pd.read_parquet(a.tables[name])
        assert list(new.columns) == list(old.columns)
        assert len(new) == len(old), name
        for col in ("t_cmd_first", "t_first", "t", "depth", "code", "line"):
            if col in old:
                assert (new[col].fillna(-1.0).to_numpy() == old[col].fillna(-1.0).to_numpy()).all()
    ex = pd.read_parquet(a.tables["exchanges"])
    assert (ex["status"].astype(str) == whole.exchanges["status"]).all()
