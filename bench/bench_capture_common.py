"""Shared pieces of the capture benchmarks: a fake unit process and a proxy process."""

from __future__ import annotations

import os
import pty
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]

# A fake unit in its own process (so it does not share a GIL with the measurement): a pty
# that answers "0\r" to every CR it receives and, with --count, reports how many bytes
# arrived and their CRC when its stdin closes.
UNIT = r"""
import sys, threading, zlib
from conform.link import PtyEndpoint
pty = PtyEndpoint(write_timeout=None)
print(pty.path, flush=True)
total, crc, stop = 0, 0, threading.Event()
def watch():
    sys.stdin.read()
    stop.set()
threading.Thread(target=watch, daemon=True).start()
while not stop.is_set():
    data = pty.read(65536, 0.05)
    if data:
        total += len(data)
        crc = zlib.crc32(data, crc)
        n = data.count(b"\r")
        if n:
            pty.write(b"0\r" * n)
print(total, crc, flush=True)
"""


def env() -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(REPO))


def start_unit() -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-c", UNIT], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, env=env(), cwd=REPO)
    path = proc.stdout.readline().decode().strip()
    return proc, path


def stop_unit(proc: subprocess.Popen) -> tuple[int, int]:
    out, _ = proc.communicate(b"", timeout=30)
    total, crc = out.decode().split()[-2:]
    return int(total), int(crc)


def start_proxy(unit_path: str, output: Path, *extra: str, stderr: Any = subprocess.PIPE
                ) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-m", "conform", "proxy", "--unit", unit_path,
                             "-o", str(output), *extra], stdout=subprocess.PIPE,
                            stderr=stderr, env=env() | {"TERM": "xterm-256color"}, cwd=REPO)
    path = proc.stdout.readline().decode().strip()
    if not path:
        raise SystemExit(f"proxy failed: {proc.stderr.read().decode()}")
    return proc, path


def terminal() -> tuple[int, threading.Event]:
    """A pty to give a process as its terminal (its screen read and dropped by a thread);
    the slave end, and the event that stops the reading."""
    master, slave = pty.openpty()
    stop = threading.Event()

    def drain() -> None:
        import select

        while not stop.is_set():
            if select.select([master], [], [], 0.1)[0]:
                try:
                    os.read(master, 1 << 16)
                except OSError:
                    return

    threading.Thread(target=drain, daemon=True).start()
    return slave, stop
