"""Values the unit computes, read back from states where computing them wrong would show.

- ``SW/st6-bits`` (every run, motion-free): SW6 stores ST6 byte as written (GVE64 §13.5.12
  "SW6 – zapíše do ST6 byte x"): INTA without INTCOM, then INTCOM, STOP and FREE without INTA,
  each read back with SR6 and F. A unit that sets INTCOM whenever INTA is written, or keeps
  a bit it was told to clear, answers another byte.
- ``<cmd>/in-motion/...`` (full profile, motion opt-in): the position counters read while a
  vector accelerates, cruises and brakes (A, V, the ramp of GVE64 §13.5.3), while a braking
  HALT runs on into the next queued vector (§13.5.9: "INTA=1 RUN=0 – při brždění vektory
  doběhly"), while a chain of continuous C vectors runs without stopping (§13.5.2), under VK
  with a VL cap (§13.5.3, §13.5.4) and while XM changes the speed of a running vector
  (§13.5.5); all from counters set away from zero (§13.5.6). Read at rest they only show where
  a move ends; read under way they show the speed profile that got it there. On a link a
  position read under way is compared with the tolerance for motion still under way, one read
  at rest exactly.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from conform.families.gve.conformance.from_state import state_setup
from conform.families.gve.conformance.motion_free import _cites, _read_position
from conform.families.gve.conformance.script import POSITION, Step

RESET = Step(reset=True)
# the ST6 bytes written, by bit name (status.toml st6_bit): INTA alone, INTCOM with STOP and
# FREE and without INTA, then nothing
_ST6_WRITES = (("INTA",), ("INTCOM", "STOP", "FREE"), ())


def _st6(b: Any, names: tuple[str, ...]) -> int:
    return sum(1 << b.spec.status.bit(n) for n in names)


def st6_checks(b: Any) -> None:
    """``SW/st6-bits``: each bit of ST6 as SW6 wrote it, read back by SR6 and F."""
    if "SW" not in b.v.commands or 6 not in b.v.status_words:
        return
    steps: list[Step] = [RESET]
    for names in _ST6_WRITES:
        steps += [b.raw(f"!0SW6,{_st6(b, names):02X}", subject=True),
                  b.cmd_step("SR", [6], subject=False), b.cmd_step("F", [], subject=False)]
    b.add("SW", "st6-bits", "SW6 writes ST6 as given: INTA alone (INTCOM stays 0), then INTCOM, "
          "STOP and FREE without INTA; SR6 and F read each byte back", steps,
          clause=_cites(b, 'SW', 'SR'))


def _vec(b: Any, *values: int) -> str:
    """A vector for the variant's axes (the first ``len(axes)`` values, zeros after)."""
    n = len(b.v.axes)
    return ",".join(str(x) for x in (*values, 0, 0, 0, 0)[:n])


def _pf(b: Any, wait: float) -> Step:
    return b.cmd_step("PF", [], subject=True, kind=POSITION, wait=wait)


def _reads_under_way(b: Any, waits: tuple[float, ...]) -> list[Step]:
    return [_pf(b, w) for w in waits]


def _at_rest(b: Any, wait: float) -> list[Step]:
    return [Step(wait=wait), *_read_position(b), b.cmd_step("F", [], subject=False),
            b.cmd_step("SR", [6], subject=False)]


def in_motion_checks(b: Any) -> None:
    """The ``in-motion`` checks (full profile with the motion opt-in only: they move)."""
    v = b.v
    if not (b.deep and b.motion):
        return
    setup = [RESET, *state_setup(b)]  # counters away from zero: a sum done wrong shows
    # one long L: accelerating (A10: 10 000 pulses/s², 0.5 s to V5000), cruising, braking
    b.add("L", "in-motion/profile", "A10 V5000 and one long L from non-zero counters: PF read "
          "while it accelerates, cruises and brakes, then every position form at rest",
          [*setup, b.raw("!0A10"), b.raw("!0V5000"), b.raw(f"!0L{_vec(b, 6000, -3000, 1500, -750)}"),
           *_reads_under_way(b, (0.1, 0.25, 0.3, 0.4, 0.4, 0.3)), *_at_rest(b, 1.0)],
          clause=_cites(b, 'L', 'A', 'PF'))
    # continuous C vectors: the chain runs without stopping between them, a vector sent while
    # the one before runs joins it if it arrives before that one starts braking
    b.add("C", "in-motion/chain", "three C vectors queued at once, then one sent while they "
          "run: PF read along the chain, every position form at rest",
          [*setup, b.raw("!0A10"), b.raw("!0V5000"),
           b.raw(f"!0C{_vec(b, 2000, 1000, 0, 300)}"), b.raw(f"!0C{_vec(b, 2000, -1000, 500, 0)}"),
           b.raw(f"!0C{_vec(b, -1000, 0, 0, 300)}"),
           *_reads_under_way(b, (0.3, 0.4, 0.4)),
           b.raw(f"!0C{_vec(b, 1500, 0, -700, 0)}", wait=0.1),
           *_reads_under_way(b, (0.2, 0.3, 0.3, 0.3)), *_at_rest(b, 2.0)],
          clause=_cites(b, 'C', 'PF'))
    # a chain whose speeds change: a slower V for the next vectors (entered above their peak),
    # a vector too short to brake in before the end, one too short to reach its speed
    b.add("C", "in-motion/speed-changes", "C vectors at V5000, then V2000 for the next ones, "
          "a 40-pulse one at the end, then at V8000 one of 300: PF read along the chain; at rest",
          [*setup, b.raw("!0A10"), b.raw("!0V5000"), b.raw(f"!0C{_vec(b, 4000, 0, 0, 0)}"),
           b.raw("!0V2000"), b.raw(f"!0C{_vec(b, 1500, 300, 0, 0)}"),
           b.raw(f"!0C{_vec(b, 40, 0, 0, 0)}"), b.raw("!0V8000"),
           b.raw(f"!0C{_vec(b, 300, 0, 0, 0)}"),
           *_reads_under_way(b, (0.3, 0.4, 0.3, 0.3, 0.3, 0.3, 0.3)), *_at_rest(b, 1.5)],
          clause=_cites(b, "C", "V", "PF"))
    # HALT too late to stop within the running vector: the brake runs on into the next one
    # (§13.5.9, SR6 "INTA=1 RUN=0/1"); then G runs the rest. Where the brake ends follows when
    # H arrived, which a link does not fix to the pulse (13 pulses for 2.6 ms at 5000/s): it
    # is read by PF as G sets off from there (exact in-process, within the tolerance for
    # motion under way on a link); ST6 and F at rest, and the position after all of it, do
    # not depend on it
    b.add("H", "in-motion/brake-spill", "H 0.7 s into three 3000-pulse C vectors at V5000 A10 "
          "(rest needs 1250 pulses, 750 are left): ST6 and F once it stopped; G then runs the "
          "rest, PF read as it sets off from where the brake ended and under way; at rest",
          [*setup, b.raw("!0A10"), b.raw("!0V5000"), *[b.raw(f"!0C{_vec(b, 3000, 0, 0, 0)}")] * 3,
           dataclasses.replace(b.halt(), wait=0.7, subject=True),
           b.cmd_step("F", [], subject=False), b.cmd_step("SR", [6], subject=False),
           b.cmd_step("G", []), *_reads_under_way(b, (0.0, 0.2, 0.4)), *_at_rest(b, 2.5)],
          clause=_cites(b, 'H', 'G', 'SR'))
    # VK: the path speed along the Euclidean length, capped by VL so no axis outruns its limit
    if "VK" in v.commands and "VL" in v.commands:
        limits = ",".join(["5000", "1500", "5000", "5000"][: len(v.axes)])
        b.add("VK", "in-motion/vl-cap", "VK, VL with Y at 1500, V5000 and an L of 3000,4000: PF "
              "read under way shows the capped path speed; VN and VL back, at rest",
              [*setup, b.raw("!0A10"), b.raw("!0VK"), b.raw(f"!0VL{limits}"), b.raw("!0V5000"),
               b.raw(f"!0L{_vec(b, 3000, 4000, 0, 0)}"), *_reads_under_way(b, (0.3, 0.5, 0.5)),
               *_at_rest(b, 2.5), b.raw("!0VN"),
               b.raw("!0VL" + ",".join([str(v.max_rate)] * len(v.axes)))],
              clause=_cites(b, 'VK', 'VL'))
    # XM on a running vector: the speed changes under way
    if "XM" in v.commands:
        b.add("XM", "in-motion", "XM50 while a long C runs at V5000, then XM100: PF read under "
              "way after each; at rest",
              [*setup, b.raw("!0A10"), b.raw("!0V5000"), b.raw(f"!0C{_vec(b, 8000, 0, 0, 0)}"),
               b.raw("!0XM50", wait=0.7, subject=True), *_reads_under_way(b, (0.2, 0.3)),
               b.raw("!0XM100", subject=True), *_reads_under_way(b, (0.2, 0.3)),
               *_at_rest(b, 2.5)],
              clause=b.clause("XM"))
    # a C sent while the only queued one cruises, long before it would brake: it joins the
    # running one, which does not slow down at its end (§13.5.2)
    b.add("C", "in-motion/join-late", "one long C at V5000 alone, a second C sent 0.4 s in: PF "
          "read where the first would brake if the second had not joined it; at rest",
          [*setup, b.raw("!0A10"), b.raw("!0V5000"), b.raw(f"!0C{_vec(b, 5000, 0, 0, 0)}"),
           b.raw(f"!0C{_vec(b, 3000, 1000, 0, 0)}", wait=0.4, subject=True),
           *_reads_under_way(b, (0.4, 0.2, 0.2, 0.2, 0.3)), *_at_rest(b, 1.5)],
          clause=_cites(b, 'C', 'PF'))

    # the shapes of a C chain: B the speed at each junction, $ the threshold below which a
    # vector only accelerates towards B, T the pause between non-continuous vectors (L)
    b.add("B", "in-motion/junctions", "B2000 and $800 for a chain of C vectors, long and short "
          "(600 pulses), then T20 and two L vectors: PF read under way; at rest",
          [*setup, b.raw("!0A10"), b.raw("!0V5000"), b.raw("!0B2000", subject=True),
           b.raw("!0$800", subject=True), b.raw(f"!0C{_vec(b, 3000, 0, 0, 0)}"),
           b.raw(f"!0C{_vec(b, 600, 200, 0, 0)}"), b.raw(f"!0C{_vec(b, 600, -200, 0, 0)}"),
           b.raw(f"!0C{_vec(b, 2000, 0, 100, 0)}"), *_reads_under_way(b, (0.3, 0.4, 0.3, 0.3, 0.3)),
           Step(wait=1.5), b.raw("!0T20", subject=True), b.raw(f"!0L{_vec(b, 1000, 0, 0, 0)}"),
           b.raw(f"!0L{_vec(b, 0, 1000, 0, 0)}"), *_reads_under_way(b, (0.2, 0.3, 0.2)),
           *_at_rest(b, 1.5)],
          clause=_cites(b, 'B', '$', 'T'))
    # XU, XD, XA on queued vectors while the first of them runs
    if all(c in v.commands for c in ("XU", "XD", "XA")):
        b.add("XA", "in-motion", "V4000 and three queued C vectors; XU, XD, then V2000 and XA "
              "while they run: PF read after each; at rest",
              [*setup, b.raw("!0A10"), b.raw("!0V4000"),
               *[b.raw(f"!0C{_vec(b, 2500, 500, 0, 0)}")] * 3,
               b.raw("!0XU", wait=0.6, subject=True), *_reads_under_way(b, (0.3,)),
               b.raw("!0XD", subject=True), b.raw("!0XD", subject=True),
               *_reads_under_way(b, (0.3,)), b.raw("!0V2000"), b.raw("!0XA", subject=True),
               *_reads_under_way(b, (0.2, 0.4, 0.4)), *_at_rest(b, 3.0)],
              clause=b.clause("XA"))


def input_checks(b: Any) -> None:
    """``I1/inputs-polarity`` (every run; the inputs are the emulator's, a link skips it): each port's
    inputs asserted and released with both polarities, I1 and I2 read after each change, then
    the interrupts enabled on the asserted inputs: the cause bits of the right word (ST4 for
    port 1, ST5 for port 2), INTA, and nothing of the other port (GVE64 §13.5.12)."""
    v = b.v
    if not all(c in v.commands for c in ("I1", "I2", "SR", "SW")):
        return
    ports = {1: v.input_bits.get("port1", []), 2: v.input_bits.get("port2", [])}
    reads = [b.cmd_step("I1", [], subject=True, kind=""), b.cmd_step("I2", [], subject=True, kind="")]
    words = [b.cmd_step("SR", [w], subject=False) for w in (4, 5, 6) if w in v.status_words]
    steps: list[Step] = [RESET]
    # polarity: the first bit of each port active high (ST2/ST3 bit set), the others low
    for port, bits in ports.items():
        if bits and 2 + port - 1 in v.status_words:
            steps.append(b.raw(f"!0SW{port + 1},{1 << bits[0]:02X}"))
    for port, bits in ports.items():
        for bit in bits[:1] + bits[-1:]:
            steps += [Step(input=(port, bit, True)), *reads]
    for port, bits in ports.items():  # enable the interrupts of what is asserted
        if bits and port - 1 in v.status_words:
            mask = (1 << bits[0]) | (1 << bits[-1])
            steps += [b.raw(f"!0SW{port - 1},{mask:02X}", subject=True), *words]
    for port, bits in ports.items():
        for bit in bits[:1] + bits[-1:]:
            steps += [Step(input=(port, bit, False)), *reads]
    steps += words
    b.add("I1", "inputs-polarity", "inputs of both ports asserted with both "
          "polarities and released, I1 and I2 read after each; the interrupts enabled on them: "
          "ST4, ST5 and ST6 read back", steps, clause=_cites(b, "I1", "SR", "SW"))
