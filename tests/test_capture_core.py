"""The sans-I/O capture core: session records, frame decoding, the sniffer's merge."""

from __future__ import annotations

import base64

from hypothesis import given, settings
from hypothesis import strategies as st

from conform.capture.merge import Merger
from conform.capture.session import CaptureSession, escape_bytes, unescape_text, wire_time
from conform.families.gve.decode import LineTracker, make_decoder
from conform.families.gve.protocol.checksum import append_checksum


@settings(max_examples=60, deadline=None)
@given(st.binary(max_size=64))
def test_escaped_text_round_trips(data):
    text = escape_bytes(data)
    assert text.isascii() and text.isprintable()
    assert unescape_text(text) == data


def test_raw_chunk_payload_and_running_offsets():
    s = CaptureSession(baud=115200)
    (r1,) = s.chunk("host", b"!0L1000,0,0\r", 10.0)
    (r2,) = s.chunk("host", b"!0?\r", 10.5)
    (u1,) = s.chunk("unit", b"0\r", 10.2)
    assert r1.topic == "/serial/host" and u1.topic == "/serial/unit"
    p = r1.payload
    assert base64.b64decode(p["data"]) == b"!0L1000,0,0\r"
    assert p["hex"] == "21 30 4C 31 30 30 30 2C 30 2C 30 0D"
    assert p["text"] == "!0L1000,0,0\\r" and p["length"] == 12 and p["offset"] == 0
    assert p["t_first"] == 10.0 - 12 * 10 / 115200
    assert r1.log_time == 10_000_000_000
    assert r2.payload["offset"] == 12 and r2.payload["seq"] == 2
    assert u1.payload["offset"] == 0


def test_first_byte_estimate_never_precedes_the_previous_read():
    s = CaptureSession(baud=9600)
    s.chunk("unit", b"x", 1.0)
    (r,) = s.chunk("unit", b"y" * 100, 1.01)  # 100 bytes at 9600 Bd take 0.104 s
    assert r.payload["t_first"] == 1.0
    (h,) = s.chunk("host", b"z", 5.0, t_first=4.9)  # a caller-given time is kept
    assert h.payload["t_first"] == 4.9


def test_link_event_and_log_records():
    s = CaptureSession()
    link, log = s.link_event("disconnect", "unit", "EIO", 3.25)
    assert link.topic == "/link" and link.payload == {
        "kind": "disconnect", "side": "unit", "detail": "EIO", "t": 3.25}
    assert log.topic == "/log" and log.payload["level"] == 3
    assert log.payload["timestamp"] == {"sec": 3, "nsec": 250_000_000}
    assert set(log.payload) == {"timestamp", "level", "message", "name", "file", "line"}


# -- frames and exchanges ---------------------------------------------------------------

def decode(stream: list[tuple[str, bytes]], variant: str = "gve64-v19"):
    s = CaptureSession(baud=115200, decoder=make_decoder(variant))
    frames, exchanges = [], []
    t = 100.0
    for direction, data in stream:
        t += 0.01
        for r in s.chunk(direction, data, t):
            (frames if r.topic == "/frames" else exchanges if r.topic == "/exchanges"
             else []).append(r.payload)
    for r in s.finish(t + 1):
        (frames if r.topic == "/frames" else exchanges).append(r.payload)
    return frames, exchanges


def test_commands_and_answers_pair_into_exchanges():
    frames, exchanges = decode([
        ("host", b"!0L1000,0,0\r"), ("unit", b"0\r"),
        ("host", b"!0PF\r"), ("unit", b"0,-1000,2000,50\r"),
        ("host", b"!0SW8,F1\r"), ("unit", b"5\r"),
        ("host", b"!0V1000\r"), ("unit", b"8\r"),
    ])
    assert [f["kind"] for f in frames] == ["command", "answer"] * 2 + ["rejection", "answer"] \
        + ["command", "answer"]
    assert frames[0]["name"] == "L" and frames[0]["args"][:3] == [1000, 0, 0]
    assert frames[3]["fields"] == ["-1000", "2000", "50"]
    assert frames[4]["code"] == 5 and frames[4]["name"] == "SW"
    assert frames[7]["code"] == 0 and frames[7]["inta"] is True
    assert [e["status"] for e in exchanges] == ["answered"] * 4
    assert [e["name"] for e in exchanges] == ["L", "PF", "SW", "V"]
    assert all(e["latency"] > 0 for e in exchanges)
    assert exchanges[1]["answer"] == "0,-1000,2000,50"
    assert frames[1]["offset"] == 0 and frames[3]["offset"] == 2


def test_manual_packet_example_with_checksums():
    cmds = [b"!0C697,30,0", b"!0C692,92,0"]
    stream = [("host", b"!0%+\r"), ("unit", b"0,5C\r"), ("host", b"!0*S,FA\r")]
    stream += [("host", append_checksum(c) + b"\r") for c in cmds]
    stream += [("host", append_checksum(b"!0*E2") + b"\r"),
               ("unit", append_checksum(b"0,2") + b"\r"),
               ("host", b"!0%-,CF\r"), ("unit", b"0\r"), ("host", b"!0?\r"), ("unit", b"0,x\r")]
    frames, exchanges = decode(stream)
    roles = [(f["direction"], f["packet_role"]) for f in frames if f["packet"] == 1]
    assert roles == [("host", "start"), ("host", "member"), ("host", "member"),
                     ("host", "end"), ("unit", "answer")]
    assert all(f["checksum_status"] == "ok" for f in frames[1:8]), frames
    assert frames[2]["checksum"] == "FA"
    assert [e["name"] for e in exchanges] == ["%", "*E", "%", "?"]
    assert exchanges[1]["packet_commands"] == 2 and exchanges[1]["packet"] == 1
    assert frames[-2]["checksum_mode"] is False and frames[-1]["checksum_status"] == "none"


def test_bad_and_missing_checksums_are_flagged():
    frames, _ = decode([("host", b"!0%+\r"), ("unit", b"0,5C\r"),
                        ("host", b"!0A100,4E\r"), ("unit", b"4,60\r"),
                        ("host", b"!0A100\r"), ("unit", b"4\r")])
    assert frames[2]["kind"] == "rejection" and frames[2]["checksum_status"] == "bad"
    assert frames[4]["checksum_status"] == "missing"
    assert frames[5]["checksum_status"] == "missing"


def test_capture_started_with_checksums_already_on():
    frames, _ = decode([("host", append_checksum(b"!0A100") + b"\r"),
                        ("unit", append_checksum(b"0") + b"\r")])
    assert frames[0]["kind"] == "command" and frames[0]["checksum_status"] == "ok"
    assert frames[1]["checksum_status"] == "ok"


def test_unanswered_unsolicited_and_silent_lines():
    frames, exchanges = decode([
        ("host", b"!0PF\r"), ("host", b"!0PF\r"), ("unit", b"0,1,2,3\r"),  # first gave up
        ("unit", b"0\r"),  # nothing asked
        ("host", b"!3V100\r"),  # another unit's address: silence is owed
        ("host", b"!0?\r"),  # never answered before the end
        ("unit", b"\xff\xfe\r"),
    ])
    assert [e["status"] for e in exchanges] == [
        "unanswered", "answered", "unsolicited", "answered"]
    assert frames[-1]["kind"] == "garbled"
    assert exchanges[-1]["answer"] == "\\xff\\xfe"


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(min_value=1, max_value=60), min_size=1, max_size=12))
def test_frames_do_not_depend_on_how_reads_split_the_bytes(cuts):
    host = b"!0L1000,0,0\r!0%+\r!0PF,58\r"
    unit = b"0\r0,5C\r0,1,2,3,0E\r"
    whole_f, whole_e = decode([("host", host[:12]), ("unit", unit[:2]), ("host", host[12:17]),
                               ("unit", unit[2:7]), ("host", host[17:]), ("unit", unit[7:])])
    pieces: list[tuple[str, bytes]] = []
    for lo, hi, u_lo, u_hi in ((0, 12, 0, 2), (12, 17, 2, 7), (17, len(host), 7, len(unit))):
        for direction, data in (("host", host[lo:hi]), ("unit", unit[u_lo:u_hi])):
            i = 0
            for c in cuts:
                if i >= len(data):
                    break
                pieces.append((direction, data[i:i + c]))
                i += c
            if i < len(data):
                pieces.append((direction, data[i:]))
    split_f, split_e = decode(pieces)
    keep = ("kind", "text", "offset", "length", "name", "code", "checksum_status", "packet")
    assert [{k: f[k] for k in keep} for f in split_f] == \
        [{k: f[k] for k in keep} for f in whole_f]
    assert [e["status"] for e in split_e] == [e["status"] for e in whole_e]


def test_line_tracker_terminator_modes():
    t = LineTracker("host", "cr")
    lines = t.feed(b"\n!0?\r\n!0PF\r", 0, 1.0, 1.0)
    assert [(ln.data, ln.offset, ln.length) for ln in lines] == [(b"!0?", 1, 4), (b"!0PF", 6, 5)]
    t = LineTracker("host", "cr-or-lf")
    assert [ln.data for ln in t.feed(b"a\r\nb\nc", 0, 1.0, 1.0)] == [b"a", b"b"]
    assert t.rest(2.0).data == b"c"
    t = LineTracker("host", "crlf")
    assert [ln.data for ln in t.feed(b"a\rb\r\n", 0, 1.0, 1.0)] == [b"a\rb"]


# -- the sniffer's merge -----------------------------------------------------------------

def order(merger: Merger, reads: list[tuple[str, bytes, float]], end: float):
    out = []
    for direction, data, t in reads:
        out += merger.push(direction, data, t)
    out += merger.tick(end)
    out += merger.flush()
    return out


def test_merge_orders_by_estimated_first_byte():
    m = Merger(115200)
    cmd, ans = b"!0L1000,0,0\r", b"0\r"
    # the unit's read returned first, but its bytes began after the command ended
    out = order(m, [("unit", ans, 1.0030), ("host", cmd, 1.0032)], 2.0)
    assert [c.direction for c in out] == ["host", "unit"]
    assert out[0].t_first == 1.0032 - wire_time(len(cmd), 115200)


def test_merge_puts_an_answer_after_its_command_even_against_the_clock():
    m = Merger(115200)
    # USB latency: the answer's read returned 5 ms before the command's
    out = order(m, [("unit", b"0\r", 1.000), ("host", b"!0?\r", 1.005)], 2.0)
    assert [c.direction for c in out] == ["host", "unit"]
    assert out[1].reordered and out[1].t_first < out[0].t_first


def test_merge_equal_times_put_the_host_first():
    m = Merger(None)
    out = order(m, [("host", b"!0PF\r", 1.0), ("unit", b"0,1,2,3\r", 1.0),
                    ("unit", b"0\r", 1.0), ("host", b"!0?\r", 1.0)], 2.0)
    assert [c.data for c in out] == [b"!0PF\r", b"!0?\r", b"0,1,2,3\r", b"0\r"]


def test_merge_lets_unsolicited_bytes_through_after_the_hold():
    m = Merger(115200, hold=0.2)
    assert m.push("unit", b"Y,1\r", 1.0) == []
    assert m.tick(1.1) == []  # waiting: its command may still be on its way
    out = m.tick(1.3)
    assert [c.data for c in out] == [b"Y,1\r"] and not out[0].reordered


def test_merge_packets_owe_one_answer():
    """GVE's count of owed answers (its family's ``host_lines``): a packet owes one."""
    from conform.families import family

    m = Merger(None, host_lines=family("gve").host_lines())
    reads = [("unit", b"0,2\r", 1.0), ("host", b"!0*S\r!0C1,1,0\r", 1.01),
             ("host", b"!0C2,2,0\r!0*E2\r", 1.02)]
    out = order(m, reads, 2.0)
    assert [c.direction for c in out] == ["host", "host", "unit"]


def test_merge_without_a_family_rule_owes_every_line_an_answer():
    """The engine's own count: each host line owes an answer, so an answer that comes back
    before a second line's read goes right after the first line."""
    m = Merger(None)
    reads = [("unit", b"0,2\r", 1.0), ("host", b"!0*S\r!0C1,1,0\r", 1.01),
             ("host", b"!0C2,2,0\r!0*E2\r", 1.02)]
    out = order(m, reads, 2.0)
    assert [c.direction for c in out] == ["host", "unit", "host"]
