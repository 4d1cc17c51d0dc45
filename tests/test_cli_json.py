"""``--json``: one JSON document on stdout, the human summary on stderr."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from conform.cli.main import main

REPO = Path(__file__).resolve().parent.parent
CAPTURE = str(REPO / "captures" / "good-rs232.mcap")


def _json(argv, capsys, code=0):
    with pytest.raises(SystemExit) as info:
        main(argv)
    out, err = capsys.readouterr()
    assert info.value.code == code, err
    return json.loads(out), err


def test_run_json(tmp_path, capsys):
    doc, err = _json(["run", "-q", "--json", "--target", "emu:gve64-v10", "--variant",
                      "gve64-v19", "--no-machine", "--check", "*/V/valid", "--check",
                      "*/VL/valid", "--report", str(tmp_path / "r")], capsys, code=1)
    grades = {c["id"]: c["grade"] for c in doc["checks"]}
    assert grades == {"gve64-v19/13.5.3/V/valid": "PASS", "gve64-v19/13.5.3/VL/valid": "FAIL"}
    assert doc["exit"] == 1 and doc["report"] == str(tmp_path / "r")
    assert doc["command"].startswith("conform run -q --json --target emu:gve64-v10 --variant ")
    assert doc["runs"][0]["counts"]["FAIL"] == 1
    assert "FAIL gve64-v19/13.5.3/VL/valid" in err and "report:" in err


def test_run_list_json(capsys):
    doc, _ = _json(["run", "--list", "--json", "--check", "*/C/queue-full"], capsys)
    assert [c["id"] for c in doc["checks"]] == ["gve64-v19/13.5.2/C/queue-full"]


def test_analyze_json(tmp_path, capsys):
    doc, err = _json(["analyze", CAPTURE, "--json", "--no-progress", "--report",
                      str(tmp_path / "a")], capsys)
    assert doc["capture"] == CAPTURE and doc["metrics"]["exchanges"] > 0
    assert doc["report"].endswith("index.html") and isinstance(doc["findings"], list)
    assert "exchanges in" in err


def test_capture_info_json(capsys):
    doc, _ = _json(["capture", "info", CAPTURE, "--json"], capsys)
    assert doc["state"] and doc["bytes"]


def test_spec_json(capsys):
    doc, _ = _json(["spec", "list", "--json"], capsys)
    assert [v["variant"] for v in doc["variants"] if v["family"] == "gve"] == [
        "gve64-v10", "gve64-v19", "gve64-phantom", "gve124"]
    assert [v["variant"] for v in doc["families"]["grbl"]["variants"]] == ["grbl-1.1f"]
    doc, _ = _json(["spec", "show", "gve64-v19", "--json"], capsys)
    assert doc["variant"] == "gve64-v19" and any(c["command"] == "C" for c in doc["commands"])
    doc, _ = _json(["spec", "show", "gve124", "V", "--json"], capsys)
    assert doc["command"] == "V" and "GVE124" in doc["clause"]
    doc, _ = _json(["spec", "diff", "gve64-v19", "gve124", "--json"], capsys)
    assert doc["a"] == "gve64-v19" and doc["differences"]
    assert {"kind", "what", "gve64-v19", "gve124", "clause"} == set(doc["differences"][0])


@pytest.mark.slow
def test_run_json_through_a_pipe_is_pure_json(tmp_path):
    """As a script would use it: stdout parses whole, progress lines stay on stderr."""
    env = {"PYTHONPATH": str(REPO), "CONFORM_PROGRESS_SECONDS": "0.2", "PATH": "/usr/bin:/bin"}
    run = subprocess.run([sys.executable, "-m", "conform", "run", "--json", "--check",
                          "*/13.5/sequences", "--check", "*/V/*"], capture_output=True,
                         text=True, cwd=tmp_path, env=env, timeout=300)
    assert run.returncode == 0, run.stderr
    doc = json.loads(run.stdout)
    assert doc["report"].startswith("reports/") and doc["exit"] == 0
    progress = [x for x in run.stderr.splitlines() if x.startswith("conform run: ")]
    assert progress, run.stderr  # off a terminal: periodic lines naming the check
    assert any("gve64-v19/" in x and "/" in x.split(")")[1] for x in progress)
    assert (tmp_path / "reports" / "latest" / "index.html").exists()
