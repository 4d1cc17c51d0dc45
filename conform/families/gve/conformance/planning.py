"""Speed planning read back under way: the corners of the ramp planner a plain course never meets.

Full profile with the motion opt-in only (they move). Every check starts from counters set away
from zero and reads PF while the move is under way (on a link with the tolerance for motion under
way, at rest exactly). The ramps follow GVE64 §13.5.2-13.5.5 (one acceleration A for speeding up
and slowing down, V the cruise speed, B the speed at the junction of continuous C vectors, ``$``
the length below which a vector only speeds up towards B, T the pause after a vector that ends
at rest) and §13.5.9 (HALT brakes at A, on into the queued C vectors if it must):

- ``C/planning/short-from-rest``: a C shorter than its ramp, from rest, with a C queued behind it
  (it speeds up all the way and hands on what it reached); then with B2000 and $100 a 200-pulse C
  that reaches exactly B at its end (2·A·200 = 2000²: the planner's boundary between "reaches
  the exit speed" and "cannot").
- ``C/planning/enter-above-peak``: after a C at V5000 a 300-pulse C at V1000, entered at 5000
  and too short to brake to 1000: it brakes all the way, the next one takes over its speed.
- ``T/planning/pause``: T24, a lone C that ends at rest and the next C sent just after it: PF
  and XM sent during the pause before that one starts (planned, not moving yet).
- ``H/planning/while-braking``: H while an L is already on its final ramp, a C queued behind it:
  the brake starts from the speed of that moment, not from V, and ends where the L ends.
- ``XM/planning/b-below-v``: XM on a long C with B below V: a long vector (``$`` and more) still
  cruises at V·XM, not at B.
- ``H/planning/spill-diagonal``: H spilling into queued diagonal and A-axis C vectors, with VN
  (path = the dominant axis) and with VK (path = X, Y, Z Euclidean, never less than the
  dominant axis): where the brake ends depends on each vector's path length; PF read while G
  runs on from there.
- ``XM/planning/max-rate``: XM200 on V at the variant's max rate: every axis stays within the
  max rate (GVE64 §1, §14.1), VN and VK.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from conform.families.gve.conformance.from_state import state_setup
from conform.families.gve.conformance.in_motion import RESET, _at_rest, _reads_under_way, _vec
from conform.families.gve.conformance.motion_free import _cites, _read_position
from conform.families.gve.conformance.script import POSITION, Step


def _c(b: Any, *values: int) -> Step:
    return b.raw(f"!0C{_vec(b, *values)}")


def planning_checks(b: Any) -> None:
    """The ``planning`` checks (full profile with the motion opt-in only: they move)."""
    v = b.v
    if not (b.deep and b.motion):
        return
    setup = [RESET, *state_setup(b), b.raw("!0A10"), b.raw("!0V5000")]
    # A10 = 10 000 pulses/s²: 100 pulses from rest reach sqrt(2·10 000·100) ≈ 1414 pulses/s,
    # far below V5000; the 200-pulse C with B2000 reaches 2000 = B exactly at its end
    b.add("C", "planning/short-from-rest", "A10 V5000: a 100-pulse C from rest with a C queued "
          "behind it, PF under way; then B2000 $100 and a 200-pulse C that reaches B exactly at "
          "its end, a C behind it, PF under way; at rest",
          [*setup, _c(b, 100, 0, 0, 0), _c(b, 2000, 500, 0, 0),
           *_reads_under_way(b, (0.05, 0.1, 0.2)), *_at_rest(b, 0.8),
           b.raw("!0B2000", subject=True), b.raw("!0$100", subject=True),
           _c(b, 200, 0, 0, 0), _c(b, 2000, -500, 0, 0),
           *_reads_under_way(b, (0.1, 0.1, 0.2, 0.3)), *_at_rest(b, 1.0)],
          clause=_cites(b, "C", "B", "$"))
    # entered at 5000, 300 pulses at V1000 would need 1200 pulses to brake to 1000
    b.add("C", "planning/enter-above-peak", "C of 4000 at V5000, then V1000 and a 300-pulse C "
          "(too short to brake down to 1000), then a long C: PF under way; at rest",
          [*setup, _c(b, 4000, 0, 0, 0), b.raw("!0V1000", subject=True), _c(b, 300, 100, 0, 0),
           _c(b, 1500, 0, 0, 0), *_reads_under_way(b, (0.6, 0.2, 0.1, 0.1, 0.1, 0.3, 0.5)),
           *_at_rest(b, 1.5)],
          clause=_cites(b, "C", "V", "PF"))
    # a lone C of 1000 at A10 V5000 is a triangle of 0.632 s ending at rest; the next C sent
    # just after it ends waits the T24 pause, planned but not moving: PF and XM50 land in it
    if "XM" in v.commands:
        b.add("T", "planning/pause", "T24 and a lone C of 1000 at V5000; the next C sent just "
              "after it stops, PF and XM50 during the T pause before that one starts; PF under "
              "way, at rest",
              [*setup, b.raw("!0T24", subject=True), _c(b, 1000, 0, 0, 0),
               b.raw(f"!0C{_vec(b, 0, 1000, 0, 0)}", wait=0.632),
               b.cmd_step("PF", [], subject=True, kind=POSITION), b.raw("!0XM50", subject=True),
               b.cmd_step("PF", [], subject=True, kind=POSITION),
               *_reads_under_way(b, (0.1, 0.2, 0.3, 0.3)), *_at_rest(b, 1.0)],
              clause=_cites(b, "T", "XM", "PF"))
    # L of 6000: 0.5 s up, 0.7 s at 5000, 0.5 s down; H 1.45 s in, at about 2500 pulses/s:
    # braking from that speed at A ends where the L ends, whenever on that ramp H arrives. The
    # C queued behind it keeps ST6 off the knife-edge of "the vectors ran out while braking"
    # (RUN=0), which an L ending at that very moment would be on a link
    b.add("H", "planning/while-braking", "an L of 6000 at V5000 with a C queued behind it, H "
          "1.45 s in while the L brakes at its end: where the brake ends, F and SR6 (the C is "
          "left); G runs the C, at rest",
          [*setup, b.raw(f"!0L{_vec(b, 6000, -2000, 0, 0)}"), _c(b, 0, 1000, 0, 0),
           dataclasses.replace(b.halt(), wait=1.45, subject=True),
           *_read_position(b), b.cmd_step("F", [], subject=False),
           b.cmd_step("SR", [6], subject=False), b.cmd_step("G", []), *_at_rest(b, 1.0)],
          clause=_cites(b, "H", "A", "SR"))
    if "XM" in v.commands:
        b.add("XM", "planning/b-below-v", "B2000 and a C of 9000 at V5000, XM50 0.7 s in, "
              "then XM100 on its final ramp: PF under way after each; at rest",
              [*setup, b.raw("!0B2000"), _c(b, 9000, 0, 0, 0),
               b.raw("!0XM50", wait=0.7, subject=True), *_reads_under_way(b, (0.2, 0.3, 0.5)),
               b.raw("!0XM100", wait=0.9, subject=True), *_reads_under_way(b, (0.1, 0.1)),
               *_at_rest(b, 2.0)],
              clause=b.clause("XM"))
    # the first C: 0.5 s up (1250 pulses), then 5000 pulses/s; H 0.75 s in leaves 500 pulses of
    # it and 750 more to brake: through (300,400) and into the A-axis vector. Where the brake
    # ends follows when H arrived, which a link does not fix: it is read by PF while G runs on
    # from there (under way: exact in-process, within the moving tolerance on a link); the
    # position at rest after all of them does not depend on it
    spill = [_c(b, 3000, 0, 0, 0), _c(b, 300, 400, 0, 0), _c(b, 0, 0, 0, 400),
             _c(b, 300, 400, 0, 0), _c(b, 1000, 0, 0, 0),
             dataclasses.replace(b.halt(), wait=0.75, subject=True),
             b.cmd_step("F", [], subject=False), b.cmd_step("SR", [6], subject=False),
             b.cmd_step("G", []), *_reads_under_way(b, (0.0, 0.1, 0.1)), *_at_rest(b, 1.0)]
    vk = "VK" in v.commands and "VN" in v.commands and len(v.axes) >= 4
    if len(v.axes) >= 4:
        b.add("H", "planning/spill-diagonal", "H 0.75 s into a C of 3000 followed by C vectors "
              "(300,400), (0,0,0,400), (300,400): the brake runs on into them; F, SR6, then G "
              "and PF under way from where it ended, with VN" + (" and again with VK" if vk else ""),
              [*setup, *([b.raw("!0VN")] if vk else []), *spill,  # VN said: not left to A26
               *([b.raw("!0VK", subject=True), *spill, b.raw("!0VN")] if vk else [])],
              clause=_cites(b, "H", "C", "VK") if vk else _cites(b, "H", "C"))
    # XM200 of V at the max rate: the max rate still caps every axis
    if "XM" in v.commands and v.max_rate:
        top = int(v.max_rate)
        big = top * 2
        # a diagonal whose capped path speed has a fraction near 1 (a rounded cap shows)
        frac = {y: (top * (big * big + y * y) ** 0.5 / big) % 1.0 for y in range(big // 4, big // 4 + 300)}
        diag = (big, max(frac, key=frac.__getitem__))
        b.add("XM", "planning/max-rate", f"A1000, V{top} (the max rate) and XM200: an L of {big} "
              "along X, then with VK a diagonal one; PF under way shows no axis above the max "
              "rate; at rest",
              [*setup, *([b.raw("!0VN")] if vk else []), b.raw("!0A1000"), b.raw(f"!0V{top}"),
               b.raw("!0XM200", subject=True),
               b.raw(f"!0L{_vec(b, big, 0, 0, 0)}"), *_reads_under_way(b, (0.5, 0.5, 0.5)),
               *_at_rest(b, 1.5),
               *([b.raw("!0VK"), b.raw(f"!0L{_vec(b, *diag)}"),
                  *_reads_under_way(b, (0.5, 0.5, 0.5, 0.4)), *_at_rest(b, 1.5), b.raw("!0VN")]
                 if vk else [])],
              clause=_cites(b, "XM", "V") + ", " + v.clause("max_rate"))
