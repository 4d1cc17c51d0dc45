"""Zero bytes lost through ``conform proxy`` at a sustained 921 600 Bd-equivalent rate.

A sender streams GVE command lines at 92 160 B/s into the proxy's pty; a fake unit process
behind another pty counts and checksums what arrives and answers ``0`` to every line; the
proxy records everything. Afterwards the unit's count and CRC, the answers the sender got,
and both directions in the MCAP file are compared with what was sent.

    python bench/bench_capture_throughput.py --seconds 30      # the target run is 600 s

It prints the proxy's CPU per second of traffic, the bytes lost and how long the proxy took
to finish the file after SIGTERM; the last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import shutil
import signal
import tempfile
import threading
import time
import zlib
from pathlib import Path

from bench_capture_common import start_proxy, start_unit, stop_unit, terminal

from conform.capture.reader import open_capture
from conform.capture.recover import capture_info
from conform.link import open_port

TARGET_RATE = 92_160  # bytes/s: 921 600 Bd, 8N1
TARGET_CPU = 0.35  # core-seconds of the proxy per second of traffic, decoding on
TARGET_STOP = 3.0  # seconds from SIGTERM to a complete file


def _cpu_seconds(pid: int) -> float:
    """User + system CPU of a running process (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    import os

    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def command_stream():
    i = 0
    while True:
        yield b"!0C%d,%d,0\r" % (i % 100_000, (i * 7) % 1000)
        i += 1


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=600.0)
    ap.add_argument("--rate", type=int, default=TARGET_RATE, help="bytes/s from the sender")
    ap.add_argument("--no-decode", action="store_true", help="record raw bytes only")
    ap.add_argument("--keep", type=Path, default=None, help="keep the capture here")
    ap.add_argument("--live", action="store_true",
                    help="the proxy with its live view on, drawn on a pty as on a terminal")
    args = ap.parse_args()

    workdir = Path(tempfile.mkdtemp(prefix="bench-capture-"))
    output = args.keep or workdir / "throughput.mcap"
    unit, unit_path = start_unit()
    extra = ["--baud", "921600"] + (["--no-decode"] if args.no_decode else
                                    ["--variant", "gve64-v19"])
    screen = None
    if args.live:
        screen = terminal()
        proxy, host_path = start_proxy(unit_path, output, *extra, "--live", stderr=screen[0])
    else:
        proxy, host_path = start_proxy(unit_path, output, *extra)
    sender = open_port(host_path, 921600, write_timeout=None)

    answers = bytearray()
    done = threading.Event()

    def drain() -> None:
        while not done.is_set():
            answers.extend(sender.read(65536, 0.05))

    reader = threading.Thread(target=drain, daemon=True)
    reader.start()

    sent, crc, n_lines = 0, 0, 0
    lines = command_stream()
    tick = 0.01
    t0 = time.monotonic()
    next_t = t0
    max_behind = 0.0
    while time.monotonic() - t0 < args.seconds:
        target = int((time.monotonic() - t0 + tick) * args.rate)
        block = bytearray()
        while sent + len(block) < target:
            block += next(lines)
        sender.write(bytes(block))
        sent += len(block)
        n_lines += block.count(b"\r")
        crc = zlib.crc32(block, crc)
        next_t += tick
        behind = time.monotonic() - next_t
        max_behind = max(max_behind, behind)
        if behind < 0:
            time.sleep(-behind)
    elapsed = time.monotonic() - t0
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and len(answers) < 2 * n_lines:
        time.sleep(0.2)  # let the last answers come back
    done.set()
    reader.join()
    proxy_cpu = _cpu_seconds(proxy.pid)
    t_term = time.monotonic()
    proxy.send_signal(signal.SIGTERM)
    try:
        proxy.wait(60)
    except Exception:  # noqa: BLE001 - a proxy that does not finish is the figure
        proxy.kill()
        proxy.wait()
    finish = time.monotonic() - t_term
    sender.close()
    unit_total, unit_crc = stop_unit(unit)

    cap = open_capture(output)
    info = capture_info(output)
    host_stream_crc = 0
    host_len = 0
    for c in cap.raw_chunks("host"):
        host_stream_crc = zlib.crc32(c["bytes"], host_stream_crc)
        host_len += len(c["bytes"])
    unit_len = info.bytes["unit"]

    lost_to_unit = sent - unit_total
    lost_in_file = sent - host_len
    rate = sent / elapsed
    rate_ratio = rate / TARGET_RATE
    capture_mb = output.stat().st_size / 1e6
    print(f"ran {elapsed:.1f} s (target 600 s), decode={'off' if args.no_decode else 'on'}")
    print(f"sender rate      {rate:,.0f} B/s  (target {TARGET_RATE:,} B/s, ratio "
          f"{rate_ratio:.3f}); sender fell behind its schedule by at most "
          f"{max_behind * 1000:.1f} ms")
    print(f"sent             {sent:,} bytes in {n_lines:,} lines")
    print(f"unit received    {unit_total:,} bytes, crc {'match' if unit_crc == crc else 'MISMATCH'}"
          f"  -> lost {lost_to_unit}")
    print(f"recorded host    {host_len:,} bytes, crc "
          f"{'match' if host_stream_crc == crc else 'MISMATCH'}  -> lost {lost_in_file}")
    print(f"answers          {len(answers):,} bytes at the sender, {unit_len:,} recorded "
          f"(expected {2 * n_lines:,})")
    print(f"capture          {capture_mb:.1f} MB, state {info.state}, "
          f"{sum(info.messages.values()):,} messages, gaps {info.gaps}")
    ok = (lost_to_unit == 0 and lost_in_file == 0 and unit_crc == crc
          and host_stream_crc == crc and unit_len == 2 * n_lines == len(answers))
    end = info.metadata.get("conform.session_end", {})
    print(f"recorder         writer backlog at most {end.get('max_backlog', '?')} items; "
          f"proxy finished {finish:.2f} s after SIGTERM")
    print(f"zero bytes lost: {'YES' if ok else 'NO'}")
    writer_cpu = float(end.get("recorder_cpu_s") or "nan")
    backlog = str(end.get("max_backlog", ""))
    writer_per_s = writer_cpu / elapsed
    per_s = proxy_cpu / elapsed
    cpu_ratio = per_s / TARGET_CPU
    stop_ratio = finish / TARGET_STOP
    print(f"recorder CPU     {per_s:.3f} core-s per s of traffic for the whole proxy process "
          f"(pumps, recorder, decoding; target <= {TARGET_CPU}, ratio {cpu_ratio:.2f}); "
          f"writer thread alone {writer_per_s:.3f}")
    print(f"stop             complete file {finish:.2f} s after SIGTERM (target <= {TARGET_STOP} s, "
          f"ratio {stop_ratio:.2f})")
    lost = max(lost_to_unit, lost_in_file, 2 * n_lines - unit_len)
    if screen is not None:
        screen[1].set()
    print(json.dumps({"seconds": round(elapsed, 2), "decode": not args.no_decode,
                      "live_view": args.live,
                      "sent_bytes": sent, "lines": n_lines, "lost_bytes": lost, "zero_lost": ok,
                      "sender_rate": round(rate), "target_rate": TARGET_RATE,
                      "rate_ratio": round(rate_ratio, 4),
                      "sender_max_behind_ms": round(max_behind * 1000, 2),
                      "answers_bytes": len(answers), "answers_recorded": unit_len,
                      "messages": sum(info.messages.values()), "gaps": info.gaps,
                      "max_backlog": int(backlog) if backlog.isdigit() else None,
                      "recorder_cpu_per_s": round(per_s, 4),
                      # None, not NaN, when the session end did not say (NaN is not JSON)
                      "writer_thread_cpu_per_s": (round(writer_per_s, 4)
                                                  if writer_per_s == writer_per_s else None),
                      "stop_s": round(finish, 3), "state": info.state,
                      "capture_mb": round(capture_mb, 2),
                      "target_cpu_per_s": TARGET_CPU, "cpu_ratio": round(cpu_ratio, 3),
                      "target_stop_s": TARGET_STOP, "stop_ratio": round(stop_ratio, 3)}))
    if args.keep is None:
        shutil.rmtree(workdir, ignore_errors=True)


if __name__ == "__main__":
    main()
