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


# -- what the stated tolerance lets through, and what it does not (no recordings needed) --

def _recording(writes: list[tuple[float, bytes]], change: dict[str, str] | None = None) -> str:
    """A transcript of what the grbl judge unit answers to ``writes``, with the first line
    starting with each key of ``change`` replaced by its value (a recording of a unit that
    differs there)."""
    from conform.emulator.judge import lines_of

    unit = family("grbl").judge_unit("grbl-1.1f")
    unit.poll(0.0)
    events: list[tuple[float, str]] = []
    for t, data in writes:
        for when, out in unit.poll(t):
            events += [(when, "< " + x.rstrip("\r\n")) for x in lines_of(out)]
        unit.receive(data, t)
        shown = data.decode("latin-1")
        events.append((t, "> " + shown.rstrip("\n") if shown.endswith("\n") else
                       ">! " + shown.encode("unicode_escape").decode()))
    for when, out in unit.poll(writes[-1][0] + 3.0):
        events += [(when, "< " + x.rstrip("\r\n")) for x in lines_of(out)]
    text = []
    todo = dict(change or {})
    for when, line in sorted(events, key=lambda e: e[0]):
        for old in list(todo):
            if line.startswith("< " + old):
                line = "< " + todo.pop(old)
        text.append(f"{when:.4f} {line}")
    assert not todo, f"nothing to change for {list(todo)}"
    return "\n".join(text) + "\n"


def _judged(text: str):
    from conform.emulator.judge import parse_text

    return judge_recording(parse_text(text, "t"), family("grbl"), "grbl-1.1f")


MOVE = [(0.0, b"G1 X20 F300\n"), (1.5, b"?"), (6.0, b"?")]


def test_moving_reports_agree_within_the_tolerance_only() -> None:
    assert _judged(_recording(MOVE)).agrees
    same = _recording(MOVE)
    moving = next(x for x in same.splitlines() if "<Run|" in x).split("< ", 1)[1]
    pos = float(moving.split("MPos:")[1].split(",")[0])
    for shift, agrees in ((0.4, True), (3.0, False)):
        off = moving.replace(f"MPos:{pos:.3f}", f"MPos:{pos + shift:.3f}")
        v = _judged(_recording(MOVE, {moving: off}))
        assert v.agrees is agrees, (shift, render(v))
    # at rest a report is exact
    rest = next(x for x in same.splitlines() if "<Idle|" in x).split("< ", 1)[1]
    assert not _judged(_recording(MOVE, {rest: rest.replace("20.000", "20.004")})).agrees


RESET = [(0.0, b"G1 X20 F500\n"), (0.8, b"\x18"), (1.6, b"?"), (2.0, b"?")]


def test_a_reset_during_motion_is_followed_within_the_tolerance_only() -> None:
    """Where a reset stops a moving machine depends on its moment: a recorded machine that
    stopped 0.024 mm (6 steps) from the reference's place is followed there and every later
    report compared from there; one 5 mm away is not, and its reports differ."""
    same = _recording(RESET)
    assert "ALARM:3" in same and _judged(same).agrees
    alarm = next(x for x in same.splitlines() if "<Alarm|" in x).split("< ", 1)[1]
    pos = alarm.split("MPos:")[1].split(",")[0]
    for shift, agrees in ((-0.024, True), (5.0, False)):
        moved = same.replace(f"MPos:{pos},", f"MPos:{float(pos) + shift:.3f},")
        v = _judged(moved)
        assert v.agrees is agrees, (shift, render(v))
    assert [x for d in v.differences for x in d.recorded][0].startswith("<Alarm|")
