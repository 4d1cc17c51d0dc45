"""The Marlin reference unit held to the real firmware: every recording of Marlin 2.1.2.4 in
the shared recordings folder (``recordings/marlin-2.1.2.4/``: text transcripts and the two
MCAP sessions) is judged equal by ``conform emulate judge FILE --variant marlin-2.1``, after the
masks ``MarlinFamily.judge_mask`` states (protocol/codec.py mask_volatile) and the tolerance
of ``judge_near`` (positions after a quickstop).

The folder is found at ``../shared/recordings`` next to the repository, or at
``$CONFORM_RECORDINGS``; where it is absent the tests are skipped, except under CI (CI=true),
where a missing folder is a failure."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
FOLDER = "marlin-2.1.2.4"


def _root() -> Path:
    env = os.environ.get("CONFORM_RECORDINGS")
    if env:
        return Path(env)
    for up in (REPO.parent, *REPO.parents):
        candidate = up / "shared" / "recordings"
        if candidate.is_dir():
            return candidate
    return REPO.parent / "shared" / "recordings"


ROOT = _root() / FOLDER
FILES = sorted([*ROOT.glob("*.transcript"), *ROOT.glob("*.mcap")]) if ROOT.is_dir() else []


def _need_folder() -> None:
    if FILES:
        return
    why = f"no recordings of Marlin 2.1.2.4 at {ROOT} (set CONFORM_RECORDINGS)"
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(why)
    pytest.skip(why)


def test_the_folder_is_there_in_ci() -> None:
    _need_folder()
    names = {p.name for p in FILES}
    assert {"send300.mcap", "printcore.mcap"} <= names
    assert len([n for n in names if n.endswith(".transcript")]) >= 4
    assert (ROOT / "VARIANT").read_text().strip() == "marlin-2.1"


@pytest.mark.parametrize("name", [p.name for p in FILES] or ["(none)"])
def test_every_recording_is_judged_equal(name: str) -> None:
    _need_folder()
    from conform.emulator.judge import judge_recording, read_transcript
    from conform.families import family

    verdict = judge_recording(read_transcript(ROOT / name), family("marlin"), "marlin-2.1")
    got = [(d.after_host, d.recorded, d.reference) for d in verdict.differences]
    assert verdict.recorded_lines > 0 and verdict.same == verdict.recorded_lines
    assert verdict.agrees, f"{name}: {verdict.same} of {verdict.recorded_lines} lines " \
        f"matched; differences: {json.dumps(got[:3])}"


@pytest.mark.slow
def test_the_command_judges_them_equal() -> None:
    """``conform emulate judge FILE --variant marlin-2.1``, as the recordings' README says."""
    _need_folder()
    for path in FILES:
        r = subprocess.run([sys.executable, "-m", "conform", "emulate", "judge", str(path),
                            "--variant", "marlin-2.1"], capture_output=True, text=True,
                           timeout=600)
        assert r.returncode == 0 and " AGREES with the reference marlin-2.1: " in r.stdout, \
            r.stdout[-2000:] + r.stderr


@pytest.mark.parametrize(("mutant", "name"), [("deaf-while-busy", "blocking-reads.transcript"),
                                              ("silent-shutdown", "halt.transcript"),
                                              ("comment-keeps-checksum", "line-errors.transcript"),
                                              ("slow-keepalive", "send300.mcap")])
def test_a_deviant_unit_is_told_apart_by_the_recordings(mutant: str, name: str) -> None:
    """The recordings judge: a unit deaf while a dwell blocks, one that halts without
    ``echo:M112 Shutdown``, one whose ';' keeps the checksum, one with a 4 s keepalive — each
    differs from what the firmware said."""
    _need_folder()
    from conform.emulator.judge import judge, read_transcript
    from conform.families import family

    fam = family("marlin")
    v = judge(read_transcript(ROOT / name), fam.make_unit("marlin-2.1", mutant=mutant),
              fam.judge_mask("marlin-2.1"), "marlin-2.1", is_answer=fam.judge_answers(
                  "marlin-2.1"), near=fam.judge_near("marlin-2.1"))
    assert not v.agrees


def test_the_masks_and_the_tolerance() -> None:
    from conform.families import family

    fam = family("marlin")
    mask, near = fam.judge_mask("marlin-2.1"), fam.judge_near("marlin-2.1")
    assert mask("ok T:19.37 /0.00 B:19.37 /0.00 @:0 B@:0\n") == \
        mask("ok T:25.00 /0.00 B:25.00 /0.00 @:0 B@:0\n")
    assert mask("FIRMWARE_NAME:Marlin 2.1.2.4 (Nov 27 2026 10:40:41) SOURCE_CODE_URL:x\n") == \
        mask("FIRMWARE_NAME:Marlin 2.1.2.4 (conform emulator) SOURCE_CODE_URL:x\n")
    assert mask("echo:M105\r\n") == mask("echo:M105\n")
    assert mask("ok\n") != mask("ok T:1\n") and mask("Resend: 2\n") != mask("Resend: 3\n")
    a = "X:8.71 Y:0.00 Z:0.00 E:0.00 Count X:697 Y:0 Z:0\n"
    assert near(a, "X:8.75 Y:0.00 Z:0.00 E:0.00 Count X:700 Y:0 Z:0\n")
    assert not near(a, "X:9.75 Y:0.00 Z:0.00 E:0.00 Count X:780 Y:0 Z:0\n")
    assert not near(a, "X:8.71 Y:0.00 Z:0.00 E:0.00 Count X:797 Y:0 Z:0\n")
    assert not near("ok\n", "ok T:1\n")


def test_a_boot_before_the_host_wrote_is_no_reset_finding() -> None:
    """``analyze`` of a session that begins with the unit's boot banner (the port opened, the
    board reset, then the sender wrote): no "queued lines are lost" warning."""
    _need_folder()
    from conform.families import family

    for name in ("send300.mcap", "printcore.mcap"):
        a = family("marlin").analyze(str(ROOT / name))
        assert a.kinds().get("reset", 0) == 0, name
