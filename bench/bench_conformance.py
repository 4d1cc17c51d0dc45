"""Conformance run times per profile (all four variants on the emulator) and the mutant kill
rate, against the issue's targets: quick < 120 s for all four variants on one core; every
mutant caught.

    python bench/bench_conformance.py [--full] [--variant VID ...] [--mutants N]

``--variant`` (repeatable) limits the run to some variants and ``--mutants N`` to the first N
mutants, for a quick look; the targets are for the defaults (all variants, all mutants).
"""

from __future__ import annotations

import argparse
import json
import time

from conform.conformance.runner import RunOptions
from conform.families.gve.conformance.mutants import MUTANTS, mutant_targets
from conform.families.gve.conformance.runner import Runner
from conform.families.gve.conformance.suite import run_mutants, suite
from conform.families.gve.conformance.target import open_target
from conform.families.gve.spec import load_spec

QUICK_TARGET_S = 120.0
KILL_RATE_TARGET = 1.0


def run_profile(spec, profile: str, variants: list[str], out: dict) -> float:
    total = 0.0
    for vid in variants:
        target, _ = open_target(f"emu:{vid}", spec)
        checks = suite(spec, vid, profile=profile)
        t0 = time.perf_counter()
        run = Runner(spec, target, vid, options=RunOptions(profile=profile)).run(checks)
        dt = time.perf_counter() - t0
        total += dt
        counts = {k: v for k, v in run.counts().items() if v}
        print(f"  {profile:5} {vid:14} {len(checks):4} checks  {dt:6.2f} s  {counts}")
        out.setdefault("variants", {}).setdefault(vid, {})[profile] = {
            "checks": len(checks), "seconds": round(dt, 3), "counts": counts}
    return total


def main(argv: list[str] | None = None) -> None:
    spec = load_spec()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="also time the full profile")
    ap.add_argument("--variant", action="append", choices=list(spec.variants),
                    help="variant to time (repeatable; default: all four)")
    ap.add_argument("--mutants", type=int, default=len(MUTANTS),
                    help=f"how many mutants to run (default: all {len(MUTANTS)})")
    args = ap.parse_args(argv)
    variants = args.variant or list(spec.variants)
    out: dict = {"variants_run": variants, "quick_target_s": QUICK_TARGET_S}
    profiles = ["quick", "full"] if args.full else ["quick"]
    for profile in profiles:
        total = run_profile(spec, profile, variants, out)
        out[f"{profile}_s"] = round(total, 3)
        which = "all four variants" if args.variant is None else ", ".join(variants)
        line = f"{profile}: {which} in {total:.1f} s"
        if profile == "quick":
            ratio = total / QUICK_TARGET_S
            out["quick_ratio"] = round(ratio, 4)
            line += f" (target < {QUICK_TARGET_S:.0f} s: ratio {ratio:.3f})"
        print(line)
    pairs = mutant_targets(variants)[:max(0, args.mutants)]
    n = len(pairs)
    t0 = time.perf_counter()
    report, _ = run_mutants(spec, variants, machine=False, names={m.name for m, _ in pairs})
    mutants_s = time.perf_counter() - t0
    killed = sum(m["killed"] for m in report)
    on_target = sum(bool(m["expected_hit"]) for m in report)
    kill_rate = killed / n if n else 0.0
    print(f"mutants: {killed}/{n} killed, {on_target}/{n} by the check "
          f"meant to catch them, kill rate {kill_rate:.0%} "
          f"(directed checks, {mutants_s:.1f} s)")
    # the state machine on its own (quick profile): how many faults random sequences find
    t0 = time.perf_counter()
    found = []
    for m, vid in pairs:
        target, _ = open_target(f"emu:{vid}:{m.name}", spec)
        [check] = suite(spec, vid, patterns=["*/sequences"])
        result = Runner(spec, target, vid, options=RunOptions(profile="quick")).run_check(check)
        if result.grade.value == "FAIL":
            found.append(m.name)
    sm_s = time.perf_counter() - t0
    print(f"state machine alone (quick): {len(found)}/{n} mutants "
          f"({', '.join(found)}) in {sm_s:.1f} s")
    out.update({"mutants": n, "mutants_killed": killed, "mutants_on_target": on_target,
                "kill_rate": round(kill_rate, 4), "kill_rate_target": KILL_RATE_TARGET,
                "kill_rate_ratio": round(kill_rate / KILL_RATE_TARGET, 4),
                "mutants_s": round(mutants_s, 3), "state_machine_found": len(found),
                "state_machine_mutants": found, "state_machine_s": round(sm_s, 3)})
    print(json.dumps(out))


if __name__ == "__main__":
    main()
