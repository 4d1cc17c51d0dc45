"""A report's replay command re-runs the check as it was run: on a real unit the options the
check depends on (--allow-motion, --max-steps, --allow-eeprom, --inputs-control, --baud,
--dialect) are kept, or the replay would only SKIP; and a replay leaves reports/latest alone."""

from __future__ import annotations

import json
import os
import shlex

import pytest

from conform.cli.main import main
from conform.conformance.results import CheckResult, Grade
from conform.report.view import replay_command

RUN = ("conform run --target /dev/ttyUSB0 --allow-motion --max-steps 2000 --allow-eeprom "
       "--inputs-control /tmp/emu.sock --baud=57600 --check '*/L/*' -q --report out")


def test_replay_keeps_the_options_the_check_depends_on():
    c = CheckResult(id="gve64-v19/13.5.9/L/position-1", clause="§13.5.9", level="MUST",
                    title="L", grade=Grade.FAIL, target="/dev/ttyUSB0", variant="gve64-v19")
    argv = shlex.split(replay_command(c, RUN))
    assert argv[:8] == ["conform", "run", "--target", "/dev/ttyUSB0", "--variant", "gve64-v19",
                        "--replay", "gve64-v19/13.5.9/L/position-1"]
    rest = argv[8:]
    assert rest == ["--allow-motion", "--max-steps", "2000", "--allow-eeprom",
                    "--inputs-control", "/tmp/emu.sock", "--baud=57600"]
    assert "--check" not in rest and "--report" not in rest   # the run's choice, not the check's


def test_a_replay_leaves_reports_latest_alone(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        main(["run", "--check", "*/V/*", "--no-machine", "-q"])
    assert info.value.code == 0
    latest = os.readlink(tmp_path / "reports" / "latest")
    results = json.loads((tmp_path / "reports" / "latest" / "results.json").read_text())
    check_id = results["checks"][0]["id"]
    with pytest.raises(SystemExit) as info:
        main(["run", "--replay", check_id, "-q"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert os.readlink(tmp_path / "reports" / "latest") == latest
    own = out.split("report: ")[-1].strip()
    assert os.path.exists(own) and "/" + latest + "/" not in own   # its own folder, named


def test_runs_of_the_same_second_keep_their_own_reports(tmp_path, monkeypatch):
    from conform.report import render

    monkeypatch.chdir(tmp_path)
    first = render.default_dir()
    first.mkdir(parents=True)
    second = render.default_dir()
    assert second != first and not second.exists()
