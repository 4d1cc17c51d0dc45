"""Crash safety: SIGKILL a recording process at random moments, then salvage the file."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conform.capture.reader import open_capture
from conform.capture.recover import recover

REPO = Path(__file__).resolve().parents[1]

# A recorder under steady traffic: a command and its answer every 4 ms, each chunk tagged
# with its number so that the test can tell exactly what survived.
CHILD = r"""
import sys, time
from conform.capture.recorder import Recorder
rec = Recorder(sys.argv[1], {"capture_method": "kill-test", "baud": 115200,
                             "variant": "gve64-v19"})
print("ready", rec.now(), flush=True)
i = 0
while True:
    t = rec.now()
    rec.chunk("host", b"!0C%d,0,0\r" % i, t)
    rec.chunk("unit", b"0\r", t + 0.0005)
    i += 1
    time.sleep(0.004)
"""

KILLS = 20
MAX_LOSS = 1.0  # seconds of data a kill may cost


def expected_host(n: int) -> bytes:
    return b"".join(b"!0C%d,0,0\r" % i for i in range(n))


@pytest.mark.slow
@pytest.mark.long(45)
def test_sigkill_at_random_moments_loses_at_most_the_last_second(tmp_path):
    rng = random.Random(20240611)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    for k in range(KILLS):
        path = tmp_path / f"k{k}.mcap"
        proc = subprocess.Popen([sys.executable, "-c", CHILD, str(path)], env=env,
                                stdout=subprocess.PIPE, cwd=REPO)
        line = proc.stdout.readline().decode().split()
        assert line and line[0] == "ready"
        time.sleep(rng.uniform(0.0, 1.6))
        t_kill = time.time()
        proc.send_signal(signal.SIGKILL)
        proc.wait(5)
        part = tmp_path / f"k{k}.mcap.part"
        assert part.exists() and not path.exists()
        res = recover(part)
        cap = open_capture(res.output)
        assert cap.clean, k
        chunks = list(cap.raw_chunks("host"))
        host = b"".join(c["bytes"] for c in chunks)
        # no holes: what survived is exactly the first n commands
        n = host.count(b"\r")
        assert host == expected_host(n), k
        assert [c["offset"] for c in chunks] == [sum(len(x["bytes"]) for x in chunks[:i])
                                                 for i in range(len(chunks))]
        t_ready = float(line[1])
        if t_kill - t_ready > MAX_LOSS + 0.05:
            assert chunks, f"kill {k}: nothing salvaged after {t_kill - t_ready:.2f} s"
            lost = t_kill - chunks[-1]["t_read"]
            assert lost <= MAX_LOSS, f"kill {k}: lost {lost:.3f} s"
        assert cap.metadata["conform.session"]["capture_method"] == "kill-test"
