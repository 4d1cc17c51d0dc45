"""The emulator around the reference unit: fault injection, control commands, the serving loop
(in-process with a fake clock and port), and `conform emulate` as a real pty/TCP device."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest
from conftest import stop_emulator

from conform.emulator.control import send_control
from conform.emulator.serve import ControlServer, Emulator
from conform.errors import UserError
from conform.families.gve.unit import Unit
from conform.families.gve.unit.control import run_control
from conform.link.faults import FaultConfig, FaultInjector, FaultyEndpoint

# ---------------------------------------------------------------- fault injection (sans-I/O)


def test_fault_spec_parsing():
    cfg = FaultConfig.parse("corrupt=1e-3,drop=0.01,latency=1-16,garble=0.05,disconnect=0.5,"
                            "downtime=2,host.latency=3")
    assert cfg.host.corrupt == cfg.unit.corrupt == 1e-3
    assert cfg.host.latency == (0.003, 0.003) and cfg.unit.latency == (0.001, 0.016)
    assert cfg.unit.garble == 0.05 and cfg.host.garble == 0.0
    assert cfg.disconnect == 0.5 and cfg.downtime == 2.0
    assert not FaultConfig.parse("").active
    for bad in ("noise=1", "corrupt=2", "latency=5-1", "x.drop=0.1", "host.disconnect=1", "drop"):
        with pytest.raises(UserError):
            FaultConfig.parse(bad)


def test_faults_are_reproducible_and_ordered():
    cfg = FaultConfig.parse("corrupt=0.05,drop=0.05,latency=1-16,garble=0.2")
    data = [b"0,%d,%d\r" % (i, i * 7) for i in range(300)]

    def run(seed):
        inj = FaultInjector(cfg, seed)
        return [inj.feed("unit", d, i * 0.001) for i, d in enumerate(data)], inj.counts

    a, counts = run(3)
    b, _ = run(3)
    c, _ = run(4)
    assert a == b and a != c
    times = [t for out in a for t, _ in out]
    assert times == sorted(times)
    for i, out in enumerate(a):
        for t, _ in out:
            assert i * 0.001 + 0.001 <= t
    sent = sum(len(d) for d in data)
    got = sum(len(x) for out in a for _, x in out)
    assert 0.85 * sent < got < sent
    assert counts["corrupted"] > 0 and counts["dropped"] > 0 and counts["garbled"] > 0


def test_no_faults_pass_through_and_disconnects():
    inj = FaultInjector(FaultConfig.parse("unit.drop=1"), 1)
    assert inj.feed("host", b"!0V1\r", 1.0) == [(1.0, b"!0V1\r")]
    assert inj.feed("unit", b"0\r", 1.0) == []
    inj = FaultInjector(FaultConfig.parse("disconnect=10,downtime=0.5"), 2)
    first = inj.next_disconnect()
    assert first is not None and first > 0
    assert not inj.disconnect_due(first - 1e-6)
    assert inj.disconnect_due(first)
    assert inj.feed("host", b"x", first + 0.1) == []
    assert inj.feed("host", b"x", first + 0.6) == [(first + 0.6, b"x")]
    assert inj.next_disconnect() > first + 0.5


class FakePort:
    """An in-memory Endpoint: ``inbox`` is what the peer wrote, ``sent`` what we wrote."""

    def __init__(self, clock):
        self.clock = clock
        self.inbox: list[bytes] = []
        self.sent: list[tuple[float, bytes]] = []
        self.closed = False
        self.name = "fake"

    def read(self, max_bytes=4096, timeout=0.1):
        if self.inbox:
            return self.inbox.pop(0)
        self.clock.t += timeout or 0.0
        return b""

    def write(self, data):
        self.sent.append((self.clock.t, data))

    def close(self):
        self.closed = True


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t

    def sleep(self, dt):
        self.t += dt


def test_faulty_endpoint_delays_writes():
    clock = FakeClock()
    port = FakePort(clock)
    ep = FaultyEndpoint(port, FaultInjector(FaultConfig.parse("latency=10"), 0), clock=clock)
    ep.write(b"!0V1\r")
    assert port.sent == []
    clock.t += 0.011
    ep.flush()
    assert port.sent == [(clock.t, b"!0V1\r")]
    port.inbox.append(b"0\r")
    assert ep.read(100, 0.05) == b"0\r"


# ---------------------------------------------------------------- control commands


def test_control_commands(spec):
    unit = Unit(spec.variant("gve64-v19"))
    assert run_control(unit, "press stop", 0.0).startswith("ok I1=7F")
    assert not unit.inta  # not enabled
    run_control(unit, "release stop", 0.05)
    unit.exchange(b"!0SW0,80\r", 0.1)
    unit.exchange(b"!0L100000,0,0\r", 0.2)
    assert run_control(unit, "press 1.7", 0.5).endswith("INTA=1 ST4=80 ST5=00")
    state = json.loads(run_control(unit, "state", 0.6)[3:])
    assert state["status"][6] == "C1" and state["queue"] == 1
    assert run_control(unit, "input 2 7 off", 0.7).startswith("ok I1=7F I2=40")
    assert run_control(unit, "press nothing", 0.8).startswith("error")
    assert run_control(unit, "input 1 9 on", 0.8).startswith("error")
    assert run_control(unit, "fly", 0.8).startswith("error")
    assert run_control(unit, "help", 0.8).startswith("ok commands")


# ---------------------------------------------------------------- the serving loop, in-process


def serve_steps(emu, clock, until):
    while clock.t < until:
        emu.step()


def test_emulator_paces_answers_at_wire_speed(spec):
    clock = FakeClock()
    port = FakePort(clock)
    unit = Unit(spec.variant("gve64-v19"), t0=clock.t)
    emu = Emulator(unit, port, baud=9600, clock=clock)
    port.inbox.append(b"!0?\r")
    serve_steps(emu, clock, 100.2)
    (t, data), = port.sent
    assert data == b"0,IP64MPG v19 10.9.2010\r"
    wire_in = 4 * 10 / 9600
    wire_out = len(data) * 10 / 9600
    assert t == pytest.approx(100.0 + wire_in + wire_out, abs=0.021)


def test_emulator_with_faults_and_recorder(spec):
    class Rec:
        def __init__(self):
            self.chunks, self.events = [], []

        def chunk(self, direction, data, t_read=None, t_first=None):
            self.chunks.append((direction, data))

        def link_event(self, kind, detail="", side="session", t=None):
            self.events.append(kind)

    clock = FakeClock()
    port = FakePort(clock)
    rec = Rec()
    unit = Unit(spec.variant("gve64-v19"), t0=clock.t)
    inj = FaultInjector(FaultConfig.parse("unit.latency=5"), 1, t0=clock.t)
    emu = Emulator(unit, port, injector=inj, recorder=rec, clock=clock)
    port.inbox.append(b"!0V100\r")
    serve_steps(emu, clock, 100.1)
    (t, data), = port.sent
    assert data == b"0\r" and t >= 100.005
    assert rec.chunks == [("host", b"!0V100\r"), ("unit", b"0\r")]
    # an injected disconnect closes and reopens the port
    reopened = []
    inj2 = FaultInjector(FaultConfig.parse("disconnect=5,downtime=0.2"), 3, t0=clock.t)
    emu2 = Emulator(Unit(spec.variant("gve64-v19"), t0=clock.t), FakePort(clock), injector=inj2,
                    recorder=rec, clock=clock, sleep=clock.sleep,
                    reopen=lambda: reopened.append(1) or FakePort(clock))
    serve_steps(emu2, clock, clock.t + 3.0)
    assert reopened and "disconnect" in rec.events and "reconnect" in rec.events


def test_control_socket(spec, tmp_path):
    clock = FakeClock()
    path = str(tmp_path / "ctl.sock")
    control = ControlServer(path)
    try:
        unit = Unit(spec.variant("gve64-v19"), t0=clock.t)
        emu = Emulator(unit, FakePort(clock), control=control, control_handler=run_control, clock=clock)
        import threading

        reply = {}
        th = threading.Thread(
            target=lambda: reply.setdefault("r", send_control(path, "press stop")))
        th.start()
        deadline = time.monotonic() + 5
        while th.is_alive() and time.monotonic() < deadline:
            emu.step()
            time.sleep(0.001)
        th.join(1)
        assert reply["r"].startswith("ok I1=7F")
    finally:
        control.close()
    assert not os.path.exists(path)


# ---------------------------------------------------------------- conform emulate, for real


def start(*args):
    proc = subprocess.Popen([sys.executable, "-m", "conform", "emulate", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    path = proc.stdout.readline().strip()
    info = proc.stderr.readline()
    assert path, info
    sock = info.split("control: ")[1].split(";")[0].strip()
    return proc, path, sock


def stop(proc, sig=signal.SIGTERM):
    stop_emulator(proc, sig)
    assert proc.returncode in (0, 1, 2), "the emulator did not stop on a signal"
    return proc.returncode, proc.stderr_text


CLIENT = r"""
import sys, time, serial
s = serial.serial_for_url(sys.argv[1], 115200, timeout=2)
def ex(line):
    s.write(line + b"\r")
    out = b""
    while not out.endswith(b"\r"):
        c = s.read(1)
        if not c:
            break
        out += c
    return out.decode().rstrip("\r")
print(ex(b"!0?"), ex(b"!0%+"), ex(b"!0A100,4F"), ex(b"!0%-,CF"), ex(b"!0SW0,80"),
      ex(b"!0V5000"), ex(b"!0L100000,0,0"), sep="|", flush=True)
sys.stdin.readline()          # the test presses STOP meanwhile
print(ex(b"!0SR4"), ex(b"!0F"), ex(b"!0H"), ex(b"!3V1") or "-", sep="|", flush=True)
"""


@pytest.mark.slow
def test_pyserial_client_on_the_pty(tmp_path):
    rec = tmp_path / "emu.mcap"
    proc, path, sock = start("gve64-v19", "--record", str(rec))
    try:
        assert path.startswith("/dev/")
        client = subprocess.Popen([sys.executable, "-c", CLIENT, path], stdin=subprocess.PIPE,
                                  stdout=subprocess.PIPE, text=True)
        first = client.stdout.readline().strip().split("|")
        assert first == ["0,IP64MPG v19 10.9.2010", "0,5C", "0,5C", "0", "0", "0", "0"]
        out = subprocess.run([sys.executable, "-m", "conform", "emulate", "control", sock,
                              "press", "stop"], capture_output=True, text=True, timeout=20)
        assert out.returncode == 0 and "INTA=1" in out.stdout
        client.stdin.write("\n")
        client.stdin.flush()
        second = client.stdout.readline().strip().split("|")
        assert second[0] == "8,80" and second[1].startswith("8,") and second[2] == "8"
        assert second[3] == "-"  # another address: silence (read timed out)
        client.wait(10)
    finally:
        code, err = stop(proc)
    assert code == 0, err
    from conform.capture import open_capture

    cap = open_capture(rec)
    assert b"!0?\r" in cap.stream("host") and b"0,5C\r" in cap.stream("unit")


@pytest.mark.slow
def test_tcp_two_emulators_and_dialect(tmp_path):
    prof = tmp_path / "p.toml"
    prof.write_text('[dialect]\nA9 = "hex-index"\n')
    a, url_a, _ = start("gve124", "--tcp", "0", "--profile", str(prof), "--baud", "115200")
    b, url_b, _ = start("gve64-v10", "--tcp", "0", "--dialect", "A10=every-line")
    try:
        import serial

        assert url_a.startswith("socket://") and url_a != url_b
        for url, expect in ((url_a, b"0,IP124 v7/50 2.4.2018\r0,01\r"),
                            (url_b, b"0,IP64MPG v10\r0,2\r")):
            s = serial.serial_for_url(url, timeout=2)
            s.write(b"!0?\r")
            got = s.read_until(b"\r")
            s.write(b"!0@\r")
            got += s.read_until(b"\r")
            s.close()
            assert got == expect
    finally:
        assert stop(a)[0] == 0
        assert stop(b, signal.SIGINT)[0] == 0


@pytest.mark.slow
def test_cli_mistakes_are_one_line():
    for args in (["nosuch"], ["gve64-v19", "--dialect", "A99=x"], ["gve64-v19", "--faults",
                                                                    "noise=1"],
                 ["gve64-v19", "--profile", "/nonexistent.toml"]):
        out = subprocess.run([sys.executable, "-m", "conform", "emulate", *args],
                             capture_output=True, text=True, timeout=30)
        assert out.returncode != 0 and out.stdout == ""
        assert len(out.stderr.strip().splitlines()) == 1 and "Traceback" not in out.stderr
    out = subprocess.run([sys.executable, "-m", "conform", "emulate", "control", "/nonexist.sock",
                          "state"], capture_output=True, text=True, timeout=30)
    assert out.returncode != 0 and "cannot reach" in out.stderr
