"""Real grbl senders nobody here wrote, judged against the grbl reference unit on a real pty:
grbl-streamer 2.0.2 (PyPI, the engine of several GUIs) in its two modes, bCNC 0.9.16's sender
engine (PyPI, headless), and a sender behaving as grbl's own doc/script/stream.py (its
behaviour re-implemented in tests/senders/stream_like.py). Each gets the verdict its design
deserves (docs/grbl.md §Real senders), from check-sender and from proxy + analyze:

- grbl-streamer incremental: send-response, one line per answer; clean.
- grbl-streamer default: character counting whose status thread sends $G and $# outside
  the count after grbl's banner: within-buffer FAIL, an rx-overflow-hazard on the wire.
- bCNC: character counting with its $G/$# inside the count: clean (run with
  CONFORM_BCNC_PYTHON=an interpreter that has bCNC; see pyproject.toml's test extra).
- stream.py -s: send-response after a "\\r\\n\\r\\n" wake-up (empty lines are lines, not
  realtime bytes): clean. stream.py's counting mode goes on after ALARM: alarm-stops FAIL.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conform.conformance.results import Grade
from conform.families.grbl.sendercheck.scenarios import default_job, run_scenarios

pytestmark = pytest.mark.slow
SENDERS = Path(__file__).resolve().parent / "senders"
REPO = SENDERS.parent.parent
MUSTS = ("within-buffer", "realtime-out-of-band", "job-in-order", "nothing-lost", "honest-exit")


def judge(tmp_path, script, mode, scenarios=("stream",), moves=60, python=sys.executable,
          timeout=90):
    run, sessions = run_scenarios([python, str(SENDERS / script), "{port}", "{job}",
                                   *([mode] if mode else [])], scenarios=list(scenarios),
                                  timeout=timeout, directory=tmp_path / f"{script}-{mode}",
                                  job=default_job(moves))
    return {c.id.split("/", 2)[2]: c.grade for c in run.checks}, sessions


def test_grbl_streamer_incremental_is_send_response_and_clean(tmp_path):
    pytest.importorskip("grbl_streamer")
    g, (s,) = judge(tmp_path, "grbl_streamer_sender.py", "incremental")
    assert {k: g[f"stream/{k}"] for k in MUSTS} == dict.fromkeys(MUSTS, Grade.PASS)
    assert s.analysis.metrics["streaming_method"] == "send-response"
    assert s.returncode == 0


def test_grbl_streamer_default_overflows_with_its_uncounted_polls(tmp_path):
    pytest.importorskip("grbl_streamer")
    g, (s,) = judge(tmp_path, "grbl_streamer_sender.py", "default")
    assert g["stream/within-buffer"] is Grade.FAIL
    assert s.analysis.metrics["max_bytes_in_flight"] > 128
    assert s.analysis.metrics["streaming_method"] == "character-counting"


def _bcnc_python() -> str:
    """An interpreter with bCNC (its wheel installs top-level ``tests``/``test`` packages that
    would hide this project's tests, so it is kept out of the test extra): $CONFORM_BCNC_PYTHON,
    else this one when it has bCNC."""
    named = os.environ.get("CONFORM_BCNC_PYTHON")
    if named:
        return named
    pytest.importorskip("bCNC", reason="bCNC is not installed (set CONFORM_BCNC_PYTHON)")
    return sys.executable


def test_bcnc_counts_everything_it_sends(tmp_path):
    g, (s,) = judge(tmp_path, "bcnc_sender.py", None, python=_bcnc_python())
    assert {k: g[f"stream/{k}"] for k in MUSTS} == dict.fromkeys(MUSTS, Grade.PASS)
    assert s.analysis.metrics["streaming_method"] == "character-counting"
    assert s.analysis.metrics["max_bytes_in_flight"] <= 128


def test_stream_py_settings_mode_is_send_response_despite_its_wake_up(tmp_path):
    g, sessions = judge(tmp_path, "stream_like.py", "settings", ("stream", "slow-link"))
    for scenario in ("stream", "slow-link"):
        assert {k: g[f"{scenario}/{k}"] for k in MUSTS} == dict.fromkeys(MUSTS, Grade.PASS)
    assert all(s.analysis.metrics["streaming_method"] == "send-response" for s in sessions)


def test_stream_py_counting_mode_streams_on_after_an_alarm(tmp_path):
    g, _ = judge(tmp_path, "stream_like.py", "counting", ("stream", "alarm"))
    assert {k: g[f"stream/{k}"] for k in MUSTS} == dict.fromkeys(MUSTS, Grade.PASS)
    assert g["alarm/alarm-stops"] is Grade.FAIL


@pytest.mark.long(74)
def test_stream_py_counting_mode_fails_only_where_stream_py_really_does(tmp_path):
    """Every scenario, at 115 200 Bd and on the slow link: stream.py's counting mode keeps
    within the buffer and loses nothing (its wake-up's answers are its own, however late the
    banner arrives); it FAILs only where stream.py itself goes wrong: it streams on after an
    ALARM, and an answer lost or damaged on the way leaves it waiting for ever."""
    from conform.families.grbl.sendercheck.scenarios import SCENARIOS

    g, _ = judge(tmp_path, "stream_like.py", "counting", tuple(SCENARIOS), timeout=25)
    failed = {k for k, v in g.items() if v is Grade.FAIL}
    assert failed == {"alarm/alarm-stops", "lost-answers/terminates",
                      "garbled-answers/terminates"}, {k: g[k] for k in failed}
    for scenario in ("stream", "slow-link"):
        assert {k: g[f"{scenario}/{k}"] for k in MUSTS} == dict.fromkeys(MUSTS, Grade.PASS)


def _conform(*args: str, **kw):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.Popen([sys.executable, "-m", "conform", *args], env=env, text=True, **kw)


@pytest.mark.parametrize(("mode", "method", "hazard"), [("incremental", "send-response", False),
                                                         ("default", "character-counting", True)])
def test_grbl_streamer_through_proxy_then_analyze(tmp_path, mode, method, hazard):
    """conform emulate serve + conform proxy + the real sender, then conform analyze --json."""
    pytest.importorskip("grbl_streamer")
    unit, sender = tmp_path / "grbl.pty", tmp_path / "sender.pty"
    job = tmp_path / "job.gcode"
    # at F1000 (not the default job's F3000) the moves outlast the lines: the planner fills
    # and its oks pace the sender, so a counting sender is ahead on the wire even when a
    # loaded machine slows it down (at F3000 it could fall behind the moves and look
    # send-response, which the analysis would then rightly call it)
    job.write_text("\n".join(x.replace("F3000", "F1000") for x in default_job(60)) + "\n")
    cap = tmp_path / "session.mcap"
    emu = _conform("emulate", "serve", "grbl-1.1f", "--link", str(unit),
                   stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    proxy = None
    try:
        assert emu.stdout.readline().strip() == str(unit)
        proxy = _conform("proxy", "--unit", str(unit), "-o", str(cap), "--link", str(sender),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        assert proxy.stdout.readline().strip()
        run = subprocess.run([sys.executable, str(SENDERS / "grbl_streamer_sender.py"),
                              str(sender), str(job), mode], capture_output=True, text=True,
                             timeout=120)
        assert run.returncode == 0, run.stderr[-2000:]
        time.sleep(0.3)
        proxy.send_signal(signal.SIGINT)
        proxy.communicate(timeout=60)
    finally:
        for p in (proxy, emu):
            if p is not None and p.poll() is None:
                p.terminate()
                p.wait(10)
    a = subprocess.run([sys.executable, "-m", "conform", "analyze", str(cap), "--json"],
                       capture_output=True, text=True, timeout=120)
    assert a.returncode == 0, a.stderr
    doc = json.loads(a.stdout)
    assert doc["metrics"]["streaming_method"] == method
    kinds = {f["kind"]: f["severity"] for f in doc["findings"]}
    assert ("rx-overflow-hazard" in kinds) is hazard
    if hazard:
        assert kinds["rx-overflow-hazard"] == "hazard"
