"""Live captures end to end: ``conform proxy`` and ``conform sniff`` over ptys, faults included."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conform.capture.live import SniffCapture
from conform.capture.reader import open_capture
from conform.link import PtyEndpoint, open_port

REPO = Path(__file__).resolve().parents[1]


def read_until(endpoint, n: int, timeout: float = 3.0) -> bytes:
    out = b""
    deadline = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        out += endpoint.read(4096, 0.05)
    return out


def start_proxy(*args: str) -> tuple[subprocess.Popen, str]:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-m", "conform", "proxy", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, cwd=REPO)
    first = proc.stdout.readline().decode().strip()
    assert first.startswith("/"), proc.stderr.read().decode()
    return proc, first


def exchange(sender, unit, command: bytes, answer: bytes) -> None:
    sender.write(command)
    assert read_until(unit, len(command)) == command
    unit.write(answer)
    assert read_until(sender, len(answer)) == answer


def wait_for(predicate, timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
def test_proxy_forwards_records_and_finishes_on_signal(tmp_path, sig):
    out = tmp_path / "proxy.mcap"
    with PtyEndpoint() as unit:
        proc, host_path = start_proxy("--unit", unit.path, "-o", str(out), "--baud", "115200",
                                      "--variant", "gve64-v19")
        try:
            with open_port(host_path, 115200) as sender:
                exchange(sender, unit, b"!0L1000,0,0\r", b"0\r")
                exchange(sender, unit, b"!0PF\r", b"0,1000,0,0\r")
            proc.send_signal(sig)
            assert proc.wait(10) == 0, proc.stderr.read().decode()
        finally:
            proc.kill()
    cap = open_capture(out)
    assert cap.clean and not (tmp_path / "proxy.mcap.part").exists()
    assert cap.stream("host") == b"!0L1000,0,0\r!0PF\r"
    assert cap.stream("unit") == b"0\r0,1000,0,0\r"
    ex = list(cap.exchanges())
    assert [(e["name"], e["answer"], e["status"]) for e in ex] == [
        ("L", "0", "answered"), ("PF", "0,1000,0,0", "answered")]
    assert all(0 <= e["latency"] < 1 for e in ex)
    session = cap.metadata["conform.session"]
    assert session["capture_method"] == "proxy" and session["unit_port"] == unit.path
    assert session["host_port"] == host_path and session["baud"] == "115200"
    kinds = [(e["kind"], e["side"]) for e in cap.link_events()]
    assert ("open", "host") in kinds and ("open", "unit") in kinds and kinds[-1][0] == "close"


def test_proxy_unit_vanishes_without_reconnect(tmp_path):
    out = tmp_path / "gone.mcap"
    unit = PtyEndpoint()
    proc, host_path = start_proxy("--unit", unit.path, "-o", str(out), "--no-decode")
    try:
        with open_port(host_path, 115200) as sender:
            exchange(sender, unit, b"!0?\r", b"0,IP64MPG v19\r")
            unit.close()  # adapter unplugged
            assert proc.wait(10) == 1
        err = proc.stderr.read().decode().strip().splitlines()
        assert "Traceback" not in "\n".join(err)
        assert any("unit port lost" in line for line in err)
    finally:
        proc.kill()
    cap = open_capture(out)
    assert cap.clean
    assert cap.stream("host") == b"!0?\r" and cap.stream("unit") == b"0,IP64MPG v19\r"
    assert [e["kind"] for e in cap.link_events() if e["side"] == "unit"] == ["open",
                                                                            "disconnect"]


def test_proxy_reconnects_when_the_unit_comes_back(tmp_path):
    out = tmp_path / "back.mcap"
    link = tmp_path / "unit-link"
    unit = PtyEndpoint(link=link)
    proc, host_path = start_proxy("--unit", str(link), "-o", str(out), "--reconnect",
                                  "--no-decode")
    try:
        with open_port(host_path, 115200) as sender:
            exchange(sender, unit, b"!0?\r", b"0,v19\r")
            unit.close()
            part = tmp_path / "back.mcap.part"
            wait_for(lambda: any(e["kind"] == "disconnect"
                                 for e in open_capture(part).link_events()))
            unit = PtyEndpoint(link=link)
            wait_for(lambda: any(e["kind"] == "reconnect"
                                 for e in open_capture(part).link_events()))
            exchange(sender, unit, b"!0PF\r", b"0,0,0,0\r")
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
    finally:
        proc.kill()
        unit.close()
    cap = open_capture(out)
    assert cap.stream("host") == b"!0?\r!0PF\r"
    assert cap.stream("unit") == b"0,v19\r0,0,0,0\r"
    unit_events = [e["kind"] for e in cap.link_events() if e["side"] == "unit"]
    assert unit_events[0] == "open" and "disconnect" in unit_events
    assert unit_events.index("reconnect") > unit_events.index("disconnect")


def test_proxy_bad_unit_is_one_line(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    res = subprocess.run([sys.executable, "-m", "conform", "proxy", "--unit",
                          str(tmp_path / "nope"), "-o", str(tmp_path / "x.mcap")],
                         capture_output=True, env=env, cwd=REPO, timeout=30)
    assert res.returncode != 0
    assert len(res.stderr.decode().strip().splitlines()) == 1
    assert "nope" in res.stderr.decode() and not (tmp_path / "x.mcap.part").exists()


def test_sniffer_merges_both_taps_and_survives_one_vanishing(tmp_path):
    out = tmp_path / "sniff.mcap"
    host_tap, unit_tap = PtyEndpoint(), PtyEndpoint()
    sniff = SniffCapture(host_tap.path, unit_tap.path, out, baud=115200, variant="gve64-v19")
    try:
        for cmd, ans in ((b"!0L1000,0,0\r", b"0\r"), (b"!0PF\r", b"0,1,2,3\r")):
            host_tap.write(cmd)
            time.sleep(0.02)
            unit_tap.write(ans)
            time.sleep(0.02)
        time.sleep(0.1)
        host_tap.close()  # the host-side adapter is unplugged
        wait_for(lambda: any(e["kind"] == "disconnect" for e in
                             open_capture(sniff.recorder.part).link_events()))
        unit_tap.write(b"0,late\r")
        time.sleep(0.5)
        assert not sniff.wait(0)
    finally:
        sniff.stop()
        sniff.close()
        unit_tap.close()
    cap = open_capture(out)
    assert cap.clean
    assert cap.stream("host") == b"!0L1000,0,0\r!0PF\r"
    assert cap.stream("unit") == b"0\r0,1,2,3\r0,late\r"
    chunks = list(cap.raw_chunks())
    assert [c["direction"] for c in chunks][:2] == ["host", "unit"]
    assert all(c["t_first"] <= c["t_read"] for c in chunks)
    assert chunks[0]["t_read"] - chunks[0]["t_first"] == pytest.approx(12 * 10 / 115200, abs=1e-6)
    ex = list(cap.exchanges())
    assert [(e["name"], e["status"]) for e in ex][:2] == [("L", "answered"), ("PF", "answered")]
    assert cap.metadata["conform.session"]["capture_method"] == "sniff"


def test_sniff_cli_until_sigint(tmp_path):
    out = tmp_path / "s.mcap"
    a, b = PtyEndpoint(), PtyEndpoint()
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-m", "conform", "sniff", "--host-port", a.path,
                             "--unit-port", b.path, "-o", str(out), "--baud", "38400"],
                            stderr=subprocess.PIPE, env=env, cwd=REPO)
    try:
        proc.stderr.readline()  # "recording ..." once both ports are open
        a.write(b"!0?\r")
        time.sleep(0.05)
        b.write(b"0,v\r")
        time.sleep(0.4)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(10) == 0
    finally:
        proc.kill()
        a.close(), b.close()
    cap = open_capture(out)
    assert cap.stream("host") == b"!0?\r" and cap.stream("unit") == b"0,v\r"
    assert cap.metadata["conform.session"]["baud"] == "38400"


def test_proxy_records_the_sender_closing_and_reopening_its_pty(tmp_path):
    out = tmp_path / "reopen.mcap"
    unit = PtyEndpoint()
    proc, host_path = start_proxy("--unit", unit.path, "-o", str(out), "--no-decode")
    part = tmp_path / "reopen.mcap.part"
    try:
        with open_port(host_path, 115200) as sender:
            exchange(sender, unit, b"!0?\r", b"0,v19\r")
        wait_for(lambda: any(e["kind"] == "disconnect" for e in open_capture(part).link_events()))
        with open_port(host_path, 115200) as sender:
            exchange(sender, unit, b"!0PF\r", b"0,0,0,0\r")
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
    finally:
        proc.kill()
        unit.close()
    cap = open_capture(out)
    assert cap.stream("host") == b"!0?\r!0PF\r"
    host_events = [e["kind"] for e in cap.link_events() if e["side"] == "host"]
    assert host_events[0] == "open"
    assert host_events.index("reconnect") > host_events.index("disconnect")


def test_peer_watch_reports_edges_only():
    from conform.link.peerwatch import IN_CLOSE_NOWRITE, IN_CLOSE_WRITE, IN_OPEN, PeerWatch

    seen = []
    w = PeerWatch("/nonexistent/pty", lambda kind, detail: seen.append(kind))
    assert not w.active
    w.feed([IN_OPEN, IN_OPEN, IN_CLOSE_WRITE])  # a sender that opens the device twice
    assert seen == []
    w.feed([IN_CLOSE_NOWRITE, IN_OPEN, IN_CLOSE_WRITE])
    assert seen == ["disconnect", "reconnect", "disconnect"]
    w.close()
