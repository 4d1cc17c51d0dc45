"""The property a host relies on to get a unit back: after any byte sequence, the recovery of
conform.families.gve.testing.fuzz.recovery_frames (end the line, close a packet, J) and the deaf time after J,
the unit answers a valid command as the tables say. In-process over every variant and dialect,
and over a real pty against `conform emulate`."""

from __future__ import annotations

import os
import select
import signal
import time
import tty

import pytest
from conftest import stop_emulator
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conform.families.gve.protocol import append_checksum, encode_answer
from conform.families.gve.spec import load_spec
from conform.families.gve.testing.fuzz import recovery_frames
from conform.families.gve.unit import Unit

SPEC = load_spec()
LINES = [b"!0*S\r", b"!0%+\r", b"!0%-,CF\r", b"!0J\r", b"!0WX,100,10,0,10\r", b"!0L1000,0,0\r",
         b"!0H\r", b"!0Y+\r", b"!0C5,5,0\r", b"!0K\r", b"!0SW0,FF\r", b"!0SW6,80\r", b"\r\n",
         b"!0", b"!0*E3\r", b"!0>\r", b"!7V10\r", b"!0C" + b"9" * 5000 + b"\r"]
chunks = st.lists(st.tuples(st.one_of(st.binary(max_size=48), st.sampled_from(LINES)),
                            st.floats(0.0, 0.3)), max_size=25)
dialects = st.fixed_dictionaries({
    qid: st.sampled_from(list(q.alternatives)) for qid, q in SPEC.questions.items()})


def version_answer(variant) -> bytes:
    """What the tables say ``?`` answers after a reset (answer row of commands.toml, the
    variant's firmware, checksums as the reset table has them)."""
    return encode_answer(0, False, (variant.firmware,),
                         checksum_on=bool(variant.reset.get("checksum", False)))


def probe(variant, term: bytes) -> bytes:
    body = b"!%d?" % variant.interpolator_address
    return (append_checksum(body) if variant.reset.get("checksum") else body) + term


@given(variant=st.sampled_from(list(SPEC.variants)), choices=dialects, sent=chunks)
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_any_bytes_then_J_and_its_deaf_time_bring_the_unit_back(variant, choices, sent):
    v, d = SPEC.variant(variant), SPEC.dialect(choices)
    unit = Unit(v, d)
    t = 0.0
    for data, dt in sent:
        t += dt
        unit.receive(data, t)
        unit.poll(t)
    for frame in recovery_frames(v, d):
        t = max(t, unit.now)
        t, _ = unit.exchange(frame, t)  # waits for what is still due (a W, a halt)
    t = max(t, unit.now) + float(v.reset.get("ready_after_s", 2.0)) + 0.01
    term = b"\r\n" if d["A1"] == "crlf" else b"\r"
    _, out = unit.exchange(probe(v, term), t)
    assert out == version_answer(v)


# ---------------------------------------------------------------- over a real pty

class _Pty:
    def __init__(self, path: str) -> None:
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(self.fd)

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            select.select([], [self.fd], [], 1.0)
            try:
                view = view[os.write(self.fd, view):]
            except BlockingIOError:
                pass

    def read_quiet(self, quiet: float) -> bytes:
        """Everything until nothing came for ``quiet`` seconds."""
        out = b""
        while select.select([self.fd], [], [], quiet)[0]:
            out += os.read(self.fd, 65536)
        return out

    def read_line(self, timeout: float) -> bytes:
        out = b""
        deadline = time.monotonic() + timeout
        while not out.endswith(b"\r") and time.monotonic() < deadline:
            if select.select([self.fd], [], [], 0.05)[0]:
                out += os.read(self.fd, 1)
        return out


@pytest.fixture
def live(emulate):
    proc, path = emulate("gve64-v19", "--baud", "115200")
    port = _Pty(path)
    yield proc, port
    os.close(port.fd)
    stop_emulator(proc, signal.SIGTERM)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr_text


@pytest.mark.slow
@given(sent=st.lists(st.one_of(st.binary(max_size=64),
                               st.sampled_from([x for x in LINES if b"W" not in x])),
                     min_size=1, max_size=8))
@settings(max_examples=3, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
def test_over_a_pty_any_bytes_then_J_bring_conform_emulate_back(live, sent):
    proc, port = live
    v = SPEC.variant("gve64-v19")
    for data in sent:
        port.write(data)
    port.read_quiet(0.5)          # the host waits for what is still due
    for frame in recovery_frames(v, SPEC.dialect()):
        port.write(frame)
        port.read_quiet(0.15)
    time.sleep(float(v.reset["ready_after_s"]) + 0.2)
    port.read_quiet(0.1)
    port.write(probe(v, b"\r"))
    assert port.read_line(3.0) == version_answer(v)
    assert proc.poll() is None
