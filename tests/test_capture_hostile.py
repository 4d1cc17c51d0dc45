"""A generated hostile-capture corpus against ``capture info``, ``capture recover`` and
``analyze``: one clear line and exit 2, or an honest damaged/truncated status and a non-zero
exit; never a traceback, a signal, a hang or more than 2 GB of RSS.

The whole corpus runs with every command but ``analyze`` (which runs on every third file and
on every content-hostile one) to keep CI time; bench/bench_hostile_captures.py runs all of it
with larger bombs.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hostile_captures import base_files, check_corpus, corpus, intact_info

REPO = Path(__file__).resolve().parent.parent


@pytest.mark.slow
@pytest.mark.long(96)
def test_hostile_corpus(tmp_path):
    paths = corpus(tmp_path / "corpus", bomb_bytes=1 << 30, count=6)
    intact = {name: intact_info(data, tmp_path) for name, data in base_files().items()}
    env = dict(os.environ, PYTHONPATH=str(REPO), CORPUS_TIMEOUT="60")
    counts, failures = check_corpus(paths, intact, tmp_path, env, analyze_every=3)
    assert counts["capture info"]["files"] == len(paths)
    assert not failures, "\n".join(failures[:80])


# -- one regression test per hostile class that once crashed or lied (issue 12) -------------

def test_json_null_payloads_end_in_an_honest_status_not_a_segfault(tmp_path):
    from hostile_captures import run_commands, written

    p = tmp_path / "null.mcap"
    p.write_bytes(written([("/serial/host", b"null", i) for i in range(50)]))
    env = dict(os.environ, PYTHONPATH=str(REPO))
    (r,) = run_commands([["analyze", str(p)]], env)
    assert "signal" not in r and r["exc"] is None
    assert r["code"] == 1 and "unreadable" in r["out"]


def test_lz4_bomb_stops_at_the_size_its_chunk_claims():
    import resource

    from hostile_captures import _bomb_chunk

    from conform.capture.scan import decompress_chunk

    data = _bomb_chunk("lz4", 1 << 30, 1000)
    raw = data[data.index(b"lz4") + 3 + 8:]  # the chunk's records field
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with pytest.raises(ValueError, match="larger than its chunk claims"):
        decompress_chunk("lz4", raw, 1000, 0)
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 200 * 1024


def test_zeroed_first_chunk_opcode_is_damage_not_clean(tmp_path, capsys):
    from hostile_captures import SAMPLE, _records

    from conform.capture.recover import capture_info
    from conform.cli.main import main

    data = bytearray(SAMPLE.read_bytes())
    first = next(pos for pos, op, _ in _records(bytes(data)) if op == 0x06)
    data[first] = 0
    p = tmp_path / "z.mcap"
    p.write_bytes(bytes(data))
    info = capture_info(p)
    assert info.state == "damaged" and "unknown opcode 0x00" in info.status.notes[0]
    with pytest.raises(SystemExit) as ex:
        main(["analyze", str(p)])
    assert ex.value.code == 1 and "capture damaged" in capsys.readouterr().out


def test_hostile_numbers_are_handled_honestly(tmp_path):
    from hostile_captures import _session, written

    from conform.families.gve.analysis import analyze

    p = tmp_path / "baud.mcap"
    p.write_bytes(written(_session(), metadata={"baud": "1e400", "variant": "gve64-v19"}))
    a = analyze(p)
    assert any("not a usable rate" in n for n in a.notes) and a.metrics["baud"]["used"] > 0
    p = tmp_path / "nan.mcap"
    p.write_bytes(written(_session(times=lambda i: float("nan") if i % 3 == 0 else 1.75e9 + i)))
    a = analyze(p)
    # every third read in both directions (10 each) is NaN: timed as the read before it
    assert a.raw.status.bad_times == 20 and "unusable time" in a.raw.status.describe()
    assert np.isfinite(a.exchanges["t_cmd_first"]).all()
