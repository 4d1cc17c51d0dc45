"""The README's recording walk-through, as a user runs it: emulator, proxy, sender, analysis;
the proxy says what it records and how much, off a terminal too."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.slow


def _conform(*args: str, **kw):
    env = {**os.environ, "PYTHONPATH": str(REPO), "CONFORM_PROGRESS_SECONDS": "0.2"}
    return subprocess.Popen([sys.executable, "-m", "conform", *args], env=env, text=True, **kw)


def test_proxy_records_a_send_and_says_so(tmp_path):
    unit, sender = tmp_path / "gve.pty", tmp_path / "sender.pty"
    job = tmp_path / "job.txt"
    job.write_text("V20000\nA200\n" + "C20,0,0\nC0,20,0\n" * 10)
    emu = _conform("emulate", "serve", "gve64-v19", "--baud", "115200", "--link", str(unit),
                   stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    proxy = None
    try:
        assert emu.stdout.readline().strip() == str(unit)
        proxy = _conform("proxy", "--unit", str(unit), "-o", str(tmp_path / "session.mcap"),
                         "--link", str(sender), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        assert proxy.stdout.readline().strip()  # the sender's pty
        send = _conform("send", str(job), "--target", str(sender), "--allow-motion",
                        stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        out, err = send.communicate(timeout=120)
        assert send.returncode == 0, err
        assert "sent 22 job lines" in out
        time.sleep(0.5)  # at least two progress lines of the proxy
        proxy.send_signal(signal.SIGINT)
        _, perr = proxy.communicate(timeout=60)
        assert proxy.returncode == 0, perr
    finally:
        for p in (proxy, emu):
            if p is not None and p.poll() is None:
                p.terminate()
                p.wait(10)
    lines = perr.splitlines()
    assert lines[0].startswith("conform proxy: recording ") and "(Ctrl-C to stop)" in lines[0]
    counts = [x for x in lines if x.startswith("conform proxy: recording — host ")]
    assert counts and "unit " in counts[-1]
    assert lines[-1] == f"conform proxy: recorded {tmp_path / 'session.mcap'}"
    analyze = _conform("analyze", str(tmp_path / "session.mcap"), "--json",
                       stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    aout, aerr = analyze.communicate(timeout=120)
    assert analyze.returncode == 0, aerr
    import json

    assert json.loads(aout)["metrics"]["exchanges"] >= 22  # the job and the reads around it
