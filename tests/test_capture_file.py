"""Capture files: the recorder, the reader, info, recover, and files that are not what they say."""

from __future__ import annotations

import json
import os
import struct
import threading
import time

import pytest
from mcap.reader import make_reader

from conform.capture.reader import open_capture
from conform.capture.recorder import Recorder, RecordingError
from conform.capture.recover import capture_info, recover
from conform.cli.main import main
from conform.errors import UserError


def record(path, *, variant="gve64-v19", recorder=Recorder, **kw) -> Recorder:
    rec = recorder(path, {"capture_method": "test", "baud": 115200, "variant": variant,
                          "unit_port": "/dev/null"}, **kw)
    t = rec.now()
    rec.chunk("host", b"!0L1000,0,0\r", t)
    rec.chunk("unit", b"0\r", t + 0.002)
    rec.chunk("host", b"!0PF\r", t + 0.01)
    rec.chunk("unit", b"0,1,2,3\r", t + 0.012)
    rec.link_event("baud", "115200", side="unit")
    rec.log("warning", "something to see")
    return rec


def test_recording_is_a_valid_mcap_with_every_channel(tmp_path):
    path = tmp_path / "run.mcap"
    rec = record(path)
    assert rec.part.exists() and not path.exists()
    rec.close()
    assert path.exists() and not rec.part.exists()
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        topics = {c.topic: c for c in summary.channels.values()}
        assert set(topics) == {"/serial/host", "/serial/unit", "/frames", "/exchanges", "/link",
                               "/log"}
        assert all(c.message_encoding == "json" for c in topics.values())
        schemas = {s.id: s for s in summary.schemas.values()}
        assert all(s.encoding == "jsonschema" for s in schemas.values())
        assert schemas[topics["/log"].schema_id].name == "foxglove.Log"
        for s in schemas.values():
            json.loads(s.data)
        assert summary.statistics.channel_message_counts
        chunk_compression = {ci.compression for ci in summary.chunk_indexes}
        assert chunk_compression == {"zstd"}
        for _schema, _channel, message in reader.iter_messages():
            json.loads(message.data)
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    session = meta["conform.session"]
    for key in ("tool_version", "capture_method", "unit_port", "baud", "variant",
                "clock_source"):
        assert session[key], key
    assert meta["conform.session_end"]["bytes_host"] == "17"


def test_reader_gives_chunks_frames_exchanges_events(tmp_path):
    path = tmp_path / "run.mcap"
    record(path).close()
    cap = open_capture(path)
    assert cap.clean and not cap.truncated
    assert cap.stream("host") == b"!0L1000,0,0\r!0PF\r"
    assert cap.stream("unit") == b"0\r0,1,2,3\r"
    chunks = list(cap.raw_chunks())
    assert [c["direction"] for c in chunks] == ["host", "unit", "host", "unit"]
    assert [c["offset"] for c in chunks] == [0, 0, 12, 2]
    exchanges = list(cap.exchanges())
    assert [(e["name"], e["answer"], e["status"]) for e in exchanges] == [
        ("L", "0", "answered"), ("PF", "0,1,2,3", "answered")]
    assert 0 < exchanges[0]["latency"] < 0.01
    assert len(list(cap.frames())) == 4
    assert [e["kind"] for e in cap.link_events()] == ["baud"]
    assert any(log["message"] == "something to see" and log["level"] == 3
               for log in cap.logs())
    assert cap.metadata["conform.session"]["variant"] == "gve64-v19"
    df = cap.table("/exchanges")
    assert list(df["name"]) == ["L", "PF"]
    assert len(cap.table("host")) == 2


class _HeldRecorder(Recorder):
    """A recorder whose writer thread starts work only when ``release`` is set: what was
    queued before then is one moment, however the machine schedules the two threads."""

    def __init__(self, *args, **kw):
        self.release = threading.Event()
        super().__init__(*args, **kw)

    def _run(self):
        self.release.wait()
        super()._run()


def test_without_a_variant_only_raw_is_recorded(tmp_path):
    path = tmp_path / "raw.mcap"
    rec = record(path, variant="", recorder=_HeldRecorder)
    rec.release.set()
    rec.close()
    info = capture_info(path)
    assert info.reads["host"] == 2 and info.messages["/frames"] == 0
    assert info.messages["/serial/host"] == 1  # format 2: the reads of a moment in one batch
    assert info.bytes == {"host": 17, "unit": 10} and info.state == "clean"


def test_unknown_variant_is_logged_not_fatal(tmp_path):
    path = tmp_path / "x.mcap"
    record(path, variant="gve99").close()
    logs = [log["message"] for log in open_capture(path).logs()]
    assert any("frames not decoded" in m and "gve99" in m for m in logs)


def test_recorder_is_thread_safe(tmp_path):
    path = tmp_path / "threads.mcap"
    rec = Recorder(path, {"capture_method": "test"})

    def blast(direction: str, tag: bytes) -> None:
        for i in range(300):
            rec.chunk(direction, tag + b"%04d;" % i)

    threads = [threading.Thread(target=blast, args=(d, t)) for d, t in
               (("host", b"h"), ("unit", b"u"))]
    for t in threads:
        t.start()
    for i in range(50):
        rec.log("info", f"line {i}")
    for t in threads:
        t.join()
    rec.close()
    cap = open_capture(path)
    assert cap.stream("host") == b"".join(b"h%04d;" % i for i in range(300))
    assert cap.stream("unit") == b"".join(b"u%04d;" % i for i in range(300))


def test_misuse_is_reported(tmp_path):
    rec = Recorder(tmp_path / "a.mcap")
    with pytest.raises(ValueError):
        rec.chunk("sideways", b"x")
    with pytest.raises(ValueError):
        rec.link_event("exploded", "")
    rec.close()
    rec.close()  # idempotent
    with pytest.raises(RecordingError):
        rec.chunk("host", b"x")
    (tmp_path / "b.mcap.part").write_bytes(b"left over")
    with pytest.raises(RecordingError, match="recover"):
        Recorder(tmp_path / "b.mcap")


# -- truncation, recovery, hostile input -------------------------------------------------

def test_every_truncation_is_read_or_recovered(tmp_path):
    path = tmp_path / "full.mcap"
    record(path, flush_interval=0).close()
    data = path.read_bytes()
    full_host = open_capture(path).stream("host")
    sizes = sorted(set(range(8, len(data), max(1, len(data) // 60))) | {len(data) - 1})
    for size in sizes:
        cut = tmp_path / f"cut{size}.mcap.part"
        cut.write_bytes(data[:size])
        cap = open_capture(cut)
        host = cap.stream("host")
        assert full_host.startswith(host)
        assert cap.truncated
        res = recover(cut)
        fixed = open_capture(res.output)
        assert fixed.clean and fixed.stream("host") == host
        assert "conform.recovery" in fixed.metadata


def test_recover_refuses_to_overwrite(tmp_path):
    path = tmp_path / "r.mcap"
    record(path).close()
    part = tmp_path / "s.mcap.part"
    part.write_bytes(path.read_bytes()[:-100])
    out = recover(tmp_path / "s.mcap").output  # finds the .part
    assert out == tmp_path / "s.mcap"
    with pytest.raises(UserError, match="exists"):
        recover(part)
    assert recover(part, force=True).output == out


def _hostile_files(tmp_path, good: bytes) -> dict[str, bytes]:
    magic = good[:8]
    files = {
        "empty": b"",
        "text": b"hello, world\n",
        "magic_only": magic,
        "huge_length": magic + b"\x01" + struct.pack("<Q", 2**62) + b"xx",
        "short_header": magic + b"\x01\x05",
        "garbage_after_magic": magic + os.urandom(2000),
        "bad_string": magic + b"\x01" + struct.pack("<Q", 8) + struct.pack("<I", 2**31) + b"abcd",
    }
    # flip a byte inside the first chunk's compressed data: its CRC must catch it
    flipped = bytearray(good)
    i = good.index(b"\x06", 40) + 80
    flipped[i] ^= 0xFF
    files["flipped"] = bytes(flipped)
    # a chunk that claims to inflate to an absurd size
    files["bomb"] = magic + good[8:40] + b"\x06" + struct.pack("<Q", 60) + struct.pack(
        "<QQQI", 0, 0, 2**40, 0) + struct.pack("<I", 4) + b"zstd" + struct.pack("<Q", 8) + b"x" * 8
    return files


def test_hostile_files_never_crash_the_reader(tmp_path):
    good_path = tmp_path / "good.mcap"
    record(good_path).close()
    for name, data in _hostile_files(tmp_path, good_path.read_bytes()).items():
        p = tmp_path / f"{name}.mcap"
        p.write_bytes(data)
        try:
            cap = open_capture(p)
            list(cap.messages())
            status = cap.status
        except UserError as exc:
            assert "\n" not in str(exc)
            continue
        assert not status.clean, name
        info = capture_info(p)
        assert info.state != "clean"
        out = recover(p, tmp_path / f"{name}.fixed.mcap")
        assert open_capture(out.output).clean


def test_cli_info_and_recover_and_bad_input(tmp_path, capsys):
    path = tmp_path / "c.mcap"
    record(path).close()
    with pytest.raises(SystemExit) as ex:
        main(["capture", "info", str(path)])
    assert ex.value.code == 0
    out = capsys.readouterr().out
    assert "state:          clean" in out and "/serial/host" in out and "bytes host:     17" in out
    with pytest.raises(SystemExit) as ex:
        main(["capture", "info", "--json", str(path)])
    assert json.loads(capsys.readouterr().out)["bytes"] == {"host": 17, "unit": 10}
    part = tmp_path / "d.mcap.part"
    part.write_bytes(path.read_bytes()[:-300])
    with pytest.raises(SystemExit) as ex:
        main(["capture", "recover", str(part)])
    assert ex.value.code == 0  # salvaged: a success; what was lost is said on stdout
    out = capsys.readouterr().out
    assert "salvaged" in out and "lost: " in out
    for name, data in _hostile_files(tmp_path, path.read_bytes()).items():
        p = tmp_path / f"h-{name}.mcap"
        p.write_bytes(data)
        for cmd in ("info", "recover"):
            with pytest.raises(SystemExit) as ex:
                main(["capture", cmd, str(p)])
            captured = capsys.readouterr()
            assert "Traceback" not in captured.err
            if ex.value.code == 2:
                assert len(captured.err.strip().splitlines()) == 1, (name, captured.err)
            elif ex.value.code != 0:  # an honest truncated/damaged status
                assert any(w in captured.out for w in ("truncated", "damaged", "lost")), name
    with pytest.raises(SystemExit) as ex:
        main(["capture", "info", str(tmp_path / "missing.mcap")])
    assert ex.value.code == 2
    assert "no such file" in capsys.readouterr().err


def _records(data: bytes):
    """(offset, opcode, length) of each top-level record."""
    pos = 8
    while pos + 9 <= len(data):
        opcode = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        yield pos, opcode, length
        pos += 9 + length


def test_a_lost_first_chunk_does_not_lose_the_rest(tmp_path):
    path = tmp_path / "many.mcap"
    rec = Recorder(path, {"capture_method": "test"}, flush_interval=0)
    for i in range(40):
        rec.chunk("host", b"!0C%d,0,0\r" % i)
        time.sleep(0.002)
    rec.close()
    data = bytearray(path.read_bytes())
    first_chunk = next(pos for pos, opcode, _ in _records(bytes(data)) if opcode == 0x06)
    data[first_chunk + 60] ^= 0xFF  # inside the chunk that holds schemas and channels
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(bytes(data))
    full = b"".join(b"!0C%d,0,0\r" % i for i in range(40))
    cap = open_capture(broken)
    host = cap.stream("host")
    assert host == full  # the data came in later chunks; only their channel records were lost
    assert cap.status.damaged_chunks == 1
    assert capture_info(broken).bytes["host"] == len(host)
    fixed = open_capture(recover(broken).output)
    assert fixed.clean and fixed.stream("host") == host


def test_the_writer_gathers_reads_for_a_flush_interval_and_close_cuts_that_short(tmp_path):
    path = tmp_path / "gather.mcap"
    rec = Recorder(path, {"capture_method": "test"}, flush_interval=60.0)
    rec.chunk("host", b"!0PF\r")  # the first read after a quiet spell is on disk at once
    deadline = time.monotonic() + 20
    while capture_info(rec.part).bytes["host"] != 5 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert capture_info(rec.part).bytes["host"] == 5
    rec.chunk("host", b"!0?\r")  # gathered: the next flush is a minute away...
    time.sleep(0.2)
    assert capture_info(rec.part).bytes["host"] == 5
    t0 = time.monotonic()
    rec.close()  # ...but closing does not wait for it
    assert time.monotonic() - t0 < 30
    assert open_capture(path).stream("host") == b"!0PF\r!0?\r"
