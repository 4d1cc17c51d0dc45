"""grbl mutants: the reference unit with one firmware bug each (issue: 15 bug classes, one per
fact the real firmware showed, plus a setting range widened at its documented minimum).
Every one must be killed by the check meant for it, not merely by some check."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from conform.families.grbl.conformance.checks import run_checks
from conform.families.grbl.conformance.mutants import MUTANTS, run_mutants
from conform.families.grbl.spec.load import load_grbl

G = load_grbl()


def test_there_are_at_least_fifteen_bug_classes():
    assert len(MUTANTS) >= 15
    assert "setting-0-widened" in MUTANTS


@pytest.fixture(scope="module")
def report():
    rep, _ = run_mutants(G, "grbl-1.1f", lambda target, vid: run_checks(target, vid, spec=G))
    return {m["name"]: m for m in rep}


@pytest.mark.parametrize("name", list(MUTANTS))
def test_each_mutant_is_killed_by_the_check_meant_for_it(report, name):
    m = report[name]
    assert m["killed"], m
    assert m["expected_hit"], (m["catches"], m["caught_by"])


def test_conform_run_mutants_and_a_mutant_target(tmp_path):
    p = subprocess.run([sys.executable, "-m", "conform", "run", "--mutants", "--variant",
                        "grbl-1.1f", "--json", "--report", str(tmp_path / "all")],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    doc = json.loads(p.stdout)
    assert len(doc["mutants"]) == len(MUTANTS) and all(m["killed"] for m in doc["mutants"])
    q = subprocess.run([sys.executable, "-m", "conform", "run", "--target",
                        "emu:grbl-1.1f:m7-built", "--report", str(tmp_path / "one")],
                       capture_output=True, text=True, timeout=300)
    assert q.returncode == 1
    assert "FAIL grbl-1.1f/gcode.c/example/m7-not-built" in q.stdout
    r = subprocess.run([sys.executable, "-m", "conform", "run", "--target",
                        "emu:grbl-1.1f:no-such-bug"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "no mutant 'no-such-bug'" in r.stderr
    assert "Traceback" not in r.stderr
