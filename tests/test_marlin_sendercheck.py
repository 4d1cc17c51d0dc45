"""check-sender for Marlin against real programs over a pty: a careful sender passes every
rule in every scenario; Printrun's printcore (2.2.0, installed headless) is graded as its
source behaves: it waits for ever after a lost ok (printcore._sendnext waits for `clear`, set
only by an answer) and, after the unit resets, answers Marlin's `Resend: 1` by sending the whole
job again from line 1 (printcore._listen takes `start` as a mere greeting)."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

SENDERS = Path(__file__).parent / "senders"


def check_sender(tmp_path, program, *scenarios, timeout=None):
    args = [sys.executable, "-m", "conform", "check-sender", "--variant", "marlin-2.1",
            "--report", str(tmp_path), "--json"]
    for s in scenarios:
        args += ["--scenario", s]
    if timeout:
        args += ["--timeout", str(timeout)]
    p = subprocess.run([*args, "--", sys.executable, str(SENDERS / program), "{port}", "{job}"],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode in (0, 1), p.stderr
    data = json.loads(p.stdout)
    return p.returncode, {c["id"].split("/", 2)[2]: c for c in data["checks"]}


@pytest.mark.slow
@pytest.mark.long(45)
def test_a_careful_sender_passes_every_scenario(tmp_path):
    code, checks = check_sender(tmp_path, "marlin_careful.py")
    bad = {k: c["actual"] for k, c in checks.items() if c["grade"] in ("FAIL", "DEVIATION", "ERROR")}
    assert code == 0 and not bad
    assert checks["noisy/resend-exact"]["grade"] == "PASS"
    assert checks["reset/stops-after-reset"]["grade"] == "PASS"
    truth = json.loads((tmp_path / "noisy" / "truth.json").read_text())
    assert truth["resends"] and not truth["twice"]


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("printrun") is None,
                    reason="printrun not installed (pip install --no-deps printrun==2.2.0)")
def test_printcore_is_graded_as_its_source_behaves(tmp_path):
    code, checks = check_sender(tmp_path, "marlin_printcore.py", "clean", "noisy", "lost-ok",
                                "reset", timeout=15)
    assert code == 1
    assert checks["clean/none-skipped"]["grade"] == "PASS"
    assert checks["noisy/resend-exact"]["grade"] == "PASS"
    assert checks["lost-ok/finishes"]["grade"] == "FAIL"
    assert "still running at the timeout" in checks["lost-ok/finishes"]["actual"]
    assert checks["reset/stops-after-reset"]["grade"] == "FAIL"
    assert checks["reset/none-twice"]["grade"] == "FAIL"
    # on the wire: after the reset the unit asks for line 1 and printcore sends the job again
    out = (tmp_path / "reset" / "program.out").read_text()
    assert "RECV: Resend: 1" in out and "SENT: N1 G1 " in out.split("RECV: Resend: 1", 1)[1]
