"""Judging grbl senders with ground truth: the reference senders in
tests/senders/grbl_counting.py, one right and each of the others with one known mistake, run
on a real pty against the grbl reference unit (115200 Bd pacing, wall clock). The right one
passes every scenario; each wrong one is caught by the rule its mistake breaks. Expected
grades follow from the sender's documented mode, never from what the unit answered."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from conform.conformance.results import Grade
from conform.families.grbl.sendercheck.scenarios import SCENARIOS, default_job, run_scenarios

SENDER = Path(__file__).resolve().parent / "senders" / "grbl_counting.py"


def judge(tmp_path, mode, scenarios, timeout=60, moves=100):
    run, sessions = run_scenarios([sys.executable, str(SENDER), "{port}", "{job}", mode],
                                  scenarios=scenarios, timeout=timeout,
                                  directory=tmp_path / mode, job=default_job(moves))
    return {c.id.split("/", 2)[2]: c.grade for c in run.checks}, sessions


def failed(grades):
    return {k for k, g in grades.items() if g in (Grade.FAIL, Grade.DEVIATION)}


@pytest.mark.slow
def test_the_right_sender_survives_lost_answers_and_a_pulled_cable(tmp_path):
    g, sessions = judge(tmp_path, "good", ["lost-answers", "link-loss"], moves=50)
    assert not failed(g), g
    lost, unplugged = sessions
    assert lost.faults["lost_answers"] > 0 and lost.restarts == []       # answers were lost
    assert lost.returncode == 0 and lost.lost == 0
    assert unplugged.faults["unplugged"] == 1 and unplugged.restarts     # grbl restarted
    assert unplugged.returncode == 1                                     # and it said so
    assert g["link-loss/restart-stops"] is Grade.PASS
    assert g["lost-answers/executed-once"] is Grade.PASS


@pytest.mark.slow
def test_the_right_sender_passes_every_other_scenario(tmp_path):
    g, sessions = judge(tmp_path, "good", [n for n in SCENARIOS
                                           if n not in ("lost-answers", "link-loss")], moves=50)
    assert not failed(g), {k: v for k, v in g.items() if v in (Grade.FAIL, Grade.DEVIATION)}
    by = {s.scenario.name: s for s in sessions}
    assert g["feed-hold/hold-respected"] is Grade.PASS and g["slow-link/planner-fed"] is Grade.PASS
    assert by["garbled-answers"].faults["garbled_answers"] > 0
    assert g["error/error-recovery"] is Grade.PASS and g["alarm/alarm-stops"] is Grade.PASS
    assert g["stream/error-recovery"] is Grade.NOT_APPLICABLE


# mode, scenario, the rules its mistake must break (more may fail as consequences)
BAD = [
    ("uncounted-poll", "stream", {"stream/within-buffer", "stream/nothing-lost"}),
    ("counts-realtime", "stream", {"stream/within-buffer"}),
    ("realtime-line", "stream", {"stream/realtime-out-of-band"}),
    ("ignore-error", "error", {"error/error-recovery", "error/honest-exit"}),
    ("ignore-alarm", "alarm", {"alarm/alarm-stops"}),
    ("resend", "lost-answers", {"lost-answers/executed-once"}),
    ("waits-forever", "lost-answers", {"lost-answers/terminates"}),
    ("continue-after-restart", "link-loss", {"link-loss/restart-stops"}),
    ("auto-resume", "feed-hold", {"feed-hold/hold-respected"}),
    ("fast-poll", "stream", {"stream/poll-rate"}),
    ("send-response", "slow-link", {"slow-link/planner-fed"}),
]


@pytest.mark.parametrize("mode,scenario,rules", [
    pytest.param(*b, marks=() if b[0] == "resend" else pytest.mark.slow) for b in BAD])
def test_each_wrong_sender_is_caught_by_its_rule(tmp_path, mode, scenario, rules):
    g, _ = judge(tmp_path, mode, [scenario], timeout=4 if mode == "waits-forever" else 60,
                 moves=40)
    assert rules <= failed(g), g
    if mode in ("fast-poll", "auto-resume", "ignore-error", "send-response"):
        assert failed(g) == rules, g            # nothing else is wrong with these


@pytest.mark.slow
def test_an_overflowing_sender_is_caught_by_check_sender_and_analyze(tmp_path):
    """Through the commands a user types; the capture check-sender records is the evidence."""
    rep = tmp_path / "rep"
    p = subprocess.run([sys.executable, "-m", "conform", "check-sender", "--variant",
                        "grbl-1.1f", "--scenario", "stream", "--report", str(rep), "--",
                        sys.executable, str(SENDER), "{port}", "{job}", "overflow"],
                       capture_output=True, text=True, timeout=180)
    assert p.returncode == 1, p.stdout + p.stderr
    results = json.loads((rep / "results.json").read_text())
    g = {c["id"].split("/", 2)[2]: c["grade"] for c in results["checks"]}
    assert g["stream/within-buffer"] == "FAIL" and g["stream/nothing-lost"] == "FAIL"
    # the terminal names what failed and sums up the rest, as GVE's does (not a line per rule)
    lines = p.stdout.splitlines()
    failing = sorted(k for k, v in g.items() if v not in ("PASS", "NOT-APPLICABLE"))
    assert len(lines) == len(failing) + 2, lines
    assert sorted(x.split()[1] for x in lines[:-2]) == failing   # "  FAIL scenario/rule (...)"
    capture = rep / "stream" / "session.mcap"
    truth = json.loads((rep / "stream" / "truth.json").read_text())
    assert truth["bytes_lost"] > 0
    a = subprocess.run([sys.executable, "-m", "conform", "analyze", str(capture), "--report",
                        str(tmp_path / "an")], capture_output=True, text=True, timeout=120)
    assert a.returncode == 0, a.stderr
    assert "protocol family grbl" in a.stdout and "rx-overflow-hazard" in a.stdout
    found = json.loads((tmp_path / "an" / "findings.json").read_text())
    assert any(f["kind"] == "rx-overflow-hazard" for f in found["findings"])


@pytest.mark.parametrize("args", [["--scenario", "nope", "--", sys.executable],
                                  ["--", "/nonexistent/x"],
                                  ["--timeout", "-1", "--", sys.executable], []])
def test_usage_errors_are_one_line(tmp_path, args, capsys):
    from conform.cli.main import main

    with pytest.raises(SystemExit) as exc:
        main(["check-sender", "--variant", "grbl-1.1f", "--report", str(tmp_path / "r"), *args])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1 and "Traceback" not in err, err


@pytest.mark.parametrize("sent,scenario,grade", [
    (["G90", "G1X-1F100", "G0X0"], "stream", "PASS"),
    (["G90", "$G", "G1 X-1 F100", "G0X0"], "stream", "PASS"),      # polls are not the job's
    (["G90", "G0X0"], "stream", "FAIL"),                             # a line skipped
    (["G90", "G1X-1F100", "G1X-1F100", "G0X0"], "stream", "FAIL"),   # a line sent twice
    (["G90"], "error", "PASS"),                                      # stopped early: a prefix
    (["G1X-1F100"], "error", "FAIL"),
    # what grbl executes is compared, not the text (gcode.c reads G01 as G1, X-1.0 as X-1)
    (["G90", "G01 X-1.0 F100", "G00 X0"], "stream", "PASS"),
    (["G90", "G1X-2F100", "G0X0"], "stream", "FAIL"),               # another move
])
def test_job_in_order_rule(sent, scenario, grade):
    from conform.families.grbl.analysis.analyze import Exchange, GrblAnalysis
    from conform.families.grbl.sendercheck.rules import in_order
    from conform.families.grbl.sendercheck.session import SenderRun

    a = GrblAnalysis("", "grbl", "grbl-1.1f", "",
                     [Exchange(i, t, len(t) + 1, 0.0) for i, t in enumerate(sent)], [], {})
    run = SenderRun(SCENARIOS[scenario], ["G90", "G1X-1F100", "G0X0"], a, 0, 0, False, "")
    assert in_order(run)[0] == grade


def test_truth_counts_lines_run_twice_and_lines_never_run():
    from conform.families.grbl.sendercheck.rules import compare

    job = ["G90", "G1 X-1 F100 ; cut", "G0X0"]
    t = compare(job, [["G90", 0], ["G1X-1F100", 0], ["G1X-1F100", 0], ["G0X0", 20]])
    assert t.doubles == ["G1X-1F100"] and t.missing == ["G0X0"] and not t.extras
    assert not t.whole
    t = compare(job, [["$G", 0], ["G90", 0], ["G1X-1F100", 0], ["G0X0", 0], ["M5", 0]])
    assert t.whole and t.extras == ["M5"]


def test_a_line_of_modal_words_split_in_two_is_the_same_program():
    """grbl-streamer splits G21G90 into G21 and G90 and writes G1 as G01: the same blocks."""
    from conform.families.grbl.sendercheck.rules import compare

    job = ["G21G90", "G1X-1F100", "M2"]
    t = compare(job, [["G21", 0], ["G90", 0], ["G01X-1.000F100", 0], ["M2", 0]])
    assert t.whole and not t.extras and not t.doubles


def test_realtime_rule_counts_realtime_bytes_sent_as_lines_not_empty_lines():
    """stream.py wakes grbl with "\r\n\r\n" (four empty lines, grbl's own idiom): fine.
    "?\n" is a realtime byte and an empty line: the rule's evidence."""
    from conform.families.grbl.analysis.analyze import analyze_streams
    from conform.families.grbl.sendercheck.rules import realtime_not_lines
    from conform.families.grbl.sendercheck.session import SenderRun

    def grade(host: bytes) -> str:
        a = analyze_streams([(0.0, host)], [(0.1, b"ok\r\n" * 8)])
        return realtime_not_lines(SenderRun(SCENARIOS["stream"], ["G90"], a, 0, 0, False, ""))[0]

    assert grade(b"\r\n\r\nG90\n?") == "PASS"
    assert grade(b"\r\n\r\nG90\n?\n?\n?") == "FAIL"          # its polls, as lines


def _in_order_said(sent, job=("G90", "G1X-1F100", "G0X0"), scenario="stream"):
    from conform.families.grbl.analysis.analyze import Exchange, GrblAnalysis
    from conform.families.grbl.sendercheck.rules import in_order
    from conform.families.grbl.sendercheck.session import SenderRun

    a = GrblAnalysis("", "grbl", "grbl-1.1f", "",
                     [Exchange(i, t, len(t) + 1, 0.0) for i, t in enumerate(sent)], [], {})
    return in_order(SenderRun(SCENARIOS[scenario], list(job), a, 0, 0, False, ""))


@pytest.mark.parametrize("sent,named", [
    # a line left out (grbl-streamer's preprocessor drops G5): the line and what came instead
    (["\n", "G90", "G0X0"], "job line 2 'G1X-1F100' was skipped: in its place the wire had "
                            "wire line 3 'G0X0' (job line 3 'G0X0')"),
    (["G90", "G1X-1F100", "G1X-1F100", "G0X0"],
     "job line 3 'G0X0' was due, but the wire had wire line 3 'G1X-1F100' (job line 2 "
     "'G1X-1F100') again (a line sent again)"),
    (["G90"], "job line 2 'G1X-1F100' never went on the wire, nor the 1 after it"),
    (["G90", "G1X-1F100", "G0X0", "G0 X0"], "after the job's last line wire line 4 'G0 X0' "
                                            "(job line 3 'G0X0') was sent again"),
])
def test_job_in_order_names_the_job_line_and_what_the_wire_had_instead(sent, named):
    grade, _want, said = _in_order_said(sent)
    assert grade == "FAIL" and named in said, said


def test_every_verdict_on_a_line_names_the_job_line():
    """executed-once, honest-exit and restart-stops name the job line (number and text), not
    only a canonical block."""
    from conform.families.grbl.analysis.analyze import GrblAnalysis
    from conform.families.grbl.sendercheck.rules import executed_once, honest_exit, restart_stops
    from conform.families.grbl.sendercheck.session import SenderRun

    job = ["G21 G90", "G1 X-1 F100 (cut)", "G0X0", "M2"]
    a = GrblAnalysis("", "grbl", "grbl-1.1f", "", [], [], {})
    twice = SenderRun(SCENARIOS["stream"], job, a, 0, 0, False, "",
                      taken=[["G21G90", 0], ["G1X-1F100", 0], ["G1X-1F100", 0], ["G0X0", 0],
                             ["M2", 0]])
    assert "job line 2 'G1 X-1 F100 (cut)' ran twice" in executed_once(twice)[2]
    short = SenderRun(SCENARIOS["stream"], job, a, 0, 0, False, "",
                      taken=[["G21G90", 0], ["G1X-1F100", 0]])
    grade, _w, said = honest_exit(short)
    assert grade == "FAIL" and "the first never executed: job line 3 'G0X0'" in said
    on = SenderRun(SCENARIOS["link-loss"], job, a, 0, 1, False, "",
                   taken=[["G21G90", 0], ["G1X-1F100", 0], ["G0X0", 0]], restarts=[2])
    assert "the first job line 3 'G0X0'" in restart_stops(on)[2]


def test_a_banner_delayed_by_a_slow_link_is_not_a_reset():
    """stream.py wakes grbl with "\\r\\n\\r\\n" at once; on a slow link the power-up banner is
    still on its way, so it arrives after those lines went out. grbl answered them after it
    started: their oks are theirs, not unsolicited, and nothing is lost."""
    from conform.families.grbl.analysis.analyze import analyze_streams
    from conform.families.grbl.sendercheck.rules import nothing_lost
    from conform.families.grbl.sendercheck.session import SenderRun

    banner = b"\r\nGrbl 1.1f ['$' for help]\r\n"
    host = [(0.0, b"\r\n\r\n"), (2.0, b"G21G90\n"), (2.01, b"G1X-1F100\n")]
    unit = [(0.06, banner), (0.14, b"ok\r\nok\r\nok\r\nok\r\n"), (2.1, b"ok\r\n"),
            (2.11, b"ok\r\n")]
    a = analyze_streams(host, unit)
    assert a.metrics["answered"] == a.metrics["lines"] == 6
    assert not [f for f in a.findings if f.kind == "unsolicited-answer"]
    grade, _w, said = nothing_lost(SenderRun(SCENARIOS["slow-link"], ["G21G90", "G1X-1F100"],
                                             a, 0, 0, False, ""))
    assert grade == "PASS", said
    # a real reset still empties grbl's buffer: the line sent before it is never answered and
    # the next ok belongs to the line sent after it
    host = [(0.0, b"G21G90\n"), (0.5, b"\x18"), (1.0, b"G1X-1F100\n")]
    unit = [(0.6, banner), (1.1, b"ok\r\n")]
    a = analyze_streams(host, unit)
    first, second = a.exchanges
    assert first.answer is None and first.t_gone is not None and second.answer == "ok"
    grade, _w, said = nothing_lost(SenderRun(SCENARIOS["stream"], ["G21G90", "G1X-1F100"],
                                             a, 0, 0, False, ""))
    assert grade == "FAIL" and "the first without an answer: wire line 1 'G21G90' (job line 1" \
        in said, said


def test_within_buffer_names_the_line_that_overfilled_it():
    from conform.families.grbl.analysis.analyze import analyze_streams
    from conform.families.grbl.sendercheck.rules import within_buffer
    from conform.families.grbl.sendercheck.session import SenderRun

    job = [f"G1X-{i}.5Y-1.25F3000 (a comment)" for i in range(1, 9)]
    host = [(0.0, b"".join(f"G1X-{i}.5Y-1.25F3000\n".encode() for i in range(1, 9)))]
    a = analyze_streams(host, [(1.0, b"ok\r\n" * 8)])
    grade, _w, said = within_buffer(SenderRun(SCENARIOS["stream"], job, a, 0, 0, False, ""))
    assert grade == "FAIL" and "the most when wire line 8 'G1X-8.5Y-1.25F3000' (job line 8 " \
        "'G1X-8.5Y-1.25F3000 (a comment)') went out" in said, said
