"""The conformance runner against the in-process emulator: clean on every variant, fails a v10
that is expected to be a v19 at the version clause, grades open questions as DEVIATION, skips
and stops safely on real units."""

from __future__ import annotations

import time

import pytest

from conform.cli.main import main
from conform.conformance.results import Grade
from conform.conformance.runner import RunAborted, RunOptions
from conform.families.gve.conformance.checks import generate, select
from conform.families.gve.conformance.expect import Reference
from conform.families.gve.conformance.runner import Runner
from conform.families.gve.conformance.safety import Guard, SafetyRefusal, hazards
from conform.families.gve.conformance.suite import suite
from conform.families.gve.conformance.target import GveEmuTarget as EmuTarget
from conform.families.gve.conformance.target import GveLinkTarget as LinkTarget
from conform.families.gve.conformance.target import (
    emulator_factory,
    open_target,
    unit_class,
    variant_for_firmware,
)

VARIANTS = ("gve64-v10", "gve64-v19", "gve64-phantom", "gve124")


def _run(spec, target_text, variant, patterns=(), dialect=None, **opts):
    target, _ = open_target(target_text, spec, dialect=dialect)
    runner = Runner(spec, target, variant, options=RunOptions(**opts))
    return runner.run(suite(spec, variant, patterns=patterns))


@pytest.mark.parametrize("variant", VARIANTS)
def test_emulator_is_clean(spec, variant):
    run = _run(spec, f"emu:{variant}", variant, examples=6, steps=15)
    bad = [(c.id, c.grade.value, c.detail) for c in run.checks
           if c.grade not in (Grade.PASS, Grade.NOT_APPLICABLE)]
    assert bad == []
    assert len(run.checks) > 300
    assert any(c.id.endswith("/sequences") and c.grade is Grade.PASS for c in run.checks)


@pytest.mark.parametrize("variant", VARIANTS)
def test_reference_answers_what_the_tables_imply(spec, variant):
    """The subject step of each check answers the code its table row implies."""
    ref = Reference(spec, variant)
    wrong = []
    for check in generate(spec, variant):
        if check.na or check.intent is None:
            continue
        replies = ref.transcript(check.script)
        last = max(i for i, s in enumerate(check.script) if s.subject)
        reply = replies[last]
        code = int(reply.lines[0][:1], 16) & 7 if reply and reply.lines else None
        if code != check.intent:
            wrong.append((check.id, check.intent, code))
    assert wrong == []


def test_ids_are_unique_and_read_like_the_manual(spec):
    for variant in VARIANTS:
        ids = [c.id for c in suite(spec, variant)]
        assert len(ids) == len(set(ids))
    ids = {c.id for c in generate(spec, "gve64-v19")}
    assert "gve64-v19/13.5.2/C/queue-full" in ids
    assert "gve64-v19/13.5.3/V/range/pps/hi+1" in ids
    assert "gve64-v10/14.1/VL/absent" in {c.id for c in generate(spec, "gve64-v10")}
    assert "gve124/12.5.2/C/queue-full" in {c.id for c in generate(spec, "gve124")}
    picked = select(generate(spec, "gve64-v19"), ["*/C/*"])
    assert picked and all("/C/" in c.id for c in picked)


def test_v10_expected_as_v19_fails_at_the_version_clause(spec):
    run = _run(spec, "emu:gve64-v10", "gve64-v19", patterns=["*/valid"])
    failed = {c.key: c for c in run.checks if c.grade is Grade.FAIL}
    for cid in ("VL", "VK", "VN", "XM", "N<axis>"):
        check = failed[f"{cid}/valid"]
        assert "GVE64 §14.1" in check.clause
        assert check.actual.endswith("→ 3")
    assert all(c.grade is not Grade.ERROR for c in run.checks)


def test_open_question_difference_is_a_deviation(spec):
    dialect = spec.dialect({"A15": "no-effect-0"})
    run = _run(spec, "emu:gve64-v19", "gve64-v19", patterns=["*/G/nothing-to-go"],
               dialect=dialect)
    [check] = run.checks
    assert check.grade is Grade.DEVIATION
    assert (check.question, check.alternative) == ("A15", "no-effect-0")
    assert check.expected.endswith("→ 6") and check.actual.endswith("→ 0")
    assert check.log and check.log[0].dir == "tx"


def test_state_machine_adopts_a_deviation_and_finds_a_fault(spec):
    dialect = spec.dialect({"A10": "every-line"})
    run = _run(spec, "emu:gve64-v19", "gve64-v19", patterns=["*/sequences"], dialect=dialect,
               examples=10, steps=20, seed=3)
    [check] = run.checks
    assert check.grade is Grade.DEVIATION and check.question == "A10"
    run = _run(spec, "emu:gve64-v19:index-stuck", "gve64-v19", patterns=["*/sequences"],
               examples=10, steps=20, seed=1)
    [check] = run.checks
    assert check.grade is Grade.FAIL
    assert check.seed == 1 and check.replay.endswith("@1")
    assert check.sequence[0] == "(reset)" and check.sequence[-1].startswith("!0@")
    assert any(e.dir == "rx" for e in check.log)


class UnitEndpoint:
    """A reference unit behind the ``Endpoint`` interface, on the wall clock (no thread)."""

    def __init__(self, spec, variant):
        self.unit = unit_class()(spec.variant(variant), spec.dialect())
        self.t0 = time.monotonic()
        self.sent = []
        self.name = "fake://unit"

    def _now(self):
        return time.monotonic() - self.t0

    def write(self, data):
        self.sent.append(data)
        self.unit.receive(data, self._now())

    def read(self, max_bytes=4096, timeout=0.1):
        end = time.monotonic() + (timeout or 0)
        while True:
            out = b"".join(b for _, b in self.unit.poll(self._now()))
            if out or time.monotonic() >= end:
                return out
            time.sleep(0.0005)

    def close(self):
        pass


def test_real_unit_skips_motion_and_refuses_it(spec):
    endpoint = UnitEndpoint(spec, "gve64-v19")
    target = LinkTarget(endpoint, "fake://unit", Guard(False, None, False), 115200)
    runner = Runner(spec, target, "gve64-v19")
    checks = select(generate(spec, "gve64-v19"), ["*/C/valid", "*/V/valid", "*/EW/valid"])
    run = runner.run(checks)
    grades = {c.key: c.grade for c in run.checks}
    assert grades == {"C/valid": Grade.SKIPPED, "V/valid": Grade.PASS,
                      "EW/valid": Grade.SKIPPED}
    assert not any(b"!0C" in line for line in endpoint.sent)
    with pytest.raises(SafetyRefusal):
        target.exchange(b"!0L100,0,0\r")
    bounded = Guard(True, 50, False)
    with pytest.raises(SafetyRefusal):
        bounded.check(b"!0C51,0,0\r")
    bounded.check(b"!0C-50,20,0\r")
    assert hazards(b"!0O0,FF\r") == set() and hazards(b"!0O0,FE\r") == {"actuator"}
    assert hazards(b"!7V0\r") == set() and hazards(b"!7V500\r") == {"actuator"}


def test_ctrl_c_halts_deletes_and_switches_outputs_off(spec):
    target = EmuTarget(emulator_factory(spec, "gve64-v19"), "emu:gve64-v19")
    runner = Runner(spec, target, "gve64-v19")
    checks = select(generate(spec, "gve64-v19"), ["*/C/valid", "*/V/valid"])

    def interrupt(result):
        raise KeyboardInterrupt

    with pytest.raises(RunAborted) as info:
        runner.run(checks, progress=interrupt)
    aborted = info.value.run.aborted
    assert "Ctrl-C" in aborted and "H →" in aborted and "D →" in aborted and "O0,FF →" in aborted
    sent = [e.data for e in target.log if e.dir == "note"]
    assert sent == [b"abort: !0H\r", b"abort: !0D\r", b"abort: !0O0,FF\r"]


def test_firmware_string_maps_to_a_variant(spec):
    assert variant_for_firmware(spec, "IP64MPG v10")[0] == "gve64-v10"
    assert variant_for_firmware(spec, "IP124 v7/50 2.4.2018")[0] == "gve124"
    assert variant_for_firmware(spec, "something else")[0] == "gve64-v19"


def test_cli_exit_codes(tmp_path, capsys):
    def code(*args):
        with pytest.raises(SystemExit) as info:
            main(list(args))
        return info.value.code

    assert code("run", "-q", "--report", str(tmp_path / "a"), "--check", "*/V/*") == 0
    assert (tmp_path / "a" / "index.html").exists()
    assert code("run", "-q", "--target", "emu:gve64-v10", "--variant", "gve64-v19",
                "--check", "*/VL/valid", "--report", str(tmp_path / "b")) == 1
    assert code("run", "--variant", "gve64-v99") == 2
    assert code("run", "--target", "/dev/nonexistent-port", "--allow-motion") == 2
    assert code("run", "--target", "/dev/nonexistent-port", "--variant", "gve64-v19") == 2
    capsys.readouterr()
    assert code("run", "--list", "--check", "*/C/*") == 0
    out = capsys.readouterr().out
    assert "gve64-v19/13.5.2/C/queue-full\t" in out
    assert code("run", "-q", "--replay", "gve64-v19/13.5.3/V/valid",
                "--report", str(tmp_path / "c")) == 0


@pytest.mark.slow
def test_pytest_plugin_runs_checks_as_items(tmp_path):
    import subprocess
    import sys
    import xml.etree.ElementTree as ET

    junit = tmp_path / "j.xml"
    base = [sys.executable, "-m", "pytest", "-p", "conform",
            "-q", "--rootdir", str(tmp_path), str(tmp_path), "-p", "no:cacheprovider"]
    plain = subprocess.run(base, capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert "no tests ran" in plain.stdout  # without --conform-target: no items
    run = subprocess.run(base + ["--conform-target=emu:gve64-v10", "--conform-variant=gve64-v19",
                                 "--conform-check=*/V*/valid", f"--junitxml={junit}"],
                         capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert run.returncode == 1, run.stdout[-2000:]
    assert "GVE64 §14.1" in run.stdout
    cases = {(c.get("classname"), c.get("name")): c
             for c in ET.parse(junit).getroot().iter("testcase")}
    assert cases["gve64-v19.13.5.3", "V/valid"].find("failure") is None
    assert cases["gve64-v19.13.5.3", "VL/valid"].find("failure") is not None


@pytest.mark.slow
def test_run_against_the_emulator_on_a_pty(tmp_path):
    """End to end through a real pty: identification by '?', J resets, motion SKIPPED."""
    import json
    import subprocess
    import sys

    emu = subprocess.Popen([sys.executable, "-m", "conform", "emulate", "gve64-v10"],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        port = emu.stdout.readline().strip()
        assert port.startswith("/dev/")
        out = tmp_path / "r"
        run = subprocess.run(
            [sys.executable, "-m", "conform", "run", "-q", "--target", port, "--report", str(out),
             "--no-machine", "--check", "*/V/valid", "--check", "*/13.7/status-range",
             "--check", "*/C/valid", "--check", "*/L/position-1"], capture_output=True,
            text=True, timeout=120)
        assert run.returncode == 0, run.stdout + run.stderr
        data = json.loads((out / "results.json").read_text())
        grades = {c["id"]: c["grade"] for c in data["checks"]}
        assert grades == {"gve64-v10/13.5.3/V/valid": "PASS",
                          "gve64-v10/13.7/status-range": "PASS",
                          "gve64-v10/13.5.2/C/valid": "PASS",  # zero-pulse without motion
                          "gve64-v10/13.5.2/L/position-1": "SKIPPED"}
        assert "variant: firmware 'IP64MPG v10' is gve64-v10" in data["runs"][0]["notes"]
    finally:
        emu.terminate()
        emu.wait(10)


def test_lost_link_ends_the_run(spec):
    class DeadEndpoint(UnitEndpoint):
        def write(self, data):
            from conform.link import PortGone

            raise PortGone("fake://unit: peer hung up")

    target = LinkTarget(DeadEndpoint(spec, "gve64-v19"), "fake://unit", Guard(False, None, False),
                        115200, ready_after=0.0)
    checks = select(generate(spec, "gve64-v19"), ["*/V/*"])
    run = Runner(spec, target, "gve64-v19").run(checks)
    assert run.aborted and "link lost" in run.aborted
    assert [c.grade for c in run.checks] == [Grade.ERROR] * 3


@pytest.mark.parametrize("variant", VARIANTS)
def test_every_error_code_has_a_directed_check(spec, variant):
    """Each code 0–7 a command of the variant can give (errors.toml `raised_by`) is the intent of
    at least one directed check, which the reference answers with exactly that code (above)."""
    v = spec.variant(variant)
    applicable = {code for code, e in spec.errors.items()
                  if "*" in e.raised_by or any(c in v.commands for c in e.raised_by)}
    intents = {c.intent for c in generate(spec, variant) if c.na is None}
    assert applicable == set(range(8))
    assert applicable <= intents


def test_timing_words_are_checks(spec):
    """An answer that comes late fails "at once"; a watchdog of 1 s is the A13 deviation."""
    v = spec.variant("gve64-v19")
    checks = suite(spec, "gve64-v19", patterns=["*/timing/*"], machine=False)
    late = EmuTarget(lambda: unit_class()(v, spec.dialect(), answer_delay=0.2), "late")
    grades = {c.key: c.grade for c in Runner(spec, late, "gve64-v19").run(checks).checks}
    assert grades == {"timing/at-once": Grade.FAIL, "timing/watchdog": Grade.FAIL}
    d = spec.dialect({"A13": "1s"})
    slow_wd = EmuTarget(lambda: unit_class()(v, d), "wd")
    run = Runner(spec, slow_wd, "gve64-v19").run(checks)
    assert {c.key: (c.grade, c.question) for c in run.checks} == {
        "timing/at-once": (Grade.PASS, None), "timing/watchdog": (Grade.DEVIATION, "A13")}


def test_firmware_string_and_eeprom_read_back_are_exact(spec):
    """`?` is compared byte for byte with the variant's firmware string on a real unit too, and
    an EEPROM byte the script wrote is read back exactly (not just by shape)."""
    by_key = {c.key: c for c in generate(spec, "gve64-v19")}
    ref = Reference(spec, "gve64-v19")
    from conform.families.gve.conformance.expect import judge

    for key, good, bad in [("?/valid", b"0,IP64MPG v19 10.9.2010", b"0,IP64MPG v19 10.9.2011"),
                           ("EW/read-back", b"0,5A", b"0,5B")]:
        script = by_key[key].script
        expected = ref.transcript(script)
        for text, grade in ((good, "PASS"), (bad, "FAIL")):
            actual = list(expected)
            last = actual[-1]
            actual[-1] = type(last)(last.tx, last.t_tx, [text], t_rx=last.t_rx)
            assert judge(ref, script, actual, loose=True).grade == grade, (key, text)
