"""What a `conform check-sender` run costs: every scenario for the family's careful test sender
(GVE: tests/senders/careful.py; grbl: tests/senders/grbl_counting.py good; Marlin:
tests/senders/marlin_careful.py), wall time per
scenario and in all, and the process CPU time, against a target of 60 s for the full matrix (a
check a user runs often must stay short).

    python bench/bench_check_sender.py [--repeat N] [--variant V]

Most of the time is the program's own (its timeouts, the unit's motion); the median of N runs
is reported because the machine may be shared.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

from conform.families import default_variant, family_for_variant
from conform.sendercheck.grade import check

TARGET_S = 60.0
SENDERS = Path(__file__).resolve().parents[1] / "tests" / "senders"
# the test sender that passes every MUST rule, per family: (script, arguments after {job})
CAREFUL = {"gve": ("careful.py", ()), "grbl": ("grbl_counting.py", ("good",)),
           "marlin": ("marlin_careful.py", ())}


def cpu() -> float:
    ru = [resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]
    return sum(r.ru_utime + r.ru_stime for r in ru)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=1, help="runs of the whole matrix")
    ap.add_argument("--variant", default=None, help="the unit (default: the default family's)")
    args = ap.parse_args()
    repeat, variant = args.repeat, args.variant or default_variant()
    if repeat < 1:
        ap.error("--repeat must be at least 1")
    family = family_for_variant(variant)
    if family.name not in CAREFUL:
        ap.error(f"--variant {variant}: no careful test sender for the {family.name} family")
    script, extra = CAREFUL[family.name]
    command = [sys.executable, str(SENDERS / script), "{port}", "{job}", *extra]
    totals, per, cpus = [], {n: [] for n in family.check_sender.scenarios}, []
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as d:
            c0, t0 = cpu(), time.perf_counter()
            r = check(command, variant=variant, directory=Path(d))
            totals.append(time.perf_counter() - t0)
            cpus.append(cpu() - c0)
        for s in r.scenarios:
            per[s.name].append(s.session.duration)
        if r.exit_code != 0:
            print(f"  the careful sender failed a MUST rule (exit {r.exit_code})")
    for name, ts in per.items():
        print(f"  {name:14} {statistics.median(ts):6.2f} s (program run)")
    total = statistics.median(totals)
    cpu_s = statistics.median(cpus)
    ratio = total / TARGET_S
    print(f"full matrix: {total:.1f} s wall (median of {repeat}), {cpu_s:.1f} s "
          f"CPU; target {TARGET_S:.0f} s, ratio {ratio:.2f}")
    print(json.dumps({"variant": variant, "total_s": round(total, 2), "cpu_s": round(cpu_s, 2), "repeat": repeat,
                      "exit_code": r.exit_code,
                      "target_s": TARGET_S, "ratio": round(ratio, 3),
                      "scenarios_s": {n: round(statistics.median(t), 2) for n, t in per.items()}}))


if __name__ == "__main__":
    main()
