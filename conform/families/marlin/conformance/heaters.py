"""Marlin's heater waits as a host sees them: the temperature read until it is sane, M109 and
M190 collected until their ok, and the W: countdown of the residency timer (temperature.cpp
``Temperature::wait_for_hotend``/``wait_for_bed``); shared by the directed and from-state
checks."""

from __future__ import annotations

import re
from itertools import pairwise

from conform.families.marlin.conformance.check import ok_kind as _ok_kind
from conform.families.marlin.conformance.session import Session, Talk

_W = re.compile(r" W:(\?|\d+)$")
_HEATERS = {"M109": (0, "t", "M104 S0"), "M190": (1, "b", "M140 S0")}


SANE = (1.0, 120.0)
"""°C a heater may read before a heating check heats it: right after a reset Marlin reads
``T:0.00`` until the sensor's first samples are in (recorded for 2.1.2.4's native build), and
a reading outside this is a sensor not read yet, or broken: nothing is heated from it."""


def _temperature(s: Session, group: str, tries: int = 10) -> float | None:
    """The heater's temperature from M105 (``t`` hotend, ``b`` bed), asked again (every
    0.5 s, ``tries`` times) until the reading is sane (SANE); None if it never is."""
    for i in range(tries):
        if i:
            s.wait(0.5)
        got = s.talk(b"M105\n")
        hit = s.spec.messages["ok_temp"].pattern.match(got.lines[0]) if got.lines else None
        temps = hit and s.spec.messages["temps"].pattern.match(hit.group("temps"))
        value = temps.group(group) if temps else None
        if value is not None and SANE[0] <= float(value) <= SANE[1]:
            return float(value)
    return None


def _wait_for_temperature(s: Session, code: str, m108_after: float | None = None
                          ) -> tuple[Talk | None, str]:
    """``code S<now + 5>`` (a small step, gentle on a real heater), collected until its ok
    (and M108's, when ``m108_after`` seconds into the wait it is sent); the heater switched
    off after. (None, why) when the temperature could not be read."""
    h, group, off = _HEATERS[code]
    now = _temperature(s, group)
    if now is None:
        return None, (f"no sane temperature in M105's answer ({SANE[0]:g}-{SANE[1]:g} °C, "
                      f"asked 10 times): nothing heated")
    residency = s.v.temp_residency if h == 0 else s.v.temp_bed_residency
    s.target.send(f"{code} S{round(now) + 5}\n".encode())
    first = Talk([], s.target.now(), s.target.now())
    if m108_after is not None:
        first = s.wait(m108_after)
        s.target.send(b"M108\n")
    oks = 1 if m108_after is None else 2
    got = s.collect(until=lambda ls: s.oks(first.lines + ls) >= oks, timeout=residency * 2 + 120,
                    linger=0.1)
    s.talk(f"{off}\n".encode())
    return Talk(first.lines + got.lines, first.t0, got.t, first.times + got.times), ""


def _countdown(s: Session, got: Talk) -> tuple[list[tuple[float, str]], float | None]:
    """The wait's reports (time, W: field) and the time of the first ok."""
    reports = [(t, m.group(1)) for t, x in zip(got.times, got.lines, strict=True)
               if s.spec.classify(x)[0] == "temps" and (m := _W.search(x))]
    ok_t = next((t for t, x in zip(got.times, got.lines, strict=True) if _ok_kind(s, x)), None)
    return reports, ok_t


def _residency_problems(s: Session, code: str, reports: list[tuple[float, str]],
                        ok_t: float | None) -> list[str]:
    residency = s.v.temp_residency if code == "M109" else s.v.temp_bed_residency
    problems = []
    before = [r for r in reports if ok_t is None or r[0] <= ok_t]
    if ok_t is None:
        problems.append("no ok")
    if len(before) < 2:
        return problems + [f"{len(before)} W: reports before the ok"]
    if before[0][1] != "?":
        problems.append(f"first report W:{before[0][1]} (the timer is not set yet: W:?)")
    gaps = [b[0] - a[0] for a, b in pairwise(before)]
    if not all(0.8 <= g <= 1.3 for g in gaps):
        problems.append(f"reports {min(gaps):.2f}..{max(gaps):.2f} s apart")
    counts = [int(w) for _, w in before if w != "?"]
    if not counts:
        return problems + ["no W:<seconds> report: the residency timer never ran"]
    if not residency - 1 <= counts[0] <= -(-residency * 4 // 3):
        problems.append(f"the countdown starts at W:{counts[0]}")
    if any(b != a - 1 for a, b in pairwise(counts)) or counts[-1] != 0:
        problems.append("W: does not count down by one to 0: " + ",".join(map(str, counts)))
    if ok_t is not None and not 0 <= ok_t - before[-1][0] <= 1.3:
        problems.append(f"ok {ok_t - before[-1][0]:.2f} s after W:0")
    return problems
