"""check-sender over real ptys: the test senders in tests/senders/ graded as expected.

Each run starts the emulator (wall clock, 115200 Bd pacing) behind the proxy and the sender
as a subprocess; the fast tests run one or two scenarios per sender, the full matrix is
marked slow.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from conform.cli.main import main
from conform.families.gve.sendercheck.compare import compare
from conform.families.gve.sendercheck.family import GVE
from conform.sendercheck.family import FAIL, MUST, NA, PASS, WARN
from conform.sendercheck.grade import check

SENDERS = Path(__file__).resolve().parent / "senders"


def _run(tmp_path: Path, sender: str, names: list[str], **kw) -> object:
    cmd = [sys.executable, str(SENDERS / f"{sender}.py"), "{port}", "{job}"]
    kw.setdefault("timeout", 120)  # generous: a loaded machine must not fail `terminates`
    return check(cmd, names=names, directory=tmp_path / sender, **kw)


def _grades(results) -> dict[tuple[str, str], str]:
    return {(v.scenario, v.rule): v.grade for v in results.verdicts}


@pytest.mark.slow
def test_careful_sender_passes_clean_and_lost_answers(tmp_path):
    r = _run(tmp_path, "careful", ["clean", "lost-answers"])
    g = _grades(r)
    assert r.exit_code == 0, [v for v in r.verdicts if v.grade == FAIL]
    for scn in ("clean", "lost-answers"):
        for rule in ("terminates", "simplex", "checksums", "recovery-asks", "no-blind-resend",
                     "vectors-exact", "honest-exit"):
            assert g[(scn, rule)] == PASS, (scn, rule)
    s = r.scenarios[1].session
    assert s.faults["lost_answers"] > 0  # the scenario really lost answers
    assert s.comparison.exact and s.comparison.accepted == s.comparison.job


def test_blind_sender_fails_on_lost_answers(tmp_path):
    r = _run(tmp_path, "blind", ["lost-answers"])
    g = _grades(r)
    assert r.exit_code == 1
    assert g[("lost-answers", "no-blind-resend")] == FAIL
    assert g[("lost-answers", "recovery-asks")] == FAIL
    assert g[("lost-answers", "simplex")] == PASS
    # the ground truth shows the consequence: the unit took some vectors twice
    s = r.scenarios[0].session
    assert s.comparison.doubles
    assert g[("lost-answers", "vectors-exact")] == FAIL
    assert g[("lost-answers", "honest-exit")] == WARN  # exit 0 for a job moved twice


def test_pipelining_sender_fails_simplex(tmp_path):
    r = _run(tmp_path, "pipelined", ["clean"])
    g = _grades(r)
    assert g[("clean", "simplex")] == FAIL
    assert r.exit_code == 1


def test_hanging_sender_is_stopped_and_graded(tmp_path):
    cmd = [sys.executable, str(SENDERS / "hang.py"), "{port}"]
    r = check(cmd, names=["clean"], directory=tmp_path / "hang", timeout=1.5)
    g = _grades(r)
    assert g[("clean", "terminates")] == FAIL
    assert r.scenarios[0].session.hung
    assert r.exit_code == 1


def test_cli_reports_and_exit_codes(tmp_path):
    out = tmp_path / "rep"
    p = subprocess.run([sys.executable, "-m", "conform", "check-sender", "--report", str(out),
                        "--scenario", "clean", "--", sys.executable,
                        str(SENDERS / "careful.py"), "{port}", "{job}"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    for name in ("index.html", "summary.md", "junit.xml", "results.json"):
        assert (out / name).stat().st_size > 0
    res = json.loads((out / "results.json").read_text())
    assert res["exit_code"] == 0
    assert all({"rule", "grade", "clause", "scenario"} <= set(v) for v in res["verdicts"])
    assert all(v["clause"] for v in res["verdicts"])
    for f in res["findings"]:
        assert {"kind", "severity", "clause", "scenario"} <= set(f)
    assert (out / "clean" / "session.mcap").exists() and (out / "clean" / "truth.json").exists()


@pytest.mark.parametrize("args", [[], ["--scenario", "nope", "--", "true"],
                                  ["--", "/nonexistent/sender", "{port}"],
                                  ["--timeout", "-1", "--", "true"]])
def test_cli_usage_errors(args, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["check-sender", *args])
    err = capsys.readouterr().err
    assert exc.value.code == 2
    assert err.count("\n") == 1 and "Traceback" not in err


def test_compare_names_doubles_lost_and_altered():
    a, b, c = ("C", (1, 0)), ("C", (0, 1)), ("C", (1, 1))
    job = [a, a, b, c, b]
    assert compare(job, job).exact
    r = compare(job, [a, a, a, b, c, b])
    assert len(r.doubles) == 1 and not r.lost and not r.extras
    r = compare(job, [a, b, c, b])
    assert len(r.lost) == 1 and not r.doubles
    r = compare(job, [a, a, c, c, b])
    assert len(r.altered) == 1
    r = compare(job, [a, a, b], tail_may_be_missing=True)
    assert r.exact and r.prefix


def test_every_rule_cites_a_clause_and_every_scenario_is_graded():
    assert {r.level for r in GVE.rules} <= {MUST, "SHOULD"}
    for rule in GVE.rules:
        assert rule.clause and rule.id
    for tag_rule in ("interrupt-stops", "link-resumes", "checksums-on-noise"):
        rule = next(r for r in GVE.rules if r.id == tag_rule)
        assert any(rule.applies(s) for s in GVE.scenarios.values())
    assert NA  # graded NOT-APPLICABLE elsewhere


@pytest.mark.slow
def test_full_matrix(tmp_path):
    """Every scenario for the careful sender (no MUST failure) and the blind one (fails)."""
    r = _run(tmp_path, "careful", list(GVE.scenarios))
    bad = [(v.scenario, v.rule, v.detail) for v in r.verdicts if v.grade == FAIL]
    assert r.exit_code == 0, bad
    g = _grades(r)
    assert g[("stop", "interrupt-stops")] == PASS
    assert g[("stop", "interrupt-resolved")] == PASS
    assert g[("link-loss", "vectors-exact")] == PASS
    assert g[("slow-unit", "queue-full-paced")] == PASS
    b = _run(tmp_path, "blind", ["slow-unit", "stop", "noisy"])
    assert b.scenarios[0].session.count("queue-full-polling") > 0  # queue full did happen
    gb = _grades(b)
    assert gb[("slow-unit", "queue-full-paced")] == WARN  # hammering
    assert gb[("stop", "interrupt-stops")] == FAIL  # it kept streaming after INTA
    assert gb[("noisy", "checksums-on-noise")] == WARN


def test_stop_scenario_on_a_gve124_uses_its_own_inputs(tmp_path):
    r = _run(tmp_path, "careful", ["stop"], variant="gve124")
    g = _grades(r)
    s = r.scenarios[0].session
    assert all(e["reply"].startswith("ok") for e in s.events)  # IN2: a GVE124 has no IN7
    assert g[("stop", "interrupt-stops")] == PASS and g[("stop", "interrupt-resolved")] == PASS
    assert r.exit_code == 0
    assert all(len(v) == 3 for _k, v in s.job)  # 3-axis vectors for a 3-axis unit


@pytest.mark.slow
def test_reference_sender_stops_on_an_interrupt(tmp_path):
    """`conform send` itself, judged: after INTA it sends no vector, waits for the brake,
    deletes the queue with D and exits 1 with a clear message."""
    cmd = [sys.executable, "-m", "conform", "send", "{job}", "--target", "{port}",
           "--allow-motion", "--checksums"]
    r = check(cmd, names=["stop"], directory=tmp_path / "send", timeout=120)
    g = _grades(r)
    s = r.scenarios[0].session
    assert g[("stop", "interrupt-stops")] == PASS
    assert g[("stop", "interrupt-resolved")] == PASS
    assert g[("stop", "interrupt-krd-idle")] == PASS
    assert s.exit_code == 1 and r.exit_code == 0
    assert "stopped by the unit" in (s.directory / "program.err").read_text()
    assert [e["command"] for e in s.truth["events"]] == ["D"]
