"""The analyser on small hand-made captures: decoding, pairing, timing, findings, bad input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

from conform.analysis import write_parquet, write_report
from conform.analysis.rawread import b64decode_many
from conform.capture.recorder import Recorder
from conform.cli.main import cli
from conform.errors import UserError
from conform.families.gve.analysis import analyze
from conform.families.gve.protocol import append_checksum

T0 = 1_750_000_000.0
BAUD = 115200


class Clock:
    def __init__(self) -> None:
        self.t = T0

    def __call__(self) -> float:
        return self.t


def record(path: Path, script: list[tuple[str, bytes, float]], *, baud: int | None = BAUD,
           variant: str | None = "gve64-v19") -> Path:
    """Write (direction, bytes, seconds after T0 the read returned) as a capture."""
    clock = Clock()
    meta: dict = {"capture_method": "test"}
    if baud:
        meta["baud"] = baud
    if variant:
        meta["variant"] = variant
    rec = Recorder(path, meta, clock=clock, decode=False)
    for direction, data, t in script:
        clock.t = T0 + t
        rec.chunk(direction, data, T0 + t)
    rec.close()
    return path


def simplex(pairs: list[tuple[bytes, bytes]], gap: float = 0.002, think: float = 0.001,
            start: float = 0.0) -> list[tuple[str, bytes, float]]:
    """A well-behaved conversation: each command, its answer after ``gap``, then ``think``."""
    out = []
    t = start
    for cmd, ans in pairs:
        t += len(cmd) * 10 / BAUD
        out.append(("host", cmd, t))
        if ans:
            t += gap + len(ans) * 10 / BAUD
            out.append(("unit", ans, t))
        t += think
    return out


def cs(body: bytes) -> bytes:
    return append_checksum(body) + b"\r"


def test_b64_bulk_decoder_matches_base64() -> None:
    import base64

    items = [b"", b"a", b"ab", b"abc", b"\x00\xff\r", bytes(range(256))]
    enc = [base64.b64encode(x) for x in items]
    chars = np.frombuffer(b"".join(enc), np.uint8)
    offs = np.concatenate([[0], np.cumsum([len(e) for e in enc])])
    data, lens = b64decode_many(chars, offs)
    assert lens.tolist() == [len(x) for x in items]
    assert data.tobytes() == b"".join(items)


def test_clean_session_decodes_and_times(tmp_path: Path) -> None:
    p = record(tmp_path / "a.mcap", simplex([
        (b"!0V2000\r", b"0\r"), (b"!0C100,0,0\r", b"0\r"), (b"!0C0,100,0\r", b"0\r"),
        (b"!0PF\r", b"0,100,100,0\r"), (b"!0PF\r", b"0,100,100,0\r"),
    ]))
    a = analyze(p)
    ex = a.exchanges
    assert ex["status"].tolist() == ["answered"] * 5
    assert ex["name"].tolist() == ["V", "C", "C", "PF", "PF"]
    assert a.metrics["vectors_accepted"] == 2
    assert a.findings == []
    # wire time is bytes x 10 / baud; the rest of the round trip is the unit's 2 ms
    row = ex.iloc[1]
    assert row["wire_cmd"] == pytest.approx(11 * 10 / BAUD)
    assert row["unit_time"] == pytest.approx(0.002, abs=2e-5)
    assert row["host_time"] == pytest.approx(0.001, abs=2e-5)
    assert a.metrics["positions"]["checked"] >= 1
    frames = a.frames("unit")
    assert frames["text"].tolist()[3] == "0,100,100,0"


def test_checksum_mode_and_errors_both_directions(tmp_path: Path) -> None:
    bad_cmd = b"!0C1,0,0,00\r"  # wrong checksum as sent
    p = record(tmp_path / "c.mcap", simplex([
        (b"!0%+\r", cs(b"0")), (cs(b"!0C5,0,0"), cs(b"0")), (bad_cmd, cs(b"4")),
        (cs(b"!0C6,0,0"), b"0,00\r"),  # answer with a bad checksum
        (cs(b"!0%-"), b"0\r"), (b"!0C7,0,0\r", b"0\r"),
    ]))
    a = analyze(p)
    kinds = a.metrics["finding_counts"]
    assert kinds.get("checksum-error") == 2
    dirs = sorted(f.extra["direction"] for f in a.findings if f.kind == "checksum-error")
    assert dirs == ["host", "unit"]
    assert a.host.checksum_mode.tolist() == [False, True, True, True, True, False]
    assert a.exchanges["name"].tolist()[-1] == "C"
    # the C6 answer was uncertain and the sender moved on without asking: possible loss
    assert kinds.get("lost-vector") == 1


def test_simplex_violation_pairs_first_in_first_out(tmp_path: Path) -> None:
    script = [("host", b"!0C1,0,0\r", 0.001), ("host", b"!0C2,0,0\r", 0.0015),
              ("unit", b"0\r", 0.003), ("unit", b"1\r", 0.0035),
              ("host", b"!0C3,0,0\r", 0.006), ("unit", b"0\r", 0.008)]
    a = analyze(record(tmp_path / "s.mcap", script))
    ex = a.exchanges
    assert ex["answer_frame"].tolist() == [0, 1, 2]
    assert ex["code"].tolist() == [0, 1, 0]
    viol = [f for f in a.findings if f.kind == "simplex-violation"]
    assert len(viol) == 1 and viol[0].severity == "error"
    assert viol[0].frames[:2] == ["host:0", "host:1"]


def test_recovery_careful_vs_blind(tmp_path: Path) -> None:
    careful = simplex([
        (b"!0@\r", b"0,5\r"), (b"!0C10,0,0\r", b"0\r"), (b"!0C20,0,0\r", b"x\r"),
        (b"!0>\r", b"!0C20,0,0\r0\r"), (b"!0C30,0,0\r", b""), (b"!0@\r", b"0,7\r"),
        (b"!0C30,0,0\r", b"0\r"), (b"!0P4\r", b"0,60,0,0,0\r"), (b"!0P4\r", b"0,60,0,0,0\r"),
    ], think=0.3)
    a = analyze(record(tmp_path / "careful.mcap", careful))
    k = a.metrics["finding_counts"]
    assert k.get("repeat-used") == 1 and k.get("index-checked") == 1
    assert not a.hazards()
    blind = simplex([
        (b"!0C10,0,0\r", b"0\r"), (b"!0C20,0,0\r", b"0,?\r"), (b"!0C20,0,0\r", b"0\r"),
        (b"!0P4\r", b"0,50,0,0,0\r"), (b"!0P4\r", b"0,50,0,0,0\r"),
    ])
    b = analyze(record(tmp_path / "blind.mcap", blind))
    kb = b.metrics["finding_counts"]
    assert kb.get("blind-resend") == 1 and kb.get("double-move") == 1
    dm = [f for f in b.findings if f.kind == "double-move"][0]
    assert dm.row == 1 and dm.severity == "hazard"


def test_refused_vector_then_moved_on_is_a_confirmed_loss(tmp_path: Path) -> None:
    p = record(tmp_path / "l.mcap", simplex([
        (b"!0C10,0,0\r", b"0\r"), (b"!0C20,0,0\r", b"5\r"), (b"!0C30,0,0\r", b"0\r"),
    ]))
    a = analyze(p)
    lost = [f for f in a.findings if f.kind == "lost-vector"]
    assert len(lost) == 1 and lost[0].extra["confirmed"] is True


def test_queue_full_polling_and_error_code_context(tmp_path: Path) -> None:
    pairs = [(b"!0C10,0,0\r", b"1\r")] * 5 + [(b"!0C10,0,0\r", b"0\r"), (b"!0V0\r", b"5\r")]
    a = analyze(record(tmp_path / "q.mcap", simplex(pairs, think=0.0)))
    q = [f for f in a.findings if f.kind == "queue-full-polling"]
    assert len(q) == 1 and q[0].extra["polls"] == 5 and q[0].extra["runs"] == 1
    assert q[0].extra["pattern"] == "immediate"
    err = [f for f in a.findings if f.kind == "error-code"]
    assert len(err) == 1 and "out of range" in err[0].message or "parameter" in err[0].message


def test_packets_long_wait_reset(tmp_path: Path) -> None:
    packet = b"!0*S\r!0C10,0,0\r!0C20,0,0\r!0*E2\r"
    script = simplex([(packet, b"0,2\r"), (b"!0H\r", b"8\r")])
    script[-1] = ("unit", b"8\r", script[-1][2] + 0.3)  # HALT answers after braking
    script += simplex([(b"!0J\r", b"0\r")], start=script[-1][2] + 0.001)
    a = analyze(record(tmp_path / "p.mcap", script))
    ex = a.exchanges
    assert ex["packet_role"].tolist()[:4] == ["start", "member", "member", "end"]
    assert a.metrics["vectors_accepted"] == 2
    k = a.metrics["finding_counts"]
    assert k.get("long-wait") == 1 and k.get("reset") == 1


@pytest.mark.parametrize("given", ["folder", "stream"])
def test_a_second_pass_writes_the_tables_once(tmp_path: Path, given: str) -> None:
    """A capture re-timed at the estimated baud is decoded twice; its Parquet tables hold
    the second pass's rows only, whether ``parquet`` is a folder or a stream (a fleet's)."""
    import pyarrow.parquet as pq

    from conform.analysis.tables import ParquetStream

    pairs = [(b"!0C100,0,0\r", b"0\r"), (b"!0PF\r", b"0,100,0,0\r")] * 30
    p = record(tmp_path / "b.mcap", simplex(pairs), baud=9600)
    out = tmp_path / "tables"
    a = analyze(p, parquet=out if given == "folder" else ParquetStream(out))
    assert a.baud == 115200  # re-timed: a second pass
    for name, n in (("exchanges", len(a.exchanges)), ("frames_host", len(a.exchanges))):
        assert pq.read_table(out / f"{name}.parquet").num_rows == n == 60


def test_garbage_half_frames_and_unsolicited(tmp_path: Path) -> None:
    script = [("unit", b"\x00\xff0\r", 0.0005), ("host", b"\xfe\xfegarbage\r", 0.001),
              ("host", b"!0C1,0,0\r", 0.002), ("unit", b"0\r", 0.003),
              ("host", b"!0C2,0", 0.004)]
    a = analyze(record(tmp_path / "g.mcap", script))
    k = a.metrics["finding_counts"]
    assert k.get("garbage-sent") == 1
    assert k.get("unsolicited-answer") == 1 or k.get("garbled-answer") == 1
    assert a.exchanges["status"].tolist() == ["silent", "answered", "partial"]


def test_wrong_baud_guess_is_detected(tmp_path: Path) -> None:
    pairs = [(b"!0C100,0,0\r", b"0\r"), (b"!0PF\r", b"0,100,0,0\r"),
             (b"!0F\r", b"0,00\r")] * 30
    p = record(tmp_path / "b.mcap", simplex(pairs), baud=9600)
    a = analyze(p)
    assert a.metrics["finding_counts"].get("baud-mismatch") == 1
    assert a.baud == 115200
    slow = [(c, a_) for c, a_ in pairs]
    script = []
    t = 0.0
    for c, ans in slow:  # really at 19200 while the capture claims 115200
        t += len(c) * 10 / 19200
        script.append(("host", c, t))
        t += 0.001 + len(ans) * 10 / 19200
        script.append(("unit", ans, t))
        t += 0.002
    b = analyze(record(tmp_path / "b2.mcap", script, baud=115200))
    assert b.baud == 19200


def test_truncated_capture_is_analysed_as_far_as_it_goes(tmp_path: Path) -> None:
    pairs = [(b"!0C%d,0,0\r" % i, b"0\r") for i in range(3000)]
    full = record(tmp_path / "full.mcap", simplex(pairs))
    data = full.read_bytes()
    # cut inside the chunk that holds the session's middle: where a fixed fraction of the file
    # falls, or what the last chunk holds, follows how the recorder's writer thread happened to
    # gather the chunks (the indexes and summary after them can be a third of the file, and
    # the record written at close can be a chunk of its own)
    with full.open("rb") as f:
        chunks = list(make_reader(f).get_summary().chunk_indexes)
    first = min(c.message_start_time for c in chunks)
    middle = (first + max(c.message_end_time for c in chunks)) // 2
    mid = min((c for c in chunks if c.message_end_time >= middle),
              key=lambda c: c.message_end_time)
    assert mid.message_start_time > first, "the session's first half is in chunks before it"
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: mid.chunk_start_offset + mid.chunk_length // 2])
    a = analyze(cut)
    assert not a.raw.status.complete
    assert 0 < len(a.exchanges) < 3000
    assert a.metrics["finding_counts"].get("capture-damaged", 0) >= 1


def test_foreign_capture_without_metadata(tmp_path: Path) -> None:
    p = record(tmp_path / "f.mcap", simplex([(b"!0C1,0,0\r", b"0\r")]), baud=None,
               variant=None)
    a = analyze(p)
    assert a.variant.id == "gve64-v19" and any("no variant" in n for n in a.notes)
    assert a.metrics["vectors_accepted"] == 1


def test_cli_reports_and_not_mcap(tmp_path: Path) -> None:
    p = record(tmp_path / "a.mcap", simplex([(b"!0C1,0,0\r", b"0\r"), (b"!0C2,0,0\r", b"x\r"),
                                             (b"!0C2,0,0\r", b"0\r")]))
    out = tmp_path / "rep"
    r = CliRunner().invoke(cli, ["analyze", str(p), "--report", str(out), "--parquet",
                                 str(tmp_path / "pq")])
    assert r.exit_code == 0, r.output
    assert "blind-resend" in r.output
    doc = json.loads((out / "findings.json").read_text())
    assert {"findings", "metrics"} <= set(doc)
    f = doc["findings"][0]
    assert {"kind", "t", "severity", "message"} <= set(f)
    html = (out / "index.html").read_text()
    assert "data:image/png;base64," in html and "http://" not in html.replace(
        "http://www.w3.org", "")
    assert (out / "summary.md").read_text().startswith("# Session analysis")
    assert (tmp_path / "pq" / "exchanges.parquet").exists()
    bad = tmp_path / "x.mcap"
    bad.write_text("hello")
    from conform.cli.main import main

    with pytest.raises(SystemExit) as exc:
        main(["analyze", str(bad)])
    assert exc.value.code != 0
    with pytest.raises(UserError, match="not an MCAP"):
        analyze(bad)


def test_report_and_parquet_api(tmp_path: Path) -> None:
    src = Path(__file__).resolve().parent.parent / "captures" / "usb-packets.mcap"
    if not src.exists():
        pytest.skip("sample captures not generated")
    p = tmp_path / "u.mcap"
    shutil.copy(src, p)
    a = analyze(p, whatif_replays=False)
    paths = write_report(a, tmp_path / "r")
    assert paths["html"].stat().st_size > 10_000
    tables = write_parquet(a, tmp_path / "pq")
    import pandas as pd

    ex = pd.read_parquet(tables["exchanges"])
    assert len(ex) == len(a.exchanges)


@pytest.mark.slow
def test_report_plots_over_time_and_time_range(tmp_path: Path) -> None:
    from conform.analysis.plots import all_plots
    from conform.cli.main import main

    src = Path(__file__).resolve().parent.parent / "captures" / "careless-noisy.mcap"
    a = analyze(src)
    plots = all_plots(a)
    assert {"latency", "latency_time", "throughput", "queue", "path"} <= set(plots)
    a.time_range = (2.0, 6.0)
    zoomed = all_plots(a)
    assert zoomed["latency_time"] != plots["latency_time"]
    with pytest.raises(SystemExit) as exc:
        main(["analyze", str(src), "--time-range", "9:3"])
    assert exc.value.code == 2


def test_parquet_streams_in_row_groups(tmp_path: Path) -> None:
    """Tables are written a row group at a time: the slice size changes the row groups,
    never the table; repeating text comes back categorical."""
    import pandas as pd
    import pyarrow.parquet as pq

    src = Path(__file__).resolve().parent.parent / "captures" / "careless-noisy.mcap"
    a = analyze(src, whatif_replays=False)
    small = write_parquet(a, tmp_path / "small", row_group=97)
    big = write_parquet(a, tmp_path / "big")
    assert set(small) == set(big) >= {"exchanges", "frames_host", "frames_unit", "series",
                                      "queue_depth"}
    for name in small:
        x, y = pd.read_parquet(small[name]), pd.read_parquet(big[name])
        pd.testing.assert_frame_equal(x, y)
        n = len(x)
        assert pq.ParquetFile(small[name]).num_row_groups == max(1, -(-n // 97))
    ex = pd.read_parquet(big["exchanges"])
    assert len(ex) == len(a.exchanges)
    assert isinstance(ex["name"].dtype, pd.CategoricalDtype)
    assert isinstance(ex["status"].dtype, pd.CategoricalDtype)
    assert ex["command"].iloc[1] == a.host_text(1)
    t = ex["t_cmd_first"].to_numpy()
    assert np.allclose(t, a.exchanges["t_cmd_first"].to_numpy() - a.t0, equal_nan=True)


def _figure_of(monkeypatch: pytest.MonkeyPatch, draw, a):  # noqa: ANN001
    """The matplotlib figure ``draw(a)`` makes (kept instead of turned into a PNG)."""
    from conform.families.gve.analysis import plots

    kept = []
    monkeypatch.setattr(plots, "to_png", lambda fig: kept.append(fig) or "png")
    assert draw(a) == "png"
    return kept[0]


def test_latency_cdf_shows_the_slowest_host_turnaround(monkeypatch: pytest.MonkeyPatch) -> None:
    """A long session with one host turnaround of 500 ms among 2 ms ones: thinning the
    CDF for drawing keeps it and the axis reaches beyond it (it was cut off)."""
    import pandas as pd

    from conform.analysis.plots import MAX_POINTS
    from conform.families.gve.analysis.plots import latency_plots

    n = 2 * MAX_POINTS + 1   # thinned to every 3rd point: the last one fell out
    host = np.full(n, 0.002)
    host[n // 2] = 0.5
    ex = pd.DataFrame({"status": "answered", "rtt": np.full(n, 0.002),
                       "unit_time": np.full(n, 0.0003), "host_time": host})

    class Whole:
        whole = True
        exchanges = ex

    fig = _figure_of(monkeypatch, latency_plots, Whole())
    cdf = fig.axes[1]
    line, = (ln for ln in cdf.get_lines() if ln.get_label() == "host turnaround")
    assert max(line.get_xdata()) == pytest.approx(500.0)
    assert cdf.get_xlim()[1] > 500.0


def test_path_plot_leaves_the_path_visible_on_a_long_job(monkeypatch: pytest.MonkeyPatch
                                                          ) -> None:
    """usb-latency's circle has 475 junctions and 167 stops: junctions are not dotted (only
    a few are), stops are thinned to at most MARKERS and the legend says so."""
    from conform.families.gve.analysis.plots import MARKERS, path_plot

    a = analyze(str(Path(__file__).resolve().parent.parent / "captures" / "usb-latency.mcap"))
    fig = _figure_of(monkeypatch, path_plot, a)
    lines = fig.axes[0].get_lines()
    labels = [ln.get_label() for ln in lines]
    assert not any(lb.startswith("junction") for lb in labels), labels
    marked = [ln for ln in lines if ln.get_marker() not in ("None", None, "")]
    assert marked and all(len(ln.get_xdata()) <= MARKERS for ln in marked)
    assert sum(len(ln.get_xdata()) for ln in marked) < 200
    stopped, = (lb for lb in labels if lb.startswith("stopped"))
    assert stopped == "stopped (167, 1 in 2 drawn)"
