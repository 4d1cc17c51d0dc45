"""What the recordings of the real grbl 1.1f firmware showed the reference unit lacked, each
held in-process on virtual time (so it is checked without the recordings folder too; the
recordings themselves are judged in tests/test_grbl_recordings.py)."""

from __future__ import annotations

import pytest

from conform.families.grbl.spec.load import f32, load_grbl, print_float
from conform.families.grbl.unit.model import GrblUnit

G = load_grbl()
V = G.variant("grbl-1.1f")


class Talk:
    def __init__(self, **options: object) -> None:
        self.u = GrblUnit(V, G, **options)
        self.t = 0.0
        self.u.poll(0.0)

    def __call__(self, data: bytes, wait: float = 0.3) -> list[str]:
        self.t += 0.01
        self.u.receive(data, self.t)
        self.t += wait
        text = b"".join(d for _, d in self.u.poll(self.t)).decode("latin-1")
        return text.split("\r\n")[:-1]

    def report(self) -> str:
        return next(x for x in self(b"?") if x.startswith("<"))


@pytest.mark.parametrize(("value", "places", "shown"), [
    (99999.9, 3, "99999.904"), (99999.9, 0, "100000"), (1.23456, 3, "1.235"),
    (0.0004, 3, "0.000"), (25.0, 3, "25.000"), (0.0, 0, "0"), (-1.5, 3, "-1.500")])
def test_floats_print_as_printfloat_rounds_them(value, places, shown) -> None:
    assert print_float(f32(value), places) == shown


def test_integer_settings_are_eight_bits_and_homing_off_turns_soft_limits_off() -> None:
    s = Talk()
    assert s(b"$26=65535\n") == ["ok"] and "$26=255" in s(b"$$\n")
    assert s(b"$26=256\n") == ["ok"] and "$26=0" in s(b"$$\n")
    assert s(b"$0=259\n") == ["ok"] and "$0=3" in s(b"$$\n")
    assert s(b"$22=1\n") == ["ok"] and s(b"$20=1\n") == ["ok"]
    assert s(b"$22=0\n") == ["ok"] and "$20=0" in s(b"$$\n")


def test_g_shows_the_feed_as_stored() -> None:
    s = Talk()
    s(b"G20 G93\n")
    s(b"F250\n")
    assert "F250" in s(b"$G\n")[0]          # inverse time: not converted
    s(b"G94 F10\n")                         # gcode.c: from G93 the F word is taken as given
    assert "F10" in s(b"$G\n")[0]
    s(b"F10\n")
    assert "F254" in s(b"$G\n")[0]          # G20 G94: inches per minute stored as mm/min


def test_ov_and_wco_are_forced_by_the_events_that_change_them() -> None:
    s = Talk()
    s.report(), s.report()                  # WCO:, then Ov: after a reset
    assert s(b"M3 S1000\n") == ["ok"]
    assert s.report().endswith("|FS:0,1000|Ov:100,100,100|A:S>")
    assert s.report().endswith("|FS:0,1000>")
    s(b"\x90")                              # feed override to 100: changes nothing
    assert "Ov:" not in s.report()
    s(b"\x9a")                              # spindle +10 %: Ov: forced, FS: not while idle
    assert s.report().endswith("|FS:0,1000|Ov:100,100,110|A:S>")
    assert s(b"G92 X1\n") == ["ok"]
    assert "|WCO:-1.000,0.000,0.000" in s.report()
    assert s(b"G10 L2 P2 Y5\n") == ["ok"]   # not the active system: nothing forced
    assert "WCO:" not in s.report()
    assert s(b"G55\n") == ["ok"] and "|WCO:" in s.report()


def test_lines_wait_in_a_hold_and_m0_is_answered_after_cycle_start() -> None:
    s = Talk()
    s(b"!")
    assert s(b"$G\n") == []                 # held: not read
    assert s(b"~")[:1] == ["[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]"]
    assert s(b"M0\n") == []
    assert s.report().startswith("<Hold:0|")
    assert s(b"~") == ["ok"]


def test_spindle_stop_in_a_hold_and_its_restore() -> None:
    s = Talk()
    s(b"M3 S500\n")
    s.report(), s.report()
    s(b"!")
    s(b"\x9e")
    assert s.report().startswith("<Hold:0|") and "|FS:0,0" in s.report()
    assert s(b"~") == ["[MSG:Restoring spindle]"]
    assert "|FS:0,500" in s.report()


def test_positions_are_whole_steps() -> None:
    s = Talk()
    s(b"G1 X0.001 F100\n", wait=1.0)
    assert "MPos:0.000,0.000,0.000" in s.report()
    s(b"G1 X0.003\n", wait=1.0)
    assert "MPos:0.004,0.000,0.000" in s.report()


def test_homing_without_switches_fails_or_is_cut_by_a_reset() -> None:
    s = Talk(switches=False)
    s(b"$22=1\n")
    assert s(b"$H\n", wait=5.0) == []       # seeking, no answer, no report
    assert s(b"\x18", wait=1.0)[:2] == ["ALARM:6", "ok"]
    assert s.report().startswith("<Alarm|")
    s(b"$X\n")
    assert s(b"$H\n", wait=60.0)[:2] == ["ALARM:9", "ok"]   # 300 mm at 500 mm/min, no switch
