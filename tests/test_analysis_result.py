"""The engine's shared analysis result (conform.analysis.result): the finding record, the
variant a capture is analysed as, the lines and files every line-based family's result
writes, and the one-line error for a folder that cannot take the tables."""

from __future__ import annotations

import json
from dataclasses import dataclass
from types import SimpleNamespace

import pyarrow.parquet as pq
import pytest

from conform.analysis.result import Finding, ResultBase, capture_variant, findings_table, save_tables
from conform.errors import UserError


@dataclass
class Toy(ResultBase):
    findings: list[Finding]
    metrics: dict


def toy() -> Toy:
    found = [Finding("late", 1.5, "warning", "slow", "§1"),
             Finding("lost", 2.25, "hazard", "gone", "§2", {"line": 7}),
             Finding("bad", 3.0, "error", "wrong")]
    return Toy("x.mcap", "toy", "toy-1", "by its bytes", found,
               {"duration_s": 4.0, "hazards": 1, "finding_counts": {"late": 1, "lost": 1, "bad": 1}},
               notes=["a note"])


def test_a_finding_as_json_puts_its_extra_keys_in_place_of_extra():
    f = Finding("lost", 2.0, "hazard", "gone", "§2", {"line": 7})
    assert f.to_dict() == {"kind": "lost", "t": 2.0, "severity": "hazard", "message": "gone",
                           "clause": "§2", "line": 7}
    assert list(f.to_dict()) == ["kind", "t", "severity", "message", "clause", "line"]


def test_the_variant_asked_then_the_captures_then_the_default_with_a_note():
    meta = {"conform.session": {"variant": "toy-2"}}
    known = {"toy-1", "toy-2"}
    assert capture_variant(meta, "toy-1", known, "toy-1", "Toy") == ("toy-1", [])
    assert capture_variant(meta, None, known, "toy-1", "Toy") == ("toy-2", [])
    assert capture_variant({}, None, known, "toy-1", "Toy") == ("toy-1", [])
    assert capture_variant(meta, None, {"toy-1"}, "toy-1", "Toy") == (
        "toy-1", ["variant 'toy-2' is not a Toy variant; analysed as toy-1"])


def test_the_findings_lines_list_serious_findings_only_and_at_most_as_asked():
    a = toy()
    assert a.findings_lines() == [
        "findings: late 1, lost 1, bad 1",
        "      2.2500s hazard  lost: gone", "      3.0000s error   bad: wrong", "note: a note"]
    assert a.findings_lines(1) == [
        "findings: late 1, lost 1, bad 1", "      2.2500s hazard  lost: gone", "note: a note"]
    assert [f.kind for f in a.hazards()] == ["lost"] and a.kinds()["bad"] == 1


def test_a_damaged_file_is_noted_after_the_reading_notes():
    a = toy()
    a.add_notes(["read note"], SimpleNamespace(complete=False, problem="ends early"))
    assert not a.complete and a.notes == ["a note", "read note", "capture incomplete: ends early"]


def test_the_report_files_and_the_fleet_row(tmp_path):
    a = toy()
    paths = a.report_files(str(tmp_path / "r"), lambda: a.summary_markdown(["# toy", "", "head"]),
                           lambda: "<html></html>\n")
    doc = json.loads(paths["json"].read_text())
    assert doc["format"] == "conform-toy-analysis/1" and doc["findings"][1]["extra"] == {"line": 7}
    md = paths["md"].read_text()
    assert md.startswith("# toy\n\nhead\n\n- duration_s: 4.0\n- hazards: 1\n\n## Findings\n\n")
    assert "- 2.2500 s hazard lost: gone [§2]\n" in md and "finding_counts" not in md
    assert paths["html"].read_text() == "<html></html>\n"
    row = a.fleet_row_of(10, 2.5, [1.0, 2.0, 3.0, None], mine=3)
    assert row["state"] == "clean" and row["exchanges"] == 10 and row["rtt_max_ms"] is None
    assert row["findings"] == {"late": 1, "lost": 1, "bad": 1} and row["mine"] == 3


def test_the_tables_are_written_or_refused_in_one_line(tmp_path):
    a = toy()
    out = save_tables(tmp_path / "t", {"findings": findings_table(a.findings)})
    assert pq.read_table(out["findings"]).column("kind").to_pylist() == ["late", "lost", "bad"]
    (tmp_path / "file").write_text("not a folder")
    with pytest.raises(UserError, match="cannot write the tables"):
        save_tables(tmp_path / "file" / "t", {"findings": findings_table(a.findings)})
