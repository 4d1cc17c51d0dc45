"""grbl mutants: the reference unit with one firmware bug each (15 bug classes, one per
fact the real firmware showed, a setting range widened at its documented minimum, and the
bugs seen only from a non-default state: a neighbouring command's effect, a reset that keeps).
Every one must be killed by the check meant for it, not merely by some check."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from conform.families.grbl.conformance.checks import run_checks
from conform.families.grbl.conformance.mutants import MUTANTS
from conform.families.grbl.spec.load import load_grbl

G = load_grbl()


def test_there_are_at_least_thirty_bug_classes():
    assert len(MUTANTS) >= 30
    assert "setting-0-widened" in MUTANTS


@pytest.fixture(scope="module")
def mutants_run(tmp_path_factory):
    """`conform run --mutants` once (in-process: the command's own code, without a second
    interpreter): the sweep every test of this module reads, so that it runs once."""
    from click.testing import CliRunner

    from conform.cli.main import cli

    out = tmp_path_factory.mktemp("mutants")
    r = CliRunner().invoke(cli, ["run", "--mutants", "--variant", "grbl-1.1f", "--json", "-q",
                                 "--report", str(out)])
    return r, out


@pytest.fixture(scope="module")
def report(mutants_run):
    r, _ = mutants_run
    return {m["name"]: m for m in json.loads(r.stdout)["mutants"]}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(MUTANTS))
@pytest.mark.long(130)
def test_each_mutant_is_killed_by_the_check_meant_for_it(report, name):
    m = report[name]
    assert m["killed"], m
    assert m["expected_hit"], (m["catches"], m["caught_by"])


@pytest.mark.slow
def test_conform_run_mutants_and_a_mutant_target(mutants_run, tmp_path):
    from click.testing import CliRunner

    from conform.cli.main import cli

    r, out = mutants_run
    assert r.exit_code == 0, r.output[-2000:]
    doc = json.loads(r.stdout)
    assert doc["report"] == str(out) and (out / "results.json").is_file()
    assert len(doc["mutants"]) == len(MUTANTS) and all(m["killed"] for m in doc["mutants"])
    assert doc["mutants"] == json.loads((out / "results.json").read_text())["mutants"]
    q = CliRunner().invoke(cli, ["run", "--target", "emu:grbl-1.1f:m7-built", "--report",
                                 str(tmp_path / "one")])
    assert q.exit_code == 1, q.output[-2000:]
    assert "FAIL grbl-1.1f/gcode.c/example/m7-not-built" in q.stdout
    r = subprocess.run([sys.executable, "-m", "conform", "run", "--target",
                        "emu:grbl-1.1f:no-such-bug"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "no mutant 'no-such-bug'" in r.stderr
    assert "Traceback" not in r.stderr


@pytest.mark.parametrize("name", ["jog-checked-first", "fraction-is-23"])
def test_random_sequences_find_a_mutant_and_shrink_it_to_its_replay(name):
    """The hypothesis machine drives the mutant and the reference side by side and shrinks
    the first difference to the shortest sequence: one line for these bugs."""
    from conform.conformance.target import EmuTarget

    m = MUTANTS[name]
    target = EmuTarget(lambda: m.make(G, "grbl-1.1f"), f"emu:grbl-1.1f:{name}")
    try:
        run = run_checks(target, "grbl-1.1f", spec=G, patterns=["*/sequences/*"])
    finally:
        target.close()
    (c,) = run.checks
    assert c.grade.name == "FAIL"
    replay = c.actual.split("replay: ")[1]
    assert replay.count("\\n") == 1, replay          # shrunk to one line


def test_random_sequences_agree_on_the_reference():
    from conform.conformance.target import EmuTarget
    from conform.families.grbl.unit.model import GrblUnit

    target = EmuTarget(lambda: GrblUnit(G.variant("grbl-1.1f"), G), "emu:grbl-1.1f")
    try:
        (c,) = run_checks(target, "grbl-1.1f", spec=G, patterns=["*/sequences/*"]).checks
    finally:
        target.close()
    assert c.grade.name == "PASS" and "random sequences agreed" in c.actual


# the mutants that show only from a non-default state (from_state.py): none of the checks
# that came before those rows catches them; each is caught by its row, and those whose row
# needs no motion and no EEPROM write are caught in a default run on a real unit too
FROM_STATE = [n for n, m in MUTANTS.items() if all(p.startswith("from_state/") for p in m.catches)]
DEFAULT_RUN = {"g92-ignores-tlo", "g92-zeroes-other-axes", "g92.1-no-wco-refresh", "g43.1-adds",
               "g43.1-ignores-inches", "g90.1-accepted", "m30-keeps-coord", "reset-keeps-g92",
               "reset-keeps-overrides", "check-exit-keeps-modes", "feed-reset-resets-all",
               "g49-keeps-tlo", "g91.1-as-g91", "g21-sets-g90", "g54-clears-g92", "g17-ignored",
               "g80-ignored", "g93-ignored"}


@pytest.mark.slow
def test_the_from_state_mutants_are_new_bug_classes(report):
    assert len(FROM_STATE) >= 14
    for name in FROM_STATE:
        old = [c for c in report[name]["caught_by"]
               if "/from_state/" not in c and "/in_motion/" not in c
               and "/system_effects/" not in c]
        assert not old, (name, old)     # the checks before the rows (and the in_motion and
        # system_effects checks, which came after them) did not see it


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(DEFAULT_RUN))
def test_a_default_run_on_a_real_unit_catches_it(report, name):
    from conform.families.grbl.conformance.checks import generate

    unflagged = {c.id for c in generate(G, "grbl-1.1f") if not c.motion and not c.eeprom}
    assert set(report[name]["expected_hit"]) & unflagged, report[name]["expected_hit"]
