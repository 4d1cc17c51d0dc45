"""Conformance over a real pty against `conform emulate`: the same grades as in-process, the unit's
state kept across checks without a J per check, the envelope of --max-steps, reports of runs that
stop early, and the halt retried until the unit acknowledges it."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from contextlib import contextmanager

import pytest
import serial
from test_conformance import UnitEndpoint  # the reference unit behind an endpoint

from conform.cli.main import main
from conform.conformance.results import Grade
from conform.conformance.runner import RunOptions
from conform.families.gve.conformance.checks import generate, select
from conform.families.gve.conformance.readiness import READY_MARGIN
from conform.families.gve.conformance.runner import Runner
from conform.families.gve.conformance.safety import Guard, not_verified
from conform.families.gve.conformance.state import StateKeeper
from conform.families.gve.conformance.suite import suite
from conform.families.gve.conformance.target import GveEmuTarget as EmuTarget
from conform.families.gve.conformance.target import GveLinkTarget as LinkTarget
from conform.families.gve.conformance.target import emulator_factory, open_target
from conform.link import open_port

# a subset that exercises every way to a check's state: commands only (V, checksum), J with a
# polled readiness (@, > depend on what came before), J with the measured readiness (J itself),
# motion and its read-back, HALT/GO, the queue, EEPROM write and read-back, an out-of-range value
SUBSET = ["V/valid", "V/checksum", "V/bad-checksum", "V/range/velocity/hi+1", "@/advance",
          "L/position-1", "H/running", "EW/read-back", "[?]/valid", "K/valid", "C/valid",
          "SR/interrupt", "timing/*", "unknown-command"]


@contextmanager
def served(variant: str, *extra: str, control: str | None = None, mutant: str | None = None):
    more = ["--control", control] if control else []
    cmd = [sys.executable, "-m", "conform", "emulate", "serve", variant, *extra, *more]
    if mutant is not None:  # a deviant unit (no CLI option): the family's serve() names it
        cmd = [sys.executable, "-c", "from conform.families.gve.serve import serve; "
               f"serve({variant!r}, baud=115200, mutant={mutant!r})"]
    emu = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert emu.stdout is not None
        port = emu.stdout.readline().strip()
        assert port.startswith("/dev/"), port
        _answering(port)
        yield port
    finally:
        emu.terminate()
        emu.wait(10)


def _answering(port: str, within: float = 30.0) -> None:
    """Wait until the emulator answers ``!0?`` (it identifies itself; nothing changes), as a
    unit is switched on before a run: on a loaded machine its first answers can come later
    than the run's first timeouts, and a late one would be taken for the next line's."""
    link = serial.Serial(port, 115200, timeout=0.5)
    try:
        deadline = time.monotonic() + within
        while time.monotonic() < deadline:
            link.write(b"!0?\r")
            if link.read_until(b"\r"):
                break
        time.sleep(0.2)   # what else was on its way, then nothing left for the run to read
        link.reset_input_buffer()
    finally:
        link.close()


def _grades(run):
    return {c.key: c.grade for c in run.checks}


def _link_run(spec, port, variant, checks, guard, inputs=None, **opts):
    target = LinkTarget(open_port(port, 115200, 0.1), port, guard, 115200)
    target.inputs = inputs
    try:
        return Runner(spec, target, variant, options=RunOptions(**opts)).run(checks)
    finally:
        target.close()


@pytest.mark.slow
@pytest.mark.parametrize("variant,extra", [("gve124", ("--baud", "115200"))])
def test_link_grades_equal_in_process(spec, variant, extra, tmp_path):
    guard = Guard(True, 1000000, True)
    checks = suite(spec, variant, patterns=SUBSET, guard=guard)
    checks = [c for c in checks if not c.id.endswith("/sequences")]
    checks.append(suite(spec, variant, patterns=["*/sequences"])[0])
    opts = dict(examples=2, steps=10, machine_budget=3.0)
    emu = Runner(spec, EmuTarget(emulator_factory(spec, variant), f"emu:{variant}", guard),
                 variant, options=RunOptions(**opts)).run(checks)
    control = str(tmp_path / "emu.sock")
    with served(variant, *extra, control=control) as port:
        link = _link_run(spec, port, variant, checks, guard, inputs=control, **opts)
    assert _grades(link) == _grades(emu)
    assert _grades(link)["SR/interrupt"] is Grade.PASS
    assert not [c for c in link.checks if c.grade in (Grade.FAIL, Grade.ERROR)]
    state = link.state
    # most checks start from commands; J only where the reference says a check needs it
    assert state["tidy"] >= 8 and 1 <= state["resets"] + state["quiet_resets"] <= 6, state
    # deaf ~2 s after J; on a loaded machine the first answer may come later, as long as it
    # comes before the runner would call the link lost (READY_MARGIN past the deaf time)
    assert 1.9 < state["readiness_s"] < 2.0 + READY_MARGIN
    assert link.estimate_s and link.machine_budget_s == 3.0


def test_tidy_restores_what_commands_can_and_j_the_rest(spec):
    """The keeper's plan comes from the reference: commands for what they restore, J for the
    @ index, the line > repeats, a K without R."""
    guard = Guard.emulated()
    target = EmuTarget(emulator_factory(spec, "gve64-v19"), "x", guard)
    keeper = StateKeeper(Runner(spec, target, "gve64-v19").ref, target)
    by_key = {c.key: c for c in generate(spec, "gve64-v19")}

    def after(key):
        keeper.plan(by_key[key].script)
        keeper.done(True)

    lines, why = keeper.plan(by_key["V/valid"].script)
    assert lines is None and why == "state unknown"
    keeper.done(True)
    after("L/position-1")
    lines, _ = keeper.plan(by_key["V/checksum"].script)
    assert lines is not None and b"!0N\r" in lines and b"!0V1000\r" in lines
    keeper.done(True)
    lines, _ = keeper.plan(by_key["V/valid"].script)  # V/checksum left checksums on
    assert lines is not None and lines[0].startswith(b"!0%-,")
    keeper.done(True)
    lines, why = keeper.plan(by_key["@/advance"].script)
    assert lines is None and "@" in why
    keeper.done(True)
    after("K/valid")
    lines, why = keeper.plan(by_key["C/valid"].script)
    assert lines is None and "K" in why


def test_rejected_j_keeps_the_checksum_belief(spec):
    target, _ = open_target("emu:gve64-v19", spec)
    target.exchange(b"!0%+\r")
    assert target.checksum_on
    reply = target.exchange(b"!0J,00\r")  # wrong checksum: refused, nothing reset
    assert reply.lines and reply.lines[0][:1] == b"4"
    assert target.checksum_on
    target.exchange(target.frame("!0J"))
    assert not target.checksum_on


def test_halt_is_retried_until_acknowledged_over_a_pty(spec):
    """Ctrl-C right after a J: the unit is deaf ~2 s; H goes again every 0.25 s until it is
    answered, then D and O0,FF."""
    with served("gve64-v19", "--baud", "115200") as port:
        target = LinkTarget(open_port(port, 115200, 0.1), port, Guard(True, 1000, False), 115200)
        try:
            target.exchange(b"!0V10\r")
            target.send(b"!0J\r")
            t0 = time.monotonic()
            what = target.safe_stop()
            took = time.monotonic() - t0
        finally:
            target.close()
    assert what.startswith("sent H → 8 (after ") and "D → 0" in what and "O0,FF → 0" in what
    tries = int(what.split("(after ", 1)[1].split(" ", 1)[0])
    assert tries >= 3
    assert 1.8 < took < 7.0
    hs = [e for e in target.log if e.dir == "tx" and e.data == b"!0H\r"]
    assert len(hs) == tries


@pytest.mark.slow
def test_small_envelope_over_a_pty_completes_inside_it(spec, tmp_path):
    """--max-steps 300: what cannot fit is SKIPPED with the reason, the rest runs, the guard
    never has to refuse a line, and the report is written."""
    out = tmp_path / "r"
    with served("gve64-v19") as port:
        code = _cli(["run", "-q", "--target", port, "--variant", "gve64-v19", "--allow-motion",
                     "--max-steps", "300", "--report", str(out), "--check", "W/valid",
                     "--check", "L/position-*", "--check", "C/queue-full", "--check",
                     "L/range/pulses/*", "--check", "G/resume", "--check", "V/valid"])
    assert code == 0
    data = json.loads((out / "results.json").read_text())
    grades = {c["id"].split("/", 2)[2]: (c["grade"], c["detail"]) for c in data["checks"]}
    assert grades["V/valid"][0] == "PASS" and grades["C/queue-full"][0] == "PASS"
    assert grades["W/valid"][0] == "PASS"  # travels of 100 pulses
    hi = grades["L/range/pulses/hi"]
    assert hi[0] == "SKIPPED" and "cannot be done inside --max-steps 300" in hi[1]
    assert not any(g == "ERROR" or "refused" in d for g, d in grades.values())
    [run] = data["runs"]
    assert run["complete"] and any(g["reason"].startswith("outside the envelope")
                                   for g in run["not_verified"])


def _cli(args):
    try:
        main(args)
    except SystemExit as exc:
        return exc.code
    return 0


def test_machine_draws_inside_the_envelope(spec):
    target = EmuTarget(emulator_factory(spec, "gve64-v19"), "emu:gve64-v19",
                       Guard(True, 40, True))
    runner = Runner(spec, target, "gve64-v19", options=RunOptions(examples=25, steps=30))
    [check] = suite(spec, "gve64-v19", patterns=["*/sequences"])
    result = runner.run_check(check)
    assert result.grade is Grade.PASS, result.detail


def test_guard_firing_is_an_error_and_the_run_goes_on(spec, monkeypatch):
    """The send-time guard as the last defence: that check ERRORs, the unit is halted, the
    next check runs."""
    import conform.families.gve.conformance.runner as runner_mod

    monkeypatch.setattr(runner_mod, "skip_reason", lambda *a: None)
    endpoint = UnitEndpoint(spec, "gve64-v19")
    target = LinkTarget(endpoint, "fake://unit", Guard(True, 50, False), 115200)
    checks = select(generate(spec, "gve64-v19"), ["*/L/position-1", "*/V/valid"])
    run = Runner(spec, target, "gve64-v19").run(checks)
    moved, other = (run.checks if run.checks[0].key.startswith("L/") else run.checks[::-1])
    assert moved.grade is Grade.ERROR and "exceeds --max-steps 50" in moved.detail
    assert "H →" in moved.detail and "D →" in moved.detail
    assert other.grade is Grade.PASS and run.complete


def test_harness_exception_still_writes_an_incomplete_report(spec, tmp_path, monkeypatch):
    calls = []
    real = Runner.run_check

    def flaky(self, check):
        calls.append(check.id)
        if len(calls) == 3:
            raise RuntimeError("boom")
        return real(self, check)

    monkeypatch.setattr(Runner, "run_check", flaky)
    out = tmp_path / "r"
    code = _cli(["run", "-q", "--target", "emu:gve64-v19", "--no-machine", "--check",
                 "V/*", "--report", str(out)])
    assert code == 2
    data = json.loads((out / "results.json").read_text())
    [run] = data["runs"]
    assert not run["complete"] and "harness error after 2 checks: RuntimeError: boom" in (
        run["aborted"])
    assert len(data["checks"]) == 2


def test_not_verified_says_how_to_enable(spec):
    target = LinkTarget(UnitEndpoint(spec, "gve64-v19"), "fake://unit", Guard(False, None, False), 115200)
    checks = select(generate(spec, "gve64-v19"), ["*/C/valid", "*/EW/valid", "*/I1/inputs"])
    run = Runner(spec, target, "gve64-v19").run(checks)
    how = {g["reason"]: g["how"] for g in run.not_verified}
    assert how["needs motion"] == "--allow-motion --max-steps N"
    assert how["needs eeprom"] == "--allow-eeprom"
    assert how["needs inputs driven"] == "--inputs-control PATH"
    assert not_verified(run.checks) == run.not_verified


@pytest.mark.slow
def test_a_link_gone_silent_is_an_error_not_a_fail(spec, monkeypatch):
    """A unit that stops answering mid-run (a cable pulled; the port stays open): the check that
    met the silence is ERROR, and the run stops cleanly after three, marked incomplete."""

    class GoesSilent(UnitEndpoint):
        silent = False

        def write(self, data):
            self.silent = self.silent or data.startswith(b"!0V")
            if not self.silent:
                super().write(data)

    import conform.families.gve.conformance.state as state

    monkeypatch.setattr(state, "READY_MARGIN", 0.5)  # the deaf time + 0.5 s of silence: lost
    target = LinkTarget(GoesSilent(spec, "gve64-v19"), "fake://unit", Guard(False, None, False),
                        115200, ready_after=0.2)
    checks = select(generate(spec, "gve64-v19"), ["*/V/*", "*/A/*"])
    run = Runner(spec, target, "gve64-v19").run(checks)
    grades = [c.grade for c in run.checks]
    assert Grade.FAIL not in grades and grades[-3:] == [Grade.ERROR] * 3
    assert grades[0] is Grade.PASS  # V/* ran before the silence
    assert "link lost" in run.aborted and not run.complete
    assert any("no answer to F" in c.detail for c in run.checks)
