"""Benchmark of the motion executor (conform.families.gve.unit.motion) in virtual time.

Three figures, each printed with its target and the ratio to it:

1. a 1 000 000-vector C job (a polyline circle of short C vectors), the queue kept full,
   time advanced event by event: wall time (target <= 20 s) and peak RSS (target <= 1 GB);
2. raw ``push`` throughput into a queue that is never drained;
3. the unit model's pattern per received C command: ``advance(t)``, check ``queue_len``,
   ``push`` (or refuse with "queue full"); commands arrive as fast as vectors finish, so
   nearly every one is accepted and completes a vector (the accepting path, planning included);
   its target is the 140 000 C vectors/s the whole parse+model+answer path must reach.

Run: ``python bench/bench_motion.py`` (``--vectors N`` for a shorter job, ``--ops N`` for
fewer timed pushes and commands, ``--tracemalloc`` to also measure Python allocations of a
100 000-vector job).
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import sys
import time
import tracemalloc

from conform.families.gve.unit.motion import MotionExecutor, MotionParams

JOB_TARGET_S = 20.0
RSS_TARGET_MB = 1024.0
MODEL_TARGET_PER_S = 140_000.0


def circle(segments: int, radius: int) -> list[tuple[int, int, int, int]]:
    """Relative C vectors of a closed polygon; they sum to zero exactly."""
    pts = [(round(radius * math.cos(2 * math.pi * i / segments)),
            round(radius * math.sin(2 * math.pi * i / segments))) for i in range(segments)]
    pts.append(pts[0])
    return [(pts[i + 1][0] - pts[i][0], pts[i + 1][1] - pts[i][1], 0, 0)
            for i in range(segments)]


def params() -> MotionParams:
    # V20000 A200 B15000 $512 T5: short vectors at B, like a host that brakes for corners.
    return MotionParams(v=20_000.0, a=200_000.0, b=15_000.0, short=512, pause=0.005)


def run_job(n_vectors: int, segs: list) -> tuple[float, MotionExecutor]:
    """Keep the queue full, advance to each completion; return wall seconds and executor."""
    ex = MotionExecutor(axes=4, capacity=420, max_rate=125_000, params=params())
    push = ex.push
    advance = ex.advance
    next_event = ex.next_event_time
    cap = ex.capacity
    n = len(segs)
    pushed = 0
    t0 = time.perf_counter()
    while True:
        room = cap - ex.queue_len
        while room and pushed < n_vectors:
            push(segs[pushed % n])
            pushed += 1
            room -= 1
        t = next_event()
        if t is None:
            break
        advance(t)
    return time.perf_counter() - t0, ex


def push_rate(n: int, segs: list) -> float:
    ex = MotionExecutor(capacity=n + 1, params=params())
    push = ex.push
    m = len(segs)
    t0 = time.perf_counter()
    for i in range(n):
        push(segs[i % m])
    return n / (time.perf_counter() - t0)


def model_pattern_rate(n_cmds: int, segs: list, dt: float) -> tuple[float, int]:
    """advance + queue check + push per command, one command every ``dt`` of virtual time."""
    ex = MotionExecutor(capacity=420, max_rate=125_000, params=params())
    push = ex.push
    advance = ex.advance
    cap = ex.capacity
    m = len(segs)
    accepted = 0
    t0 = time.perf_counter()
    for i in range(n_cmds):
        advance(i * dt)
        if ex.queue_len < cap:
            push(segs[accepted % m])
            accepted += 1
    return n_cmds / (time.perf_counter() - t0), accepted


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vectors", type=int, default=1_000_000)
    ap.add_argument("--ops", type=int, default=1_000_000,
                    help="pushes and model-pattern commands timed")
    ap.add_argument("--tracemalloc", action="store_true")
    args = ap.parse_args(argv)
    if args.vectors < 1 or args.ops < 1:
        ap.error("--vectors and --ops must be at least 1")

    segs = circle(10_000, 200_000)          # chords of about 126 pulses: short vectors
    wall, ex = run_job(args.vectors, segs)
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    scale = args.vectors / 1_000_000
    target = JOB_TARGET_S * scale
    job_rate = args.vectors / wall
    job_ratio = wall / target
    rss_ratio = rss_mb / RSS_TARGET_MB
    print(f"job: {args.vectors} C vectors in {wall:.2f} s wall "
          f"({job_rate:,.0f} vectors/s), virtual time {ex.now:.1f} s, "
          f"final position {ex.position}, starvations {ex.starvations}")
    print(f"  target <= {target:.1f} s: ratio {job_ratio:.3f} "
          f"({'OK' if wall <= target else 'MISSED'})")
    print(f"  peak RSS {rss_mb:.0f} MB, target <= {RSS_TARGET_MB:.0f} MB: ratio "
          f"{rss_ratio:.3f} ({'OK' if rss_mb <= RSS_TARGET_MB else 'MISSED'})")

    rate = push_rate(args.ops, segs)
    push_share = MODEL_TARGET_PER_S / rate
    print(f"push: {rate:,.0f} pushes/s ({1e6 / rate:.2f} us each); "
          f"share of a {MODEL_TARGET_PER_S:,.0f}/s command budget: "
          f"{push_share:.3f}")

    cmd_rate, accepted = model_pattern_rate(args.ops, segs, ex.now / args.vectors)
    model_ratio = cmd_rate / MODEL_TARGET_PER_S
    model_share = MODEL_TARGET_PER_S / cmd_rate
    print(f"model pattern (advance + queue_len + push): {cmd_rate:,.0f} commands/s, "
          f"{accepted} accepted; ratio to {MODEL_TARGET_PER_S:,.0f}/s: "
          f"{model_ratio:.2f}x (executor share of the budget "
          f"{model_share:.3f})")

    peak = None
    if args.tracemalloc:
        tracemalloc.start()
        run_job(100_000, segs)
        _cur, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        print(f"tracemalloc: 100000-vector job peak Python allocations {peak / 1e6:.2f} MB")
    ok = wall <= target and rss_mb <= RSS_TARGET_MB
    print(json.dumps({
        "vectors": args.vectors, "job_wall_s": round(wall, 3), "job_vectors_per_s": round(job_rate),
        "virtual_s": round(ex.now, 3), "final_position": list(ex.position),
        "starvations": ex.starvations, "job_target_s": target, "job_ratio": round(job_ratio, 4),
        "peak_rss_mb": round(rss_mb, 1), "rss_target_mb": RSS_TARGET_MB,
        "rss_ratio": round(rss_ratio, 4), "ops": args.ops, "push_per_s": round(rate),
        "push_us": round(1e6 / rate, 4), "push_budget_share": round(push_share, 4),
        "model_commands_per_s": round(cmd_rate), "model_accepted": accepted,
        "model_target_per_s": MODEL_TARGET_PER_S, "model_ratio": round(model_ratio, 3),
        "model_budget_share": round(model_share, 4),
        "tracemalloc_peak_mb": None if peak is None else round(peak / 1e6, 3), "ok": ok}))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
