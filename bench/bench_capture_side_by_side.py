"""The throughput bench on two checkouts of conform, alternating, in one sitting.

A shared, loaded machine moves the recorder's CPU figure by a quarter from one run to the
next; alternating runs of this checkout's code and another's (e.g. main's, from ``git
worktree add ../base main --detach``) and comparing medians gives a ratio that the load
does not decide. Each run is ``bench/bench_capture_throughput.py`` of that checkout, with
that checkout on ``PYTHONPATH`` (its proxy and its recorder).

    python bench/bench_capture_side_by_side.py --base ../base --seconds 20 --runs 3
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
TARGET_CPU = 0.35  # core-s of the proxy per s of traffic (bench_capture_throughput.py)
KEYS = ("recorder_cpu_per_s", "writer_thread_cpu_per_s", "lost_bytes", "stop_s")


def run(checkout: Path, seconds: float) -> dict:
    """One throughput run of ``checkout``'s code: its JSON last line."""
    proc = subprocess.run(
        [sys.executable, str(checkout / "bench" / "bench_capture_throughput.py"),
         "--seconds", str(seconds)],
        cwd=checkout, env=dict(os.environ, PYTHONPATH=str(checkout)), capture_output=True,
        text=True, timeout=seconds + 180)
    lines = proc.stdout.strip().splitlines()
    if proc.returncode or not lines:
        raise SystemExit(f"{checkout}: bench failed ({proc.returncode}): {proc.stderr[-2000:]}")
    return json.loads(lines[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=Path, required=True, help="the other checkout (e.g. main's)")
    ap.add_argument("--seconds", type=float, default=20.0, help="seconds of traffic per run")
    ap.add_argument("--runs", type=int, default=3, help="runs of each, alternating")
    args = ap.parse_args()
    sides = {"base": args.base.resolve(), "this": HERE}
    results: dict[str, list[dict]] = {name: [] for name in sides}
    for i in range(args.runs):
        for name, checkout in sides.items():
            r = run(checkout, args.seconds)
            results[name].append(r)
            load = os.getloadavg()[0]
            print(f"run {i + 1} {name:4}: recorder {r['recorder_cpu_per_s']:.3f} core-s/s, "
                  f"writer {r['writer_thread_cpu_per_s']}, lost {r['lost_bytes']}, "
                  f"stop {r['stop_s']:.2f} s (load {load:.2f})", flush=True)
    medians = {name: {k: statistics.median(float(r[k]) for r in rs if r[k] is not None)
                      for k in KEYS} for name, rs in results.items()}
    ratio = medians["this"]["recorder_cpu_per_s"] / medians["base"]["recorder_cpu_per_s"]
    for name in sides:
        m = medians[name]
        print(f"median {name:4}: recorder {m['recorder_cpu_per_s']:.3f} core-s/s (target "
              f"<= {TARGET_CPU}, ratio {m['recorder_cpu_per_s'] / TARGET_CPU:.2f}), writer "
              f"{m['writer_thread_cpu_per_s']:.3f}, stop {m['stop_s']:.2f} s, "
              f"lost at most {max(r['lost_bytes'] for r in results[name])}")
    print(f"this / base: {ratio:.3f}")
    print(json.dumps({"seconds": args.seconds, "runs": args.runs, "base": str(sides["base"]),
                      "median": medians, "cpu_ratio_to_base": round(ratio, 3),
                      "cpu_ratio_to_target": round(medians["this"]["recorder_cpu_per_s"]
                                                   / TARGET_CPU, 3),
                      "lost_bytes": max(r["lost_bytes"] for rs in results.values() for r in rs),
                      "runs_raw": {name: [{k: r[k] for k in KEYS} for r in rs]
                                   for name, rs in results.items()}}))


if __name__ == "__main__":
    main()
