"""Benchmarks of the reference unit (not a test): prints figures and their ratio to target.

1. In-process throughput of C vectors through parse + model + answer (target >= 140 000/s on
   one core): a sender keeps the queue fed; every line is a fresh C vector, the queue-full
   retries (answer 1) are counted apart.
2. Virtual-time simulation of a 1 000 000-vector job (target <= 20 s, <= 1 GB): the same
   sender on a 115 200 Bd line (wire time advances the virtual clock), to the end of motion.

    python bench/bench_unit.py [--variant gve64-v19] [--vectors 1000000] [--throughput 300000]
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import sys
import time

from conform.families.gve.spec import load_spec
from conform.families.gve.unit import Unit

TARGET_RATE = 140_000
TARGET_JOB_S = 20.0
TARGET_JOB_MB = 1024.0


def make_lines(n: int, naxes: int) -> list[bytes]:
    """A circle cut into short C vectors (the shape of an engraving job)."""
    out = []
    r = 20000.0
    px = py = 0
    for i in range(1, n + 1):
        a = 2 * math.pi * i / n
        x, y = round(r * math.cos(a)), round(r * math.sin(a))
        dx, dy = x - px, y - py
        px, py = x, y
        out.append(b"!0C%d,%d,%d\r" % (dx, dy, i % 3 - 1) if naxes else b"")
    return out


def throughput(unit: Unit, lines: list[bytes], count: int, peek: bool) -> tuple[float, int, int]:
    """(seconds, accepted vectors, queue-full answers) for ``count`` accepted vectors.

    With ``peek`` the sender looks at the queue length (in-process) and lets virtual time run
    to the next vector end before sending into a full queue, so every line is accepted;
    without it, it sends blindly and waits after each answer 1 (one retry per vector).
    """
    exchange = unit.exchange
    nd = unit.next_deadline
    ex = unit.executor
    cap = unit.variant.queue
    n = len(lines)
    t = 0.0
    accepted = full = 0
    start = time.perf_counter()
    while accepted < count:
        if peek and ex.queue_len >= cap:
            t = nd()
        line = lines[accepted % n]
        t, ans = exchange(line, t)
        if ans[0] == 0x31:  # "1": queue full; wait for the next vector to finish
            full += 1
            te = nd()
            if te is not None and te > t:
                t = te
            continue
        accepted += 1
    return time.perf_counter() - start, accepted, full


def job(unit: Unit, lines: list[bytes], count: int, baud: int) -> tuple[float, float, int, int]:
    """(wall seconds, virtual seconds, vectors, retries) of a whole job on a paced line."""
    exchange = unit.exchange
    nd = unit.next_deadline
    n = len(lines)
    per_byte = 10.0 / baud
    t = 0.0
    sent = retries = 0
    start = time.perf_counter()
    while sent < count:
        line = lines[sent % n]
        t, ans = exchange(line, t + len(line) * per_byte)
        t += len(ans) * per_byte
        if ans[0] == 0x31:
            retries += 1
            te = nd()
            if te is not None and te > t:
                t = te
            continue
        sent += 1
    while unit.queue_len:
        te = nd()
        if te is None:
            break
        t = max(t, te)
        unit.poll(t)
    return time.perf_counter() - start, t, sent, retries


def main(argv: list[str] | None = None) -> int:
    spec = load_spec()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variant", default="gve64-v19", choices=list(spec.variants))
    ap.add_argument("--vectors", type=int, default=1_000_000)
    ap.add_argument("--throughput", type=int, default=300_000)
    ap.add_argument("--baud", type=int, default=115200)
    args = ap.parse_args(argv)
    if args.vectors < 1 or args.throughput < 1 or args.baud < 1:
        ap.error("--vectors, --throughput and --baud must be at least 1")
    variant = spec.variant(args.variant)
    lines = make_lines(3600, len(variant.axes))
    result: dict = {"variant": variant.id, "target_rate": TARGET_RATE}

    for peek in (True, False):
        unit = Unit(variant)
        for setup in (b"!0V20000\r", b"!0A200\r", b"!0B5000\r", b"!0$200\r"):
            unit.exchange(setup, 0.0)
        secs, accepted, full = throughput(unit, lines, args.throughput, peek)
        rate = accepted / secs
        lines_rate = (accepted + full) / secs
        ratio = rate / TARGET_RATE
        key = "fed" if peek else "blind"
        result.update({f"{key}_accepted": accepted, f"{key}_seconds": round(secs, 3),
                       f"{key}_queue_full": full, f"{key}_vectors_per_s": round(rate),
                       f"{key}_lines_per_s": round(lines_rate), f"{key}_ratio": round(ratio, 3)})
        how = "fed to room " if peek else "blind+retry "
        print(f"throughput  {variant.id} {how}: {accepted:,} C vectors accepted and executed "
              f"in {secs:.2f} s ({full:,} queue-full answers besides) = {rate:,.0f} vectors/s, "
              f"{lines_rate:,.0f} lines/s; target >= {TARGET_RATE:,}/s: "
              f"ratio {ratio:.2f}")

    unit = Unit(variant)
    for setup in (b"!0V20000\r", b"!0A200\r", b"!0B5000\r", b"!0$200\r"):
        unit.exchange(setup, 0.0)
    wall, virtual, sent, retries = job(unit, lines, args.vectors, args.baud)
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    job_ratio = wall / TARGET_JOB_S
    rss_ratio = rss_mb / TARGET_JOB_MB
    print(f"job         {variant.id}: {sent:,} vectors ({retries:,} retries) at {args.baud} Bd, "
          f"{virtual / 3600:.2f} h of machining simulated in {wall:.1f} s wall "
          f"(target <= {TARGET_JOB_S:.0f} s: ratio {job_ratio:.2f}); "
          f"peak RSS {rss_mb:.0f} MB (target <= {TARGET_JOB_MB:.0f} MB: "
          f"ratio {rss_ratio:.2f}); starvations {unit.executor.starvations}")
    result.update({"job_vectors": sent, "job_retries": retries, "baud": args.baud,
                   "job_virtual_s": round(virtual, 3), "job_wall_s": round(wall, 3),
                   "job_target_s": TARGET_JOB_S, "job_ratio": round(job_ratio, 4),
                   "peak_rss_mb": round(rss_mb, 1), "rss_target_mb": TARGET_JOB_MB,
                   "rss_ratio": round(rss_ratio, 4),
                   "starvations": unit.executor.starvations})
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
