"""End to end: a pyserial sender talks through ``conform proxy`` to ``conform emulate``; the
capture holds both directions byte for byte, and every message fits its channel's schema."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import jsonschema
import pytest
import serial
from mcap.reader import make_reader

from conform.capture.reader import open_capture

REPO = Path(__file__).resolve().parents[1]
ENV = dict(os.environ, PYTHONPATH=str(REPO))


def start(*args: str) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-m", "conform", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=ENV, cwd=REPO)
    first = proc.stdout.readline().decode().strip()
    assert first, proc.stderr.read().decode()
    return proc, first


def read_answer(port: serial.Serial, lines: int = 1, timeout: float = 3.0) -> bytes:
    out = b""
    deadline = time.monotonic() + timeout
    while out.count(b"\r") < lines and time.monotonic() < deadline:
        out += port.read(64)
    return out


@pytest.mark.slow
def test_sender_through_proxy_to_emulator_is_recorded_byte_exact(tmp_path):
    out = tmp_path / "session.mcap"
    emu, emu_path = start("emulate", "gve64-v19")
    proxy = None
    try:
        proxy, host_path = start("proxy", "--unit", emu_path, "-o", str(out), "--baud", "115200",
                                 "--variant", "gve64-v19")
        sent = b""
        received = b""
        script = [(b"!0%+\r", 1), (b"!0V5000,98\r", 1), (b"!0C100,0,0,09\r", 1),
                  (b"!0C100,0,0,05\r", 1), (b"!0>,BB\r", 2), (b"!0@,BD\r", 1),
                  (b"!0P4,01\r", 1), (b"!0%-,CF\r", 1), (b"!0SR6\r", 1)]
        with serial.serial_for_url(host_path, 115200, timeout=0.05) as port:
            for line, n in script:
                port.write(line)
                sent += line
                received += read_answer(port, n)
        assert received.count(b"\r") == sum(n for _, n in script)
        # a wrong checksum is refused (4) and, by A29's default, `>` repeats the last good line
        assert b"4,60\r!0C100,0,0,09\r0,5C\r" in received
        proxy.send_signal(signal.SIGINT)
        assert proxy.wait(10) == 0, proxy.stderr.read().decode()
    finally:
        for p in (proxy, emu):
            if p is not None and p.poll() is None:
                p.send_signal(signal.SIGTERM)
                p.wait(10)
    cap = open_capture(out)
    assert cap.clean
    assert cap.stream("host") == sent
    assert cap.stream("unit") == received
    ex = list(cap.exchanges())
    assert [e["status"] for e in ex] == ["answered"] * len(script)
    assert [e["command"] for e in ex] == [line[:-1].decode() for line, _ in script]
    assert [e["name"] for e in ex] == ["%", "V", "C", None, ">", "@", "P4", "%", "SR"]
    assert ex[4]["answer"] == "0,5C"  # `>`: the echo is a frame of its own, then the answer
    assert "echo" in [f["kind"] for f in cap.frames()]
    # every message is JSON that validates against its channel's jsonschema (what Foxglove reads)
    with open(out, "rb") as f:
        reader = make_reader(f)
        validators = {}
        count = 0
        for schema, channel, message in reader.iter_messages():
            if channel.id not in validators:
                assert schema.encoding == "jsonschema"
                validators[channel.id] = jsonschema.Draft202012Validator(json.loads(schema.data))
            validators[channel.id].validate(json.loads(message.data))
            count += 1
    assert count >= 4  # format 2: raw, frames and exchanges come in batches
    assert len(list(cap.frames())) > 2 * len(script)
