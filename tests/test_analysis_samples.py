"""The sample captures in captures/ give exactly what captures/README.md says they show."""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path

import pytest

from conform.families.gve.analysis import analyze

CAPTURES = Path(__file__).resolve().parent.parent / "captures"


@cache
def sample(name: str):  # type: ignore[no-untyped-def]
    path = CAPTURES / f"{name}.mcap"
    if not path.exists():
        pytest.fail(f"{path} is missing: run python captures/make_captures.py")
    return analyze(path)


def test_samples_are_small() -> None:
    for p in CAPTURES.glob("*.mcap"):
        assert p.stat().st_size < 5 * 1024 * 1024, p


def test_good_rs232_recovers_without_hazards() -> None:
    a = sample("good-rs232")
    assert a.kinds() == {"garbled-answer": 1, "repeat-used": 1, "no-answer": 1,
                         "index-checked": 1}
    assert a.hazards() == []
    assert {f.severity for f in a.findings} <= {"info", "warning"}
    assert a.metrics["positions"]["checked"] >= 1
    assert a.metrics["queue"]["starvations"] == 0
    # the vector whose answer was garbled was found taken with `>`: all 316 are counted
    assert a.metrics["vectors_accepted"] == 316


def test_usb_latency_starves_the_queue() -> None:
    a = sample("usb-latency")
    assert a.kinds() == {"starvation": 243}
    q = a.metrics["queue"]
    assert q["starvations"] == 243 and q["standstill_s"] > 1.0
    # the round trip is dominated by the converter: 16 ms of host turnaround
    assert a.metrics["latency"]["host_time"]["median"] == pytest.approx(0.016, abs=0.001)
    w = {x["scenario"]: x for x in q["whatif"]}
    assert w["as captured"]["keeps_up"] is False
    assert w["packets of 20"]["keeps_up"] is True
    assert w["packets of 20"]["starvations"] <= 1


def test_usb_packets_keep_the_queue_fed() -> None:
    a = sample("usb-packets")
    assert a.kinds() == {}
    assert a.metrics["vectors_accepted"] == 476 and a.metrics["exchanges"] == 44
    assert a.metrics["queue"]["starvations"] == 0


def test_careless_noisy_hazards() -> None:
    a = sample("careless-noisy")
    assert a.kinds() == {"blind-resend": 3, "checksum-error": 3, "double-move": 1,
                         "error-code": 10, "garbled-answer": 2, "lost-vector": 1,
                         "no-answer": 1, "queue-full-polling": 2423}
    dm = [f for f in a.findings if f.kind == "double-move"]
    assert [f.row for f in dm] == [200] and a.host_text(200) == "!0C0,50,0,DD"
    lost = [f for f in a.findings if f.kind == "lost-vector"]
    assert [f.row for f in lost] == [300] and lost[0].extra["confirmed"] is True
    assert a.host_text(300) == "!0C-2000,0,0,67"
    q = [f for f in a.findings if f.kind == "queue-full-polling"][0]
    assert q.extra["runs"] == 61 and q.extra["pattern"] == "immediate"
    assert all(f.severity == "hazard" for f in a.findings
               if f.kind in ("blind-resend", "double-move", "lost-vector"))


def test_proxy_emulator_noisy_recovers_without_hazards() -> None:
    """Recorded live: `conform send` (careful) → `conform proxy` pty → `conform emulate` with faults."""
    a = sample("proxy-emulator-noisy")
    assert a.kinds() == {"checksum-error": 3, "error-code": 10, "garbled-answer": 5,
                         "no-answer": 3, "repeat-used": 11}
    assert a.hazards() == []
    assert "simplex-violation" not in a.kinds() and "baud-mismatch" not in a.kinds()
    assert a.metrics["vectors_accepted"] == 316
    assert a.metrics["positions"]["checked"] >= 1


# -- grbl: recorded live through `conform proxy` between `conform send` and `conform emulate
# -- serve grbl-1.1f` (captures/README.md); expected figures from the job and grbl's tables

ARC = CAPTURES / "jobs" / "grbl-arc.nc"


def _arc_lines() -> list[str]:
    """The job's lines as they go on the wire: comment lines and blank lines left out, the
    rest without spaces and ';' remarks."""
    out = []
    for raw in ARC.read_text().splitlines():
        text = raw.split(";")[0].strip()
        if text and not text.startswith("("):
            out.append(text.replace(" ", ""))
    return out


@pytest.mark.parametrize("name,method", [("grbl-counting", "character-counting"),
                                         ("grbl-send-response", "send-response")])
def test_grbl_samples_stream_the_whole_job(name: str, method: str) -> None:
    from conform.families import family
    from conform.families.grbl.spec.load import load_grbl

    rx_buffer = load_grbl().variant("grbl-1.1f").rx_buffer
    a = family("grbl").analyze(str(CAPTURES / f"{name}.mcap"))
    lines = _arc_lines()
    m = a.metrics
    assert (m["lines"], m["ok"], m["errors"], m["alarms"]) == (len(lines), len(lines), 0, 0)
    assert [e.text for e in a.exchanges] == lines
    assert m["streaming_method"] == method and m["hazards"] == 0 and a.findings == []
    longest = max(len(x) + 1 for x in lines)
    if method == "send-response":
        assert m["max_lines_in_flight"] == 1 and m["max_bytes_in_flight"] == longest
    else:   # the buffer filled, and never past its size
        assert rx_buffer - longest < m["max_bytes_in_flight"] <= rx_buffer
    # the unit ended where the job's last line leads, standing
    last = re.search(r"X([-\d.]+)Y([-\d.]+)", lines[-1])
    assert a.reports[-1][1].startswith(f"<Idle|MPos:{last[1]},{last[2]},0.000|")


# -- Marlin: recorded live through `conform proxy` between `conform send` and `conform emulate
# -- serve marlin-2.1` with noise on the host's bytes (captures/README.md); figures from the job

RING = CAPTURES / "jobs" / "marlin-ring.gcode"


def test_marlin_sample_takes_the_whole_job_once_despite_the_noise(tmp_path) -> None:
    from conform.families import family

    job = [x.strip() for x in RING.read_text().splitlines()
           if x.strip() and not x.startswith(";")]
    a = family("marlin").analyze(str(CAPTURES / "marlin-noisy.mcap"), keep_lines=True)
    m = a.metrics
    taken = [h.text for h in a.lines if h.accepted]
    # the sender's M110 first, the job line by line, then its final M400 and M114
    assert taken == ["M110 N0", *job, "M400", "M114"]
    assert m["accepted"] == len(job) + 3 and m["oks"] == m["host_lines"]
    # every line the noise damaged was rejected, asked for again and sent again
    assert m["resends"] == m["checksum_errors"] == m["host_lines"] - m["accepted"] > 0
    assert (m["twice_confirmed"], m["twice_possible"], m["never_confirmed"],
            m["never_possible"]) == (0, 0, 0, 0)
    # the G4 S5 of the job blocks for 5 s: busy: processing at least twice (every 2 s)
    assert m["busy_periods"] >= 1 and m["busy_s"] >= 5
    assert [f.kind for f in a.findings if f.severity in ("hazard", "error")] == []
    files = a.write_report(str(tmp_path))
    page = files["html"].read_text()
    assert 'class="verdict ERROR"' in page and f"rejected {m['resends']} line(s)" in page
    assert page.count("data:image/png;base64,") == 4      # latency, resends, busy, in flight
    assert "ok_p50_ms" not in page and "time from a line to its ok" in page
