"""The reference sender: job loading, G-code, packets, policies, against the reference unit."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from conform.cli.main import cli
from conform.errors import UserError
from conform.families.gve.analysis import analyze
from conform.families.gve.protocol import CommandParser
from conform.families.gve.sender.core import Sender
from conform.families.gve.sender.gcode import GcodeOptions, gcode_segments, gcode_to_items, junction_speed
from conform.families.gve.sender.job import load_job, parse_item
from conform.families.gve.sender.links import LinkModel, halt_and_delete
from conform.families.gve.sender.session import send_emulated
from conform.families.gve.spec import load_spec

SPEC = load_spec()
VAR = SPEC.variant("gve64-v19")
DIA = SPEC.dialect()


def vectors(n: int, seed: int = 1) -> list:
    import random

    rng = random.Random(seed)
    parser = CommandParser(VAR, DIA)
    lines = ["V20000", "A200", "B5000"]
    lines += [f"C{rng.randint(-200, 200)},{rng.randint(-200, 200)},0" for _ in range(n)]
    return [parse_item(x, VAR, parser) for x in lines]


def intended(items: list) -> tuple[int, ...]:
    pos = [0, 0, 0, 0]
    for it in items:
        v = it.vector
        if v:
            for k, x in enumerate(v):
                pos[k] += x
    return tuple(pos)


def test_vector_file_and_errors(tmp_path: Path) -> None:
    p = tmp_path / "job.txt"
    p.write_text("# comment\n!0V1000\nC10,0,0 ; inline\n\n!0L0,5,0\n")
    items = load_job(p, VAR, DIA)
    assert [i.name for i in items] == ["V", "C", "L"]
    assert items[1].vector == (10, 0, 0) and items[1].motion
    p.write_text("V1000\nC10,zz,0\n")
    with pytest.raises(UserError, match=r"job.txt:2"):
        load_job(p, VAR, DIA)


def test_gcode_vectors_carry_rounding_and_junction_speeds(tmp_path: Path) -> None:
    text = "G21 G90\nF600\nG1 X1.005 Y0\nG1 X2.01 Y0\nG1 X2.01 Y1\nG2 X3.01 Y2 I1 J0\n"
    opts = GcodeOptions(steps_per_mm=(100.0, 100.0, 100.0))
    segs = gcode_segments(text, opts)
    assert sum(s.d[0] for s in segs) == 301 and sum(s.d[1] for s in segs) == 200
    items = gcode_to_items(text, VAR, DIA, opts)
    names = [i.name for i in items]
    assert names[:3] == ["A", "$", "V"] and "B" in names and names.count("C") == len(segs)
    # straight on: no slowdown; a right angle: well below the feed; a U-turn: stop
    v = 1000.0
    assert junction_speed((1, 0, 0), (1, 0, 0), v, opts, 100) == v
    assert junction_speed((1, 0, 0), (0, 1, 0), v, opts, 100) < v
    assert junction_speed((1, 0, 0), (-1, 0, 0), v, opts, 100) == 0.0
    bad = tmp_path / "bad.nc"
    bad.write_text("G1 X1\nG5 X2\n")
    with pytest.raises(UserError, match="bad.nc:2"):
        load_job(bad, VAR, DIA)


def test_packets_group_c_and_b_only() -> None:
    items = vectors(25)
    s = Sender(items, VAR, packet=10)
    kinds = [(u.packet, len(u.items)) for u in s.units]
    assert kinds[:3] == [(False, 1), (False, 1), (True, 11)]  # V, A, then B + 10 C
    assert sum(n for _, n in kinds) == len(items)


@pytest.mark.parametrize("packet,checksums", [(1, False), (1, True), (10, True)])
def test_careful_sender_on_a_clean_line_is_clean(tmp_path: Path, packet: int,
                                                 checksums: bool) -> None:
    items = vectors(120)
    rec = tmp_path / "c.mcap"
    res = send_emulated(items, VAR, DIA, packet=packet, checksums=checksums, record=rec)
    assert res.sender.failed is None
    assert res.position == intended(items) == res.sender.last_position
    a = analyze(rec)
    assert a.findings == []
    assert a.metrics["vectors_accepted"] == 120


def test_careful_sender_on_a_noisy_line_has_no_hazards(tmp_path: Path) -> None:
    items = vectors(300, seed=2)
    rec = tmp_path / "n.mcap"
    link = LinkModel(noise=0.004, seed=11, latency=0.002)
    res = send_emulated(items, VAR, DIA, checksums=True, link=link, record=rec)
    assert res.sender.failed is None
    assert res.sender.stats.garbled + res.sender.stats.timeouts > 0
    assert res.position == intended(items)
    a = analyze(rec)
    assert a.hazards() == []
    k = a.kinds()
    assert k.get("repeat-used", 0) + k.get("index-checked", 0) > 0


def test_careless_sender_moves_twice_and_is_caught(tmp_path: Path) -> None:
    items = vectors(60, seed=3)
    rec = tmp_path / "x.mcap"
    link = LinkModel(corrupt_answers={20}, corrupt_commands={40})
    res = send_emulated(items, VAR, DIA, policy="careless", link=link, record=rec)
    assert res.position != intended(items)
    a = analyze(rec)
    k = a.kinds()
    assert k.get("blind-resend") == 1 and k.get("double-move") == 1
    assert k.get("lost-vector") == 1
    assert all(f.extra.get("confirmed", True) for f in a.findings if f.kind == "lost-vector")


def test_queue_full_is_waited_out() -> None:
    parser = CommandParser(VAR, DIA)
    items = [parse_item(x, VAR, parser) for x in ["V20000"] + ["C400,0,0"] * 450]
    res = send_emulated(items, VAR, DIA)
    assert res.sender.stats.queue_full > 0
    assert res.position == (450 * 400, 0, 0, 0)


def test_cli_send_emulated_and_safety(tmp_path: Path) -> None:
    job = tmp_path / "j.txt"
    job.write_text("V5000\nC100,0,0\nC0,100,0\n")
    r = CliRunner().invoke(cli, ["send", str(job), "--target", "emu:gve124", "--checksums",
                                 "--record", str(tmp_path / "j.mcap")])
    assert r.exit_code == 0, r.output
    assert "final position: (100, 100, 0)" in r.output
    assert (tmp_path / "j.mcap").exists()
    r = CliRunner().invoke(cli, ["send", str(job), "--target", "/dev/null-not-a-port"])
    assert r.exit_code != 0
    assert "--allow-motion" in str(r.exception) or "--allow-motion" in r.output


class FakePort:
    def __init__(self) -> None:
        self.written: list[bytes] = []
        self.timeout = 0.0

    def write(self, data: bytes) -> None:
        self.written.append(data)

    def read_until(self, term: bytes) -> bytes:
        return b"8\r" if len(self.written) == 1 else b"0\r"


def test_interrupt_sends_halt_then_delete() -> None:
    s = Sender(vectors(3), VAR)
    port = FakePort()
    answers = halt_and_delete(s, port)
    assert port.written == [b"!0H\r", b"!0D\r"] and answers == [b"8\r", b"0\r"]


class UnitPort:
    """A pyserial-like port whose other end is the reference unit on the wall clock."""

    def __init__(self) -> None:
        import time

        from conform.families.gve.unit import Unit

        self.clock = time.monotonic
        self.unit = Unit(VAR, DIA, t0=self.clock())
        self.timeout = 0.0
        self.pending = b""

    @property
    def in_waiting(self) -> int:
        self._pull()
        return len(self.pending)

    def _pull(self) -> None:
        for _t, data in self.unit.poll(self.clock()):
            self.pending += data

    def write(self, data: bytes) -> None:
        self.unit.receive(data, self.clock())

    def read(self, n: int = 1) -> bytes:
        import time

        end = self.clock() + (self.timeout or 0.0)
        while True:
            self._pull()
            if self.pending or self.clock() >= end:
                out, self.pending = self.pending[:n], self.pending[n:]
                return out
            time.sleep(0.0005)


def test_run_serial_on_the_wall_clock() -> None:
    from conform.families.gve.sender.links import run_serial

    parser = CommandParser(VAR, DIA)
    items = [parse_item(x, VAR, parser) for x in ["V50000", "C100,0,0", "C0,100,0", "C-50,0,0"]]
    s = Sender(items, VAR, checksums=True, packet=2, poll_interval=0.01)
    run_serial(s, UnitPort())
    assert s.failed is None and s.last_position == (50, 100, 0, 0)


@pytest.mark.parametrize("seed", [0, 6, 11, 23])
def test_careful_sender_never_moves_twice_on_a_very_noisy_line(seed: int) -> None:
    """Heavy noise (0.6 % of bytes damaged): answers, echoes of `>` and `>` itself get hit.
    The careful sender must end exactly where the job ends, or stop, never guess."""
    items = vectors(150, seed=seed)
    link = LinkModel(noise=0.006, seed=seed, latency=0.002)
    res = send_emulated(items, VAR, DIA, checksums=True, link=link)
    assert res.sender.stats.garbled + res.sender.stats.timeouts > 0
    if res.sender.failed is None:
        assert res.position == intended(items)
    else:
        assert "stopping" in res.sender.failed


def test_careful_sender_after_a_lost_checksum_on_answer() -> None:
    """`%+` taken but its answer lost: the next `%+` (sent unsummed) is refused with a summed
    4, which shows checksums are already on."""
    items = vectors(20, seed=1)
    link = LinkModel(seed=1, corrupt_answers={0})
    res = send_emulated(items, VAR, DIA, checksums=True, link=link)
    assert res.sender.failed is None and res.sender.done
    assert res.position == intended(items)
