"""The link layer: ptys, pyserial ports and URLs, the TCP server, the forwarding loops."""

from __future__ import annotations

import threading
import time

import pytest

from conform.errors import LinkError
from conform.link import (
    Forwarder,
    PortGone,
    PtyEndpoint,
    Reopener,
    Tap,
    TcpServerEndpoint,
    open_port,
)


def read_until(endpoint, n: int, timeout: float = 2.0) -> bytes:
    out = b""
    deadline = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        out += endpoint.read(4096, 0.05)
    return out


def test_pty_is_raw_both_ways():
    with PtyEndpoint() as pty, open_port(pty.path, 115200) as port:
        every_byte = bytes(range(256))
        port.write(every_byte)
        assert read_until(pty, 256) == every_byte  # no echo, no CR/LF translation
        pty.write(b"0\r\n\x03\x1a")
        assert read_until(port, 5) == b"0\r\n\x03\x1a"


def test_pty_read_times_out_empty():
    with PtyEndpoint() as pty:
        t0 = time.monotonic()
        assert pty.read(10, 0.05) == b""
        assert time.monotonic() - t0 >= 0.04


def _sees_it_gone(port) -> None:
    """The peer's reads end in PortGone (within a second), and it closes its port."""
    with pytest.raises(PortGone):
        for _ in range(20):
            port.read(10, 0.05)
    port.close()


def test_closing_the_pty_unplugs_the_peer():
    pty = PtyEndpoint()
    port = open_port(pty.path, 115200)
    pty.close()
    _sees_it_gone(port)
    with pytest.raises(PortGone):
        pty.read(10, 0.01)


def test_pty_symlink_is_a_stable_name(tmp_path):
    link = tmp_path / "unit"
    with PtyEndpoint(link=link) as pty:
        assert pty.path == str(link)
        assert link.resolve() == pty.device or str(link.resolve()) == pty.device
        with open_port(str(link), 115200) as port:
            port.write(b"x")
            assert read_until(pty, 1) == b"x"
    assert not link.exists()


def test_a_reopened_pty_path_never_reaches_another_pty():
    """The kernel hands a closed pty's number to the next pty opened anywhere: a proxy or a
    sniffer reopening /dev/pts/N after its pty went away must not reach another program's
    port. While the reopener lives, the number stays taken and the path stays gone."""
    first = PtyEndpoint()
    path = first.device
    again = Reopener(path, 115200)
    again().close()
    first.close()
    held = [PtyEndpoint() for _ in range(8)]     # the lowest free numbers go first
    try:
        assert path not in [pty.device for pty in held]
        with pytest.raises(LinkError) as err:
            again()
        assert path in str(err.value) and "\n" not in str(err.value)
        again.close()                            # let go: the number is free again
    finally:
        for pty in held:
            pty.close()


def test_an_unplugged_pty_keeps_its_number_until_closed():
    """An emulator's line down (--faults disconnect): the peer is hung up and the device node
    goes, but no other pty can take the number until the emulator lets it go."""
    pty = PtyEndpoint()
    port = open_port(pty.device, 115200)
    pty.unplug()
    _sees_it_gone(port)
    with pytest.raises(LinkError):
        open_port(pty.device, 115200)
    others = [PtyEndpoint() for _ in range(4)]
    try:
        assert pty.device not in [o.device for o in others]
    finally:
        for o in others:
            o.close()
        pty.close()


def test_the_same_pty_opens_again_and_a_symlink_follows_its_new_pty(tmp_path):
    with PtyEndpoint() as pty:
        again = Reopener(pty.device, 115200)
        for _ in range(2):
            again().close()
    again.close()
    link = tmp_path / "unit"
    again = Reopener(str(link), 115200)
    for _ in range(2):     # made again for each new pty, as check-sender and --reconnect do
        with PtyEndpoint(link=link) as pty, again() as port:
            port.write(b"x")
            assert read_until(pty, 1) == b"x"


def test_a_line_that_hangs_up_while_it_is_opened_is_a_link_error(monkeypatch):
    """pyserial opens the device, then flushes it; a line dropped in between (an adapter
    pulled, an emulator's line going down) makes that flush fail with termios.error, which
    is no OSError: open_port says so in one line instead of letting it through."""
    import serial.serialposix as posix

    pty = PtyEndpoint()
    flush = posix.termios.tcflush

    def hang_up_first(fd, queue):
        pty.unplug()                      # the line drops between open() and the flush
        return flush(fd, queue)

    monkeypatch.setattr(posix.termios, "tcflush", hang_up_first)
    try:
        with pytest.raises(LinkError) as err:
            open_port(pty.device, 115200)
    finally:
        pty.close()
    assert pty.device in str(err.value) and "\n" not in str(err.value)


def test_open_port_failure_is_one_line_link_error(tmp_path):
    with pytest.raises(LinkError) as err:
        open_port(str(tmp_path / "no-such-tty"), 115200)
    assert "no-such-tty" in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(LinkError):
        open_port("socket://127.0.0.1:1", 115200)
    with pytest.raises(LinkError):
        open_port("", 115200)


def test_loop_url_without_descriptor():
    with open_port("loop://", 115200) as port:
        port.write(b"!0?\r")
        assert read_until(port, 4) == b"!0?\r"
        assert port.read(10, 0.02) == b""


def test_tcp_server_serves_one_client_at_a_time():
    events: list[tuple[str, str]] = []
    with TcpServerEndpoint(on_event=lambda k, d: events.append((k, d))) as server:
        server.write(b"dropped: nobody listens")
        client = open_port(server.path, 115200)
        assert server.wait_client(2.0)
        client.write(b"!0PF\r")
        assert read_until(server, 5) == b"!0PF\r"
        server.write(b"0,1,2,3\r")
        assert read_until(client, 8) == b"0,1,2,3\r"
        second = open_port(server.path, 115200)
        second.write(b"!0?\r")
        assert read_until(server, 4) == b"!0?\r"
        assert [k for k, _ in events] == ["open", "disconnect", "open"]
        second.close()
        client.close()
        assert server.read(10, 0.1) == b""
        assert not server.connected


def _collector():
    chunks: list[tuple[str, bytes, float]] = []
    events: list[tuple[str, str, str]] = []
    return chunks, events, (lambda d, b, t: chunks.append((d, b, t))), (
        lambda k, s, d: events.append((k, s, d)))


def test_forwarder_moves_and_reports_both_ways():
    chunks, events, on_chunk, on_event = _collector()
    host, unit_pty = PtyEndpoint(), PtyEndpoint()
    sender = open_port(host.path, 115200)
    unit = open_port(unit_pty.path, 115200)
    fwd = Forwarder(host, unit, on_chunk=on_chunk, on_event=on_event)
    fwd.start()
    try:
        sender.write(b"!0L1000,0,0\r")
        assert read_until(unit_pty, 12) == b"!0L1000,0,0\r"
        unit_pty.write(b"0\r")
        assert read_until(sender, 2) == b"0\r"
    finally:
        fwd.join()
        sender.close(), unit.close(), host.close(), unit_pty.close()
    assert b"".join(b for d, b, _ in chunks if d == "host") == b"!0L1000,0,0\r"
    assert b"".join(b for d, b, _ in chunks if d == "unit") == b"0\r"
    assert [d for d, _, _ in chunks][0] == "host"
    assert not events and fwd.failure is None


def test_forwarder_ends_when_the_unit_vanishes():
    chunks, events, on_chunk, on_event = _collector()
    host, unit_pty = PtyEndpoint(), PtyEndpoint()
    unit = open_port(unit_pty.path, 115200)
    fwd = Forwarder(host, unit, on_chunk=on_chunk, on_event=on_event)
    fwd.start()
    unit_pty.close()
    assert fwd.wait(3.0)
    fwd.join()
    host.close()
    assert events and events[0][0] == "disconnect" and events[0][1] == "unit"
    assert fwd.failure and "unit port lost" in fwd.failure


def test_forwarder_reconnects_to_a_port_that_comes_back(tmp_path):
    chunks, events, on_chunk, on_event = _collector()
    link = tmp_path / "unit"
    host, unit_pty = PtyEndpoint(), PtyEndpoint(link=link)
    sender = open_port(host.path, 115200)
    fwd = Forwarder(host, open_port(str(link), 115200), on_chunk=on_chunk, on_event=on_event,
                    reopen_unit=lambda: open_port(str(link), 115200), retry_interval=0.05)
    fwd.start()
    try:
        sender.write(b"!0?\r")
        assert read_until(unit_pty, 4) == b"!0?\r"
        unit_pty.close()  # unplugged
        deadline = time.monotonic() + 3
        while not any(e[0] == "disconnect" for e in events) and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.15)  # a few failed retries
        unit_pty = PtyEndpoint(link=link)  # plugged back in
        while not any(e[0] == "reconnect" for e in events) and time.monotonic() < deadline:
            time.sleep(0.01)
        sender.write(b"!0PF\r")
        assert read_until(unit_pty, 5) == b"!0PF\r"
        unit_pty.write(b"0,0,0,0\r")
        assert read_until(sender, 8) == b"0,0,0,0\r"
    finally:
        fwd.join()
        sender.close(), host.close(), unit_pty.close()
    kinds = [e[0] for e in events]
    assert kinds[0] == "disconnect" and "reconnect" in kinds
    assert not fwd.stopped or fwd.failure is None


def test_tap_keeps_the_other_side_when_one_vanishes():
    chunks, events, on_chunk, on_event = _collector()
    a, b = PtyEndpoint(), PtyEndpoint()
    tap = Tap(open_port(a.path, 115200), open_port(b.path, 115200), on_chunk=on_chunk,
              on_event=on_event)
    tap.start()
    try:
        a.write(b"!0?\r")
        deadline = time.monotonic() + 3
        while not chunks and time.monotonic() < deadline:
            time.sleep(0.01)
        a.close()  # the host-side adapter is unplugged
        while not events and time.monotonic() < deadline:
            time.sleep(0.01)
        b.write(b"0,IP64MPG v19\r")
        while len(b"".join(c for d, c, _ in chunks if d == "unit")) < 14 and \
                time.monotonic() < deadline:
            time.sleep(0.01)
        assert not tap.stopped
    finally:
        tap.join()
        b.close()
    assert b"".join(c for d, c, _ in chunks if d == "host") == b"!0?\r"
    assert b"".join(c for d, c, _ in chunks if d == "unit") == b"0,IP64MPG v19\r"
    assert events[0][:2] == ("disconnect", "host")


def test_pty_write_times_out_when_nobody_reads():
    with PtyEndpoint(write_timeout=0.1) as pty:
        stop = threading.Event()
        with pytest.raises(LinkError):
            while not stop.is_set():
                pty.write(b"x" * 4096)
