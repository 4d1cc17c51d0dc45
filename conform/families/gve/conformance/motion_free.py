"""Checks that verify the queue, packets, HALT/GO and the status bits without moving an axis,
so that a default run (no opt-in) shows them; and the queue's edge with motion, where the vector
beyond the capacity must be seen to execute before an open question may explain it.

What makes them motion-free (docs/conformance.md, "What a default run verifies"):

- a zero-pulse vector (``C0,0,0``, ``L0,0,0``) is "a normal vector, though it has no motion
  effect" (GVE64 §13.5.2; GVE124 §12.5.2): it takes a queue place, is answered and executed,
  and no axis moves;
- ``H`` with nothing running stops nothing and sets INTA=1 (§13.5.9); with INTA=1 the queue
  is held ("INTA=1 RUN=1: interrupted, the rest of the vectors in the queue", §13.5.12 SR6)
  until ``G`` starts it or ``D`` deletes it — a queue of zero-pulse vectors either way;
- ``G`` then starts nothing but zero-pulse vectors (the guard lets ``G`` through only when the
  host knows nothing else was queued since the queue was read back empty).
"""

from __future__ import annotations

from typing import Any

from conform.families.gve.conformance.safety import hazards
from conform.families.gve.conformance.script import POSITION, Step
from conform.families.gve.protocol.checksum import append_checksum
from conform.families.gve.unit.replies import NOTHING_TO_GO, OK, QUEUE_FULL

RESET = Step(reset=True)
ZERO = "0,0,0"
SETTLE_S = 0.5  # after G releases zero-pulse vectors: the unit works through them


def zero_line(cs: bool = False, mnemonic: str = "C") -> str:
    """A zero-pulse vector whose every reading is motion-free, its checksum included when
    ``cs`` (leading zeros move the checksum until its tail starts with a letter)."""
    for pad in range(16):
        text = f"!0{mnemonic}{'0' * (pad + 1)},0,0"
        if not cs or not hazards(append_checksum(text.encode()) + b"\r"):
            return text
    raise AssertionError("no motion-free zero vector")  # pragma: no cover - 16 sums tried


def _answers_clause(b: Any) -> str:
    """The manual's answers clause (GVE64 §13.7, GVE124 §12.6)."""
    words = b.spec.questions["A13"].clauses
    return next((c for c in words if c.startswith(b.manual)), words[0])


def _cites(b: Any, *cids: str) -> str:
    return ", ".join(dict.fromkeys(b.clause(c).split(",")[0] for c in cids))


def _read_position(b: Any) -> list[Step]:
    return [b.cmd_step(pc, [], subject=False) for pc in ("P", "PF", "P4") if pc in b.v.commands]


def motion_free_checks(b: Any) -> None:
    """The zero-pulse checks of one variant (see module doc)."""
    v = b.v
    zero = f"!0C{ZERO}"
    cap = v.queue
    flags = b.cmd_step("F", [], subject=False)
    sr6 = b.cmd_step("SR", [6], subject=False)
    # the queue's capacity, its full answer and F's full bit, G draining it (§13.5.2, §13.7 1)
    fill = [b.raw(zero) for _ in range(cap)]
    b.add("C", "queue-zero",
          f"behind H, {cap} zero-pulse C vectors fit, the next answers 1 and F shows the queue "
          "full; G works them off, the queue is empty and nothing moved",
          [RESET, b.halt(), *fill, b.raw(zero, subject=True), flags, sr6,
           b.cmd_step("G", [], subject=False), Step(wait=SETTLE_S), flags,
           b.raw(zero), Step(wait=SETTLE_S), flags, *_read_position(b)],
          clause=f"{_cites(b, 'C', 'H', 'F')}, {v.clause('queue')}, {_answers_clause(b)}",
          intent=QUEUE_FULL)
    # D deletes a held queue: F empty, G has nothing left (§13.5.9)
    b.add("D", "zero-queue", "H, three zero-pulse vectors held, D deletes them: F empty, "
          "G has nothing to start (6)",
          [RESET, b.halt(), b.raw(zero), b.raw(zero), b.raw(zero), sr6,
           b.cmd_step("D", []), flags, b.cmd_step("G", [])],
          clause=_cites(b, "D", "H", "G"), intent=NOTHING_TO_GO)
    # HALT with nothing running: INTA=1 and INTCOM, RUN=0; G clears them (§13.5.9, §13.5.12)
    b.add("H", "idle", "H with nothing running answers at once with INTA; SR6 shows INTA and "
          "INTCOM, not RUN; G answers 6 and clears them",
          [RESET, b.halt(), b.cmd_step("SR", [6]), flags, b.raw("!0V1000"),
           b.cmd_step("G", []), sr6],
          clause=_cites(b, "H", "G", "SR"), intent=NOTHING_TO_GO)
    # INTA=1 RUN=1 with a held zero-pulse queue; G answers 0 and works it off (§13.5.12 SR6)
    b.add("G", "zero-queue", "H, two zero-pulse vectors held (INTA=1 RUN=1), G answers 0; "
          "then INTA=0 RUN=0 and the position unchanged",
          [RESET, b.halt(), b.raw(zero), b.raw(zero), b.cmd_step("SR", [6]),
           b.cmd_step("G", []), Step(wait=SETTLE_S), sr6, flags, *_read_position(b)],
          clause=_cites(b, "G", "SR", "C"), intent=OK)
    # the manual's recovery sequence, zero-pulse: K keeps the held queue, INTA and ST4-6; one
    # L fits (a C does not); R brings them back and G works them off (§13.5.9)
    b.add("K", "zero-recovery", "H, two zero-pulse vectors held; K, a C refused (1), L0,0,0 "
          "accepted; R restores the queue and INTA; G answers 0 and empties it",
          [RESET, b.halt(), b.raw(zero), b.raw(zero), b.raw("!0K", subject=True), sr6,
           b.raw(zero), b.raw(f"!0L{ZERO}"), Step(wait=SETTLE_S), flags,
           b.raw("!0R", subject=True), sr6, flags, b.cmd_step("G", []), Step(wait=SETTLE_S),
           flags, *_read_position(b)],
          clause=_cites(b, "K", "R", "G"), intent=OK)
    # a packet of zero-pulse vectors (and a B) is answered with its count (§13.3.3)
    if "*S" in v.commands:
        packet = [b.cmd_step("*S", [], answer=False, subject=False),
                  b.raw(zero, answer=False), b.raw("!0B1000", answer=False),
                  b.raw(zero, answer=False), b.cmd_step("*E", [3])]
        b.add("*E", "zero-packet", "a packet of two zero-pulse C vectors and a B is answered "
              "0,3 and its vectors are executed",
              [RESET, *packet, Step(wait=SETTLE_S), flags, *_read_position(b)],
              clause=_cites(b, "*S", "*E"), intent=OK, questions=("A12",))
    # position read-back around a zero-pulse L: the counters stay as N set them (§13.5.6)
    if "N<axis>" in v.commands:
        setp = [b.raw(f"!0N{axis}{(k + 1) * 1111 * (-1) ** k}") for k, axis in enumerate(v.axes)]
        b.add("L", "zero-vector", "N<axis> sets every counter; L0,0,0 is accepted and P/PF/P4 "
              "read the counters unchanged",
              [RESET, *setp, b.raw(f"!0L{ZERO}", subject=True), Step(wait=SETTLE_S),
               *[b.cmd_step(pc, []) for pc in ("P", "PF", "P4") if pc in v.commands]],
              clause=_cites(b, "L", "PF", "N<axis>"), intent=OK, questions=("A4",))
    # answers judged whole: one code, its fields, CR and nothing after it (§13.7)
    steps = [RESET, b.cmd_step("V", [1000]), flags, b.cmd_step("PF", [], kind=POSITION),
             b.cmd_step("SR", [2]), b.cmd_step("@", []), b.raw("!0ZZ", subject=True),
             b.raw("!0%+", subject=True), b.cmd_step("V", [1000], cs=True),
             b.cmd_step("PF", [], cs=True, kind=POSITION), b.raw("!0%-", cs=True, subject=True)]
    b.add(None, "framing/answers", "answers end with their CR and nothing after it: code, "
          "comma-separated fields, upper-case hex, the checksum when on", steps,
          clause=_answers_clause(b))


def queue_edge_steps(v: Any, extra: str, pulses: int = 20) -> tuple[list[Step], float]:
    """A short slow vector (``pulses`` at V10) started and stopped by H at once, zero-pulse
    vectors held behind it up to the capacity (GVE64 §13.5.2: "1 is executed, the others wait in
    the queue"), G to run it again, then ``extra`` — the vector beyond the capacity, sent while
    one runs (A5); and how long until everything has run. The fill happens while the queue is
    held, so no link is too slow for it; the position read back once the queue has run shows
    whether ``extra`` was executed."""
    halt = Step(line=b"!0H\r", timeout=v.commands["H"].answer_within)
    steps = [_line("!0V10"), _line(f"!0C{pulses},0,0"), halt]
    steps += [_line(f"!0C{ZERO}") for _ in range(v.queue - 1)]
    steps += [_line("!0G", timeout=v.commands["G"].answer_within), _line(extra, subject=True)]
    return steps, pulses / 10.0 + 1.5


def _line(text: str, **kw: Any) -> Step:
    return Step(line=text.encode("ascii") + b"\r", **kw)
