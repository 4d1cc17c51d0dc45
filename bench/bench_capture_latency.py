"""Round-trip latency the recording proxy adds, against a direct pty connection, same run.

A fake unit process answers ``0`` to every line. The client sends a 12-byte command and
times until the answer is back: first straight to the unit's pty, then through
``conform proxy`` (recording, frames decoded), interleaved in rounds so that machine load
hits both alike. Target: the proxy adds at most 1 ms at p99.

    python bench/bench_capture_latency.py --count 2000
"""

from __future__ import annotations

import argparse
import json
import shutil
import signal
import statistics
import tempfile
import time
from pathlib import Path

from bench_capture_common import start_proxy, start_unit, stop_unit

from conform.capture.reader import Capture
from conform.capture.recover import capture_info
from conform.link import open_port

TARGET_ADDED_P99 = 0.001
COMMAND = b"!0L1000,0,0\r"


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    k = min(len(ordered) - 1, max(0, round(q / 100 * (len(ordered) - 1))))
    return ordered[k]


def round_trip(port, samples: list[float]) -> None:
    t0 = time.perf_counter()
    port.write(COMMAND)
    got = b""
    while not got.endswith(b"\r"):
        got += port.read(64, 1.0)
        if time.perf_counter() - t0 > 2.0:
            raise SystemExit("no answer within 2 s")
    samples.append(time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=2000, help="round trips per path")
    ap.add_argument("--no-decode", action="store_true")
    args = ap.parse_args()
    if args.count < 1:
        ap.error("--count must be at least 1")

    workdir = Path(tempfile.mkdtemp(prefix="bench-latency-"))
    direct_unit, direct_path = start_unit()
    proxied_unit, proxied_path = start_unit()
    extra = ["--baud", "921600"] + (["--no-decode"] if args.no_decode else
                                    ["--variant", "gve64-v19"])
    output = workdir / "latency.mcap"
    proxy, host_path = start_proxy(proxied_path, output, *extra)
    direct = open_port(direct_path, 921600)
    proxied = open_port(host_path, 921600)
    for _ in range(50):  # warm up both paths
        round_trip(direct, [])
        round_trip(proxied, [])
    d: list[float] = []
    p: list[float] = []
    for i in range(args.count):
        first, second = (direct, proxied) if i % 2 == 0 else (proxied, direct)
        round_trip(first, d if first is direct else p)
        round_trip(second, d if second is direct else p)
        time.sleep(0.0005)
    proxy.send_signal(signal.SIGTERM)
    proxy.wait(60)
    direct.close(), proxied.close()
    stop_unit(direct_unit), stop_unit(proxied_unit)
    info = capture_info(output)

    pct = {name: {q: percentile(xs, q) for q in (50, 90, 99)} for name, xs in (("direct", d),
                                                                              ("proxy", p))}
    worst = {"direct": max(d), "proxy": max(p)}
    mean = {"direct": statistics.mean(d), "proxy": statistics.mean(p)}
    added = {q: pct["proxy"][q] - pct["direct"][q] for q in (50, 90, 99)}
    ratio = added[99] / TARGET_ADDED_P99
    exchanges = sum(1 for _ in Capture(output).exchanges())  # rows, not batched messages
    print(f"{args.count} round trips per path, {len(COMMAND)}-byte command, 2-byte answer, "
          f"decode={'off' if args.no_decode else 'on'}")
    print(f"{'':8}{'p50':>10}{'p90':>10}{'p99':>10}{'max':>10}   (ms)")
    for name in ("direct", "proxy"):
        print(f"{name:8}" + "".join(f"{pct[name][q] * 1e3:10.3f}" for q in (50, 90, 99))
              + f"{worst[name] * 1e3:10.3f}")
    print(f"{'added':8}" + "".join(f"{added[q] * 1e3:10.3f}" for q in (50, 90, 99)))
    print(f"added at p99: {added[99] * 1e3:.3f} ms (target <= {TARGET_ADDED_P99 * 1e3:.1f} ms, "
          f"ratio {ratio:.2f}); mean direct "
          f"{mean['direct'] * 1e3:.3f} ms, proxy {mean['proxy'] * 1e3:.3f} ms")
    print(f"capture: {info.state}, {exchanges} exchanges recorded")
    result: dict = {"count": args.count, "command_bytes": len(COMMAND),
                    "decode": not args.no_decode}
    for name in ("direct", "proxy"):
        result.update({f"{name}_p{q}_ms": round(pct[name][q] * 1e3, 4) for q in (50, 90, 99)})
        result[f"{name}_max_ms"] = round(worst[name] * 1e3, 4)
        result[f"{name}_mean_ms"] = round(mean[name] * 1e3, 4)
    result.update({f"added_p{q}_ms": round(added[q] * 1e3, 4) for q in (50, 90, 99)})
    result.update({"target_added_p99_ms": TARGET_ADDED_P99 * 1e3, "ratio": round(ratio, 3),
                   "capture_state": str(info.state), "exchanges_recorded": exchanges})
    shutil.rmtree(workdir, ignore_errors=True)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
