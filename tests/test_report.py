"""Conformance reports: the four files, their content, and re-rendering from results.json."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import pytest

from conform.cli.main import main
from conform.conformance.results import CheckResult, Grade, LogEntry, RunResults, TargetRun
from conform.report.render import write_reports


def _results():
    run = TargetRun("emu:gve64-v19", "gve64-v19", True, "quick", "2026-01-01T00:00:00")
    common = dict(clause="GVE64 §13.5.3", variant="gve64-v19", target="emu:gve64-v19")
    run.checks = [
        CheckResult("gve64-v19/13.5.3/V/valid", Grade.PASS, title="V ok", expected="!0V1000 → 0",
                    actual="!0V1000 → 0", **common),
        CheckResult("gve64-v19/13.5.3/V/range/pps/hi+1", Grade.FAIL, expected="!0V125001 → 5",
                    actual="!0V125001 → 4", detail="answer differs",
                    sequence=["(reset)", "!0V125001"],
                    replay="gve64-v19/13.5.3/V/range/pps/hi+1",
                    log=[LogEntry(0.0, "tx", b"!0V125001\r"), LogEntry(0.001, "rx", b"4\r")],
                    **common),
        CheckResult("gve64-v19/13.5.9/G/nothing-to-go", Grade.DEVIATION, question="A15",
                    alternative="no-effect-0", detail="A15=no-effect-0", **common),
        CheckResult("gve64-v19/13.5.2/C/valid", Grade.SKIPPED, detail="needs motion", **common),
        CheckResult("gve64-v19/13.5.13/@/valid", Grade.ERROR, detail="link lost <&>", **common),
        CheckResult("gve64-v19/14.1/VL/valid", Grade.NOT_APPLICABLE, detail="no VL", **common),
    ]
    return RunResults([run], "conform run", "2026-01-01T00:00:00",
                      [{"name": "v-range-code", "variant": "gve64-v19", "fault": "V code",
                        "catches": ["V/range/pps/hi+1"], "caught_by": ["x"], "killed": True}])


def test_four_files_and_their_content(tmp_path):
    out = write_reports(_results(), tmp_path / "r")
    names = sorted(p.name for p in out.iterdir())
    assert names == ["index.html", "junit.xml", "results.json", "summary.md"]
    data = json.loads((out / "results.json").read_text())
    ids = {c["id"]: c for c in data["checks"]}
    failing = ids["gve64-v19/13.5.3/V/range/pps/hi+1"]
    assert failing["grade"] == "FAIL" and failing["clause"] == "GVE64 §13.5.3"
    assert failing["expected"].endswith("5") and failing["actual"].endswith("4")
    assert failing["log"][0] == {"t": 0.0, "dir": "tx", "data": "!0V125001\r"}
    suite = ET.parse(out / "junit.xml").getroot().find("testsuite")
    cases = {c.get("name"): c for c in suite.iter("testcase")}
    assert cases["gve64-v19/13.5.3/V/range/pps/hi+1"].find("failure") is not None
    assert cases["gve64-v19/13.5.13/@/valid"].find("error") is not None
    assert cases["gve64-v19/13.5.2/C/valid"].find("skipped") is not None
    assert cases["gve64-v19/14.1/VL/valid"].find("skipped") is not None
    assert cases["gve64-v19/13.5.9/G/nothing-to-go"].find("failure") is None
    assert suite.get("failures") == "1" and suite.get("errors") == "1"
    html = (out / "index.html").read_text()
    assert "http://" not in html and "https://" not in html and "<script src" not in html
    assert "gve64-v19/13.5.3/V/range/pps/hi+1" in html and "link lost &lt;&amp;&gt;" in html
    assert "1 of 1 deviant units caught" in html
    md = (out / "summary.md").read_text()
    assert "## FAIL (1)" in md and "## DEVIATION (1)" in md and "Mutants: 1/1 killed" in md


def test_report_command_re_renders(tmp_path):
    out = write_reports(_results(), tmp_path / "r")
    (out / "index.html").unlink()
    with pytest.raises(SystemExit) as info:
        main(["report", str(out / "results.json"), "-o", str(tmp_path / "again")])
    assert info.value.code == 0
    again = RunResults.load(tmp_path / "again" / "results.json")
    assert [c.grade for c in again.checks] == [c.grade for c in _results().checks]
    assert (tmp_path / "again" / "index.html").read_text().count("class=\"detail") == 4


def test_report_of_a_missing_or_bad_file_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    for path in (tmp_path / "missing.json", bad):
        with pytest.raises(SystemExit) as info:
            main(["report", str(path)])
        assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("conform: ") for line in err)
