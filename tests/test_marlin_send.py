"""`conform send` to Marlin over a real pty against `conform emulate serve marlin-2.1`, on a
link that damages host bytes and loses answers: every line numbered and checksummed, sent
again when the unit asks, a lost ok found, each line run once, and the unit ends where the
job leads (from the job's own coordinates, read back through the emulator's state)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest


def conform(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "conform", *args], capture_output=True,
                          text=True, timeout=120)


@pytest.mark.slow
def test_a_job_streams_through_resends_and_lost_answers(emulate, tmp_path: Path):
    job = tmp_path / "job.gcode"
    moves = [(i * 0.5, (i % 3) * 0.5) for i in range(1, 81)]
    job.write_text("G90 ; absolute\n\n" + "".join(f"G1 X{x:.2f} Y{y:.2f} F6000\n"
                                                   for x, y in moves))
    sock = tmp_path / "c.sock"
    emulate("serve", "marlin-2.1", "--baud", "115200", "--link", str(tmp_path / "m.pty"),
            "--control", str(sock), "--seed", "1")
    for words in (["fault", "lose", "2"], ["fault", "line", "host.corrupt=5e-3"]):
        assert conform("emulate", "control", str(sock), *words).returncode == 0
    p = conform("send", str(job), "--target", str(tmp_path / "m.pty"), "--variant",
                "marlin-2.1", "--allow-motion", "-q", "--record", str(tmp_path / "s.mcap"))
    assert p.returncode == 0, p.stderr
    lines = 1 + len(moves)
    said = re.search(r"sent (\d+) of (\d+) job lines .*: (\d+) ok, (\d+) resent", p.stdout)
    assert said and said.groups()[:3] == (str(lines),) * 3, p.stdout
    assert int(said[4]) >= 1, p.stdout   # the noisy link made the unit ask again
    x, y = moves[-1]
    assert f"final position: X:{x:.2f} Y:{y:.2f} Z:0.00" in p.stdout
    state = json.loads(conform("emulate", "control", str(sock), "state").stdout[3:])
    # the job's lines, then M400 and M114, each numbered once and run once
    assert state["last_line"] == lines + 2 and state["twice"] == []
    assert state["position"][:2] == [x, y] and state["halted"] is False
    analysed = conform("analyze", str(tmp_path / "s.mcap"))
    assert analysed.returncode == 0 and "protocol family marlin" in analysed.stdout


@pytest.mark.slow
def test_send_without_a_variant_opens_the_port_once(emulate, tmp_path: Path, monkeypatch):
    """The probe that finds the unit (each family's question) and the stream share one open
    of the port: a board that resets when its port is opened (DTR) resets once."""
    from click.testing import CliRunner

    import conform.link.ports as ports
    from conform.cli.main import cli

    job = tmp_path / "job.gcode"
    job.write_text("G90\nG1 X1 F6000\n")
    emulate("serve", "marlin-2.1", "--baud", "115200", "--link", str(tmp_path / "m.pty"))
    opened = []
    real = ports._open

    def counting(url, *a, **k):
        opened.append(url)
        return real(url, *a, **k)

    monkeypatch.setattr(ports, "_open", counting)
    r = CliRunner().invoke(cli, ["send", str(job), "--target", str(tmp_path / "m.pty"),
                                 "--allow-motion", "-q"])
    assert r.exit_code == 0, r.output
    assert "sent 2 of 2 job lines" in r.output and "(marlin-2.1)" in r.output
    assert opened == [str(tmp_path / "m.pty")]
    with ports.held_open("loop://", 9600):
        a, b = ports.open_port("loop://", 9600), ports.open_port("loop://", 9600)
        a.close()
        b.write(b"x")
        assert a.serial is b.serial and not b.closed
    assert b.closed
