"""Fleet analysis: several captures or a folder, in parallel locally or on Dask distributed."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest

from conform.analysis.fleet import analyze_fleet, write_fleet_report
from conform.cli.main import main

CAPTURES = Path(__file__).resolve().parent.parent / "captures"


def fleet_dir(tmp_path: Path) -> Path:
    """Two machines: one with the noisy careless session, one with two clean ones."""
    root = tmp_path / "fleet"
    for machine, names in {"mill-1": ["careless-noisy"], "mill-2": ["good-rs232", "usb-packets"]}.items():
        (root / machine).mkdir(parents=True)
        for n in names:
            shutil.copy(CAPTURES / f"{n}.mcap", root / machine / f"{n}.mcap")
    (root / "mill-2" / "broken.mcap").write_text("not a capture")
    return root


def check(summary: dict, tables: Path) -> None:
    by = {(r["machine"], r["session"]): r for r in summary["sessions"]}
    assert by[("mill-1", "careless-noisy")]["hazards"] == 5
    assert by[("mill-2", "good-rs232")]["hazards"] == 0
    assert by[("mill-2", "broken")]["state"] == "error"
    assert "not an MCAP" in by[("mill-2", "broken")]["error"]
    machines = {m["machine"]: m for m in summary["machines"]}
    assert machines["mill-2"]["sessions"] == 3 and machines["mill-2"]["errors"] == 1
    assert machines["mill-1"]["exchanges"] == by[("mill-1", "careless-noisy")]["exchanges"]
    assert by[("mill-2", "usb-packets")]["rtt_p95_ms"] > 0
    df = pd.read_parquet(tables / "exchanges")  # one dataset for the whole fleet
    assert set(df["machine"].astype(str)) == {"mill-1", "mill-2"}
    assert len(df[df["session"] == "usb-packets"]) > 0


def test_fleet_on_local_processes_writes_one_dataset_and_a_summary(tmp_path):
    root = fleet_dir(tmp_path)
    s = analyze_fleet([str(root)], parquet_dir=str(tmp_path / "pq"), jobs=2)
    check(s, tmp_path / "pq")
    paths = write_fleet_report(s, tmp_path / "rep")
    doc = json.loads(paths["json"].read_text())
    assert doc["totals"]["sessions"] == 4 and doc["totals"]["errors"] == 1
    assert "| mill-1 |" in paths["markdown"].read_text()
    assert "mill-2" in paths["html"].read_text()


@pytest.mark.slow
def test_fleet_cli_exit_status_and_report(tmp_path, capsys):
    root = fleet_dir(tmp_path)
    with pytest.raises(SystemExit) as ex:
        main(["analyze", str(root / "mill-1"), str(root / "mill-2" / "good-rs232.mcap"),
              "--report", str(tmp_path / "r"), "--jobs", "1"])
    assert ex.value.code == 0
    out = capsys.readouterr().out
    assert "2 captures on 2 machines" in out
    assert (tmp_path / "r" / "fleet.json").exists()
    with pytest.raises(SystemExit) as ex:
        main(["analyze", str(root), "--jobs", "1"])
    assert ex.value.code == 1  # one capture could not be analysed: listed, and the status says so
    assert "broken.mcap" in capsys.readouterr().out


@pytest.mark.slow
def test_fleet_on_a_dask_local_cluster(tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    root = fleet_dir(tmp_path)
    # ":0": with None the scheduler still binds its HTTP server to the default port 8787
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=":0") as cluster:
        s = analyze_fleet([str(root)], parquet_dir=str(tmp_path / "pq"),
                          scheduler=cluster.scheduler_address)
    check(s, tmp_path / "pq")


def test_a_fleet_holds_grbl_and_unknown_captures_too(tmp_path):
    """Each capture is analysed by its own family, as `conform analyze FILE` would: a grbl
    session overflowing the receive buffer is a grbl row with its hazard and line latency,
    its tables a dataset of their own; bytes of no known protocol are an error row."""
    from conform.capture import Recorder
    from conform.families.grbl.analysis.streaming import stream
    from conform.families.grbl.spec.load import load_grbl
    from conform.families.grbl.unit.model import GrblUnit

    spec = load_grbl()
    unit = GrblUnit(spec.variant("grbl-1.1f"), spec)
    unit.poll(0.0)
    job = [f"G1X{-(i % 20) * 0.5:.3f}Y{-(i % 7) * 0.3:.3f}F2000" for i in range(120)]
    traffic = stream(unit, job, method="counting", extra={40: "$G", 41: "$G"}, timeout=60)
    root = tmp_path / "fleet"
    (root / "router-1").mkdir(parents=True)
    (root / "mill-1").mkdir()
    shutil.copy(CAPTURES / "good-rs232.mcap", root / "mill-1" / "good-rs232.mcap")
    rec = Recorder(root / "router-1" / "shift.mcap", {"capture_method": "test"}, decode=False,
                   clock=lambda: 1000.0)
    for t, direction, d in sorted([(t, "host", d) for t, d in traffic.host] +
                                  [(t, "unit", d) for t, d in traffic.unit]):
        rec.chunk(direction, d, t_read=1000.0 + t)
    rec.close()
    rec = Recorder(root / "router-1" / "noise.mcap", {"capture_method": "test"}, decode=False,
                   clock=lambda: 1000.0)
    for i in range(64):
        rec.chunk("host", bytes((i * 37 + k) % 256 for k in range(16)), t_read=1000.0 + i)
    rec.close()

    s = analyze_fleet([str(root)], parquet_dir=str(tmp_path / "pq"), jobs=1)
    by = {(r["machine"], r["session"]): r for r in s["sessions"]}
    grbl = by[("router-1", "shift")]
    assert grbl["family"] == "grbl" and grbl["state"] == "clean", grbl
    assert grbl["hazards"] >= 1 and grbl["findings"].get("rx-overflow-hazard", 0) >= 1
    assert grbl["exchanges"] == 122 and grbl["rtt_p50_ms"] > 0
    assert grbl["rtt_p50_ms"] <= grbl["rtt_p95_ms"] <= grbl["rtt_max_ms"]
    assert by[("mill-1", "good-rs232")]["family"] == "gve"
    noise = by[("router-1", "noise")]
    assert noise["state"] == "error" and "protocol unknown" in noise["error"]
    ex = pd.read_parquet(tmp_path / "pq" / "grbl" / "exchanges")
    assert set(ex["machine"].astype(str)) == {"router-1"} and len(ex) == 122
    assert len(pd.read_parquet(tmp_path / "pq" / "exchanges")) > 0   # the GVE dataset as before
    paths = write_fleet_report(s, tmp_path / "rep")
    assert "| router-1 | shift | grbl | clean |" in paths["markdown"].read_text()


@pytest.mark.slow
def test_one_machine_is_said_in_the_singular(tmp_path, capsys):
    good = Path(__file__).resolve().parent.parent / "captures" / "good-rs232.mcap"
    with pytest.raises(SystemExit):
        main(["analyze", str(good), str(good), "--report", str(tmp_path / "fleet"), "--jobs", "1"])
    out = capsys.readouterr().out
    assert "2 captures on 1 machine:" in out and "1 machines" not in out
    html = (tmp_path / "fleet" / "index.html").read_text()
    assert "2 sessions on 1 machine</h1>" in html
    assert (tmp_path / "fleet" / "summary.md").read_text().startswith(
        "# Fleet analysis: 2 sessions on 1 machine\n")


def _md_table(text: str, heading: str) -> list[dict[str, str]]:
    """The rows of the Markdown table under ``## heading`` as dicts by column name."""
    table = text.split(f"## {heading}\n", 1)[1].strip().split("\n\n", 1)[0]
    rows = [[c.strip() for c in ln.strip().strip("|").split("|")] for ln in table.splitlines()]
    head, body = rows[0], rows[2:]
    return [dict(zip(head, r, strict=True)) for r in body]


@pytest.mark.slow
def test_fleet_cli_writes_every_table_session_reports_and_a_styled_report(tmp_path, capsys,
                                                                         monkeypatch):
    """`--report fleet/ --parquet t/` on a folder: each session's own report under the
    fleet's folder, linked from its row; a dataset per table the README lists; the verdict,
    badges and plots of the analysis report's look; no `t//` anywhere."""
    import re

    root = tmp_path / "caps" / "mill-1"
    root.mkdir(parents=True)
    for n in ("careless-noisy", "good-rs232"):
        shutil.copy(CAPTURES / f"{n}.mcap", root / f"{n}.mcap")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as ex:
        main(["analyze", "caps/", "--report", "fleet/", "--parquet", "t/", "--jobs", "1",
              "--no-progress"])
    assert ex.value.code == 0
    cap = capsys.readouterr()
    said = cap.out + cap.err
    assert "t/exchanges" in said and "//" not in said, said
    for table in ("exchanges", "frames_host", "frames_unit", "series", "queue_depth"):
        df = pd.read_parquet(tmp_path / "t" / table)
        assert set(df["machine"].astype(str)) == {"mill-1"}, table
        assert set(df["session"].astype(str)) == {"careless-noisy", "good-rs232"}, table
    fleet = tmp_path / "fleet"
    html = (fleet / "index.html").read_text()
    for name in ("index.html", "summary.md", "fleet.json"):  # the plots' base64 aside
        text = re.sub(r"data:image/png;base64,[A-Za-z0-9+/=]+", "", (fleet / name).read_text())
        assert "//" not in text, name
    assert '<p class="verdict HAZARD"><strong>HAZARD</strong>: 5 hazards on mill-1</p>' in html
    assert 'class="badge sev-hazard">hazard: 5<' in html
    assert len(re.findall(r'<img alt="[^"]+" src="data:image/png;base64,', html)) == 2
    links = re.findall(r'<a class="session-report" href="([^"]+)">([^<]+)</a>', html)
    assert sorted(s for _h, s in links) == ["careless-noisy", "good-rs232"]
    for href, session in links:
        page = (fleet / href).read_text()
        assert f"caps/mill-1/{session}.mcap" in page and "Session analysis" in page
    doc = json.loads((fleet / "fleet.json").read_text())
    assert doc["verdict"]["word"] == "HAZARD"
    assert (fleet / "sessions" / "mill-1" / "careless-noisy" / "findings.json").exists()


@pytest.mark.slow
def test_a_machines_starved_time_is_its_sessions_starved_time(tmp_path, capsys):
    """usb-latency's queue runs dry (the session report's starvations and starved seconds):
    the machine's row says the same starved seconds as its sessions' rows and the session's
    own report, and standstill (a longer, different figure) is named and explained apart."""
    root = tmp_path / "caps" / "mill-1"
    root.mkdir(parents=True)
    for n in ("usb-latency", "good-rs232"):
        shutil.copy(CAPTURES / f"{n}.mcap", root / f"{n}.mcap")
    with pytest.raises(SystemExit) as ex:
        main(["analyze", str(tmp_path / "caps"), "--report", str(tmp_path / "fleet"),
              "--jobs", "1", "--no-progress"])
    assert ex.value.code == 0
    capsys.readouterr()
    md = (tmp_path / "fleet" / "summary.md").read_text()
    machine, = _md_table(md, "Machines")
    sessions = _md_table(md, "Sessions")
    own = json.loads((tmp_path / "fleet" / "sessions" / "mill-1" / "usb-latency" /
                      "findings.json").read_text())["metrics"]["queue"]
    assert own["starvations"] > 0 and own["starved_s"] > 0
    assert machine["starved s"] == f"{own['starved_s']:.3f}"
    assert sum(float(r["starved s"]) for r in sessions) == pytest.approx(
        float(machine["starved s"]), abs=1e-3)
    assert float(machine["standstill s"]) > float(machine["starved s"])
    assert "starved s: time the replayed queue stood empty" in md
    assert "standstill s: from the queue running empty" in md


def _flat_fleet(tmp_path: Path) -> Path:
    """The README's captures side by side in one folder, as `conform samples` writes them:
    four units (GVE's emulator, a GVE behind a proxy, a grbl, a Marlin)."""
    root = tmp_path / "captures"
    root.mkdir()
    for n in ("good-rs232", "usb-packets", "proxy-emulator-noisy", "grbl-counting",
              "grbl-send-response", "marlin-noisy"):
        shutil.copy(CAPTURES / f"{n}.mcap", root / f"{n}.mcap")
    return root


def test_captures_side_by_side_are_told_apart_by_their_unit(tmp_path):
    """A flat folder of several units' captures is not one machine named after the folder:
    each capture is its unit's (variant or family and the port it was recorded on; an
    emulator's by its variant); a per-machine subfolder still names its machine."""
    from conform.analysis.fleet import name_machines

    root = _flat_fleet(tmp_path)
    files, names = name_machines([str(root)])
    by = {f.stem: n for f, n in zip(files, names, strict=True)}
    assert by["good-rs232"] == by["usb-packets"] == "gve64-v19 emulator"
    assert by["grbl-counting"] == by["grbl-send-response"] == "grbl on vm:/tmp/gs/grbl.pty"
    assert by["marlin-noisy"] == "marlin-2.1 on vm:/tmp/md/marlin.pty"
    assert by["proxy-emulator-noisy"] == "gve64-v19 on vm:/dev/pts/1"
    (root / "mill-7").mkdir()
    shutil.copy(CAPTURES / "marlin-noisy.mcap", root / "mill-7" / "shift.mcap")
    files, names = name_machines([str(root)])
    assert dict(zip([f.name for f in files], names, strict=True))["shift.mcap"] is None  # its folder
    files, names = name_machines([str(root / "good-rs232.mcap"), str(root / "usb-packets.mcap")])
    assert names == ["captures", "captures"]   # one unit: the folder's machine, as before


def test_fleet_time_axis_latency_columns_and_tables_that_fit(tmp_path):
    """The time axis spans the sessions' wall-clock starts (an emulator's virtual clock is
    no wall-clock time: said in a note, not placed at 2025-06-15); each family's latency is
    a column named by what it measures, never GVE's round trip; the sessions table sits in a
    container that keeps it on the page."""
    from datetime import UTC, datetime

    from conform.analysis.fleetplots import time_span, timed

    s = analyze_fleet([str(_flat_fleet(tmp_path))], jobs=1)
    assert s["totals"]["machines"] == 4
    rows = {r["session"]: r for r in s["sessions"]}
    assert rows["good-rs232"]["started"] is None and rows["good-rs232"]["clock"] == "virtual"
    assert any("virtual clock" in n and "good-rs232" in n for n in s["notes"])
    lo, hi = time_span(timed(s))
    assert lo >= datetime(2026, 11, 20, tzinfo=UTC) and hi - lo < (
        datetime(2026, 11, 28, tzinfo=UTC) - datetime(2026, 11, 20, tzinfo=UTC))
    first = min(r["started"] for r in timed(s))
    assert lo.timestamp() < first   # no session on the axis' edge
    assert s["latencies"] == ["line to ok/error", "round trip", "line to ok"]
    assert rows["grbl-counting"]["latency"] == "line to ok/error"
    assert rows["marlin-noisy"]["latency"] == "line to ok"
    assert rows["good-rs232"]["latency"] == "round trip"
    paths = write_fleet_report(s, tmp_path / "rep")
    md = paths["markdown"].read_text()
    sessions = {r["session"]: r for r in _md_table(md, "Sessions")}
    assert sessions["grbl-counting"]["round trip: p50 / p95 / p99 ms"] == ""
    assert sessions["grbl-counting"]["line to ok/error: p50 / p95 / p99 ms"].count(" / ") == 2
    machines = {r["machine"]: r for r in _md_table(md, "Machines")}
    assert machines["grbl on vm:/tmp/gs/grbl.pty"]["round trip: worst p95 / p99 ms"] == ""
    assert machines["grbl on vm:/tmp/gs/grbl.pty"]["line to ok/error: worst p95 / p99 ms"]
    html = paths["html"].read_text()
    assert '<div class="wide"><table class="sessions wide-t">' in html
    assert "<th>line to ok: p50 / p95 / p99 ms</th>" in html and "rtt p50" not in html
