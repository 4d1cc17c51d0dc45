"""The Marlin reference unit's M109/M190 wait and M876, against temperature.cpp
(wait_for_hotend / wait_for_bed), gcode.cpp and e_parser.h: the expected times come from the
tables (TEMP_RESIDENCY_TIME, TEMP_WINDOW) and the heater model's stated rates."""

from __future__ import annotations

import dataclasses
import re

import pytest

from conform.families.marlin.spec import load_marlin
from conform.families.marlin.unit.unit import AMBIENT, COOLING_SLOPE, HEAT_RATE, MarlinUnit

S = load_marlin()
V = S.variant("marlin-2.1")
W = re.compile(r"^ T:[\d.]+ /[\d.]+ B:[\d.]+ /[\d.]+ @:\d+ B@:\d+ W:(\?|\d+)$")


def unit(v=V, t=1.0):
    u = MarlinUnit(v, S)
    u.poll(t)
    return u


def run(u, data, t, until):
    u.receive(data, t)
    return [(round(tt, 4), x.decode("latin-1").rstrip("\n")) for tt, x in u.poll(until)]


def with_options(v, **options):
    return dataclasses.replace(v, options={**v.options, **options})


def test_m109_reports_every_second_and_answers_after_the_residency():
    u = unit()
    got = run(u, b"M109 S35\n", 1.0, 60.0)
    reports = [(t, W.match(x).group(1)) for t, x in got if W.match(x)]
    ok_t = next(t for t, x in got if x == "ok")
    window_at = 1.0 + (35 - V.temp_window - AMBIENT) / HEAT_RATE[0]    # 3.25 s
    assert ok_t == pytest.approx(window_at + V.temp_residency, abs=1e-3)
    assert [t for t, _ in reports] == [1.0 + k for k in range(len(reports))]
    assert reports[-1][0] <= ok_t
    assert [w for _, w in reports] == ["?", "?", "?"] + [str(k) for k in range(9, -1, -1)]
    # BUSY_WHILE_HEATING (on by default): keepalives go on while waiting
    assert sum(x == "echo:busy: processing" for _, x in got) == 6


def test_already_in_the_window_the_timer_starts_a_third_later():
    u = unit()
    got = run(u, b"M109 S25\n", 1.0, 60.0)
    ok_t = next(t for t, x in got if x == "ok")
    assert ok_t == pytest.approx(1.0 + V.temp_residency * 4 / 3, abs=1e-3)
    ws = [W.match(x).group(1) for _, x in got if W.match(x)]
    assert ws[:3] == ["?", "12", "11"] and ws[-1] == "0"


def test_m190_waits_on_the_bed_with_its_residency():
    u = unit()
    got = run(u, b"M190 S30\n", 1.0, 60.0)
    ok_t = next(t for t, x in got if x == "ok")
    window_at = 1.0 + (30 - V.temp_window - AMBIENT) / HEAT_RATE[1]
    assert ok_t == pytest.approx(window_at + V.temp_bed_residency, abs=1e-3)
    assert all(" B:" in x for _, x in got if W.match(x))


def test_no_wait_without_s_or_r_and_for_s_to_a_lower_target():
    u = unit()
    assert [x for _, x in run(u, b"M109\n", 1.0, 1.01)] == ["ok"]
    run(u, b"M104 S60\n", 1.1, 30.0)                               # warm up, no wait
    assert [x for _, x in run(u, b"M109 S40\n", 30.0, 30.01)] == ["ok"]   # S: cooling, no wait


def test_r_below_what_the_heater_reaches_ends_on_the_cooling_slope():
    u = unit()
    got = run(u, b"M109 R10\n", 1.0, 200.0)
    ok_t = next(t for t, x in got if x == "ok")
    assert ok_t == pytest.approx(1.0 + COOLING_SLOPE[0][1], abs=1e-3)   # no drop at ambient
    assert all(W.match(x).group(1) == "?" for _, x in got if W.match(x))


def test_without_busy_while_heating_the_wait_says_nothing_but_reports():
    u = unit(with_options(V, BUSY_WHILE_HEATING=False))
    got = run(u, b"M109 S35\n", 1.0, 60.0)
    assert not [x for _, x in got if x.startswith("echo:busy")]
    assert sum(bool(W.match(x)) for _, x in got) == 13


def test_m108_plain_ends_the_wait_numbered_only_through_the_emergency_parser():
    """An unnumbered M108 ends M109's wait as it is read on either unit (queue.cpp critical
    commands, read by the wait's idle()); a numbered one only through the emergency parser,
    without it it waits its turn behind M109 (recordings/marlin-2.1.2.4)."""
    from conform.families.marlin.protocol.codec import frame

    for vid in ("marlin-2.1-adv", "marlin-2.1"):
        u = unit(S.variant(vid))
        u.receive(b"M109 S200\n", 1.0)
        u.poll(3.2)
        got = run(u, b"M108\n", 3.2, 60.0)
        oks = [t for t, x in got if x.startswith("ok")]
        assert len(oks) == 2 and oks[0] < 3.21 and not [x for _, x in got if W.match(x)], vid
    adv = unit(S.variant("marlin-2.1-adv"))
    adv.receive(frame(1, "M109 S200"), 1.0)
    adv.poll(3.2)
    oks = [t for t, x in run(adv, frame(2, "M108"), 3.2, 60.0) if x.startswith("ok")]
    assert len(oks) == 2 and oks[0] < 3.21
    plain = unit()
    plain.receive(frame(1, "M109 S35"), 1.0)
    plain.poll(2.5)
    got = run(plain, frame(2, "M108"), 2.5, 60.0)
    oks = [t for t, x in got if x == "ok"]
    window_at = 1.0 + (35 - V.temp_window - AMBIENT) / HEAT_RATE[0]
    assert oks[0] == pytest.approx(window_at + V.temp_residency, abs=1e-3) and len(oks) == 2


@pytest.mark.parametrize("vid", ["marlin-2.1", "marlin-2.1-adv"])
def test_m876_is_unknown_without_host_prompt_support(vid):
    u = unit(S.variant(vid))
    got = [x for _, x in run(u, b"M876 S1\n", 1.0, 2.0)]
    assert got[0] == 'echo:Unknown command: "M876 S1"' and got[1].startswith("ok")
    assert u.truth.prompt_responses == []


def test_m876_with_host_prompt_support_answers_the_prompt():
    u = unit(with_options(V, HOST_PROMPT_SUPPORT=True))
    assert [x for _, x in run(u, b"M876 S2\n", 1.0, 2.0)] == ["ok"]
    assert [n for _, n in u.truth.prompt_responses] == [2]


def test_the_emergency_parser_takes_m876_as_e_parser_h_does():
    u = unit(with_options(S.variant("marlin-2.1-adv"), HOST_PROMPT_SUPPORT=True))
    got = [x for _, x in run(u, b"M876 S3\n", 1.0, 2.0)]
    assert got == ["ok P15 B3"] and u.truth.prompt_responses == [(1.0, 3)]
    # a bare M876 leaves the parser ignoring to the next end of line: that line's S4 is lost
    run(u, b"M876\nM876 S4\nM876 S5\n", 3.0, 4.0)
    assert [n for _, n in u.truth.prompt_responses] == [3, 5]
    # the parser acts as the bytes arrive, even while M109 waits
    u.receive(b"M109 S200\n", 5.0)
    u.poll(6.0)
    u.receive(b"M876 S1\n", 6.0)
    assert u.truth.prompt_responses[-1] == (6.0, 1)
