"""Benchmark: analyse a synthetic capture of N exchanges (default 1 000 000).

Targets (issue 11): at most 6 s of CPU for 1 000 000 exchanges, at most 700 MB of peak
memory, and no more than 20 % more memory at 2 000 000 (memory that does not grow with
the capture). Prints the figures, the ratio to each target and, last, one JSON object.

    python bench/bench_analysis.py --exchanges 1000000 --keep /tmp/b1m.mcap
    python bench/bench_analysis.py --exchanges 2000000 --keep /tmp/b2m.mcap

The synthetic session is a sender streaming C vectors with checksums on at 115200 baud:
answers ``0``, runs of queue-full ``1`` polls, a ``PF`` every 200 exchanges. With
``--halts K`` the operator also pauses the machine every K exchanges (``H``, half a second,
``G``), which the queue replay follows through the motion executor, with vectors short
enough for the modelled queue to stay within the unit's capacity:

    python bench/bench_analysis.py --exchanges 1000000 --halts 50000 --keep /tmp/h1m.mcap
 It is written
the way the recorder writes a capture without a decoder (format 2: raw batches only), so
the analyser has to decode everything from the bytes. The analysis runs in its own process
so that its CPU time and peak memory (ru_maxrss) are its own.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

BAUD = 115200
T0 = 1_750_000_000.0


def _cs(body: bytes) -> bytes:
    head = body + b","
    return head + b"%02X" % (sum(head) & 0xFF)


def make_capture(path: Path, n: int, seed: int = 1, halts: int = 0) -> None:
    """Write the synthetic session in the recorder's format 2 (raw batches only); a halt
    and go every ``halts`` exchanges when given."""
    from conform.capture.batch import raw_batch
    from conform.capture.sink import McapSink

    rng = random.Random(seed)
    byte_t = 10.0 / BAUD
    with open(path, "wb") as f:
        sink = McapSink(f, chunk_size=1 << 20)
        sink.metadata("conform.session", {"capture_method": "bench synthetic",
                                          "variant": "gve64-v19", "baud": BAUD,
                                          "format_version": "2"})
        t = T0
        pos = [0, 0]
        # per direction: stream offset of the batch, bytes, lengths, t_read, t_first, order
        batch = {d: [0, bytearray(), [], [], [], []] for d in ("host", "unit")}
        count = [0]

        def flush() -> None:
            for d, b in batch.items():
                if b[2]:
                    sink.write(raw_batch(d, *b))
                    batch[d] = [b[0] + len(b[1]), bytearray(), [], [], [], []]

        def read(d: str, data: bytes, t_first: float, t_read: float) -> None:
            b = batch[d]
            b[1] += data
            b[2].append(len(data))
            b[3].append(t_read)
            b[4].append(t_first)
            b[5].append(count[0])
            count[0] += 1

        def exchange(cmd: bytes, ans: bytes, unit_s: float = 0.0003,
                     host_s: float = 0.0002) -> None:
            nonlocal t
            end = t + len(cmd) * byte_t
            read("host", cmd, t, end)
            a0 = end + unit_s
            a1 = a0 + len(ans) * byte_t
            read("unit", ans, a0, a1)
            t = a1 + host_s
            if count[0] % 8192 == 0:
                flush()

        exchange(b"!0%+\r", _cs(b"0") + b"\r")
        exchange(_cs(b"!0V20000") + b"\r", _cs(b"0") + b"\r")
        done = 2
        rnd = rng.random
        lines: dict[tuple[int, int], bytes] = {}
        ok = _cs(b"0") + b"\r"
        # with halts, short vectors: the queue the replay models then stays within the
        # unit's capacity, as a real unit's does (the long ones outrun the answers: the
        # throughput run does not mind, a replay that follows H and G through the motion
        # executor would carry an ever longer queue)
        span = 30 if halts else 400
        while done < n:
            if halts and done % halts == 0 and done < n - 1:
                exchange(_cs(b"!0H") + b"\r", ok)
                t += 0.5
                exchange(_cs(b"!0G") + b"\r", ok)
                done += 2
                continue
            if done % 200 == 0:
                exchange(_cs(b"!0PF") + b"\r",
                         _cs(b"0,%d,%d,0" % tuple(pos)) + b"\r")
                done += 1
                continue
            dx, dy = int(rnd() * (2 * span + 1)) - span, int(rnd() * (2 * span + 1)) - span
            line = lines.get((dx, dy))
            if line is None:
                line = lines[dx, dy] = _cs(b"!0C%d,%d,0" % (dx, dy)) + b"\r"
            if rnd() < 0.01:  # a run of queue-full polls
                for _ in range(rng.randint(1, 8)):
                    if done >= n - 1:
                        break
                    exchange(line, _cs(b"1") + b"\r")
                    done += 1
            exchange(line, ok)
            pos[0] += dx
            pos[1] += dy
            done += 1
        flush()
        sink.finish()


def bare_iteration(path: str) -> dict:
    from mcap.reader import make_reader

    t = time.perf_counter()
    n = 0
    with open(path, "rb") as f:
        for _schema, _channel, _message in make_reader(f).iter_messages():
            n += 1
    return {"seconds": time.perf_counter() - t, "messages": n}


def analysis(path: str) -> dict:
    from conform.families.gve.analysis import analyze

    t = time.perf_counter()
    cpu0 = time.process_time()
    steps: dict[str, float] = {}
    peaks: dict[str, float] = {}  # peak RSS (MB) reached by the end of each step
    last = [time.process_time(), "start"]

    def step(name: str) -> None:
        now = time.process_time()
        steps[last[1]] = now - last[0]
        peaks[last[1]] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        last[:] = [now, name]

    a = analyze(path, step=step)
    step("end")
    return {"seconds": time.perf_counter() - t, "cpu_s": time.process_time() - cpu0,
            "exchanges": int(a.metrics["exchanges"]),
            "vectors": int(a.metrics["vectors_accepted"]), "steps": steps, "peaks": peaks,
            "findings": a.metrics["finding_counts"]}


def _child(kind: str, path: str) -> None:
    out = bare_iteration(path) if kind == "bare" else analysis(path)
    out["max_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps(out))


def _run(kind: str, path: Path) -> dict:
    r = subprocess.run([sys.executable, __file__, "--child", kind, str(path)],
                       capture_output=True, text=True, check=True, cwd=ROOT)
    return json.loads(r.stdout.strip().splitlines()[-1])


TARGET_CPU_1M = 6.0  # s of CPU for 1 000 000 exchanges (scaled linearly for other sizes)
TARGET_RSS_MB = 700.0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--exchanges", type=int, default=1_000_000)
    ap.add_argument("--keep", type=Path, default=None, help="capture path to reuse/keep")
    ap.add_argument("--halts", type=int, default=0, help="an H ... G every this many exchanges")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        _child(*args.child)
        return
    path = args.keep or Path(tempfile.mkdtemp(prefix="bench-analysis-")) / "synthetic.mcap"
    make_rate = None
    if not path.exists():
        t = time.perf_counter()
        make_capture(path, args.exchanges, halts=args.halts)
        dt = time.perf_counter() - t
        make_rate = args.exchanges / dt
        print(f"made {path} ({path.stat().st_size / 1e6:.1f} MB) in {dt:.1f} s "
              f"({make_rate:,.0f} exchanges/s; target >= 100 000)")
    size = path.stat().st_size / 1e6
    ana = _run("analysis", path)
    target_cpu = TARGET_CPU_1M * ana["exchanges"] / 1e6
    cpu_ratio = ana["cpu_s"] / target_cpu if target_cpu else None
    rss_ratio = ana["max_rss_mb"] / TARGET_RSS_MB
    print(f"capture: {path} {size:.1f} MB, {ana['exchanges']} exchanges, "
          f"{ana['vectors']} vectors accepted")
    print(f"analysis: {ana['cpu_s']:.2f} s CPU ({ana['seconds']:.2f} s wall), "
          f"{ana['max_rss_mb']:.0f} MB peak")
    print("  CPU by step: " + ", ".join(f"{k} {v:.2f} s" for k, v in ana["steps"].items()))
    print("  peak memory by the end of each step: "
          + ", ".join(f"{k} {v:.0f} MB" for k, v in ana["peaks"].items()))
    print(f"  findings: {ana['findings']}")
    print(f"CPU     {ana['cpu_s']:.2f} s / {target_cpu:.2f} s target: ratio "
          f"{cpu_ratio:.2f}")
    print(f"memory  {ana['max_rss_mb']:.0f} MB / {TARGET_RSS_MB:.0f} MB target: ratio "
          f"{rss_ratio:.2f} (at 2 000 000: at most 1.2x the 1 000 000 "
          "figure)")
    print(json.dumps({"exchanges": ana["exchanges"], "vectors": ana["vectors"],
                      "analyze_cpu_s": round(ana["cpu_s"], 3),
                      "analyze_wall_s": round(ana["seconds"], 3),
                      "peak_rss_mb": round(ana["max_rss_mb"], 1), "capture_mb": round(size, 1),
                      "make_exchanges_per_s": round(make_rate) if make_rate else None,
                      "steps_cpu_s": {k: round(v, 3) for k, v in ana["steps"].items()},
                      "steps_peak_rss_mb": {k: round(v, 1) for k, v in ana["peaks"].items()},
                      "findings": ana["findings"],
                      "target_cpu_s": target_cpu, "target_rss_mb": TARGET_RSS_MB,
                      "cpu_ratio": None if cpu_ratio is None else round(cpu_ratio, 3),
                      "rss_ratio": round(rss_ratio, 3)}))
    if args.keep is None and os.environ.get("CONFORM_BENCH_KEEP") != "1":
        path.unlink()


if __name__ == "__main__":
    main()
