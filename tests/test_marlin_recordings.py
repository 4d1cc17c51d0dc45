"""The Marlin reference unit held to the real firmware: every recording of Marlin 2.1.2.4 in
the shared recordings folder (``recordings/marlin-2.1.2.4/``: text transcripts and the two
MCAP sessions) is judged equal by ``conform emulate judge FILE --variant marlin-2.1``, after
the masks ``MarlinFamily.judge_mask`` states (protocol/codec.py mask_volatile) and the
tolerance of ``judge_near`` (positions after a quickstop).

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


@pytest.mark.slow
@pytest.mark.parametrize("name", [p.name for p in FILES] or ["(none)"])
def test_every_recording_is_judged_equal(name: str) -> None:
    _need_folder()
    r = subprocess.run([sys.executable, "-m", "conform", "emulate", "judge", str(ROOT / name),
                        "--variant", "marlin-2.1", "--json"], capture_output=True, text=True,
                       timeout=600)
    verdict = json.loads(r.stdout)
    shown = json.dumps(verdict["differences"][:3], indent=1)
    assert r.returncode == 0 and verdict["agrees"], f"{name}: {verdict['same']} of " \
        f"{verdict['recorded_lines']} lines matched; first differences: {shown}"
    assert verdict["recorded_lines"] > 0


def test_a_boot_before_the_host_wrote_is_no_reset_finding() -> None:
    """``analyze`` of a session that begins with the unit's boot banner (the port opened, the
    board reset, then the sender wrote): no "queued lines are lost" warning."""
    _need_folder()
    from conform.families import family

    for name in ("send300.mcap", "printcore.mcap"):
        a = family("marlin").analyze(str(ROOT / name))
        assert a.kinds().get("reset", 0) == 0, name
