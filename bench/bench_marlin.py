"""Benchmark: the Marlin reference unit in-process, and the Marlin analyser on long captures.

1. A host streams N numbered lines (one in flight, noise on its line so that some are
   resent) to the reference unit in virtual time: CPU seconds, lines per CPU second and
   virtual seconds per CPU second.
2. Synthetic traffic of M host lines (a resend every 500 lines, busy: lines) is made as it
   is read and analysed, each size in a fresh process: CPU seconds of the analysis (the cost
   of making the traffic, measured alone first, taken off) and peak resident MB, for 1 M and
   2 M lines (per line, to see whether the cost stays flat).

The last line is one JSON object.

    python bench/bench_marlin.py                       # 20 000 emulated, 1 M and 2 M analysed
    python bench/bench_marlin.py --emulate 5000 --analyse 200000
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from collections.abc import Iterator
from itertools import chain
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def emulate(n: int) -> dict[str, float]:
    from conform.families.marlin.sender.sim import stream
    from conform.families.marlin.spec import load_marlin
    from conform.families.marlin.unit.faults import MarlinFaults
    from conform.families.marlin.unit.unit import MarlinUnit
    from conform.link.faults import FaultConfig

    spec = load_marlin()
    job = [f"G1 X{i % 50}.{i % 7} Y{i % 13} F9000" for i in range(1, n + 1)]
    unit = MarlinUnit(spec.variant("marlin-2.1"), spec)
    faults = MarlinFaults(FaultConfig.parse("host.corrupt=2e-4"), seed=1)
    c0 = time.process_time()
    r = stream(unit, job, faults=faults)
    cpu = time.process_time() - c0
    return {"lines": n, "cpu_s": round(cpu, 3), "lines_per_cpu_s": round(n / cpu),
            "virtual_s": round(r.end, 1), "virtual_per_cpu_s": round(r.end / cpu, 1),
            "resends": len(unit.truth.resends)}


def host_chunks(m: int) -> Iterator[tuple[float, bytes]]:
    """The host side of the synthetic traffic, made as it is read (nothing held)."""
    from conform.families.marlin.protocol.codec import frame

    t, n = 0.0, 1
    for i in range(1, m + 1):
        yield t, frame(n, f"G1 X{(i - 1) % 50}.{(i - 1) % 7} Y{(i - 1) % 13} F9000")
        t += 0.002
        n += i % 500 != 0          # a rejected line's number is used again


def unit_chunks(m: int) -> Iterator[tuple[float, bytes]]:
    """The unit side: every 500th line answered Error/Resend:, a busy: every 997 lines."""
    t, n = 0.0, 1
    for i in range(1, m + 1):
        t += 0.002
        if i % 500 == 0:
            yield t, b"Error:checksum mismatch, Last Line: %d\nResend: %d\nok\n" % (n - 1, n)
            continue
        if i % 997 == 0:
            yield t, b"echo:busy: processing\n"
        yield t + 0.001, b"ok\n"
        n += 1


def synthetic(m: int) -> tuple[list[tuple[float, bytes]], list[tuple[float, bytes]]]:
    """Both sides as lists (small sizes, for comparing analyses)."""
    return list(host_chunks(m)), list(unit_chunks(m))


def analyse_child(m: int) -> None:
    from conform.families.marlin.analysis.analyze import analyze_streams

    c0 = time.process_time()
    for _ in chain(host_chunks(m), unit_chunks(m)):   # what making the traffic costs alone
        pass
    gen = time.process_time() - c0
    c0 = time.process_time()
    a = analyze_streams(host_chunks(m), unit_chunks(m))
    cpu = time.process_time() - c0 - gen
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({"lines": m, "cpu_s": round(cpu, 2), "us_per_line": round(cpu / m * 1e6, 2),
                      "peak_mb": round(peak), "resends": a.metrics["resends"],
                      "accepted": a.metrics["accepted"]}))


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--emulate", type=int, default=20_000)
    p.add_argument("--analyse", type=int, nargs="*", default=[1_000_000, 2_000_000])
    p.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    ns = p.parse_args()
    if ns.child:
        analyse_child(ns.child)
        return
    emu = emulate(ns.emulate)
    print(f"emulator: {emu['lines']} lines in {emu['cpu_s']} CPU s = {emu['lines_per_cpu_s']} "
          f"lines/CPU s; {emu['virtual_s']} virtual s ({emu['virtual_per_cpu_s']}x real time), "
          f"{emu['resends']} resends")
    sizes = []
    for m in ns.analyse:
        out = subprocess.run([sys.executable, __file__, "--child", str(m)], capture_output=True,
                             text=True, check=True).stdout.strip().splitlines()[-1]
        r = json.loads(out)
        sizes.append(r)
        print(f"analysis: {m} lines in {r['cpu_s']} CPU s ({r['us_per_line']} µs/line), peak "
              f"{r['peak_mb']} MB")
    print(json.dumps({"emulator": emu, "analysis": sizes}))


if __name__ == "__main__":
    main()
