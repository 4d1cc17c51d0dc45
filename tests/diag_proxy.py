"""Sessions of real sender programs recorded as an integrator records them: ``conform emulate
serve`` (the family's reference unit on a pty, optionally with its fault injection),
``conform proxy`` between it and the sender's pty, the sender run to its end (or killed,
or stopped by SIGTERM), then the proxy stopped with Ctrl-C (it finishes the file).

    path = proxied(tmp, "grbl-1.1f", [python, sender, "{port}", job], name="x")

Used by the diagnosis corpus (tests/test_diagnosis_corpus.py, bench/bench_diagnosis.py)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SENDERS = Path(__file__).resolve().parent / "senders"


def _conform(*args: str, **kw) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.Popen([sys.executable, "-m", "conform", *args], env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, **kw)


def _stop(p: subprocess.Popen | None, sig: int = signal.SIGTERM) -> None:
    if p is not None and p.poll() is None:
        p.send_signal(sig)
        try:
            p.wait(30)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(10)


def proxied(directory: Path, variant: str, command: list[str], *, name: str,
            baud: int = 115200, faults: str | None = None, seed: int = 1,
            timeout: float = 120.0, signal_after: tuple[float, int] | None = None,
            env: dict[str, str] | None = None) -> tuple[Path, subprocess.CompletedProcess]:
    """Record one session of ``command`` (``{port}`` replaced by the proxy's pty) through the
    proxy; ``signal_after``: (seconds, signal) sent to the sender that long after it starts.
    Returns the capture and the sender's result."""
    directory.mkdir(parents=True, exist_ok=True)
    cap = directory / f"{name}.mcap"
    unit_pty, host_pty = directory / f"{name}.unit.pty", directory / f"{name}.host.pty"
    emu_args = ["emulate", "serve", variant, "--link", str(unit_pty), "--baud", str(baud)]
    if faults:
        emu_args += ["--faults", faults, "--seed", str(seed)]
    emu = _conform(*emu_args)
    proxy = None
    try:
        assert emu.stdout is not None and emu.stdout.readline().strip()
        proxy = _conform("proxy", "--unit", str(unit_pty), "-o", str(cap), "--link",
                         str(host_pty), "--baud", str(baud), "--variant", variant, "-q")
        assert proxy.stdout is not None and proxy.stdout.readline().strip()
        cmd = [str(host_pty) if a == "{port}" else a for a in command]
        run_env = {**os.environ, "PYTHONPATH": str(REPO), "CONFORM_BAUD": str(baud),
                   **(env or {})}
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env=run_env)
        if signal_after is not None:
            try:
                p.wait(signal_after[0])
            except subprocess.TimeoutExpired:
                p.send_signal(signal_after[1])
        try:
            out, err = p.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            out, err = p.communicate()
        result = subprocess.CompletedProcess(cmd, p.returncode, out, err)
        time.sleep(0.3)
        _stop(proxy, signal.SIGINT)
    finally:
        _stop(proxy, signal.SIGINT)
        _stop(emu)
    return cap, result


def conform_send(job: Path, *extra: str) -> list[str]:
    """``conform send JOB --target {port} --allow-motion`` as a sender command."""
    return [sys.executable, "-m", "conform", "send", str(job), "--target", "{port}",
            "--allow-motion", *extra]


def script(name: str, *args: str, python: str = sys.executable) -> list[str]:
    return [python, str(SENDERS / name), "{port}", *args]
