"""grbl traffic analysis in-process (reference senders against the reference unit), capture
files made with the Recorder, and `conform analyze` choosing the family."""

from __future__ import annotations

import subprocess
import sys

import pytest

from conform.capture import Recorder
from conform.families.grbl.analysis.analyze import analyze_streams
from conform.families.grbl.analysis.streaming import stream
from conform.families.grbl.spec.load import load_grbl
from conform.families.grbl.unit.model import GrblUnit

G = load_grbl()
V = G.variant("grbl-1.1f")
JOB = [f"G1X{-(i % 20) * 0.5:.3f}Y{-(i % 7) * 0.3:.3f}F2000" for i in range(120)]


def run(method, **kw):
    u = GrblUnit(V, G)
    u.poll(0.0)
    traffic = stream(u, JOB, method=method, **kw)
    return u, traffic, analyze_streams(traffic.host, traffic.unit)


@pytest.mark.parametrize("method,found", [("counting", "character-counting"),
                                          ("send-response", "send-response")])
def test_well_behaved_senders(method, found):
    u, traffic, a = run(method, poll=0.2)
    assert u.lost == 0 and traffic.answers == ["ok"] * len(JOB)
    m = a.metrics
    assert m["streaming_method"] == found and m["hazards"] == 0 and m["errors"] == 0
    assert m["max_bytes_in_flight"] <= 128 and m["answered"] == len(JOB)
    assert 4.5 < m["poll_rate_hz"] < 5.5 and m["status_reports"] == m["status_polls"]
    assert m["realtime_bytes"] == {"status report query": m["status_polls"]}
    assert not a.findings


def test_uncounted_lines_overflow_and_are_caught():
    u, traffic, a = run("counting", extra={40: "$G", 41: "$G"}, timeout=120)
    assert u.lost > 0
    kinds = a.kinds()
    assert kinds["rx-overflow-hazard"] >= 1
    assert a.metrics["streaming_method"] == "character-counting"     # counting, overshot
    assert any("outside the count" in f.message for f in a.findings)
    hazard = a.hazards()[0]
    assert hazard.extra["max_bytes"] > 128 and "receive buffer 128" in hazard.message
    assert kinds.get("error-response", 0) + kinds.get("unanswered-lines", 0) >= 1


def test_errors_and_alarms_are_findings():
    host = [(0.0, b"G1X1\n"), (0.1, b"G38.2Z-1F100\n")]
    u = GrblUnit(V, G)
    u.poll(0.0)
    for t, d in host:
        u.receive(d, t)
    unit = u.poll(5.0)
    a = analyze_streams(host, unit)
    kinds = a.kinds()
    assert kinds == {"alarm": 1, "error-response": 1}
    err = next(f for f in a.findings if f.kind == "error-response")
    assert "error:22 (undefined feed rate)" in err.message and "#22" in err.clause
    assert next(f for f in a.findings if f.kind == "alarm").message.startswith("ALARM:5")


def slow_moves(u, host, t, n, wait):  # noqa: ANN001
    """``n`` moves from ``t`` on, each followed ``wait`` s later by a status poll (sent to
    the unit ``u`` and kept in ``host``); the time after the last."""
    for i in range(n):
        host.append((t, b"G1X-%d.0F500\n" % (i + 1)))
        u.receive(host[-1][1], t)
        t += wait
        host.append((t, b"?"))
        u.receive(b"?", t)
        t += 0.1
    return t


def test_starved_planner_is_seen_in_status_reports():
    host, unit = [], []
    u = GrblUnit(V, G)
    u.poll(0.0)
    t = slow_moves(u, host, 0.0, 4, 3.0)  # a sender that waits far too long between moves
    unit = u.poll(t + 10)
    a = analyze_streams(host, unit)
    assert a.kinds().get("planner-starved", 0) >= 1


def record(path, host, unit, variant=""):
    rec = Recorder(path, {"capture_method": "test", "variant": variant}, decode=False,
                   clock=lambda: 1000.0)
    for t, direction, d in sorted([(t, "host", d) for t, d in host] +
                                  [(t, "unit", d) for t, d in unit]):
        rec.chunk(direction, d, t_read=1000.0 + t)
    rec.close()


def analyze_cli(path):
    return subprocess.run([sys.executable, "-m", "conform", "analyze", str(path)],
                          capture_output=True, text=True, timeout=60)


def test_analyze_detects_grbl_from_the_traffic(tmp_path):
    u, traffic, _ = run("counting", extra={40: "$G", 41: "$G"}, timeout=60)
    path = tmp_path / "noname.mcap"
    record(path, traffic.host, traffic.unit)              # no variant in the metadata
    p = subprocess.run([sys.executable, "-m", "conform", "analyze", str(path), "--report",
                        str(tmp_path / "rep"), "--parquet", str(tmp_path / "pq")],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert "protocol family grbl (" in p.stdout and "grbl messages" in p.stdout
    import json

    import pyarrow.parquet as pq

    ex = pq.read_table(tmp_path / "pq" / "exchanges.parquet").to_pydict()
    assert max(ex["bytes_in_flight"]) > 128 and ex["answer"][0] == "ok"
    found = json.loads((tmp_path / "rep" / "findings.json").read_text())
    assert found["family"] == "grbl" and found["metrics"]["hazards"] >= 1
    assert "rx-overflow-hazard" in p.stdout
    assert "not a hex digit" not in p.stdout
    # the same report set as GVE's: index.html with the findings and the plots, Markdown, JSON
    html = (tmp_path / "rep" / "index.html").read_text()
    assert "report: " + str(tmp_path / "rep" / "index.html") in p.stdout
    assert "<code>rx-overflow-hazard</code>" in html and "receive buffer 128" in html
    assert html.count('src="data:image/png;base64,') == 2 and "http" not in html.split("<body>")[1]
    assert (tmp_path / "rep" / "summary.md").read_text().startswith("# grbl capture analysis")


def test_html_report_of_a_clean_session_and_of_no_traffic(tmp_path):
    from conform.families.grbl.analysis.analyze import write_report

    _u, _traffic, a = run("counting", poll=0.2)
    html = write_report(a, str(tmp_path / "clean"))["html"].read_text()
    assert "No findings" in html and "character-counting" in html and "line to answer" in html
    assert 'alt="machine state from the status reports"' in html      # polled: the state plot
    empty = analyze_streams([], [])
    html = write_report(empty, str(tmp_path / "empty"))["html"].read_text()
    assert "No findings" in html and "data:image/png" not in html
    assert "No status reports in this session" in html


def test_unknown_protocol_is_reported_as_such(tmp_path):
    path = tmp_path / "modem.mcap"
    host = [(i * 0.1, b"AT+CSQ\r\n") for i in range(40)]
    unit = [(i * 0.1 + 0.05, b"+CSQ: 20,99\r\nOK\r\n") for i in range(40)]
    record(path, host, unit)
    p = analyze_cli(path)
    assert p.returncode == 0, p.stderr
    assert "protocol unknown" in p.stdout and "exchanges" not in p.stdout


def test_gve_capture_stays_with_the_gve_analyser(tmp_path):
    path = tmp_path / "gve.mcap"
    record(path, [(0.0, b"!0?\r")], [(0.01, b"0,IP64MPG v19 10.9.2010\r")])
    p = analyze_cli(path)
    assert p.returncode == 0, p.stderr
    assert "protocol" not in p.stdout and "exchanges" in p.stdout


def test_the_two_host_splitters_agree():
    import random

    from conform.families.grbl.protocol.codec import HostLine, HostSplitter, split_host

    rng = random.Random(1)
    for _ in range(300):
        data = bytes(rng.choice(b"G1X-0.5\n\r?!~\x18\x85\xa0 (;)$=") for _ in range(rng.randrange(300)))
        splitter = HostSplitter()
        events = splitter.feed(data[:40]) + splitter.feed(data[40:])      # fed in pieces
        lines, realtime = split_host(data)
        assert [(x.data, x.start, x.end) for x in events if isinstance(x, HostLine)] == [
            (x.data, x.start, x.end) for x in lines]
        assert [(x.byte, x.offset) for x in events if not isinstance(x, HostLine)] == [
            (x.byte, x.offset) for x in realtime]


def test_recording_a_grbl_session_says_why_frames_are_not_decoded(tmp_path):
    from conform.capture.reader import open_capture

    path = tmp_path / "g.mcap"
    rec = Recorder(path, {"variant": "grbl-1.1f"})
    rec.chunk("host", b"?")
    rec.close()
    notes = [x.get("message", "") for x in open_capture(path).logs()]
    assert any("decoded by conform analyze from the raw bytes" in n for n in notes)
    assert not any("unknown variant" in n for n in notes)


def _exchange_traffic(lines, *, wake=b"", gap=0.01, window=1):
    """Host and unit chunks of a sender that keeps ``window`` lines in flight (1: it waits
    for each answer), after an optional wake-up, polling '?' between lines."""
    host, unit, t = [], [], 0.0
    if wake:
        host.append((t, wake))
        unit.append((t + 0.005, b"ok\r\n" * (wake.count(b"\n") + wake.count(b"\r"))))
        t += 0.5
    pending = []
    for text in lines:
        host.append((t, text + b"\n"))
        host.append((t + 0.001, b"?"))
        unit.append((t + 0.002, b"<Idle|MPos:0.000,0.000,0.000|FS:0,0>\r\n"))
        pending.append(t)
        if len(pending) >= window:
            unit.append((pending.pop(0) + gap, b"ok\r\n"))
        t += gap * (1.5 if window == 1 else 0.2)
    unit += [(p + gap, b"ok\r\n") for p in pending]
    return sorted(host), sorted(unit)


def test_send_response_with_a_wake_up_and_polls_is_send_response():
    """grbl's stream.py -s: '\\r\\n\\r\\n' wakes grbl (four empty lines in flight), then each
    line waits for its ok; '?' polls are realtime bytes. None of that is counting."""
    host, unit = _exchange_traffic([b"G1X%dF100" % i for i in range(20)], wake=b"\r\n\r\n")
    a = analyze_streams(host, unit, spec=G)
    assert a.metrics["streaming_method"] == "send-response"
    assert a.metrics["max_job_lines_in_flight"] == 1


def test_send_response_with_answers_stamped_late_is_send_response():
    """Through a proxy on a loaded machine an ok may be stamped after the line the sender
    wrote on reading it (the two directions are read apart): a line now and then one ahead of
    its answer, never two, is still send-response."""
    host, unit = _exchange_traffic([b"G1X%dF100" % i for i in range(20)])
    oks = [i for i, (_t, d) in enumerate(unit) if d == b"ok\r\n"]
    for i in oks[2:12:4]:      # three answers stamped after the next line went out
        unit[i] = (unit[i][0] + 0.012, unit[i][1])
    a = analyze_streams(host, sorted(unit), spec=G)
    assert a.metrics["job_lines_back_to_back"] == 3
    assert a.metrics["streaming_method"] == "send-response"


def test_several_job_lines_in_flight_is_counting():
    host, unit = _exchange_traffic([b"G1X%dF100" % i for i in range(40)], window=4)
    a = analyze_streams(host, unit, spec=G)
    assert a.metrics["streaming_method"] == "character-counting"



def test_a_counting_sender_whose_first_fill_was_paced_is_counting():
    """grbl-streamer's character counting through a proxy on a loaded machine (a CI run): its
    first fill went out a line or two at a time, each answered by the idle planner before the
    next, so no line was more than one ahead of its answer; then, with the planner full, it
    kept six lines unanswered at every send, one line per answer. The steady state tells."""
    lines = [b"G1X%dY%dF1000" % (i % 9, i % 4) for i in range(40)]
    host, unit, t, sent = [(0.0, lines[0] + b"\n")], [], 0.0, 1
    for answered in range(len(lines)):
        t += 0.002 if answered < 5 else 0.05
        unit.append((t, b"ok\r\n"))
        for _ in range(2 if answered < 5 else 1):    # five answers make room for two lines
            if sent < len(lines):
                t += 0.001
                host.append((t, lines[sent] + b"\n"))
                sent += 1
    m = analyze_streams(host, unit, spec=G).metrics
    assert (m["answered"], m["max_job_lines_in_flight"], m["max_bytes_in_flight"]) == (40, 6, 6 * 12)
    assert m["job_lines_back_to_back"] == 5               # each one line past its answer
    assert m["streaming_method"] == "character-counting", m


def _sender_taking_poll_oks_for_its_own(lines, polls_at, *, move=0.05):
    """A send-response sender that writes its next job line on every ok, a `$G`'s too (what
    grbl-streamer's incremental mode does with its poll thread's `$G`): each poll answered
    mid-job leaves it one more line ahead for good. grbl answers in order, a move ``move``
    after the one before (a full planner), a `$G` at once."""
    host, unit, pending, sent, due = [(0.0, lines[0] + b"\n")], [], ["J"], 1, move
    polls = list(polls_at)
    for step in range(1, 100_000):
        t = step * 0.001
        if polls and t >= polls[0]:
            polls.pop(0)
            host.append((t, b"$G\n"))
            pending.append("G")
        if pending and t >= due:
            kind = pending.pop(0)
            unit.append((t, (b"[GC:G1 G54 G17 G21 G90 G94 M5 M9 T0 F1000 S0]\r\n" if kind == "G"
                             else b"") + b"ok\r\n"))
            if sent < len(lines):                       # any ok: the next line
                host.append((t + 0.0005, lines[sent] + b"\n"))
                pending.append("J")
                sent += 1
            if pending:
                due = t + (0.001 if pending[0] == "G" else move)
        if not pending and sent == len(lines):
            return sorted(host), unit
    raise AssertionError("the simulated session did not end")


def test_a_send_response_sender_ahead_only_by_poll_oks_it_took_is_send_response():
    """Three `$G` polls mid-job, each ok taken for a job line's: four job lines in flight from
    then on, none sent beyond one per answer. Its depth is what the polls' answers lent it, so
    it is no counting sender."""
    lines = [b"G1X%dY%dF1000" % (i % 9, i % 4) for i in range(40)]
    host, unit = _sender_taking_poll_oks_for_its_own(lines, [0.3, 0.6, 0.9])
    m = analyze_streams(host, unit, spec=G).metrics
    assert (m["lines"], m["answered"], m["max_job_lines_in_flight"]) == (43, 43, 4)
    assert m["job_lines_back_to_back"] == 0
    assert m["streaming_method"] == "send-response", m

def _grouped_counting_traffic(lines, *, window=5, batch=3, gap=0.03):
    """A counting sender that is slow to read: its answers reach it ``batch`` at a time (one
    read), and it writes as many lines as they made room for in one write (one read on the
    other side too). It never has more than ``window`` lines in flight."""
    host, unit, t = [], [], 0.0
    sent = min(window, len(lines))
    host.append((t, b"".join(x + b"\n" for x in lines[:sent])))
    answered = 0
    while answered < len(lines):
        t += gap
        n = min(batch, sent - answered)
        unit.append((t, b"ok\r\n" * n))
        answered += n
        more = lines[sent:sent + n]
        if more:
            host.append((t + 0.001, b"".join(x + b"\n" for x in more)))
            sent += len(more)
    return host, unit


@pytest.mark.parametrize("batch", [1, 2, 3, 5])
def test_a_counting_sender_that_reads_answers_in_groups_is_counting(batch):
    """The method comes from the wire's content, not the read timing: lines that follow
    their answers in groups are still one line per answer (the old rule, lines sent right
    after an answer, called this unbounded from a batch of 2 on)."""
    lines = [b"G1X%dY%dF3000" % (i % 9, i % 4) for i in range(60)]
    host, unit = _grouped_counting_traffic(lines, batch=batch)
    a = analyze_streams(host, unit, spec=G)
    m = a.metrics
    assert (m["lines"], m["answered"]) == (60, 60)
    assert m["streaming_method"] == "character-counting", m
    assert m["max_job_lines_in_flight"] == 5 and m["max_bytes_in_flight"] <= V.rx_buffer


def test_a_sender_that_never_waits_is_unbounded():
    """Every line written at once, the answers trickling back: far past the buffer."""
    lines = [b"G1X%dY%dF3000" % (i % 9, i % 4) for i in range(60)]
    host = [(0.0, b"".join(x + b"\n" for x in lines))]
    unit = [(0.01 * (i + 1), b"ok\r\n") for i in range(60)]
    m = analyze_streams(host, unit, spec=G).metrics
    assert m["streaming_method"] == "unbounded" and m["max_bytes_in_flight"] > V.rx_buffer


def test_an_empty_capture_is_empty():
    a = analyze_streams([], [], spec=G)
    assert a.metrics["streaming_method"] == "empty" and a.metrics["lines"] == 0


def test_findings_document_has_the_shape_gve_prints():
    """conform.analysis.report.findings_document: capture, variant, findings (kind,
    severity, ...), metrics, notes."""
    host, unit = _exchange_traffic([b"G1X%dF100" % i for i in range(5)])
    doc = analyze_streams(host, unit, spec=G, path="x.mcap").findings_document()
    assert set(doc) == {"capture", "variant", "findings", "metrics", "notes"}
    assert doc["metrics"]["streaming_method"] == "send-response"
    assert all({"kind", "severity", "t", "message"} <= set(f) for f in doc["findings"])


def test_analyze_json_on_a_grbl_capture_and_on_an_empty_one(tmp_path):
    """``conform analyze --json``: one JSON document on stdout, the shape GVE's has; a capture
    with no byte either way (a sender that died at once) is empty, not GVE traffic."""
    import json

    host, unit = _exchange_traffic([b"G1X%dF100" % i for i in range(10)], wake=b"\r\n\r\n")
    path = tmp_path / "sr.mcap"
    record(path, host, unit)
    p = subprocess.run([sys.executable, "-m", "conform", "analyze", str(path), "--json"],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)
    assert set(doc) >= {"capture", "variant", "findings", "metrics", "notes"}
    assert doc["variant"] == "grbl-1.1f" and doc["metrics"]["streaming_method"] == "send-response"
    assert "protocol family grbl" in p.stderr
    empty = tmp_path / "dead.mcap"
    record(empty, [], [])
    for args in ([], ["--json"]):
        q = subprocess.run([sys.executable, "-m", "conform", "analyze", str(empty), *args],
                           capture_output=True, text=True, timeout=60)
        assert q.returncode == 0, q.stderr
        assert "empty capture" in (q.stderr if args else q.stdout)
        assert "gve" not in (q.stdout + q.stderr).lower()
    assert json.loads(q.stdout)["empty"] is True


def test_every_plot_is_on_the_session_time_axis(monkeypatch):
    """Status polls two seconds before the first line: the state plot, the buffer plot and
    the latency plot all count seconds from the session's first byte (as the findings and
    the other families' plots do), so a line and the state it caused line up."""
    from conform.analysis import plots
    from conform.families.grbl.analysis import htmlreport

    kept = []
    for mod in (plots, htmlreport):
        monkeypatch.setattr(mod, "to_png", lambda fig: kept.append(fig) or "png", raising=False)
    u = GrblUnit(V, G)
    u.poll(0.0)
    host = []
    for t in (0.0, 1.0):                       # polled while idle, before any line
        host.append((t, b"?"))
        u.receive(b"?", t)
    t = slow_moves(u, host, 2.0, 6, 0.5)
    a = analyze_streams(host, u.poll(t + 10), spec=G)
    for name, draw in (("machine", htmlreport.machine_plot), ("buffer", htmlreport.buffer_plot),
                       ("latency", htmlreport.latency_plot)):
        kept.clear()
        assert draw(a) == "png", name
        ax = kept[0].axes[0]
        assert ax.get_xlabel() == "s from the start", name
        first = min(ax.get_lines()[0].get_xdata())  # the state, bytes in flight, latency
        want = a.reports[0][0] if name == "machine" else 2.0
        assert first == pytest.approx(want, abs=0.05), name
    assert a.t0 == 0.0 and a.metrics["duration_s"] > 5.0


@pytest.mark.parametrize(("next_after", "verdict"), [
    (0.002, "the sender stopped after it"),   # on its way before the error could be read
    (0.5, "the sender went on"),
])
def test_a_line_sent_as_the_error_arrived_is_not_going_on(next_after, verdict):
    """A counting sender may write its next line in the same instant error:N arrives (the
    recorder sees the error first); only a line sent after the host could have read the error
    (REACTION_S) says the sender went on."""
    host = [(0.0, b"G1X1F100\n"), (0.1, b"G1X2\n"), (0.2, b"G5X1\n")]
    unit = [(0.05, b"ok\r\n"), (0.15, b"ok\r\n"), (0.25, b"error:20\r\n")]
    host.append((0.25 + next_after, b"G1X3\n"))
    unit.append((0.3 + next_after, b"ok\r\n"))
    a = analyze_streams(host, unit)
    err = next(f for f in a.findings if f.kind == "error-response")
    assert err.message.endswith(verdict), err.message
