"""What a command writes is checked before it starts: a recorded capture is never replaced
without --force, a report folder that cannot be written and a link path taken by a file are one
line and exit 2 — never a traceback, never a lost file."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from conform.cli.main import main

REPO = Path(__file__).resolve().parent.parent
GOOD = str(REPO / "captures" / "good-rs232.mcap")
JOB = str(REPO / "captures" / "jobs" / "part.nc")
PRECIOUS = b"a session recorded yesterday"
# a folder nobody may write, root included (sysfs), and one that cannot be created there
LOCKED, UNCREATABLE = "/sys", "/sys/conform-report"


def _one_line(argv, capsys, code=2):
    with pytest.raises(SystemExit) as info:
        main(argv)
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert info.value.code == code, (out, err)
    assert len(lines) == 1 and lines[0].startswith("conform: "), err
    return lines[0]


@pytest.mark.parametrize("argv, option", [
    (["proxy", "--unit", "/dev/null", "-o", "{f}"], "-o"),
    (["sniff", "--host-port", "/dev/null", "--unit-port", "/dev/zero", "-o", "{f}"], "-o"),
    (["send", JOB, "--target", "emu:gve64-v19", "--record", "{f}"], "--record"),
    (["emulate", "gve64-v19", "--record", "{f}"], "--record"),
], ids=["proxy", "sniff", "send", "emulate"])
def test_an_existing_capture_is_refused_without_force(argv, option, tmp_path, capsys):
    kept = tmp_path / "session.mcap"
    kept.write_bytes(PRECIOUS)
    line = _one_line([a.replace("{f}", str(kept)) for a in argv], capsys)
    assert f"{option} {kept}: the file exists" in line and "--force" in line
    assert kept.read_bytes() == PRECIOUS
    assert sorted(p.name for p in tmp_path.iterdir()) == ["session.mcap"]


def test_force_replaces_the_capture(tmp_path, capsys):
    from conform.capture.reader import open_capture

    kept = tmp_path / "session.mcap"
    kept.write_bytes(PRECIOUS)
    with pytest.raises(SystemExit) as info:
        main(["send", JOB, "--target", "emu:gve64-v19", "--record", str(kept), "--force"])
    assert info.value.code == 0, capsys.readouterr()
    assert open_capture(kept).clean and open_capture(kept).stream("host")


def test_proxy_link_onto_a_file_is_refused(tmp_path, capsys):
    taken = tmp_path / "sender.pty"
    taken.write_bytes(PRECIOUS)
    line = _one_line(["proxy", "--unit", "/dev/null", "-o", str(tmp_path / "new.mcap"),
                      "--link", str(taken)], capsys)
    assert f"--link {taken}: a file is there" in line
    assert taken.read_bytes() == PRECIOUS and not (tmp_path / "new.mcap").exists()


def test_sniff_refuses_the_same_port_twice(tmp_path, capsys):
    line = _one_line(["sniff", "--host-port", "/dev/null", "--unit-port", "/dev/null", "-o",
                      str(tmp_path / "s.mcap")], capsys)
    assert "--host-port and --unit-port are both /dev/null" in line


@pytest.mark.skipif(not os.path.isdir(LOCKED), reason="needs sysfs")
@pytest.mark.parametrize("argv, folder, says", [
    (["analyze", GOOD, "--report", LOCKED], LOCKED, "cannot write there"),
    (["analyze", GOOD, "--report", UNCREATABLE], UNCREATABLE, "cannot create the folder"),
    (["analyze", str(REPO / "captures"), "--report", LOCKED], LOCKED, "cannot write there"),
    (["analyze", GOOD, "--parquet", UNCREATABLE], UNCREATABLE, "cannot create the folder"),
    (["check-sender", "--report", UNCREATABLE, "--", "true", "{port}"], UNCREATABLE,
     "cannot create"),
    (["check-sender", "--variant", "grbl-1.1f", "--report", LOCKED, "--", "true", "{port}"],
     LOCKED,
     "cannot write there"),
    (["run", "--report", LOCKED, "--check", "*/V/valid"], LOCKED, "cannot write there"),
], ids=["analyze-file", "analyze-new-folder", "analyze-fleet", "analyze-parquet",
        "check-sender", "check-sender-grbl", "run"])
def test_a_report_folder_that_cannot_be_written_is_one_line(argv, folder, says, capsys):
    line = _one_line(argv, capsys)
    assert folder in line and says in line, line
