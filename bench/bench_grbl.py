"""Benchmark: the grbl reference unit and the grbl analyser on a long streamed job.

A character-counting sender streams N short moves (with a '?' every 0.2 s) to the grbl
reference unit in virtual time; then the traffic is analysed in-process. Prints the CPU time
of each phase, lines per CPU second, the virtual job time, and the ratio to the targets:
the unit simulates at least 20x faster than real time, the analyser takes at least
100 000 lines per second. The last line is one JSON object.

    python bench/bench_grbl.py                # 20 000 lines
    python bench/bench_grbl.py --lines 5000 --repeat 3
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from conform.families.grbl.analysis.analyze import analyze_streams  # noqa: E402
from conform.families.grbl.analysis.streaming import stream  # noqa: E402
from conform.families.grbl.spec.load import load_grbl  # noqa: E402
from conform.families.grbl.unit.model import GrblUnit  # noqa: E402

REALTIME_TARGET = 20.0      # virtual seconds per CPU second
ANALYSIS_TARGET = 100_000   # lines per CPU second


def one(n: int) -> dict[str, float]:
    g = load_grbl()
    v = g.variant("grbl-1.1f")
    job = [f"G1X{-(i % 40) * 0.05:.3f}Y{-(i % 13) * 0.04:.3f}F3000" for i in range(n)]
    unit = GrblUnit(v, g, settings={110: 5000.0, 111: 5000.0, 120: 500.0, 121: 500.0})
    unit.poll(0.0)
    c0 = time.process_time()
    traffic = stream(unit, job, method="counting", poll=0.2, timeout=1e6)
    c1 = time.process_time()
    a = analyze_streams(traffic.host, traffic.unit)
    c2 = time.process_time()
    assert a.metrics["answered"] == n and a.metrics["hazards"] == 0
    return {"unit_cpu_s": c1 - c0, "virtual_s": traffic.end, "analysis_cpu_s": c2 - c1}


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--lines", type=int, default=20000)
    p.add_argument("--repeat", type=int, default=3)
    ns = p.parse_args()
    if ns.lines < 1 or ns.repeat < 1:
        p.error("--lines and --repeat must be at least 1")
    runs = [one(ns.lines) for _ in range(ns.repeat)]
    unit_cpu = statistics.median(r["unit_cpu_s"] for r in runs)
    ana_cpu = statistics.median(r["analysis_cpu_s"] for r in runs)
    virtual = runs[0]["virtual_s"]
    speed = virtual / unit_cpu
    rate = ns.lines / ana_cpu
    speed_ratio = speed / REALTIME_TARGET
    rate_ratio = rate / ANALYSIS_TARGET
    print(f"unit: {ns.lines} lines, {virtual:.1f} s of machine time in {unit_cpu:.2f} s CPU "
          f"(median of {ns.repeat}): {speed:.1f}x real time; target {REALTIME_TARGET:g}x, "
          f"ratio {speed_ratio:.2f}")
    print(f"analysis: {ana_cpu:.3f} s CPU: {rate:,.0f} lines/s; target {ANALYSIS_TARGET:,}, "
          f"ratio {rate_ratio:.2f}")
    print(json.dumps({"lines": ns.lines, "repeat": ns.repeat, "unit_cpu_s": round(unit_cpu, 3),
                      "virtual_s": round(virtual, 3), "realtime_factor": round(speed, 2),
                      "realtime_target": REALTIME_TARGET, "realtime_ratio": round(speed_ratio, 3),
                      "analysis_cpu_s": round(ana_cpu, 3), "analysis_lines_per_s": round(rate),
                      "analysis_target": ANALYSIS_TARGET, "analysis_ratio": round(rate_ratio, 3)}))


if __name__ == "__main__":
    main()
