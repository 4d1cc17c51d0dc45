"""Answers read from corner states where a unit that computes them wrong shows it.

Every run, motion-free:

- ``%/inta-answers``: with INTA set (GVE64 §13.5.9: a held vector waits for G) the same
  answer is read with checksums off, on and off again (GVE64 §13.3.2, §13.7: INTA is bit 3 of
  the code digit, the checksum follows the fields). A unit that keeps one encoded answer for
  both checksum states answers the other state's form.
- ``L/checksum-below``, ``C/checksum-below``: a plain vector line whose checksum is one less
  than its sum is refused like any wrong checksum (GVE64 §13.3.2); a unit that tests the sum
  only one way executes it.
- ``*E/count-below``: ``*E1`` after a packet of two vectors is a count mismatch (GVE64
  §13.3.3; A12: "a count mismatch → 4"), as ``*E3`` is.
- ``*E/refused-inside``: a vector refused inside a packet (after K only the kept L fits,
  GVE64 §13.5.9) is a packet error, not a line counted.
- ``N<axis>/counter-top``: a counter set to the top of the pulse range reads back as set
  (GVE64 §13.5.6: 32-bit signed counters; specs/gve/variants.toml ranges.pulses).
- ``SW/inta-twice``: SW6 writing INTA while INTA is already set leaves it set (GVE64 §13.5.12:
  "SW6 – zapíše do ST6 byte x"; only a 1->0 change of INTA resumes).
- ``framing/split-line``: a line whose tail comes 5 ms after its head is one line, answered as
  such under every A13 alternative (the shortest watchdog is 20 ms from the ``!``).
- ``framing/bare-address``: ``!0`` alone and ``!0V100`` without CR are both begun lines
  (GVE64 §13.7): under each A13 alternative both are answered 2, or neither.

Full profile with the motion opt-in:

- ``W/back-off``: a reference move that finds its switch backs off by ``from_switch`` (GVE64
  §13.5.7), read with PF from non-zero counters. Where the switch is depends on the machine, so
  on a link the read is compared by its shape (kind ENVIRONMENT); on the emulator exactly.
"""

from __future__ import annotations

from typing import Any

from conform.families.gve.conformance.motion_free import (
    _answers_clause,
    _cites,
    _read_position,
    zero_line,
)
from conform.families.gve.conformance.safety import hazards
from conform.families.gve.conformance.script import ENVIRONMENT, Step
from conform.families.gve.protocol.checksum import checksum

RESET = Step(reset=True)


def _below(b: Any, mnemonic: str) -> Step | None:
    """A zero-pulse vector line whose checksum is one less than its sum, motion-free."""
    for pad in range(16):
        body = f"!0{mnemonic}{'0' * (pad + 1)},0,0".encode()
        good = checksum(body + b",")
        if not good & 0xFF:
            continue
        line = body + b",%02X\r" % ((good - 1) & 0xFF)
        if not hazards(line):
            return Step(line=line, subject=True, timeout=b.v.commands[mnemonic].answer_within)
    return None  # pragma: no cover - 16 sums tried


def corner_checks(b: Any) -> None:
    """The checks of this module (see module doc)."""
    v = b.v
    sr6 = b.cmd_step("SR", [6], subject=False)
    flags = b.cmd_step("F", [], subject=False)
    # INTA answers with checksums off, on, off
    b.add("%", "inta-answers", "INTA set by a held vector: V answered with INTA with checksums "
          "off, on and off again, SR6 read in each", [
              RESET, *b.held(), b.raw("!0V1000", subject=True), sr6,
              b.raw("!0%+", subject=True), b.raw("!0V1000", cs=True, subject=True),
              b.cmd_step("SR", [6], cs=True, subject=False),
              b.raw("!0%-", cs=True, subject=True), b.raw("!0V1000", subject=True), sr6],
          clause=_cites(b, "%", "G"))
    # a checksum one below the sum, on the plain vector forms
    for mnemonic in ("L", "C"):
        bad = _below(b, mnemonic)
        if bad is not None and mnemonic in v.commands:
            b.add(mnemonic, "checksum-below", f"{mnemonic} whose checksum is one below its sum "
                  "is refused and not executed", [RESET, b.raw("!0%+"), bad,
                                                   b.raw("!0F", cs=True)],
                  questions=("A11",))
    # packets: a count below the lines sent; a vector refused inside
    if "*S" in v.commands and "*E" in v.commands:
        zero = zero_line()
        inner = [b.cmd_step("*S", [], answer=False, subject=False),
                 b.raw(zero, answer=False), b.raw(zero, answer=False)]
        b.add("*E", "count-below", "*E1 after a packet of two zero vectors: a count mismatch",
              [RESET, *inner, b.cmd_step("*E", [1]), Step(wait=0.5), flags],
              questions=("A12",))
        if "K" in v.commands and "R" in v.commands:
            b.add("*E", "refused-inside", "after H, a held zero vector and K, a C inside a "
                  "packet is refused (only the kept L fits): the packet reports the error",
                  [RESET, *b.held(), b.raw("!0K"), inner[0], inner[1], b.cmd_step("*E", [1]),
                   b.raw("!0R"), sr6],
                  questions=("A12",), clause=_cites(b, "*E", "K"))
    # a counter at the top of the pulse range
    if "N<axis>" in v.commands:
        lo, hi = v.ranges["pulses"]
        steps = [RESET, b.raw(f"!0N{v.axes[0]}{hi}", subject=True)]
        if len(v.axes) > 1:
            steps.append(b.raw(f"!0N{v.axes[1]}{lo}", subject=True))
        b.add("N<axis>", "counter-top", "N<axis> sets one counter to the top of the pulse range "
              "and one to the bottom; P/PF/P4 read them as set", [*steps, *_read_position(b)])
    # SW6: INTA written twice
    if "SW" in v.commands and 6 in v.status_words:
        inta = 1 << b.spec.status.bit("INTA")
        b.add("SW", "inta-twice", "SW6 writes INTA, then INTA again: INTA stays set; SR6 and F "
              "read it after each", [
                  RESET, b.raw(f"!0SW6,{inta:02X}", subject=True), sr6, flags,
                  b.raw(f"!0SW6,{inta:02X}", subject=True), sr6, flags],
              clause=_cites(b, "SW", "SR"))
    # the watchdog (A13): a line in two pieces; a bare begun line
    b.add(None, "framing/split-line", "a line sent in two pieces 5 ms apart is one line: "
          "answered once, as a whole", [
              RESET, Step(line=b"!0V1", answer=False),
              Step(line=b"00\r", wait=0.005, subject=True), flags],
          clause=_answers_clause(b))
    b.add(None, "framing/bare-address", "'!0' without more and '!0V100' without CR: each is a "
          "begun line, both answered 2 when the watchdog runs out, or neither", [
              RESET, Step(line=b"!0", subject=True, timeout=1.5),
              Step(line=b"!0V100", subject=True, timeout=1.5), b.raw("!0V100"), flags],
          clause=_answers_clause(b), questions=("A13",))
    # W backs off its switch (full profile, motion opt-in)
    if b.deep and b.motion and "W" in v.commands:
        axis = v.axes[0]
        offsets = [b.raw(f"!0N{axis}1234")] if "N<axis>" in v.commands else []
        b.add("W", "back-off", "W finds the switch and backs off from it; PF read at rest from "
              "non-zero counters (the switch's place is the machine's: a link compares the "
              "answer's shape)", [
                  RESET, *offsets, b.raw(f"!0W{axis},100000,2000,150,1000", subject=True,
                                               timeout=b.v.commands["W"].answer_within),
                  Step(wait=0.5), b.cmd_step("PF", [], subject=False, kind=ENVIRONMENT),
                  sr6], clause=_cites(b, "W", "PF"))
