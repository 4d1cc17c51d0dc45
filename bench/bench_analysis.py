"""Benchmark: analyse a synthetic 1 000 000-exchange capture.

Targets (issue 6): the analysis takes at most 15 s, at most 2x a bare MCAP iteration over
the same file, and at most 2 GB of memory. Prints the figures and the ratio to each target.

    python bench/bench_analysis.py                 # 1 000 000 exchanges
    python bench/bench_analysis.py --exchanges 200000 --keep /tmp/b.mcap

The synthetic session is a sender streaming C vectors with checksums on at 115200 baud:
answers ``0``, runs of queue-full ``1`` polls, a ``PF`` every 200 exchanges. It is written
the way a capture without a decoder is (raw chunk channels only, one chunk per line), so
the analyser has to decode everything from the bytes. Each phase runs in its own process so
that its peak memory (ru_maxrss) is its own.
"""

from __future__ import annotations

import argparse
import base64
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


def make_capture(path: Path, n: int, seed: int = 1) -> None:
    from conform.capture.schemas import DIRECTION_TOPIC
    from conform.capture.session import Record
    from conform.capture.sink import McapSink

    rng = random.Random(seed)
    byte_t = 10.0 / BAUD
    with open(path, "wb") as f:
        sink = McapSink(f, chunk_size=1 << 20)
        sink.metadata("conform.session", {"capture_method": "bench synthetic",
                                          "variant": "gve64-v19", "baud": BAUD})
        offsets = {"host": 0, "unit": 0}
        seqs = {"host": 0, "unit": 0}
        t = T0
        pos = [0, 0]
        enc = json.JSONEncoder(separators=(",", ":")).encode

        def chunk(direction: str, data: bytes, t_first: float, t_read: float) -> None:
            seqs[direction] += 1
            payload = {"direction": direction, "data": base64.b64encode(data).decode(),
                       "hex": data.hex(" ").upper(),
                       "text": data.decode("latin-1").replace("\r", "\\r"),
                       "length": len(data), "offset": offsets[direction], "t_read": t_read,
                       "t_first": t_first, "seq": seqs[direction]}
            offsets[direction] += len(data)
            sink.write(Record(DIRECTION_TOPIC[direction], round(t_read * 1e9), {}),
                       enc(payload).encode())

        def exchange(cmd: bytes, ans: bytes, unit_s: float = 0.0003,
                     host_s: float = 0.0002) -> None:
            nonlocal t
            end = t + len(cmd) * byte_t
            chunk("host", cmd, t, end)
            a0 = end + unit_s
            a1 = a0 + len(ans) * byte_t
            chunk("unit", ans, a0, a1)
            t = a1 + host_s

        exchange(b"!0%+\r", _cs(b"0") + b"\r")
        exchange(_cs(b"!0V20000") + b"\r", _cs(b"0") + b"\r")
        done = 2
        while done < n:
            if done % 200 == 0:
                exchange(_cs(b"!0PF") + b"\r",
                         _cs(b"0,%d,%d,0" % tuple(pos)) + b"\r")
                done += 1
                continue
            dx, dy = rng.randint(-400, 400), rng.randint(-400, 400)
            line = _cs(b"!0C%d,%d,0" % (dx, dy)) + b"\r"
            if rng.random() < 0.01:  # a run of queue-full polls
                for _ in range(rng.randint(1, 8)):
                    if done >= n - 1:
                        break
                    exchange(line, _cs(b"1") + b"\r")
                    done += 1
            exchange(line, _cs(b"0") + b"\r")
            pos[0] += dx
            pos[1] += dy
            done += 1
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
    from conform.analysis import analyze

    t = time.perf_counter()
    steps: dict[str, float] = {}
    last = [t, "start"]

    def step(name: str) -> None:
        now = time.perf_counter()
        steps[last[1]] = now - last[0]
        last[:] = [now, name]

    a = analyze(path, step=step)
    total = time.perf_counter() - t
    steps[last[1]] = time.perf_counter() - last[0]
    return {"seconds": total, "exchanges": int(a.metrics["exchanges"]),
            "vectors": int(a.metrics["vectors_accepted"]), "steps": steps,
            "findings": a.metrics["finding_counts"]}


def _child(kind: str, path: str) -> None:
    out = bare_iteration(path) if kind == "bare" else analysis(path)
    out["max_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps(out))


def _run(kind: str, path: Path) -> dict:
    r = subprocess.run([sys.executable, __file__, "--child", kind, str(path)],
                       capture_output=True, text=True, check=True, cwd=ROOT)
    return json.loads(r.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--exchanges", type=int, default=1_000_000)
    ap.add_argument("--keep", type=Path, default=None, help="capture path to reuse/keep")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        _child(*args.child)
        return
    path = args.keep or Path(tempfile.mkdtemp(prefix="bench-analysis-")) / "synthetic.mcap"
    if not path.exists():
        t = time.perf_counter()
        make_capture(path, args.exchanges)
        print(f"made {path} ({path.stat().st_size / 1e6:.1f} MB) in "
              f"{time.perf_counter() - t:.1f} s")
    size = path.stat().st_size / 1e6
    bare = _run("bare", path)
    ana = _run("analysis", path)
    ratio = ana["seconds"] / bare["seconds"]
    print(f"capture: {path} {size:.1f} MB, {bare['messages']} messages, "
          f"{ana['exchanges']} exchanges, {ana['vectors']} vectors accepted")
    print(f"bare mcap iteration: {bare['seconds']:.2f} s ({bare['max_rss_mb']:.0f} MB)")
    print(f"analysis:            {ana['seconds']:.2f} s ({ana['max_rss_mb']:.0f} MB)")
    print("  steps: " + ", ".join(f"{k} {v:.2f} s" for k, v in ana["steps"].items()))
    print(f"  findings: {ana['findings']}")
    print(f"time    {ana['seconds']:.2f} s / 15 s target: ratio {ana['seconds'] / 15:.2f}")
    print(f"vs bare {ratio:.2f}x / 2x target: ratio {ratio / 2:.2f}")
    print(f"memory  {ana['max_rss_mb']:.0f} MB / 2048 MB target: ratio "
          f"{ana['max_rss_mb'] / 2048:.2f}")
    if args.keep is None and os.environ.get("CONFORM_BENCH_KEEP") != "1":
        path.unlink()


if __name__ == "__main__":
    main()
