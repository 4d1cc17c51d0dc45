"""Hostile input to the emulator: numbers and lines no unit expects, a host that stops reading,
a --control path that is not ours; in-process and over a real pty against `conform emulate`."""

from __future__ import annotations

import os
import select
import signal
import socket
import stat
import subprocess
import sys
import time
import tty

import pytest
from conftest import stop_emulator

from conform.emulator.serve import ControlServer, Emulator
from conform.errors import UserError
from conform.families.gve.protocol import CommandParser
from conform.families.gve.unit import Unit

HUGE = b"9" * 5000


# ---------------------------------------------------------------- item 2: numbers, in-process

@pytest.mark.parametrize("dialect", [{}, {"A22": "lenient"}, {"A1": "crlf"}, {"A18": "hex-bytes"}])
def test_huge_numbers_are_out_of_range(spec, dialect):
    """More digits than Python converts (4 300) in any numeric field: answered 5, never raised."""
    d = spec.dialect(dialect)
    term = b"\r\n" if d["A1"] == "crlf" else b"\r"
    unit = Unit(spec.variant("gve64-v19"), d)
    t = 0.0
    parser = CommandParser(spec.variant("gve64-v19"), d)
    for line in (b"!0C" + HUGE + b",1,1", b"!0L1,1," + HUGE, b"!0SW" + HUGE + b",1"):
        r = parser.parse(line, False)  # the parser alone takes any length
        assert (r.kind, r.code) == ("range", 5), r
    # a unit keeps 4 096 bytes of a line: what is left of these is still far out of range
    for line in (b"!0C1,1," + HUGE, b"!0L1,1,-" + HUGE, b"!0V" + HUGE,
                 b"!0ER" + b"F" * 5000, b"!0NX-" + HUGE, b"!0EUW1," + HUGE, b"!7V" + HUGE):
        expect = b"4\r" if b"EUW" in line and d["A18"] == "hex-bytes" else b"5\r"
        t, out = unit.exchange(line + term, t + 0.01)
        assert out == expect, line[:12]
        unit.receive(line + term, t + 0.01)  # the streaming path too
        assert [a for _, a in unit.poll(t + 1)] == [expect]
        t += 1
    # leading zeros do not count: this is 3
    t, out = unit.exchange(b"!0T" + b"0" * 4000 + b"3" + term, t + 0.01)
    assert out == b"0\r" and unit.modal["T"] == 3
    # a float of any length converts (to inf): out of range too
    t, out = unit.exchange(b"!0EFW10," + HUGE + term, t + 0.01)
    assert out == (b"4\r" if d["A18"] == "hex-bytes" else b"5\r")


def test_lenient_spaces_do_not_backtrack(spec):
    """A22 lenient: a line of spaces took 100 s to reject (regex backtracking)."""
    unit = Unit(spec.variant("gve64-v19"), spec.dialect({"A22": "lenient"}))
    start = time.process_time()
    _, out = unit.exchange(b"!0C" + b" " * 4000 + b"x\r", 0.0)
    _, out2 = unit.exchange(b"!0C1," + b" " * 2000 + b"1" + b" " * 2000 + b"x\r", 1.0)
    assert out == out2 == b"4\r"
    assert time.process_time() - start < 2.0
    _, out = unit.exchange(b"!0EFW1, E5\r", 2.0)   # digits missing: a syntax error, not a crash
    assert out == b"4\r"


def test_overlong_line_is_cut(spec):
    unit = Unit(spec.variant("gve64-v19"))
    unit.receive(b"!0V100" + b"0" * 10_000, 0.0)
    unit.receive(b"0" * 10_000 + b"\r", 0.05)
    assert [a for _, a in unit.poll(1.0)] == [b"5\r"]   # the first 4 096 bytes: a big number
    _, out = unit.exchange(b"!0?\r", 2.0)
    assert out.startswith(b"0,IP64")


# ---------------------------------------------------------------- item 11: > under A1=crlf

def test_repeat_under_crlf_with_lone_crs(spec):
    unit = Unit(spec.variant("gve64-v19"), spec.dialect({"A1": "crlf"}))
    t, out = unit.exchange(b"!0C1\r2\r,3\r\n", 0.0)
    assert out == b"4\r"
    t, out = unit.exchange(b"!0>\r\n", t + 0.01)
    assert out == b"!0C12,3\r4\r"   # one echoed line, then its answer
    t, out = unit.exchange(b"!0V1\r00\r\n", t + 0.01)   # "V1\r00": not a number
    t, out = unit.exchange(b"!0>\r\n", t + 0.01)
    assert out.count(b"\r") == 2 and out.startswith(b"!0V100\r")


# ---------------------------------------------------------------- item 6: the control socket

def test_control_refuses_what_is_not_ours(tmp_path):
    keep = tmp_path / "notes.txt"
    keep.write_text("mine")
    folder = tmp_path / "folder"
    folder.mkdir()
    link = tmp_path / "link"
    link.symlink_to(keep)
    for path in (keep, folder, link):
        with pytest.raises(UserError, match="not a socket"):
            ControlServer(str(path))
    assert keep.read_text() == "mine" and folder.is_dir() and link.is_symlink()
    live = ControlServer(str(tmp_path / "live.sock"))
    try:
        with pytest.raises(UserError, match="listening"):
            ControlServer(str(tmp_path / "live.sock"))
    finally:
        live.close()
    # a socket nobody listens on (an emulator that died) is replaced
    stale = socket.socket(socket.AF_UNIX)
    stale.bind(str(tmp_path / "stale.sock"))
    stale.close()
    server = ControlServer(str(tmp_path / "stale.sock"))
    server.close()
    assert not (tmp_path / "stale.sock").exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".conform")] == []


def test_control_socket_is_private_whatever_the_umask(tmp_path):
    old = os.umask(0)
    try:
        for path in (None, str(tmp_path / "c.sock")):
            server = ControlServer(path)
            try:
                mode = stat.S_IMODE(os.stat(server.path).st_mode)
                folder = stat.S_IMODE(os.stat(os.path.dirname(server._private)).st_mode)
                assert (mode, folder) == (0o600, 0o700), server.path
            finally:
                server.close()
            assert not os.path.exists(server.path)
    finally:
        os.umask(old)


@pytest.mark.slow
def test_emulate_control_on_a_file_is_one_line(tmp_path):
    keep = tmp_path / "keep.txt"
    keep.write_text("data")
    out = subprocess.run([sys.executable, "-m", "conform", "emulate", "gve64-v19", "--control",
                          str(keep)], capture_output=True, text=True, timeout=30)
    assert out.returncode == 2 and out.stdout == ""
    assert len(out.stderr.strip().splitlines()) == 1 and "not a socket" in out.stderr
    assert keep.read_text() == "data"


# ---------------------------------------------------------------- item 10: a host that does not read

class _DeafHost:
    """A port whose reader stops reading: writes take nothing until ``reading`` is set."""

    name = "deaf-host"

    def __init__(self) -> None:
        self.inbox: list[bytes] = []
        self.got = b""
        self.reading = False

    def read(self, max_bytes: int = 4096, timeout: float | None = 0.1) -> bytes:
        return self.inbox.pop(0) if self.inbox else b""

    def write_some(self, data: bytes) -> int:
        if not self.reading:
            return 0
        self.got += data
        return len(data)

    def close(self) -> None:
        pass


def test_emulator_drops_what_the_host_does_not_read(spec):
    port = _DeafHost()
    notes: list[str] = []
    unit = Unit(spec.variant("gve64-v19"), t0=time.monotonic())
    emu = Emulator(unit, port, report=notes.append)
    port.inbox.extend([b"!0?\r"] * 50)
    deadline = time.monotonic() + 5
    while emu.bytes_dropped < 50 * 24 and time.monotonic() < deadline:
        emu.step()
    assert not emu.stopping and emu.bytes_dropped == 50 * 24 and emu.bytes_out == 0
    port.reading = True
    port.inbox.append(b"!0Q\r")
    deadline = time.monotonic() + 5
    while not port.got and time.monotonic() < deadline:
        emu.step()
    assert port.got == b"0,25020304\r"
    assert any("does not read" in n for n in notes) and any("reads again" in n for n in notes)


# ---------------------------------------------------------------- over a real pty

def _open(path: str) -> int:
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(fd)
    return fd


def _read_until(fd: int, count: int, timeout: float = 5.0) -> bytes:
    """Read until ``count`` CRs arrived (or the timeout)."""
    out = b""
    deadline = time.monotonic() + timeout
    while out.count(b"\r") < count and time.monotonic() < deadline:
        ready, _, _ = select.select([fd], [], [], 0.1)
        if ready:
            out += os.read(fd, 65536)
    return out


def _drain(fd: int) -> int:
    n = 0
    while select.select([fd], [], [], 0.3)[0]:
        n += len(os.read(fd, 65536))
    return n


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        select.select([], [fd], [], 1.0)
        try:
            view = view[os.write(fd, view):]
        except BlockingIOError:
            pass


@pytest.mark.slow
def test_live_emulator_survives_hostile_lines_and_a_host_that_stops_reading(emulate):
    proc, path = emulate("gve64-v19", "--dialect", "A22=lenient")
    fd = _open(path)
    try:
        for line, answer in ((b"!0C1,1," + HUGE + b"\r", b"5\r"), (b"!0V" + HUGE + b"\r", b"5\r"),
                             (b"!0C" + b" " * 3000 + b"x\r", b"4\r"),
                             (b"!0SR" + b"7" * 20_000 + b"\r", b"5\r")):
            _write_all(fd, line)
            assert _read_until(fd, 1) == answer, line[:10]
        # the host stops reading: ~180 kB of answers to 7 200 lines; the emulator drops them
        _write_all(fd, b"!0?\r" * 7200)
        time.sleep(3.0)
        assert proc.poll() is None
        assert _drain(fd) < 7200 * 25
        _write_all(fd, b"!0Q\r")
        assert _read_until(fd, 1).endswith(b"0,25020304\r")
    finally:
        os.close(fd)
        stop_emulator(proc, signal.SIGTERM)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr_text, proc.stderr_text
    assert "does not read" in proc.stderr_text


def test_tcp_write_some_never_waits_for_a_client_that_does_not_read():
    from conform.link.tcp import TcpServerEndpoint

    ep = TcpServerEndpoint("127.0.0.1", 0)
    client = socket.create_connection(("127.0.0.1", ep.port))
    try:
        client.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        assert ep.wait_client(5)
        chunk = b"0,IP64MPG v19 10.9.2010\r" * 2000
        start = time.monotonic()
        taken = len(chunk)
        while taken == len(chunk) and time.monotonic() - start < 10:
            taken = ep.write_some(chunk)   # the client reads nothing
        assert taken < len(chunk) and time.monotonic() - start < 10
    finally:
        client.close()
        ep.close()
