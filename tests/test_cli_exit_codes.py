"""The README's exit-status table, row by row: what CI reads from each command. Rows a slower
test already holds name it: run stopped early (test_cli_run), every signal (test_stops), the
refused outputs (test_cli_outputs), check-sender's 0 and 1 (test_check_sender), proxy and
sniff ending on a signal (test_capture_live)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conform.cli.main import main

REPO = Path(__file__).resolve().parent.parent
GOOD = str(REPO / "captures" / "good-rs232.mcap")          # a clean session, some warnings
NOISY = str(REPO / "captures" / "careless-noisy.mcap")     # hazards
JOB = str(REPO / "captures" / "jobs" / "part.nc")


def _code(argv: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as info:
        main(argv)
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return info.value.code, out, err


def _truncated(tmp_path: Path, keep: int) -> str:
    part = tmp_path / "cut.mcap.part"
    part.write_bytes(Path(GOOD).read_bytes()[:keep])
    return str(part)


# -- run ------------------------------------------------------------------------------------------

def test_run_0_when_nothing_fails(tmp_path, capsys):
    code, _, err = _code(["run", "--check", "*/V/valid", "--no-machine", "-q", "--report",
                          str(tmp_path / "r")], capsys)
    assert code == 0, err


def test_run_1_when_a_check_fails(tmp_path, capsys):
    code, out, err = _code(["run", "--target", "emu:gve64-v19:v-range-code", "--no-machine",
                            "-q", "--report", str(tmp_path / "r")], capsys)
    assert code == 1 and "  FAIL " in out, err


@pytest.mark.slow
def test_run_2_when_a_check_could_not_be_run(tmp_path, emulate):
    """--inputs-control naming no socket: the checks needing inputs are ERRORs, not passes."""
    _, pty = emulate("serve", "gve64-v19", "--baud", "115200")
    run = subprocess.run([sys.executable, "-m", "conform", "run", "--target", pty,
                          "--inputs-control", str(tmp_path / "no.sock"), "--check",
                          "*/SR/interrupt", "--no-machine", "--allow-motion", "--max-steps",
                          "2000", "-q", "--report", str(tmp_path / "r")],
                         capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(REPO)})
    assert run.returncode == 2, run.stderr
    assert re.search(r"ERROR \S+/SR/interrupt: could not be run: --inputs-control", run.stdout)
    assert (tmp_path / "r" / "results.json").exists()


# -- check-sender ---------------------------------------------------------------------------------

@pytest.mark.parametrize("args, says", [
    (["--", "true"], "no {port} in `true`"),
    (["--timeout", "0", "--", "true", "{port}"], "--timeout 0: seconds, more than 0 and at most"),
    (["--variant", "grbl-1.1f", "--", "true"], "no {port} in `true`"),
    (["--job", JOB, "--", "true", "{port}"], "is it a job of another family?"),   # g-code
    (["--variant", "grbl-1.1f", "--job", str(REPO / "captures" / "jobs" / "raster.txt"), "--",
      "true", "{port}"], "no line of it is a move a grbl unit executes"),     # GVE vectors
])
def test_check_sender_2_for_a_usage_mistake(args, says, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, _, err = _code(["check-sender", *args], capsys)
    assert code == 2 and err.count("\n") == 1 and says in err, err
    assert not list(tmp_path.iterdir()), "no session was started"


# -- send, characterize ---------------------------------------------------------------------------

def test_send_0_when_every_line_is_acknowledged(capsys):
    code, out, _ = _code(["send", JOB, "--target", "emu:gve64-v19"], capsys)
    assert code == 0 and "final position: (0, 0, 0, 0)" in out


def test_send_1_when_the_send_is_incomplete(capsys):
    code, _, err = _code(["send", JOB, "--target", "emu:gve64-v19", "--policy", "careless",
                          "--corrupt-command", "5,30,60"], capsys)
    assert code == 1 and "send incomplete" in err, err


def test_characterize_0_when_the_profile_is_written(tmp_path, capsys):
    out = tmp_path / "unit.toml"
    code, _, err = _code(["characterize", "emu:gve64-v19", "-o", str(out)], capsys)
    assert code == 0 and out.read_text().startswith("# conform characterisation profile"), err


# -- analyze --------------------------------------------------------------------------------------

@pytest.mark.parametrize("args, code", [
    ([GOOD], 0),
    ([NOISY], 0),                              # the default, --fail-on never: findings alone
    ([NOISY, "--fail-on", "hazard"], 1),
    ([GOOD, "--fail-on", "hazard"], 0),        # no hazard in a good session
    ([GOOD, "--fail-on", "warning"], 1),       # but a warning (a garbled answer)
], ids=["clean", "hazards-default", "hazards-fail-on-hazard", "clean-fail-on-hazard",
        "clean-fail-on-warning"])
def test_analyze_fails_on_findings_only_when_asked(args, code, capsys):
    got, out, err = _code(["analyze", *args], capsys)
    assert got == code, err
    if code:
        assert "(--fail-on)" in err


def test_analyze_1_for_a_damaged_capture(tmp_path, capsys):
    code, out, _ = _code(["analyze", _truncated(tmp_path, 60_000)], capsys)
    assert code == 1 and "capture damaged" in out


def test_analyze_2_for_traffic_of_another_family(capsys):
    code, _, err = _code(["analyze", GOOD, "--variant", "grbl-1.1f"], capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert "this is not grbl traffic" in err and "GVE command lines" in err


def test_analyze_several_captures_fail_on_hazards(capsys):
    code, _, err = _code(["analyze", GOOD, NOISY, "--fail-on", "hazard", "--jobs", "1"], capsys)
    assert code == 1 and "hazard(s) (--fail-on)" in err
    code, _, err = _code(["analyze", GOOD, NOISY, "--fail-on", "warning"], capsys)
    assert code == 2 and "--fail-on warning" in err


# -- capture --------------------------------------------------------------------------------------

def test_capture_info_0_clean_1_truncated(tmp_path, capsys):
    assert _code(["capture", "info", GOOD], capsys)[0] == 0
    code, out, _ = _code(["capture", "info", _truncated(tmp_path, 60_000)], capsys)
    assert code == 1 and "truncated" in out


def test_capture_recover_0_after_a_salvage_1_when_nothing_is_left(tmp_path, capsys):
    code, out, _ = _code(["capture", "recover", _truncated(tmp_path, 60_000)], capsys)
    assert code == 0 and "messages salvaged" in out and "lost: " in out
    assert (tmp_path / "cut.mcap").exists()
    code, out, _ = _code(["capture", "recover", _truncated(tmp_path, 300), "-o",
                          str(tmp_path / "nothing.mcap")], capsys)
    assert code == 1 and "0 messages salvaged" in out


# -- emulate control, spec, profile, report, ports ------------------------------------------------

def test_emulate_control_0_ok_1_refused(tmp_path, capsys, emulate):
    sock = str(tmp_path / "emu.sock")
    emulate("serve", "gve64-v19", "--control", sock)
    code, out, _ = _code(["emulate", "control", sock, "press", "stop"], capsys)
    assert code == 0 and out.startswith("ok")
    code, out, _ = _code(["emulate", "control", sock, "press", "no-such-input"], capsys)
    assert code == 1 and out.startswith("error")


def test_spec_check_0_valid_2_for_a_bad_row(tmp_path, capsys):
    tables = REPO / "specs" / "gve"
    assert _code(["spec", "check", "--specs", str(tables)], capsys)[0] == 0
    bad = tmp_path / "tables"
    shutil.copytree(tables, bad)
    with open(bad / "commands.toml", "a", encoding="utf-8") as f:
        f.write("\ngarbage = [\n")
    code, _, err = _code(["spec", "check", "--specs", str(bad)], capsys)
    assert code == 2 and "commands.toml" in err


def test_profile_diff_0_same_1_different(tmp_path, capsys):
    a = tmp_path / "a.toml"
    assert _code(["characterize", "emu:gve64-v19", "-o", str(a)], capsys)[0] == 0
    b = tmp_path / "b.toml"
    text = a.read_text()
    b.write_text(re.sub(r'^A10 = ".*"$', 'A10 = "every-line"', text, flags=re.M))
    assert _code(["profile", "diff", str(a), str(a)], capsys)[0] == 0
    code, out, _ = _code(["profile", "diff", str(a), str(b)], capsys)
    assert code == 1 and "A10" in out


def test_report_and_ports_0(tmp_path, capsys):
    assert _code(["run", "--check", "*/V/valid", "--no-machine", "-q", "--report",
                  str(tmp_path / "r")], capsys)[0] == 0
    code, _, err = _code(["report", str(tmp_path / "r" / "results.json"), "-o",
                          str(tmp_path / "again")], capsys)
    assert code == 0 and (tmp_path / "again" / "index.html").exists(), err
    assert _code(["ports"], capsys)[0] == 0


def test_the_top_level_help_names_every_family(capsys):
    from conform.families import families

    code, out, _ = _code(["--help"], capsys)
    assert code == 0
    text = " ".join(out.split())
    for fam in families():
        assert fam.name in text
        for v in fam.variants():
            assert v.id in text, v.id
    assert "130 Ctrl-C, 143 SIGTERM, 129 SIGHUP" in text


def test_run_matrix_keeps_the_target_given(tmp_path, capsys):
    """--matrix with --target: the target is run beside every variant's emulator, not dropped."""
    import json

    code, out, err = _code(["run", "--matrix", "--target", "emu:gve64-v19:v-range-code",
                            "--check", "*/V/*", "--no-machine", "-q", "--json", "--report",
                            str(tmp_path / "r")], capsys)
    assert code == 1, err   # the deviant unit's FAIL is there
    targets = [r["target"] for r in json.loads(out)["runs"]]
    assert targets[0] == "emu:gve64-v19:v-range-code"
    assert {"emu:gve64-v10", "emu:gve124"} <= set(targets)
