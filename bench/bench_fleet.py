"""Benchmark: a fleet of captures analysed at once (``conform analyze DIR``).

Makes ``--files`` synthetic captures (the session of bench_analysis.py, ``--exchanges``
each, spread over ``--machines`` machine folders), then analyses the folder on every local
core (or ``--jobs N``; ``--scheduler ADDRESS`` for Dask distributed) into one Parquet
dataset and the fleet summary. Prints wall time, CPU of the workers, throughput, the
speed-up over one process (``--serial`` runs that side by side) and, last, one JSON object.

    python bench/bench_fleet.py --files 20 --exchanges 50000
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))


def make_fleet(root: Path, files: int, machines: int, exchanges: int) -> None:
    from bench_analysis import make_capture

    for i in range(files):
        d = root / f"machine-{i % machines:02d}"
        d.mkdir(parents=True, exist_ok=True)
        make_capture(d / f"shift-{i // machines:02d}.mcap", exchanges, seed=i + 1)


def run(root: Path, out: Path, jobs: int | None, scheduler: str | None) -> dict:
    from conform.analysis.fleet import analyze_fleet, write_fleet_report

    shutil.rmtree(out, ignore_errors=True)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu0 = time.process_time()
    t = time.perf_counter()
    summary = analyze_fleet([str(root)], parquet_dir=str(out / "tables"), jobs=jobs,
                            scheduler=scheduler)
    write_fleet_report(summary, out / "report")
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
           + time.process_time() - cpu0)
    return {"wall_s": wall, "cpu_s": cpu, "summary": summary,
            "worker_peak_rss_mb": after.ru_maxrss / 1024}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", type=int, default=20)
    ap.add_argument("--machines", type=int, default=5)
    ap.add_argument("--exchanges", type=int, default=50_000, help="per capture")
    ap.add_argument("--jobs", type=int, default=None, help="local processes (default: cores)")
    ap.add_argument("--scheduler", default=None, help="Dask distributed scheduler address")
    ap.add_argument("--serial", action="store_true", help="also run on one process")
    ap.add_argument("--keep", type=Path, default=None, help="keep the fleet folder here")
    args = ap.parse_args()

    root = args.keep or Path(tempfile.mkdtemp(prefix="bench-fleet-")) / "fleet"
    if not root.exists():
        t = time.perf_counter()
        make_fleet(root, args.files, args.machines, args.exchanges)
        print(f"made {args.files} captures of {args.exchanges} exchanges in "
              f"{time.perf_counter() - t:.1f} s under {root}")
    out = root.parent / "fleet-out"
    par = run(root, out, args.jobs, args.scheduler)
    s = par["summary"]
    total = s["totals"]["exchanges"]
    jobs = args.jobs or os.cpu_count() or 1
    where = f"Dask at {args.scheduler}" if args.scheduler else f"{jobs} local processes"
    print(f"fleet: {s['totals']['sessions']} captures, {s['totals']['machines']} machines, "
          f"{total} exchanges, {s['totals']['errors']} errors ({where})")
    print(f"parallel: {par['wall_s']:.2f} s wall, {par['cpu_s']:.2f} s CPU, "
          f"{total / par['wall_s']:,.0f} exchanges/s, worker peak {par['worker_peak_rss_mb']:.0f} MB")
    result = {"files": s["totals"]["sessions"], "machines": s["totals"]["machines"],
              "exchanges": total, "errors": s["totals"]["errors"], "jobs": jobs,
              "scheduler": args.scheduler, "wall_s": round(par["wall_s"], 3),
              "cpu_s": round(par["cpu_s"], 3),
              "exchanges_per_s": round(total / par["wall_s"]),
              "worker_peak_rss_mb": round(par["worker_peak_rss_mb"], 1)}
    if args.serial:
        ser = run(root, out, 1, None)
        speedup = ser["wall_s"] / par["wall_s"]
        print(f"one process: {ser['wall_s']:.2f} s wall; speed-up {speedup:.2f}x on {jobs} "
              f"(ideal {jobs}x, ratio {speedup / jobs:.2f})")
        result.update(serial_wall_s=round(ser["wall_s"], 3), speedup=round(speedup, 3),
                      ideal_speedup=jobs, speedup_ratio=round(speedup / jobs, 3))
    if args.keep is None:
        shutil.rmtree(root.parent, ignore_errors=True)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
