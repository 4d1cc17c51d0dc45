"""The Marlin reference unit held to the real firmware: every recording of Marlin 2.1.2.4 in
the shared recordings folder (``recordings/marlin-2.1.2.4/``: text transcripts and the two
MCAP sessions) is judged by ``conform emulate judge FILE --variant marlin-2.1``, after the
masks ``MarlinFamily.judge_mask`` states (protocol/codec.py mask_volatile) and the tolerance
of ``judge_near`` (positions after a quickstop): the transcripts equal, each session equal but
for the one keepalive line stated in KNOWN (a dwell 0.17 s longer on the firmware).

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


KNOWN = {
    # The one difference left in each session: the dwell after the first moves (G1 Z5, then
    # eleven XY moves, then G4 P200) lasted 4.12 s on the firmware, 3.95 s in the model, so
    # the firmware said a second `busy:` (at 4.0 s) the model does not. The model's motion is
    # otherwise slower than the firmware's by 0.1-0.2 s in every later dwell (it stops at
    # every corner); what makes this first stretch 0.17 s slower on the firmware is not known
    # (the Z move's acceleration, 100 mm/s², is modelled). Stated here, so that any other
    # difference fails.
    "send300.mcap": [("N20 G4 P200*93", ["echo:busy: processing\n"], [])],
    "printcore.mcap": [("N19 G4 P200*87", ["echo:busy: processing\n"], [])],
}


@pytest.mark.slow
@pytest.mark.parametrize("name", [p.name for p in FILES] or ["(none)"])
def test_every_recording_is_judged_equal_but_what_is_stated(name: str) -> None:
    _need_folder()
    r = subprocess.run([sys.executable, "-m", "conform", "emulate", "judge", str(ROOT / name),
                        "--variant", "marlin-2.1", "--json"], capture_output=True, text=True,
                       timeout=600)
    verdict = json.loads(r.stdout)
    got = [(d["after_host"], d["recorded"], d["reference"]) for d in verdict["differences"]]
    assert verdict["recorded_lines"] > 0
    assert got == KNOWN.get(name, []), f"{name}: {verdict['same']} of " \
        f"{verdict['recorded_lines']} lines matched; differences: {json.dumps(got[:3])}"
    assert r.returncode == (1 if name in KNOWN else 0)


def test_a_boot_before_the_host_wrote_is_no_reset_finding() -> None:
    """``analyze`` of a session that begins with the unit's boot banner (the port opened, the
    board reset, then the sender wrote): no "queued lines are lost" warning."""
    _need_folder()
    from conform.families import family

    for name in ("send300.mcap", "printcore.mcap"):
        a = family("marlin").analyze(str(ROOT / name))
        assert a.kinds().get("reset", 0) == 0, name
