"""The recorder's writer path in one thread: decode, batch, JSON-encode and compress.

Feeds ``BatchSession`` (decoding on) and ``McapSink`` with the traffic of
bench_capture_throughput.py — a sender's reads every 10 ms at 92 160 B/s, the unit's
answers in two reads — with made-up times, no pty and no threads, and reports the CPU per
second of traffic. It isolates the writer thread's share of ``conform proxy``'s CPU from
the pumps and the machine's load (less noisy than the end-to-end bench); ``--profile``
prints where the time goes.

    python bench/bench_capture_writer.py --seconds 20 [--profile]
"""

from __future__ import annotations

import argparse
import io
import json
import time
from collections.abc import Iterator

from bench_capture_throughput import TARGET_RATE, command_stream

from conform.capture.batch import BatchSession
from conform.capture.sink import McapSink
from conform.families.gve.decode import make_decoder

TICK = 0.01  # the throughput bench's sender writes every 10 ms
FLUSH_INTERVAL = 0.25  # the recorder's default


def reads(seconds: float, rate: int = TARGET_RATE) -> Iterator[tuple[str, bytes, float, float]]:
    """(direction, bytes, t_read, t_first) as the proxy's pumps would hand them over."""
    lines = command_stream()
    t, sent = 1.75e9, 0
    for k in range(round(seconds / TICK)):
        target = int((k + 1) * TICK * rate)
        block = bytearray()
        while sent + len(block) < target:
            block += next(lines)
        sent += len(block)
        t += TICK
        yield "host", bytes(block), t, t
        n = block.count(b"\r")
        yield "unit", b"0\r" * (n // 2), t + 0.002, t + 0.001
        yield "unit", b"0\r" * (n - n // 2), t + 0.004, t + 0.003


def record(items: list[tuple[str, bytes, float, float]]) -> tuple[bytes, int]:
    """The MCAP bytes the writer would produce, and how many messages."""
    session = BatchSession(baud=921600, decoder=make_decoder("gve64-v19", baud=921600))
    out = io.BytesIO()
    sink = McapSink(out)
    next_flush = items[0][2] + FLUSH_INTERVAL
    for item in items:
        for rec in session.chunk(*item):
            sink.write(rec)
        if item[2] >= next_flush:
            for rec in session.flush():
                sink.write(rec)
            sink.flush()
            next_flush = item[2] + FLUSH_INTERVAL
    for rec in session.finish(items[-1][2]):
        sink.write(rec)
    sink.finish()
    return out.getvalue(), sink.count


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="seconds of traffic")
    ap.add_argument("--profile", action="store_true", help="print a cProfile of the run")
    args = ap.parse_args()
    items = list(reads(args.seconds))
    if args.profile:
        import cProfile
        import pstats

        prof = cProfile.Profile()
        prof.runcall(record, items)
        pstats.Stats(prof).sort_stats("tottime").print_stats(20)
    t0 = time.process_time()
    data, messages = record(items)
    cpu = time.process_time() - t0
    lines = sum(item[1].count(b"\r") for item in items if item[0] == "host")
    per_s = cpu / args.seconds
    print(f"{args.seconds:g} s of traffic: {lines:,} command lines, {len(items):,} reads, "
          f"{messages} messages, {len(data) / 1e6:.1f} MB")
    print(f"writer CPU {cpu:.3f} s: {per_s:.4f} core-s per s of traffic "
          f"({cpu / lines * 1e6:.2f} us per command and its answer)")
    print(json.dumps({"seconds": args.seconds, "lines": lines, "reads": len(items),
                      "messages": messages, "capture_mb": round(len(data) / 1e6, 2),
                      "writer_cpu_s": round(cpu, 3), "writer_cpu_per_s": round(per_s, 4)}))


if __name__ == "__main__":
    main()
