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

import pytest
from hostile_captures import base_files, check_corpus, corpus, intact_info

REPO = Path(__file__).resolve().parent.parent


@pytest.mark.slow
def test_hostile_corpus(tmp_path):
    paths = corpus(tmp_path / "corpus", bomb_bytes=1 << 30, count=6)
    intact = {name: intact_info(data, tmp_path) for name, data in base_files().items()}
    env = dict(os.environ, PYTHONPATH=str(REPO), CORPUS_TIMEOUT="60")
    counts, failures = check_corpus(paths, intact, tmp_path, env, analyze_every=3)
    assert counts["capture info"]["files"] == len(paths)
    assert not failures, "\n".join(failures[:80])
