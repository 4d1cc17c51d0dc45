"""The grbl reference unit against the real grbl 1.1f firmware: every recording in the shared
recordings folder (recorded from grbl 1.1f under grbl-sim, see its README) is judged equal by
``conform emulate judge``, with only the simulator artefacts the README names stated
(conform/families/grbl/emulate_judge.py: positions while moving within the motion model's
tolerance, the machine placed where a cut homing seek, a reset or a hold left it)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from conform.emulator.judge import judge_recording, read_transcript, render
from conform.families import family

REPO = Path(__file__).resolve().parent.parent
ENV = "CONFORM_RECORDINGS"


def _roots() -> list[Path]:
    """The repository's folder and, for a git worktree, its main repository's folder."""
    roots = [REPO]
    dotgit = REPO / ".git"
    if dotgit.is_file():       # a worktree: "gitdir: MAIN/.git/worktrees/NAME"
        text = dotgit.read_text(errors="replace").strip()
        if text.startswith("gitdir:"):
            gitdir = Path(text.split(":", 1)[1].strip())
            if gitdir.parent.name == "worktrees":
                roots.append(gitdir.parent.parent.parent)
    return roots


def _folder() -> Path | None:
    candidates = [r.parent / "shared" / "recordings" for r in _roots()]
    if os.environ.get(ENV):
        candidates.append(Path(os.environ[ENV]))
    for root in candidates:
        if (root / "grbl-1.1f").is_dir():
            return root / "grbl-1.1f"
    return None


FOLDER = _folder()
RECORDINGS = sorted(FOLDER.glob("*.transcript")) + sorted(FOLDER.glob("*.mcap")) \
    if FOLDER else []


def _absent() -> None:
    why = f"no grbl recordings (../shared/recordings relative to the repository, or ${ENV})"
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(why + ": CI must have them")
    pytest.skip(why)


def test_the_recordings_are_there() -> None:
    if FOLDER is None:
        _absent()
    assert RECORDINGS, f"{FOLDER}: no recordings in the folder"
    assert (FOLDER / "VARIANT").read_text().strip() == "grbl-1.1f"


@pytest.mark.parametrize("path", RECORDINGS, ids=lambda p: p.name)
def test_every_grbl_recording_is_judged_equal(path: Path) -> None:
    verdict = judge_recording(read_transcript(path), family("grbl"), "grbl-1.1f")
    assert verdict.recorded_lines > 0
    assert verdict.agrees, "\n".join(render(verdict, limit=10))
    assert verdict.same == verdict.recorded_lines == verdict.reference_lines


@pytest.mark.slow
def test_the_command_line_says_agrees_for_one() -> None:
    if FOLDER is None:
        _absent()
    path = FOLDER / "modal-reset.transcript"
    r = subprocess.run([sys.executable, "-m", "conform", "emulate", "judge", str(path),
                        "--variant", "grbl-1.1f"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.startswith("modal-reset.transcript: AGREES with the reference grbl-1.1f")
