"""Serving a family's reference unit on a pty for a test, as a user starts it
(``conform emulate serve ...`` in a process of its own), and reading its answer lines."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import serial


def serve(*args: str) -> tuple[subprocess.Popen, str, str]:
    """``conform emulate ARGS...``: (process, device path, control socket path)."""
    proc = subprocess.Popen([sys.executable, "-m", "conform", "emulate", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    path = proc.stdout.readline().strip()
    info = proc.stderr.readline()
    assert path.startswith("/"), info
    control = info.split("control: ", 1)[-1].split(";")[0].strip()
    return proc, path, control


def stop(proc: subprocess.Popen) -> str:
    """SIGTERM, which must stop it within 10 s; its stderr."""
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        raise AssertionError("the emulator did not stop on SIGTERM") from None
    return proc.stderr.read()


def read_lines(port: serial.Serial, n: int, timeout: float = 3.0, eol: bytes = b"\n"
               ) -> list[str]:
    """Up to ``n`` lines ending in ``eol`` (fewer when ``timeout`` passes first)."""
    buf = b""
    end = time.monotonic() + timeout
    while buf.count(eol) < n and time.monotonic() < end:
        buf += port.read(4096)
    return buf.decode("latin-1").split(eol.decode())[:-1]
