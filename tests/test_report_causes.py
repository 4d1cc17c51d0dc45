"""A failing run says first what it can: the unit is another variant than the one asked for
(its firmware string, or the emulator named), and FAILs with one root cause — the same wrong
answer code to many commands — are one line, not forty near-identical cards; a check's
expected and actual answers have their differing bytes marked."""

from __future__ import annotations

import json
import re

import pytest

from conform.cli.main import main
from conform.report.view import differing


@pytest.fixture(scope="module")
def wrong_variant(tmp_path_factory):
    """A GVE64 v10 unit run as a v19: v19's commands VL, VK, VN, XM are unknown to it."""
    out = tmp_path_factory.mktemp("wrong") / "report"
    with pytest.raises(SystemExit) as info:
        main(["run", "--target", "emu:gve64-v10", "--variant", "gve64-v19", "--no-machine", "-q",
              "--report", str(out)])
    assert info.value.code == 1
    return out


def test_the_report_says_the_variant_first_and_groups_the_cause(wrong_variant):
    results = json.loads((wrong_variant / "results.json").read_text())
    notes = results["runs"][0]["notes"]
    assert notes[0] == "hint: the target is emu:gve64-v10, not gve64-v19: try --variant gve64-v10"
    fails = [c for c in results["checks"] if c["grade"] == "FAIL"]
    unknown = [c for c in fails if c["actual"].rsplit("→", 1)[-1].strip().startswith("3")]
    assert len(unknown) >= 30   # the v10 tables: VL, VK, VN, XM do not exist there (code 3)
    html = (wrong_variant / "index.html").read_text()
    first = html[:html.index('id="sections"')]
    assert 'id="hint"' in first and "try --variant gve64-v10" in first
    causes = first[first.index('id="causes"'):]
    assert f"one cause, {len(unknown)} checks" in causes
    for command in ("VL", "VK", "VN", "XM"):
        assert f">{command}/" in causes   # links to the checks' cards
    md = (wrong_variant / "summary.md").read_text()
    assert f"one cause, {len(unknown)} checks" in md


def test_the_summary_prints_one_line_for_the_cause(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["run", "--target", "emu:gve64-v10", "--variant", "gve64-v19", "--no-machine",
              "-q", "--report", str(tmp_path / "r")])
    out = capsys.readouterr().out.splitlines()
    assert out[1] == "  hint: the target is emu:gve64-v10, not gve64-v19: try --variant gve64-v10"
    assert out[2].startswith("  FAIL ×") and "VL, VK, VN, XM" in out[2]
    assert "answered 3 where 0 or 4 or 5 was expected" in out[2]
    assert len([x for x in out if x.startswith("  FAIL")]) < 12   # not 40 lines


def test_the_differing_bytes_are_marked():
    assert differing("!0VL1000 → 0", "!0VL1000 → 3") == ("!0VL1000 → ", "0", "3", "")
    assert differing("0,IP64MPG v19 10.9.2010", "0,IP64MPG v10") == (
        "0,IP64MPG v1", "9 10.9.201", "", "0")
    assert differing("same", "same") == ("same", "", "", "")


def test_a_passing_emulator_run_says_what_it_proves(tmp_path, capsys):
    with pytest.raises(SystemExit) as info:
        main(["run", "--check", "*/V/valid", "--no-machine", "-q", "--report",
              str(tmp_path / "r")])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "checks the reference model against the tables it was built from" in out
    assert "says nothing about a real unit" in out
    html = (tmp_path / "r" / "index.html").read_text()
    assert 'id="scope"' in html[:html.index('id="failures"')]


@pytest.mark.slow
def test_check_sender_names_its_verdict_and_every_rule_short_of_pass(tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parent.parent
    hang = str(repo / "tests" / "senders" / "hang.py")
    p = subprocess.run([sys.executable, "-m", "conform", "check-sender", "--scenario", "clean",
                        "--timeout", "2", "--report", str(tmp_path / "r"), "--",
                        sys.executable, hang, "{port}", "{job}"], capture_output=True,
                       text=True, timeout=120, cwd=tmp_path)
    assert p.returncode == 1, p.stderr
    # a SHOULD rule not met is DEVIATION (the engine's grades), named like a FAIL
    assert "  DEVIATION clean/queue-fed (SHOULD" in p.stdout
    assert "  FAIL clean/terminates (MUST" in p.stdout
    html = (tmp_path / "r" / "index.html").read_text()
    title = html[html.index("<title>") + 7:html.index("</title>")]
    assert title.startswith("check-sender FAIL: ") and "[" not in title   # not a Python list
    assert re.search(r'<span class="FAIL badge[^"]*">FAIL</span>', html), html[:400]
    assert (tmp_path / "r" / "summary.md").read_text().startswith("# check-sender summary: FAIL")


def test_the_analysis_report_says_what_each_answer_code_means(tmp_path, capsys):
    from pathlib import Path

    noisy = Path(__file__).resolve().parent.parent / "captures" / "careless-noisy.mcap"
    with pytest.raises(SystemExit):
        main(["analyze", str(noisy), "--report", str(tmp_path / "an")])
    html = (tmp_path / "an" / "index.html").read_text()
    table = html[html.index("Answer codes"):]
    table = table[:table.index("</table>")]
    assert "<th>meaning</th>" in table
    assert "<td>-1</td>" in table and "no code could be read" in table   # was unexplained
    assert "queue full" in table   # code 1, from the tables (GVE64 §13.7)


def test_the_throughput_plot_axes_share_their_zero(monkeypatch):
    from pathlib import Path

    from conform.analysis import analyze
    from conform.families.gve.analysis import plots

    figures = []
    monkeypatch.setattr(plots, "to_png", lambda fig: figures.append(fig) or "png")
    a = analyze(str(Path(__file__).resolve().parent.parent / "captures" / "usb-latency.mcap"))
    assert plots.throughput_plot(a) == "png"
    left, right = figures[0].axes[:2]
    assert left.get_ylim()[0] == 0 and right.get_ylim()[0] == 0
