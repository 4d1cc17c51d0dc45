"""One runner for every family: grbl's checks run in conform.conformance.runner like GVE's, so
the estimate and ETA, the abort when the link is lost, the halt on Ctrl-C and the results come
from one code path. Driven over a real pty against `conform emulate serve grbl-1.1f`."""

from __future__ import annotations

import pytest
from test_grbl_emulator import start, stop  # `conform emulate serve grbl-1.1f` on a pty

from conform.conformance.results import Grade
from conform.conformance.runner import RunAborted, Runner, RunOptions
from conform.conformance.target import EmuTarget, open_link
from conform.families import family
from conform.families.grbl.conformance.checks import generate, select
from conform.families.grbl.spec.load import load_grbl

G = load_grbl()
VID = "grbl-1.1f"


@pytest.fixture
def emulator():
    proc, path = start()
    yield proc, path
    if proc.poll() is None:
        stop(proc)


def _checks(*patterns):
    return select(generate(G, VID), patterns)


def test_the_registry_gives_grbl_a_runner_of_the_engine():
    fam = family("grbl")
    runner = fam.runner(EmuTarget(lambda: fam.make_unit(VID), f"emu:{VID}"), VID)
    assert isinstance(runner, Runner)
    run = runner.run(_checks("*/example/*", "*/error/2?"))
    assert run.checks and all(c.grade is Grade.PASS for c in run.checks)
    assert run.aborted is None and run.estimate_s is None   # in-process: no estimate


def test_link_run_announces_the_estimate_and_the_eta(emulator):
    _, path = emulator
    said = []
    target = open_link(path)
    try:
        runner = family("grbl").runner(target, VID, options=RunOptions(
            announce=said.append, eta_every=0.0))
        checks = _checks("*/example/*")
        run = runner.run(checks)
    finally:
        target.close()
    grades = {c.id: c.grade for c in run.checks}
    assert set(grades.values()) == {Grade.PASS, Grade.SKIPPED}, grades   # writes need opt-in
    skipped = [i for i, g in grades.items() if g is Grade.SKIPPED]
    assert all(runner.estimate.per_check[i] == 0 for i in skipped)
    assert said[0].startswith(f"{path} ({VID}): {len(checks)} checks, estimate ")
    # grbl's random sequences are open-ended on a link: their time budget is announced
    assert run.machine_budget_s == runner.machine_budget() and run.machine_budget_s
    assert f"state machine budget 0:{int(run.machine_budget_s):02d}" in said[0]
    assert run.estimate_s is not None and run.estimate_s > 0
    assert any(", ETA " in s for s in said[1:])


def test_ctrl_c_halts_a_moving_grbl_and_says_so(emulator, monkeypatch):
    _, path = emulator
    target = open_link(path)
    runner = family("grbl").runner(target, VID, allow_motion=True)
    check = next(c for c in generate(G, VID) if c.id.endswith("/realtime/hold-resume"))

    def interrupted(s):
        s.talk(b"G1X-20F300\n")
        s.wait(0.3)
        raise KeyboardInterrupt

    monkeypatch.setattr(check, "run", interrupted)
    try:
        with pytest.raises(RunAborted) as caught:
            runner.run([check])
        aborted = caught.value.run.aborted
        assert aborted.startswith("interrupted (Ctrl-C) after 0 checks; ")
        assert "acknowledged by the banner" in aborted
        target.drain()
        target.send(b"?")
        target.wait(0.3)
        assert b"<Idle|" in target.drain()                  # stands: hold, then reset
    finally:
        target.close()


def test_a_lost_link_ends_a_grbl_run(emulator):
    proc, path = emulator
    target = open_link(path)
    runner = family("grbl").runner(target, VID)

    def kill_after_first(result):
        if proc.poll() is None:
            proc.kill()
            proc.wait()

    try:
        run = runner.run(_checks("*/example/*"), kill_after_first)
    finally:
        target.close()
    assert run.checks[0].grade is Grade.PASS
    assert [c.grade for c in run.checks[1:]] == [Grade.ERROR] * 3
    assert run.aborted is not None and run.aborted.startswith("link lost after 4 checks")
