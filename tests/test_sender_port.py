"""`conform send` as a user runs it: over a real pty against the emulator (wall clock,
115200 Bd pacing), a silent port, a checksum mode left on, the variant learnt from `?`, and
hostile job files (one line, exit 2)."""

from __future__ import annotations

import contextlib
import random
import subprocess
import sys
import threading
import time

import pytest

from conform.cli.main import main
from conform.emulator.serve import Emulator
from conform.families.gve.conformance.characterize import characterize
from conform.families.gve.conformance.target import open_target
from conform.families.gve.unit.model import Unit
from conform.families.gve.unit.truth import GroundTruth
from conform.link.pty import PtyEndpoint


@contextlib.contextmanager
def emulator(spec, variant: str = "gve64-v19"):
    t0 = time.monotonic()
    unit = Unit(spec.variant(variant), spec.dialect(), t0=t0)
    truth = GroundTruth(unit, t0=t0)
    ep = PtyEndpoint()
    emu = Emulator(unit, ep, baud=115200)
    th = threading.Thread(target=emu.run, daemon=True)
    th.start()
    try:
        yield ep.path, unit, truth
    finally:
        emu.stop()
        th.join(5)


def send(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "conform", "send", *args],
                          capture_output=True, text=True, timeout=timeout)


@pytest.mark.slow
def test_silent_port_fails_in_bounded_time(tmp_path, capsys):
    """In-process, so the bound times the probing itself, not a Python start on a loaded
    machine (the command line's one-line errors have their own subprocess tests)."""
    job = tmp_path / "j.txt"
    job.write_text("V1000\n")
    ep = PtyEndpoint()  # nobody answers
    try:
        t = time.monotonic()
        with pytest.raises(SystemExit) as exc:
            main(["send", str(job), "--target", ep.path])
        took = time.monotonic() - t
    finally:
        ep.close()
    err = capsys.readouterr().err
    assert exc.value.code != 0
    assert "no answer" in err and err.count("\n") == 1, err
    # a few tries of half a second each (about 5 s on an idle machine): a hang would never end,
    # and a starved worker on a loaded one took 21 s
    assert took < 60


@pytest.mark.slow
def test_checksums_left_on_are_found_and_cleared(spec, tmp_path):
    job = tmp_path / "j.txt"
    job.write_text("V5000\nC100,0,0\nC100,0,0\nC0,50,0\n")
    with emulator(spec) as (path, unit, truth):
        import serial

        with serial.Serial(path, 115200, timeout=1) as port:  # what a crashed sender left
            port.write(b"!0%+\r")
            assert port.read_until(b"\r") == b"0,5C\r"
        p = send(str(job), "--target", path, "--allow-motion")
        assert p.returncode == 0, p.stderr
        assert "checksums were left on" in p.stderr
        assert "4/4 job lines (100 %)" in p.stderr  # progress while streaming
        assert "final position: (200, 50, 0, 0)" in p.stdout
        assert not unit.checksum_on
        assert [a.vector for a in truth.accepted] == [(100, 0, 0, 0), (100, 0, 0, 0), (0, 50, 0, 0)]


@pytest.mark.slow
def test_variant_from_the_unit_no_four_axis_vector_to_a_gve124(spec, tmp_path):
    job = tmp_path / "j.txt"
    job.write_text("C100,0,0,5\n")
    with emulator(spec, "gve124") as (path, unit, truth):
        p = send(str(job), "--target", path, "--allow-motion")
        assert p.returncode == 2 and "j.txt:1" in p.stderr, p.stderr
        p = send(str(job), "--target", path, "--allow-motion", "--variant", "gve64-v19")
        assert p.returncode == 2 and "IP124" in p.stderr, p.stderr
        assert truth.accepted == []  # nothing moved


def test_characterize_leaves_checksums_as_found(spec):
    target, _ = open_target("emu:gve64-v19", spec)
    try:
        characterize(spec, target, "gve64-v19", passes=1)
        assert target.state()["checksum"] is False
        assert not target.checksum_on
    finally:
        target.close()


def _garbage(seed: int) -> bytes:
    rng = random.Random(seed)
    return bytes(rng.randrange(256) for _ in range(400))


HOSTILE = {
    "truncated.txt": b"V1000\nC100,0,",
    "garbage.txt": _garbage(1),
    "garbage.nc": _garbage(2),
    "nul.txt": b"C100\x00,0,0\n",
    "huge.txt": b"C99999999999999999999,0,0\n",
    "huge.nc": b"G1 X99999999999\n",
    "exp.nc": b"G1 X1e400\n",
    "nan.txt": b"Cnan,0,0\n",
    "nan.nc": b"G1 Xnan Y0\n",
    "inf.nc": b"G1 Xinf\n",
    "empty.txt": b"",
    "empty.nc": b"",
    "comments.txt": b"# nothing\n; here\n",
    "unclosed.nc": b"G1 X1 (never closed\n",
    "letter-o.nc": b"G1 X1O\n",
    "unknown.nc": b"G1 X1 Q5\n",
    "arc.nc": b"G2 X1 Y1\n",
    "latin1.txt": "V1000 é\n".encode("latin-1"),
    "long.txt": b"C" + b"1" * 100_000 + b",0,0\n",
}


@pytest.mark.parametrize("name", sorted(HOSTILE) + ["a-directory.nc", "missing.txt"])
def test_hostile_job_files_are_one_line_and_exit_2(name, tmp_path, capsys):
    path = tmp_path / name
    if name == "a-directory.nc":
        path.mkdir()
    elif name != "missing.txt":
        path.write_bytes(HOSTILE[name])
    with pytest.raises(SystemExit) as exc:
        main(["send", str(path), "--target", "emu:gve64-v19"])
    err = capsys.readouterr().err
    assert exc.value.code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err and name in err, err


@pytest.mark.parametrize("opt", [["--noise", "1.5"], ["--noise", "-0.1"], ["--noise", "nan"],
                                 ["--latency", "-1"], ["--timeout", "0"],
                                 ["--steps-per-mm", "nan"], ["--feed", "inf"]])
def test_bad_numbers_are_refused(opt, tmp_path, capsys):
    job = tmp_path / "j.txt"
    job.write_text("V1000\n")
    with pytest.raises(SystemExit) as exc:
        main(["send", str(job), "--target", "emu:gve64-v19", *opt])
    assert exc.value.code == 2
    assert opt[0] in capsys.readouterr().err


def test_lenient_reads_what_strict_refuses(tmp_path, capsys):
    job = tmp_path / "j.nc"
    job.write_text("%\nM3 S1000\nG1 X1 Y0 F600\nG1 X1O\n")
    with pytest.raises(SystemExit) as exc:
        main(["send", str(job), "--target", "emu:gve64-v19"])
    assert exc.value.code == 2 and "j.nc:2:1" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["send", str(job), "--target", "emu:gve64-v19", "--lenient"])
    assert exc.value.code == 0


def test_move_on_policy_with_lost_answers_does_not_exit_0(tmp_path, capsys):
    job = tmp_path / "j.txt"
    job.write_text("C100,0,0\nC100,0,0\nC0,50,0\n")
    with pytest.raises(SystemExit) as exc:
        main(["send", str(job), "--target", "emu:gve64-v19", "--policy", "move-on",
              "--corrupt-command", "1"])
    assert exc.value.code == 1
    assert "acknowledged" in capsys.readouterr().err


