"""Capture is family-neutral: the engine records raw bytes and the neutral fields of frames
and exchanges, a family's decoder declares its own fields (``CaptureFields``), they round-trip
through a recording, ``capture info``/``recover`` and reading without the family; captures
recorded before (format 1, and format 2 batches with GVE's fields in the engine's list) still
read; a family's columns reach the analysis tables and the fleet summary through its hooks."""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from mcap.reader import make_reader

from conform.capture.reader import open_capture
from conform.capture.recorder import Recorder
from conform.capture.recover import capture_info, recover
from conform.capture.schemas import EXCHANGE, FRAME, NEUTRAL, CaptureFields
from conform.capture.session import Record, to_ns

CAPTURES = Path(__file__).resolve().parent.parent / "captures"

WORDS = CaptureFields(
    frame=(("words", {"type": "integer", "description": "space-separated words"}),),
    exchange=(("same_length", {"type": "boolean"}),),
)


class WordDecoder:
    """A toy family's live decoder: LF-terminated lines, each host line answered by the
    next unit line; frames carry a word count, exchanges whether both lines are as long."""

    fields = WORDS

    def __init__(self) -> None:
        self.buf = {"host": b"", "unit": b""}
        self.start = {"host": 0, "unit": 0}
        self.owed: tuple[str, float, int] | None = None

    def feed(self, direction: str, data: bytes, offset: int, t_read: float, t_first: float
             ) -> list[Record]:
        out = []
        if not self.buf[direction]:
            self.start[direction] = offset
        self.buf[direction] += data
        while b"\n" in self.buf[direction]:
            line, _, rest = self.buf[direction].partition(b"\n")
            start = self.start[direction]
            self.buf[direction], self.start[direction] = rest, start + len(line) + 1
            text = line.decode("ascii")
            out.append(Record("/frames", to_ns(t_read), {
                "direction": direction, "kind": "command" if direction == "host" else "answer",
                "text": text, "offset": start, "length": len(line) + 1, "t_first": t_first,
                "t_last": t_read, "words": len(text.split())}))
            if direction == "host":
                self.owed = (text, t_read, start)
            elif self.owed is not None:
                cmd, t_cmd, cmd_at = self.owed
                self.owed = None
                out.append(Record("/exchanges", to_ns(t_read), {
                    "status": "answered", "command": cmd, "answer": text, "t_command": t_cmd,
                    "t_answer": t_first, "latency": t_first - t_cmd, "command_offset": cmd_at,
                    "answer_offset": start, "same_length": len(cmd) == len(text)}))
        return out

    def finish(self, t: float) -> list[Record]:
        return []


LINES = [(b"move to the left\n", b"ok done now\n"), (b"home\n", b"fine\n"),
         (b"set speed fast\n", b"error 3 here\n")]


def _record(path: Path) -> None:
    with Recorder(path, {"capture_method": "test"}, baud=115200, decoder=WordDecoder(),
                  clock=lambda: 1000.0) as rec:
        t = 1000.0
        for host, unit in LINES:
            rec.chunk("host", host, t + 0.01)
            rec.chunk("unit", unit, t + 0.02)
            t += 0.1


def test_a_family_field_round_trips_through_a_recording(tmp_path):
    path = tmp_path / "words.mcap"
    _record(path)
    cap = open_capture(path)
    frames = list(cap.frames())
    want = [(d, len(text.split())) for host, unit in LINES
            for d, text in (("host", host.decode()), ("unit", unit.decode()))]
    assert [(f["direction"], f["words"]) for f in frames] == want
    assert [e["same_length"] for e in cap.exchanges()] == [False, True, False]
    assert [e["command"] for e in cap.exchanges()] == [h.decode().strip() for h, _ in LINES]
    # the file's schemas name the family's fields next to the neutral ones, and only them
    with open(path, "rb") as f:
        schemas = {s.name: json.loads(s.data) for s in make_reader(f).get_summary().schemas.values()}
    frame_props = schemas["conform.FrameBatch"]["properties"]
    assert set(frame_props) == {"count", *FRAME["properties"], "words"}
    assert set(schemas["conform.ExchangeBatch"]["properties"]) == \
        {"count", *EXCHANGE["properties"], "same_length"}
    info = capture_info(path)
    assert info.bad_messages == 0 and info.state == "clean"
    out = recover(path, tmp_path / "again.mcap").output
    assert [f["words"] for f in open_capture(out).frames()] == [n for _, n in want]


def test_a_family_may_not_redefine_a_neutral_field():
    with pytest.raises(ValueError, match="'text'"):
        CaptureFields(frame=(("text", {"type": "integer"}),)).frame_schema()


def test_without_a_family_decoder_only_neutral_fields_are_recorded(tmp_path):
    class Plain(WordDecoder):
        fields = None  # a decoder that declares nothing

    path = tmp_path / "plain.mcap"
    with Recorder(path, {}, baud=115200, decoder=Plain(), clock=lambda: 5.0) as rec:
        rec.chunk("host", b"a b\n", 5.1)
        rec.chunk("unit", b"c\n", 5.2)
    frames = list(open_capture(path).frames())
    assert [set(f) for f in frames] == [{*NEUTRAL.frame_keys, "log_time"}] * 2


def test_format1_samples_read_without_their_family(tmp_path):
    """The sample captures (format 1, recorded with GVE's decoder) keep every field."""
    frames = list(open_capture(CAPTURES / "usb-packets.mcap").frames())
    roles = {f.get("packet_role") for f in frames}
    assert {"start", "member", "end", "answer"} <= roles
    assert all(set(NEUTRAL.frame_keys) <= set(f) for f in frames)


def test_a_format2_batch_of_the_old_recorder_still_reads(tmp_path):
    """Before the fields were the family's, the recorder wrote GVE's fields in the engine's
    own list, in this order: such a batch reads back whole."""
    from conform.capture.batch import row_columns
    from conform.capture.sink import McapSink

    old_keys = ("direction", "kind", "text", "offset", "length", "t_first", "t_last", "address",
                "name", "args", "code", "inta", "fields", "checksum", "checksum_status",
                "checksum_mode", "packet", "packet_role", "error")
    row = ("unit", "answer", "0", 0, 2, 1.0, 1.0, None, None, [], 0, True, [], None, "none",
           False, 3, "answer", None)
    path = tmp_path / "old.mcap"
    with open(path, "wb") as f:
        sink = McapSink(f)
        sink.write(Record("/frames", to_ns(1.0), row_columns([row], old_keys)))
        sink.finish()
    (frame,) = open_capture(path).frames()
    assert {k: frame[k] for k in old_keys} == dict(zip(old_keys, row, strict=True))


def test_a_family_column_reaches_the_analysis_tables(tmp_path):
    """GVE's packet columns go into the host frames table through the family's hook (the
    engine's tables code names none): dictionary-encoded roles, the recorded roles."""
    from conform.analysis import write_parquet
    from conform.families.gve.analysis import analyze

    path = CAPTURES / "usb-packets.mcap"
    tables = write_parquet(analyze(path), tmp_path / "pq")
    t = pq.read_table(tables["frames_host"])
    assert pa.types.is_dictionary(t.schema.field("packet_role").type)
    recorded = [f.get("packet_role") for f in open_capture(path).frames()
                if f["direction"] == "host"]
    assert t.column("packet_role").to_pylist() == recorded


def test_fleet_columns_come_from_the_families(monkeypatch):
    from conform.analysis import fleet
    from conform.families import FleetColumn

    class Toy:
        name = "toy"
        fleet_columns = (FleetColumn("beeps", "beeps", total=True, rate="beeps_per_s",
                                     rate_label="beeps/s", flag=True, summary=True),)

    monkeypatch.setattr(fleet, "families", lambda: [Toy()])
    base = dict.fromkeys(fleet.SUMMARY_KEYS) | {"state": "clean", "family": "toy"}
    rows = [base | {"machine": "m1", "session": "a", "duration_s": 2.0, "exchanges": 10,
                    "beeps": 4},
            base | {"machine": "m1", "session": "b", "duration_s": 2.0, "exchanges": 6,
                    "beeps": 0}]
    s = fleet.summarise(rows)
    (m,) = s["machines"]
    assert m["beeps"] == 4 and m["beeps_per_s"] == 1.0 and s["totals"]["beeps"] == 4
    assert fleet.totals_text(s["totals"], s["columns"]) == ", 4 beeps"
    assert "vectors_accepted" not in m and "hazards" not in s["totals"]
