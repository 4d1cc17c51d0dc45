"""`conform emulate serve grbl-1.1f` as a real pty at 115200 baud: banner, $$, ok, error:N,
status on '?'; `conform run` against it over the pty; a recorded overflowing sender is caught
by `conform analyze`."""

from __future__ import annotations

import functools
import json
import subprocess
import sys
import time

import pytest
import serial

from conform.families.grbl.spec.load import load_grbl
from tests import emulated
from tests.emulated import stop

G = load_grbl()
V = G.variant("grbl-1.1f")


def start(*args):
    proc, path, _ = emulated.serve("serve", "grbl-1.1f", "--baud", "115200", *args)
    return proc, path


def read_lines(port, n, timeout=3.0):
    return emulated.read_lines(port, n, timeout, eol=b"\r\n")


@pytest.fixture
def emulator():
    proc, path = start()
    yield path
    stop(proc)


def test_answers_like_grbl_over_a_pty(emulator):
    port = serial.Serial(emulator, 115200, timeout=0.05)
    try:
        # the power-up banner went out when the emulator started; pyserial flushes its input on
        # open, so whether this open still sees it is a race (no DTR reset on a pty)
        assert read_lines(port, 2, timeout=0.3) in ([], ["", V.banner])
        port.write(b"\x18")
        assert read_lines(port, 2) == ["", V.banner]                 # on Ctrl-X
        port.write(b"$$\n")
        listing = next(e for e in G.examples if e.id == "settings")
        assert tuple(read_lines(port, len(listing.expect))) == listing.expect
        port.write(b"G5\nG1X-1F100\n")
        assert read_lines(port, 2) == ["error:20", "ok"]
        port.write(b"?")
        report = read_lines(port, 1)[0]
        assert report.startswith("<Run|MPos:") and "|FS:" in report
    finally:
        port.close()


@pytest.mark.slow
def test_conform_run_over_the_pty(emulator, tmp_path):
    p = subprocess.run([sys.executable, "-m", "conform", "run", "--target", emulator,
                        "--variant", "grbl-1.1f", "--report", str(tmp_path), "-q",
                        "--check", "*/example/*", "--check", "*/error/2?",
                        "--check", "*/buffer/*"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "FAIL" not in p.stdout and "PASS" in p.stdout
    assert "setting writes SKIPPED" not in p.stdout      # notes go to the report
    assert (tmp_path / "results.json").exists()


# every check over the pty, in PARTS runs side by side (each on its own emulator): over a link a
# check waits for grbl's answers, its reset banner and the settings it restores (~400 checks)
PARTS = 4


@functools.cache
def _parts() -> list[list[str]]:
    """Every check, in PARTS of about the same length: the longest first, each to the part
    with the least so far, by the run's own estimate (the reference unit's virtual clock). Each
    part keeps the run's order: the from-state rows come last, after other checks have left
    the machine at a fractional position, which the reference adopts in whole steps where the
    unit's parser stands after the reset that starts each row (main.c gc_sync_position)."""
    from conform.conformance.target import EmuTarget
    from conform.families import family
    from conform.families.grbl.conformance.checks import SEQUENCES, GrblRunner, generate
    from conform.families.grbl.conformance.machine import link_budget

    checks = generate(G, "grbl-1.1f")
    assert any("/from_state/" in c.id for c in checks)
    sim = EmuTarget(lambda: family("grbl").make_unit("grbl-1.1f"), "estimate", baud=115200)
    runner = GrblRunner(sim, "grbl-1.1f", allow_motion=True, allow_eeprom=True)
    cost = runner.estimate_run(checks).per_check
    for c in checks:     # on a link the random sequences run for their wall-time budget
        if c.id.endswith(SEQUENCES):
            cost[c.id] += link_budget(runner.options)
    parts: list[list[str]] = [[] for _ in range(PARTS)]
    load = [0.0] * PARTS
    for c in sorted(checks, key=lambda c: -cost[c.id]):
        k = load.index(min(load))
        parts[k].append(c.id)
        load[k] += cost[c.id]
    order = {c.id: n for n, c in enumerate(checks)}
    return [sorted(part, key=order.__getitem__) for part in parts]


def test_the_parts_hold_every_check_once():
    from conform.families.grbl.conformance.checks import generate

    ids = [c.id for c in generate(G, "grbl-1.1f")]
    parts = _parts()
    assert sorted(x for part in parts for x in part) == sorted(ids) and len(set(ids)) == len(ids)
    assert all(part for part in parts)
    assert all(not set(x) & set("*?[") for x in ids)   # each id is a glob matching only itself


@pytest.mark.slow
@pytest.mark.parametrize("part", range(PARTS))
@pytest.mark.long(100)
def test_every_check_over_the_pty(emulator, tmp_path, part):
    chosen = _parts()[part]
    p = subprocess.run([sys.executable, "-m", "conform", "run", "--target", emulator,
                        "--variant", "grbl-1.1f", "--allow-motion", "--allow-eeprom",
                        "--report", str(tmp_path), "-q",
                        *(arg for x in chosen for arg in ("--check", x))],
                       capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "FAIL" not in p.stdout and "SKIPPED" not in p.stdout
    results = json.loads((tmp_path / "results.json").read_text())
    assert sorted(c["id"] for c in results["checks"]) == sorted(chosen)


SENDER = r"""
import sys, time, serial
s = serial.Serial(sys.argv[1], 115200, timeout=0.02)
time.sleep(0.2); s.read(4096)
lines = [("G1X%.3fY%.3fF3000\n" % (-(i % 20) * 0.2, -(i % 7) * 0.1)).encode() for i in range(60)]
counted, buf, i, end = [], b"", 0, time.monotonic() + 8
while i < len(lines) and time.monotonic() < end:
    if sum(counted) + len(lines[i]) <= 128:
        if i % 10 == 5:
            s.write(b"$G\n")      # a polling thread's line, outside the count
        s.write(lines[i]); counted.append(len(lines[i])); i += 1
        continue
    buf += s.read(256)
    while b"\n" in buf:
        line, _, buf = buf.partition(b"\n")
        if line.strip() == b"ok" or line.startswith(b"error"):
            if counted:
                counted.pop(0)
time.sleep(0.5)
"""


@pytest.mark.slow
def test_an_overflowing_sender_is_caught_by_analyze(tmp_path):
    cap = tmp_path / "grbl.mcap"
    proc, path = start("--record", str(cap))
    try:
        subprocess.run([sys.executable, "-c", SENDER, path], timeout=60, check=True)
    finally:
        err = stop(proc)
    assert "lost to a full receive buffer" in err
    p = subprocess.run([sys.executable, "-m", "conform", "analyze", str(cap)],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert "protocol family grbl" in p.stdout
    assert "hazard  rx-overflow-hazard" in p.stdout
    assert "streaming character-counting" in p.stdout or "streaming unbounded" in p.stdout


@pytest.mark.slow
def test_proxy_in_front_of_the_emulator_records_the_overflow(tmp_path):
    cap = tmp_path / "proxy.mcap"
    emu, path = start()
    proxy = subprocess.Popen([sys.executable, "-m", "conform", "proxy", "--unit", path, "-o",
                              str(cap), "--variant", "grbl-1.1f"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        host_path = proxy.stdout.readline().strip()
        assert host_path.startswith("/dev/"), proxy.stderr.read()
        subprocess.run([sys.executable, "-c", SENDER, host_path], timeout=60, check=True)
    finally:
        stop(proxy)
        stop(emu)
    p = subprocess.run([sys.executable, "-m", "conform", "analyze", str(cap)],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert "protocol family grbl (variant grbl-1.1f)" in p.stdout
    assert "rx-overflow-hazard" in p.stdout


def test_faults_apply_to_the_grbl_emulator():
    proc, path = start("--faults", "unit.corrupt=1", "--seed", "1")
    try:
        port = serial.Serial(path, 115200, timeout=0.05)
        read_lines(port, 2, timeout=0.3)
        port.write(b"$I\n")
        got = b""
        end = time.monotonic() + 3
        while len(got) < 30 and time.monotonic() < end:
            got += port.read(256)
        port.close()
    finally:
        stop(proc)
    assert len(got) >= 30 and b"VER" not in got and b"ok" not in got   # every byte flipped
