"""A Marlin capture analysed: detected by its bytes, the resend storm of an off-by-one sender
named with its ratio, a reset mid-job that makes the sender run lines twice named line by line
(confirmed against the unit's own ground truth), and the report, Parquet tables and fleet row."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from conform.families.marlin.analysis.analyze import analyze_capture, analyze_streams
from conform.families.marlin.sender.sim import stream, write_capture
from conform.families.marlin.spec import load_marlin
from conform.families.marlin.unit.faults import MarlinFaults
from conform.families.marlin.unit.unit import MarlinUnit
from conform.link.faults import FaultConfig

S = load_marlin()
JOB = [f"G1 X{i % 50}.{i % 7} Y{i % 13} F6000" for i in range(1, 301)]


def session(**kw):
    u = MarlinUnit(S.variant("marlin-2.1"), S)
    return u, stream(u, JOB, **kw)


@pytest.fixture(scope="module")
def storm(tmp_path_factory):
    u, r = session(faults=MarlinFaults(FaultConfig.parse("host.corrupt=1e-3"), seed=3),
                   wrong_resends=20)
    path = tmp_path_factory.mktemp("storm") / "storm.mcap"
    write_capture(str(path), r)          # no variant in the metadata: detected by its bytes
    return u, path


def test_resend_storm_is_named_with_its_ratio(storm, tmp_path):
    u, path = storm
    p = subprocess.run([sys.executable, "-m", "conform", "analyze", str(path), "--report",
                        str(tmp_path / "r"), "--parquet", str(tmp_path / "t")],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "protocol family marlin" in p.stdout
    assert "resend-storm: 21 Resend: requests" in p.stdout and "most N69" in p.stdout
    a = analyze_capture(str(path))
    resends = len(u.truth.resends)
    assert a.metrics["resends"] == resends
    assert a.metrics["resend_ratio"] == pytest.approx(resends / a.metrics["numbered"])
    why = [w for _, _, w in u.truth.resends]
    assert a.metrics["line_number_errors"] == why.count("line-number")
    assert a.metrics["checksum_errors"] == why.count("checksum") and a.metrics["storms"] == 1
    # nothing ran twice or never: the unit's ground truth agrees
    assert not [n for n, k in u.truth.executed.items() if k > 1]
    assert a.metrics["twice_confirmed"] == a.metrics["twice_possible"] == 0
    assert a.metrics["never_confirmed"] == 0
    found = json.loads((tmp_path / "r" / "findings.json").read_text())
    assert found["metrics"]["storms"] == 1
    lines = pq.read_table(tmp_path / "t" / "lines.parquet")
    assert lines.num_rows == a.metrics["host_lines"]
    assert (tmp_path / "r" / "index.html").read_text().count("resend-storm") >= 1


def test_a_reset_mid_job_and_a_restarted_sender_run_lines_twice(tmp_path):
    u, r = session(restart_at=100)
    twice = sorted(n for n, k in u.truth.executed.items() if k > 1)
    assert twice == list(range(1, 101))
    path = tmp_path / "restart.mcap"
    write_capture(str(path), r, {"variant": "marlin-2.1"})
    a = analyze_capture(str(path))
    named = sorted(f.extra["n"] for f in a.findings if f.kind == "ran-twice" and f.extra["confirmed"])
    assert named == twice
    assert a.metrics["twice_confirmed"] == 100 and a.kinds()["reset"] == 1
    row = a.fleet_row()
    assert row["family"] == "marlin" and row["hazards"] == 100 and row["exchanges"] == 401


def test_a_lost_ok_is_a_possible_double_or_nothing():
    u, r = session(faults=MarlinFaults(seed=1, lose=0.02), timeout=1.5)
    a = analyze_streams(r.host, r.unit)
    assert sum(u.truth.executed.values()) == len(JOB)      # this sender never resends unasked
    assert a.metrics["twice_confirmed"] == 0 and a.metrics["never_confirmed"] == 0
    assert a.metrics["oks"] < len(JOB)


def test_the_tables_stream_as_lines_settle_and_match_the_lines_kept(storm, tmp_path):
    """lines.parquet written a row group at a time during the pass holds one row per host
    line in send order, the same rows as the lines kept in memory."""
    from conform.families.marlin.analysis import report

    _, path = storm
    kept = analyze_capture(str(path), keep_lines=True)
    old, report.ROWS = report.ROWS, 37      # many row groups
    try:
        streamed = analyze_capture(str(path), parquet=tmp_path / "s")
    finally:
        report.ROWS = old
    assert streamed.lines == [] and streamed.metrics == kept.metrics
    f = pq.ParquetFile(tmp_path / "s" / "lines.parquet")
    assert f.num_row_groups > 5
    rows = f.read().to_pydict()
    assert rows["n"] == [x.n for x in kept.lines]
    assert rows["accepted"] == [x.accepted for x in kept.lines]
    assert sum(rows["repeat"]) == kept.metrics["repeats"]
    # asked afterwards for another folder: the same files; an analysis that kept nothing and
    # wrote nothing reads its capture again
    again = streamed.write_tables(str(tmp_path / "copy"))
    assert pq.read_table(again["lines"]).num_rows == kept.metrics["host_lines"]
    late = analyze_capture(str(path)).write_tables(str(tmp_path / "late"))
    assert pq.read_table(late["findings"]).num_rows == len(kept.findings)


def test_findings_past_the_listed_number_are_counted(monkeypatch):
    from conform.families.marlin.analysis import core

    monkeypatch.setattr(core, "MAX_KEPT", 10)
    u, r = session(restart_at=100)
    a = analyze_streams(r.host, r.unit)
    assert a.metrics["twice_confirmed"] == 100 and a.kinds()["ran-twice"] == 100
    assert sum(f.kind == "ran-twice" for f in a.findings) == 10
    assert any("90 findings not listed" in n for n in a.notes)


def test_nearest_rank_percentiles_are_exact_then_within_a_tenth_of_a_percent():
    import numpy as np

    from conform.analysis.summaries import Quantiles

    rng = np.random.default_rng(5)
    v = rng.lognormal(-4, 1, 250_000)
    small, big = Quantiles(), Quantiles()
    small.add(v[:1000])
    for part in np.array_split(v, 9):
        big.add(part)
    for q_obj, vals in ((small, v[:1000]), (big, v)):
        o = np.sort(vals)
        want = [o[min(len(o) - 1, int(q * len(o)))] for q in (0.0, 0.5, 0.95, 0.99, 1.0)]
        got = q_obj.nearest([0.0, 0.5, 0.95, 0.99, 1.0])
        if q_obj is small:
            assert got == [float(x) for x in want]
        else:
            assert got[0] == o[0] and got[-1] == o[-1]
            assert np.allclose(got, want, rtol=1e-3, atol=0)


def test_first_acceptances_kept_on_disk_read_back_after_eviction():
    """Seen keeps a record per line number in a file behind a few cached blocks: what was
    written and evicted reads back the same; a second text under one number is kept too."""
    import random

    from conform.families.marlin.analysis.core import Seen

    s = Seen()
    r = random.Random(1)
    # a thousand numbers over 31 blocks of which 4 are cached: nearly every one evicts a block
    ns = [r.randrange(0, 2_000_000) for _ in range(1000)]
    for k, n in enumerate(ns):
        s.first(n, n * 7 + 1, k * 0.5, k % 5, k % 2 == 0)
    assert len(s.blocks) == Seen.CACHED
    first = {}
    for k, n in enumerate(ns):
        first.setdefault(n, (k * 0.5, k % 5, k % 2 == 0))
    assert all(s.get(n, n * 7 + 1) == first[n] for n in ns)
    assert s.get(ns[0], 12345) is None
    s.first(ns[0], 12345, 9.0, 3, True)
    assert s.get(ns[0], 12345) == (9.0, 3, True) and s.get(ns[0], ns[0] * 7 + 1) == first[ns[0]]
    s.close()


def test_a_fleet_streams_a_marlin_captures_tables_in_one_pass(storm, tmp_path, monkeypatch):
    """In a fleet the family's analysis writes its tables as it goes: one pass per capture,
    the lines table in the fleet's dataset."""
    from conform.analysis.fleet import analyze_one
    from conform.families.marlin.analysis import analyze as marlin_analyze

    _, path = storm
    passes = []
    real = marlin_analyze.analyze_streams
    monkeypatch.setattr(marlin_analyze, "analyze_streams",
                        lambda *a, **k: passes.append(1) or real(*a, **k))
    row = analyze_one(str(path), str(tmp_path / "t"), {})
    assert row["family"] == "marlin" and not row.get("error") and len(passes) == 1
    tables = sorted((tmp_path / "t" / "marlin").rglob("*.parquet"))
    assert [p.parent.parent.name for p in tables] == ["findings", "lines"]
    assert pq.read_table(tables[1]).num_rows == row["exchanges"]
    assert not [p for p in (tmp_path / "t" / "marlin").iterdir() if p.name.startswith(".")]


def test_report_gives_the_verdict_then_the_diagnosis_when_there_is_one(tmp_path):
    """The place the Marlin diagnosis fills: its sentence right after the verdict, its
    details after the figures (the pieces every analysis report shares)."""
    from types import SimpleNamespace

    from conform.families import family

    a = family("marlin").analyze(str(Path(__file__).resolve().parent.parent / "captures" /
                                     "marlin-noisy.mcap"))
    plain = a.write_report(str(tmp_path / "plain"))["html"].read_text()
    assert 'class="diagnosis"' not in plain
    a.diagnosis = SimpleNamespace(headline="Most likely the link: 10 lines damaged on the way",
                                  causes=[], reception=[], resume=None)
    page = a.write_report(str(tmp_path / "diag"))["html"].read_text()
    verdict, diagnosis = page.index('class="verdict'), page.index('class="diagnosis"')
    badges, details = page.index('class="badge'), page.index('class="diagnosis-details"')
    assert verdict < diagnosis < badges < details
    assert "Diagnosis: Most likely the link: 10 lines damaged on the way" in page
