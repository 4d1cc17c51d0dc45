"""Every family's check-sender runs through one supervisor (conform/sendercheck): a harness
failure is graded ERROR for every rule of every family (exit status 2), the JUnit file comes
from the same writer, Ctrl-C, SIGTERM or SIGHUP stop the program running and leave the results
of the scenarios that finished, and the family contract has no second entry point.

The programs here are tiny Python one-liners that open nothing (they take ``{port}`` only
because check-sender asks for it): what is checked is the supervision around them, not a
sender's protocol.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
import xml.etree.ElementTree as ET

import pytest

import conform.link.pty
from conform.conformance.results import Grade
from conform.families import Family, family_for_variant
from conform.sendercheck.family import Family as Shapes
from conform.sendercheck.grade import check
from conform.sendercheck.report import render_junit, write_reports

# (variant, a quick scenario, a second scenario) of each built-in family
FAMILIES = [("gve64-v19", "clean", "lost-answers"), ("grbl-1.1f", "stream", "lost-answers"),
            ("marlin-2.1", "clean", "lost-ok")]

# exits at once in FIRST's scenario; elsewhere writes its pid beside the job and sleeps
SLEEPER = ("import os, sys, time\n"
           "if os.environ['CONFORM_SCENARIO'] == sys.argv[1]: sys.exit(0)\n"
           "open(os.environ['CONFORM_JOB'] + '.pid', 'w').write(str(os.getpid()))\n"
           "time.sleep(60)\n")


def test_both_families_hand_the_engine_the_same_shapes():
    for variant, _first, _second in FAMILIES:
        shapes = family_for_variant(variant).check_sender
        assert isinstance(shapes, Shapes), variant
        assert shapes.rules and shapes.scenarios
    assert not hasattr(Family, "check_sender_cli")


@pytest.mark.parametrize("variant,first,_second", FAMILIES)
def test_a_harness_failure_is_an_error_in_every_family(tmp_path, monkeypatch, variant, first,
                                                       _second):
    def no_pty(*_a, **_k):
        raise OSError("out of ptys")

    monkeypatch.setattr(conform.link.pty, "PtyEndpoint", no_pty)
    r = check([sys.executable, "-c", "pass", "{port}"], variant=variant, names=[first],
              directory=tmp_path / "r", timeout=10)
    shapes = family_for_variant(variant).check_sender
    assert [v.rule for v in r.verdicts] == [rule.id for rule in shapes.rules]
    assert {v.grade for v in r.verdicts} == {Grade.ERROR}
    assert all("out of ptys" in v.detail for v in r.verdicts)
    assert r.exit_code == 2
    assert any(f["kind"] == "harness-error" for f in r.findings)
    junit = ET.fromstring(render_junit(r).split("\n", 1)[1])
    suite = junit.find("testsuite")
    assert suite is not None and suite.get("errors") == str(len(shapes.rules))
    assert len(junit.findall(".//error")) == len(shapes.rules)


@pytest.mark.parametrize("variant,first,_second", FAMILIES)
def test_one_junit_writer_and_one_results_file_for_every_family(tmp_path, variant, first,
                                                                _second):
    """A program that ends at once without a word: graded by each family's rules, written by
    the same report code (one suite per scenario, one case per rule, classname
    VARIANT.SCENARIO)."""
    r = check([sys.executable, "-c", "pass", "{port}"], variant=variant, names=[first],
              directory=tmp_path / "r", timeout=20)
    assert r.exit_code in (0, 1) and not any(v.grade is Grade.ERROR for v in r.verdicts)
    write_reports(r, tmp_path / "r")
    junit = ET.parse(tmp_path / "r" / "junit.xml").getroot()
    assert junit.tag == "testsuites" and junit.get("name") == "conform check-sender"
    cases = junit.findall("testsuite/testcase")
    assert len(cases) == len(family_for_variant(variant).check_sender.rules)
    assert {c.get("classname") for c in cases} == {f"{variant}.{first}"}
    res = json.loads((tmp_path / "r" / "results.json").read_text())
    assert res["variant"] == variant and len(res["verdicts"]) == len(cases)
    assert [c["id"] for c in res["checks"]] == [
        f"{variant}/check-sender/{first}/{v['rule']}" for v in res["verdicts"]]
    assert (tmp_path / "r" / first / "session.mcap").exists()
    assert (tmp_path / "r" / first / "truth.json").exists()


@pytest.mark.parametrize("variant,first,second", FAMILIES)
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_an_interrupted_run_keeps_the_finished_scenarios(tmp_path, variant, first, second, sig):
    """The signal arrives while the second scenario's program runs: the program is stopped,
    and the results (and the report written from them) hold the first scenario only."""
    job = tmp_path / "r" / second / family_for_variant(variant).check_sender.job_name
    pid_file = job.with_name(job.name + ".pid")
    sent = threading.Event()

    def interrupt_once_it_runs() -> None:
        for _ in range(600):
            if pid_file.exists() and pid_file.read_text():
                os.kill(os.getpid(), sig)
                sent.set()
                return
            threading.Event().wait(0.05)

    old = signal.getsignal(sig)
    threading.Thread(target=interrupt_once_it_runs, daemon=True).start()
    r = check([sys.executable, "-c", SLEEPER, first, "{port}"], variant=variant,
              names=[first, second], directory=tmp_path / "r", timeout=30)
    assert sent.is_set() and signal.getsignal(sig) == old  # the handlers are put back
    assert [s.name for s in r.scenarios] == [first]
    assert f"during {second}" in r.interrupted
    pid = int(pid_file.read_text())
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)  # the program was stopped (and reaped)
    write_reports(r, tmp_path / "r")
    res = json.loads((tmp_path / "r" / "results.json").read_text())
    assert [s["scenario"] for s in res["scenarios"]] == [first]
    assert res["interrupted"] == r.interrupted
    assert "interrupted" in (tmp_path / "r" / "summary.md").read_text()


@pytest.mark.parametrize("variant", [v for v, _f, _s in FAMILIES])
def test_a_job_that_is_not_ascii_is_one_line(tmp_path, capsys, variant):
    from conform.cli.main import main

    job = tmp_path / "job.txt"
    job.write_text("G1X1\nG1X2 ; déjà\n", encoding="utf-8")
    with pytest.raises(SystemExit) as exc:
        main(["check-sender", "--variant", variant, "--job", str(job), "--report",
              str(tmp_path / "r"), "--", sys.executable, "-c", "pass", "{port}"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1, err
    assert f"{job}: line 2, column 9: not ASCII" in err


def test_ctrl_c_on_the_command_writes_the_report_of_the_finished_scenarios(tmp_path):
    """`conform check-sender` itself, sent SIGINT while its second scenario runs: exit 130, the
    report written for the first scenario, and the program gone."""
    import subprocess
    import time

    variant, first, second = FAMILIES[1]
    rep = tmp_path / "rep"
    pid_file = rep / second / "job.gcode.pid"
    p = subprocess.Popen([sys.executable, "-m", "conform", "check-sender", "--variant", variant,
                          "--scenario", f"{first},{second}", "--report", str(rep), "--",
                          sys.executable, "-c", SLEEPER, first, "{port}"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not (pid_file.exists() and pid_file.read_text()) and time.monotonic() < deadline:
        time.sleep(0.05)
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 130, out + err
    assert "Traceback" not in err and "interrupted (Ctrl-C)" in err
    res = json.loads((rep / "results.json").read_text())
    assert [s["scenario"] for s in res["scenarios"]] == [first]
    assert (rep / "junit.xml").exists() and (rep / "index.html").exists()
    with pytest.raises(ProcessLookupError):
        os.kill(int(pid_file.read_text()), 0)
