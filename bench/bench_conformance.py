"""Conformance run times per profile (all four variants on the emulator) and the mutant kill
rate, against the issue's targets: quick < 120 s for all four variants on one core; every
mutant caught.

    python bench/bench_conformance.py [--full]
"""

from __future__ import annotations

import sys
import time

from conform.conformance.runner import RunOptions
from conform.families.gve.conformance.mutants import MUTANTS, mutant_targets
from conform.families.gve.conformance.runner import Runner
from conform.families.gve.conformance.suite import run_mutants, suite
from conform.families.gve.conformance.target import open_target
from conform.families.gve.spec import load_spec

QUICK_TARGET_S = 120.0


def run_profile(spec, profile: str) -> float:
    total = 0.0
    for vid in spec.variants:
        target, _ = open_target(f"emu:{vid}", spec)
        checks = suite(spec, vid, profile=profile)
        t0 = time.perf_counter()
        run = Runner(spec, target, vid, options=RunOptions(profile=profile)).run(checks)
        dt = time.perf_counter() - t0
        total += dt
        counts = {k: v for k, v in run.counts().items() if v}
        print(f"  {profile:5} {vid:14} {len(checks):4} checks  {dt:6.2f} s  {counts}")
    return total


def main() -> None:
    spec = load_spec()
    profiles = ["quick", "full"] if "--full" in sys.argv else ["quick"]
    for profile in profiles:
        total = run_profile(spec, profile)
        line = f"{profile}: all four variants in {total:.1f} s"
        if profile == "quick":
            line += f" (target < {QUICK_TARGET_S:.0f} s: ratio {total / QUICK_TARGET_S:.3f})"
        print(line)
    t0 = time.perf_counter()
    report, _ = run_mutants(spec, list(spec.variants), machine=False)
    killed = sum(m["killed"] for m in report)
    on_target = sum(bool(m["expected_hit"]) for m in report)
    print(f"mutants: {killed}/{len(MUTANTS)} killed, {on_target}/{len(MUTANTS)} by the check "
          f"meant to catch them, kill rate {killed / len(MUTANTS):.0%} "
          f"(directed checks, {time.perf_counter() - t0:.1f} s)")
    # the state machine on its own (quick profile): how many faults random sequences find
    t0 = time.perf_counter()
    found = []
    for m, vid in mutant_targets(list(spec.variants)):
        target, _ = open_target(f"emu:{vid}:{m.name}", spec)
        [check] = suite(spec, vid, patterns=["*/sequences"])
        result = Runner(spec, target, vid, options=RunOptions(profile="quick")).run_check(check)
        if result.grade.value == "FAIL":
            found.append(m.name)
    print(f"state machine alone (quick): {len(found)}/{len(MUTANTS)} mutants "
          f"({', '.join(found)}) in {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
