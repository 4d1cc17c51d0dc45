"""The suite tests itself: every deviant unit is caught by the check meant to catch it."""

from __future__ import annotations

import pytest

from conform.families.gve.conformance.mutants import MUTANTS, mutant_targets
from conform.families.gve.conformance.suite import run_mutants


@pytest.fixture(scope="module")
def mutant_report(spec):
    report, _ = run_mutants(spec, ["gve64-v19"], machine=False)
    return {m["name"]: m for m in report}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(MUTANTS))
@pytest.mark.long(120)
def test_mutant_is_caught_by_its_check(mutant_report, name):
    m = mutant_report[name]
    assert m["killed"], f"{name} survived"
    hit = {c.split("/", 2)[2] for c in m["expected_hit"]}
    assert hit & set(MUTANTS[name].catches), (name, m["caught_by"][:5])


@pytest.mark.slow
def test_kill_rate_is_complete(mutant_report):
    assert len(mutant_report) == len(MUTANTS) >= 14
    assert sum(m["killed"] for m in mutant_report.values()) == len(MUTANTS)


def test_v10_mutant_runs_on_a_v10(spec):
    pairs = {m.name: v for m, v in mutant_targets(["gve64-v19"])}
    assert pairs["v10-accepts-vl"] == "gve64-v10" and pairs["no-inta"] == "gve64-v19"
