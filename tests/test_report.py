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
        CheckResult("gve64-v19/13.5.2/C/valid", Grade.SKIPPED,
                    detail="needs motion (not allowed in this run: --allow-motion)", **common),
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
    assert "## Failures (2)" in md and "## Deviations on open questions (1)" in md
    assert "Mutants: 1/1 killed" in md


def test_report_command_re_renders(tmp_path):
    out = write_reports(_results(), tmp_path / "r")
    (out / "index.html").unlink()
    with pytest.raises(SystemExit) as info:
        main(["report", str(out / "results.json"), "-o", str(tmp_path / "again")])
    assert info.value.code == 0
    again = RunResults.load(tmp_path / "again" / "results.json")
    assert [c.grade for c in again.checks] == [c.grade for c in _results().checks]
    assert (tmp_path / "again" / "index.html").read_text().count("class=\"detail") == 3


def test_report_of_a_missing_or_bad_file_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    for path in (tmp_path / "missing.json", bad):
        with pytest.raises(SystemExit) as info:
            main(["report", str(path)])
        assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("conform: ") for line in err)


def _sectioned():
    """Two targets, failures in three sections, skips for two reasons, one run cut short."""
    runs = []
    for target, aborted in (("emu:gve64-v19", None), ("/dev/pts/9", "link lost after 4 checks")):
        run = TargetRun(target, "gve64-v19", target.startswith("emu"), "quick", "t0",
                        aborted=aborted)
        common = dict(variant="gve64-v19", target=target)
        run.checks = [
            CheckResult("gve64-v19/13.5.13/J/syntax", Grade.FAIL, "GVE64 §13.5.13",
                        expected="!0J# → 4", actual="!0J# → 4,60", replay="gve64-v19/13.5.13/J/syntax",
                        log=[LogEntry(0.0, "tx", b"!0J#\r"), LogEntry(0.002, "rx", b"4,60\r")],
                        **common),
            CheckResult("gve64-v19/13.5.3/V/valid", Grade.FAIL, "GVE64 §13.5.3, GVE64 §14.1",
                        expected="!0V1000 → 0", actual="!0V1000 → 5", **common),
            CheckResult("gve64-v19/13.5/sequences", Grade.ERROR, "GVE64 §13.5", level="INFO",
                        detail="LinkError: port gone", seed=77,
                        replay="gve64-v19/13.5/sequences", **common),
            CheckResult("gve64-v19/13.5.2/C/valid", Grade.SKIPPED, "GVE64 §13.5.2",
                        detail="needs motion (not allowed in this run: --allow-motion)", **common),
            CheckResult("gve64-v19/13.5.12/EW/valid", Grade.SKIPPED, "GVE64 §13.5.12",
                        detail="needs eeprom (not allowed in this run: --allow-motion)", **common),
            CheckResult("gve64-v19/13.5.2/L/valid", Grade.PASS, "GVE64 §13.5.2", **common),
        ]
        runs.append(run)
    return RunResults(runs, "conform run --matrix", "2026-01-01T00:00:00")


def test_html_leads_with_status_skips_and_failures_by_section(tmp_path):
    html = (write_reports(_sectioned(), tmp_path) / "index.html").read_text()
    at = html.index
    # first screen: verdict, the incomplete run's reason, what was not verified and how, MUST/INFO
    assert "INCOMPLETE" in html[:at('id="summary"')]
    assert at("Incomplete run.") < at('id="failures"')
    assert "/dev/pts/9: link lost after 4 checks" in html[:at('id="failures"')]
    skipped = html[at('id="not-verified"'):at('id="failures"')]
    assert "2 checks need motion (axes, outputs, spindle)" in skipped
    assert "enable with <span class=\"mono\">--allow-motion --max-steps N</span>" in skipped
    assert "2 checks need EEPROM writes" in skipped and "--allow-eeprom" in skipped
    assert "<b>MUST</b>" in html[:at('id="failures"')] and "<b>INFO</b>" in html[:at('id="failures"')]
    # failures before every matrix, grouped by section in the manual's (numeric) order
    assert at('id="failures"') < at('id="sections"') < at('id="matrix"')
    order = [at('<h3 id="f-s-GVE64-13-5">'), at('<h3 id="f-s-GVE64-13-5-3">'),
             at('<h3 id="f-s-GVE64-13-5-13">')]
    assert order == sorted(order)
    first = html[at('<h3 id="f-s-GVE64-13-5">'):at('id="sections"')]
    assert "conform run --target /dev/pts/9 --variant gve64-v19 --replay " \
           "gve64-v19/13.5/sequences@77" in first
    j = html[at('id="c-emu-gve64-v19-gve64-v19-13-5-13-J-syntax"'):]
    assert "!0J# → 4,60" in j and '<span class="tx">' in j and "4,60\\r" in j
    assert "conform run --target emu:gve64-v19 --variant gve64-v19 --replay " \
           "gve64-v19/13.5.13/J/syntax" in j


def test_markdown_follows_the_same_order(tmp_path):
    md = (write_reports(_sectioned(), tmp_path) / "summary.md").read_text()
    at = md.index
    assert md.startswith("# Conformance summary: INCOMPLETE")
    assert at("**Incomplete run.** /dev/pts/9: link lost") < at("## Not verified") \
        < at("## Failures (6)") < at("## Commands × variants")
    assert at("### GVE64 §13.5 (") < at("### GVE64 §13.5.3 (") < at("### GVE64 §13.5.13 (")
    assert "- 2 checks need EEPROM writes — enable with `--allow-eeprom`" in md
    assert "0.002000 rx   4,60\\r" in md and "expected: `!0J# → 4`" in md
    assert "| C | GVE64 §13.5.2: 1 SKIPPED | GVE64 §13.5.2: 1 SKIPPED |" in md


def test_matrix_rows_line_up_one_command_across_variants(tmp_path):
    """GVE124's manual numbers V §12.5.3 where GVE64's says §13.5.3: the matrix has one row for
    V holding both variants' grades, each with its own clause (not two half-empty rows)."""
    out = tmp_path / "r"
    with pytest.raises(SystemExit) as info:
        main(["run", "--target", "emu:gve64-v19", "--target", "emu:gve124", "--no-machine",
              "-q", "--check", "*/V/*", "--check", "*/question/A7", "--report", str(out)])
    assert info.value.code == 0
    data = json.loads((out / "results.json").read_text())
    assert {c["subject"] for c in data["checks"]} == {"V", "A7"}
    md = (out / "summary.md").read_text()
    table = md[md.index("## Commands × variants"):].splitlines()
    assert "| command | gve64-v19 | gve124 |" in table
    v_rows = [line for line in table if line.startswith("| V |")]
    assert len(v_rows) == 1
    cells = [c.strip() for c in v_rows[0].strip("|").split("|")]
    assert cells[1].startswith("GVE64 §13.5.3: ") and "PASS" in cells[1]
    assert cells[2].startswith("GVE124 §12.5.3: ") and "PASS" in cells[2]
    html = (out / "index.html").read_text()
    matrix = html[html.index('id="sections"'):html.index('id="matrix"')]
    row = matrix[matrix.index('href="#r-V"'):]
    row = row[:row.index("</tr>")]
    assert 'title="GVE64 §13.5.3"' in row and 'title="GVE124 §12.5.3"' in row
    # the check-by-check table of the row: V/valid of both variants on one line
    details = html[html.index('<details id="r-V"'):]
    line = details[details.index(">V/valid<"):]
    assert line[:line.index("</tr>")].count("g PASS") == 2


def test_a_results_file_without_subjects_falls_back_to_the_id():
    old = CheckResult("gve64-v19/13.5.3/V/valid", Grade.PASS, "GVE64 §13.5.3")
    assert old.row == "V" and CheckResult.from_json(old.to_json()).row == "V"


def test_junit_classname_is_variant_and_section(tmp_path):
    suite = ET.parse(write_reports(_sectioned(), tmp_path) / "junit.xml").getroot()
    names = {(c.get("classname"), c.get("name")) for c in suite.iter("testcase")}
    assert ("gve64-v19.13.5.3", "gve64-v19/13.5.3/V/valid") in names
    assert all(cls for cls, _ in names)


def test_latest_link_follows_the_last_report(tmp_path):
    from conform.report.render import link_latest

    for name in ("20260101-000000", "20260101-000100"):
        link = link_latest(write_reports(_sectioned(), tmp_path / name))
    assert link == tmp_path / "latest" and link.is_symlink()
    assert (link / "index.html").resolve() == (tmp_path / "20260101-000100" / "index.html")
    (tmp_path / "x" / "latest").mkdir(parents=True)
    assert link_latest(tmp_path / "x" / "r") is None  # a real folder of that name is kept


def test_not_verified_groups_the_runners_reasons():
    from conform.report.view import not_verified

    def skipped(i, detail, target="/dev/ttyUSB0"):
        return CheckResult(f"gve64-v19/13.5.2/C/x{i}", Grade.SKIPPED, "GVE64 §13.5.2",
                           detail=detail, variant="gve64-v19", target=target)

    run = TargetRun("/dev/ttyUSB0", "gve64-v19", False, "quick", "t0")
    run.checks = [
        skipped(1, "needs actuator, motion (not allowed in this run: enable with --allow-motion "
                   "--max-steps N)"),
        skipped(2, "needs motion (not allowed in this run: --allow-motion)"),  # older wording
        skipped(3, "needs eeprom, motion (not allowed in this run: enable with --allow-motion "
                   "--max-steps N --allow-eeprom)"),
        skipped(4, "outside the envelope (a move of 4000 pulses cannot be done inside "
                   "--max-steps 1000: enable with --max-steps 4000)"),
        skipped(5, "outside the envelope (a move of 9000 pulses cannot be done inside "
                   "--max-steps 1000: enable with --max-steps 9000)"),
        skipped(6, "refused to send b'!0L2000,0,0': a move of 2000 steps exceeds --max-steps 1000"),
        skipped(7, "needs inputs driven (a real unit's inputs are switched by hand; with `conform "
                   "emulate serve` behind the link: enable with --inputs-control PATH)"),
        skipped(8, "the moon is not full"),
    ]
    groups = {g.reason: (len(g.checks), g.how) for g in not_verified(RunResults([run]))}
    assert groups == {
        "motion (axes, outputs, spindle)": (2, "--allow-motion --max-steps N"),
        "EEPROM writes and motion (axes, outputs, spindle)":
            (1, "--allow-motion --max-steps N --allow-eeprom"),
        "moves longer than --max-steps allows": (3, "--max-steps 9000"),
        "driven inputs (only an emulator can drive them)": (1, "--inputs-control PATH"),
        "the moon is not full": (1, ""),
    }
