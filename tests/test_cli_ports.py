"""``conform ports``: the listing, and --probe against the emulator on a real pty."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from conform.cli.main import main


def test_listing_has_device_description_and_hwid(capsys, monkeypatch):
    from serial.tools.list_ports_common import ListPortInfo

    info = ListPortInfo("/dev/ttyUSB7")
    info.description, info.hwid = "FT232R USB UART", "USB VID:PID=0403:6001 SER=A9XYZ"
    monkeypatch.setattr("serial.tools.list_ports.comports", lambda: [info])
    with pytest.raises(SystemExit) as exit_info:
        main(["ports"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert out.strip() == "/dev/ttyUSB7  FT232R USB UART  [USB VID:PID=0403:6001 SER=A9XYZ]"
    with pytest.raises(SystemExit):
        main(["ports", "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert doc["ports"][0]["hwid"].startswith("USB VID:PID=0403:6001")


@pytest.mark.slow
def test_probe_finds_the_emulated_unit_on_a_pty(tmp_path):
    emu = subprocess.Popen([sys.executable, "-m", "conform", "emulate", "serve", "gve64-phantom",
                            "--baud", "115200"], stdout=subprocess.PIPE,
                           stderr=subprocess.DEVNULL, text=True)
    try:
        pty = emu.stdout.readline().strip()
        assert pty.startswith("/dev/")
        run = subprocess.run([sys.executable, "-m", "conform", "ports", "--probe", "--json",
                              "--timeout", "2", pty, str(tmp_path / "not-a-port")],
                             capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stderr
        found = {p["device"]: p for p in json.loads(run.stdout)["ports"]}
        assert found[pty]["variant"] == "gve64-phantom"
        assert found[pty]["answer"] == "0,IP64MPG v19 10.9.2010 Phantom"
        assert found[str(tmp_path / "not-a-port")]["variant"] is None
        assert "cannot open" in found[str(tmp_path / "not-a-port")]["how"]
        text = subprocess.run([sys.executable, "-m", "conform", "ports", "--probe", pty],
                              capture_output=True, text=True, timeout=120).stdout
        assert "-> gve64-phantom: firmware 'IP64MPG v19 10.9.2010 Phantom'" in text
    finally:
        emu.terminate()
        emu.wait(10)
