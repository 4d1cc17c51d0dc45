"""Deviant units: the reference model with one deliberate fault each.

The suite tests itself by running against these; each names the check that must catch it.
A mutant is a subclass of :class:`conform.families.gve.unit.Unit` overriding one handler (or ``encode``),
so it behaves exactly like the reference everywhere else.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from conform.families.gve.protocol import Command, Rejection
from conform.families.gve.protocol.answers import encode_answer
from conform.families.gve.unit.model import Unit as _Reference

Unit: Any = _Reference

OK, QUEUE_FULL, SYNTAX, RANGE, NOTHING_TO_GO = 0, 1, 4, 5, 6


class WrongRangeCodeV(Unit):
    """V out of range answers 4 (syntax) instead of 5 (GVE64 §13.7)."""

    def _parse(self, line: bytes) -> Any:
        r = super()._parse(line)
        if isinstance(r, Rejection) and r.kind == "range" and r.name == "V":
            return dataclasses.replace(r, code=SYNTAX)
        return r


class QueueOneShort(Unit):
    """The C queue holds one vector fewer than the manual's 420 (128)."""

    def _cmd_C(self, args: tuple, t: float) -> Any:
        if self.queue_len >= self.variant.queue - 1:
            return 1
        return super()._cmd_C(args, t)


class IndexStuck(Unit):
    """``@`` stops advancing after the first command."""

    def _cmd_index(self, args: tuple, t: float) -> Any:
        return (OK, (str(min(self.index, 1)),))


class BadAnswerChecksum(Unit):
    """Answers carry a checksum one too high when checksums are on."""

    def encode(self, code: int, fields: Sequence[object] = ()) -> bytes:
        ans = super().encode(code, fields)
        if not self.checksum_on:
            return ans
        body, tail = ans[:-3], ans[-3:-1]
        return body + b"%02X" % ((int(tail, 16) + 1) & 0xFF) + b"\r"


class NoIntaInAnswers(Unit):
    """The answer digit never carries INTA (bit 3)."""

    def encode(self, code: int, fields: Sequence[object] = ()) -> bytes:
        return encode_answer(code, False, fields, checksum_on=self.checksum_on)


class GoWithoutWork(Unit):
    """G answers 0 when there is nothing to start (instead of 6)."""

    def _cmd_G(self, args: tuple, t: float) -> Any:
        r = super()._cmd_G(args, t)
        return OK if r == NOTHING_TO_GO else r


class V10AcceptsVL(Unit):
    """A v10 that accepts VL (a v19 command, GVE64 §14.1) and answers 0."""

    def _parse(self, line: bytes) -> Any:
        r = super()._parse(line)
        if isinstance(r, Rejection) and r.kind == "absent" and r.name == "VL":
            return Command(r.address or 0, "VL", (), False, line)
        return r

    def _execute(self, cmd: Command, t: float) -> Any:
        if cmd.name == "VL":
            return OK
        return super()._execute(cmd, t)


class FlagsWithoutCR(Unit):
    """The answer to F comes without its CR."""

    def _cmd_F(self, args: tuple, t: float) -> Any:
        code, fields = super()._cmd_F(args, t)
        return self.encode(code, fields)[:-1]


class SwappedAxes(Unit):
    """Positions report X and Y swapped."""

    @property
    def position(self) -> tuple[int, ...]:
        pos = list(super().position)
        pos[0], pos[1] = pos[1], pos[0]
        return tuple(pos)


class QueueEdgeDrop(Unit):
    """The first C vector beyond the queue's capacity is answered 0 and then lost (GVE64
    §13.5.2, §13.7 code 1): a unit that looks like A5 ``excludes-running`` until the vector
    should have executed."""

    _edge_taken = False

    def _cmd_C(self, args: tuple, t: float) -> Any:
        if self.queue_len < self.variant.queue:
            self._edge_taken = False
        r = super()._cmd_C(args, t)
        if r == QUEUE_FULL and self._kept is None and not self._edge_taken:
            self._edge_taken = True
            return OK
        return r


class LowerCaseSyntax(Unit):
    """A lower-case mnemonic is answered 4 (syntax), neither A21 alternative (3, or taken as
    the upper-case command)."""

    def _parse(self, line: bytes) -> Any:
        r = super()._parse(line)
        if (isinstance(r, Rejection) and r.kind == "unknown" and line[2:3].islower()):
            return dataclasses.replace(r, code=SYNTAX)
        return r


class AnswersCrLf(Unit):
    """Every answer ends with CR LF instead of CR alone (GVE64 §13.7: Enter 0Dh)."""

    def poll(self, t: float) -> list[tuple[float, bytes]]:
        return [(due, data.replace(b"\r", b"\r\n")) for due, data in super().poll(t)]


class NoQueueFullFlag(Unit):
    """F never shows the queue-full bit (bit 5, GVE64 §13.5.12)."""

    def _cmd_F(self, args: tuple, t: float) -> Any:
        code, fields = super()._cmd_F(args, t)
        return code, tuple("%02X" % (int(str(f), 16) & ~self._bit_full) for f in fields)


class PositionOffAtRest(Unit):
    """X reads 300 steps off at rest (a position read at rest is exact, GVE64 §13.5.10)."""

    @property
    def position(self) -> tuple[int, ...]:
        pos = list(super().position)
        pos[0] += 300
        return tuple(pos)



# -- effects seen only from a state other than reset (conformance/from_state.py) -------------

class DeleteKeepsSt5(Unit):
    """D clears ST4 and ST6 but leaves the interrupt causes of Intr8..15 (ST5) set
    (GVE64 §13.5.9: D clears ST4..ST6)."""

    def _cmd_D(self, args: tuple, t: float) -> Any:
        st5 = self._st[5]
        r = super()._cmd_D(args, t)
        self._st[5] = st5
        return r


class DeleteZeroesCounters(Unit):
    """D also zeroes the position counters (GVE64 §13.5.9: the position is kept)."""

    def _cmd_D(self, args: tuple, t: float) -> Any:
        r = super()._cmd_D(args, t)
        if r == OK:
            self._offsets = [-p for p in self._exec.position]
        return r


class RestoreForgetsSt4(Unit):
    """R restores the parked queue and flags but not ST4 (GVE64 §13.5.9: R restores what K
    kept)."""

    def _cmd_R(self, args: tuple, t: float) -> Any:
        kept = self._kept
        r = super()._cmd_R(args, t)
        if kept is not None and r == OK:
            self._st[4] = 0
        return r


class KeepZeroesCounters(Unit):
    """K parks the queue and also zeroes the position counters (only the queue and ST4..ST6
    are parked, GVE64 §13.5.9)."""

    def _cmd_K(self, args: tuple, t: float) -> Any:
        r = super()._cmd_K(args, t)
        if r == OK:
            self._offsets = [-p for p in self._exec.position]
        return r


class HaltClearsCauses(Unit):
    """H sets INTA and INTCOM and also clears the interrupt causes ST4/ST5 (a HALT leaves
    them, GVE64 §13.5.9)."""

    def _cmd_H(self, args: tuple, t: float) -> Any:
        r = super()._cmd_H(args, t)
        self._st[4] = self._st[5] = 0
        return r


class GoClearsPolarity(Unit):
    """G clears ST2..ST5 where it should clear only the causes ST4/ST5 (GVE64 §13.5.9): the
    neighbouring polarity words go too."""

    def _cmd_G(self, args: tuple, t: float) -> Any:
        r = super()._cmd_G(args, t)
        if r == OK:
            self._st[2] = self._st[3] = 0
        return r


class ZeroSkipsLastAxis(Unit):
    """N zeroes every counter but the last axis's (GVE64 §13.5.6: every counter)."""

    def _cmd_N(self, args: tuple, t: float) -> Any:
        last = self._offsets[-1]
        r = super()._cmd_N(args, t)
        self._offsets[-1] = last
        return r


class SetAxisZeroesNext(Unit):
    """N<axis> sets its axis and zeroes the next one (GVE64 §13.5.6: one counter)."""

    def _cmd_N_axis(self, args: tuple, t: float) -> Any:
        r = super()._cmd_N_axis(args, t)
        i = self.variant.axes.index(args[0]) + 1
        if i < len(self._offsets):
            self._offsets[i] = -self._exec.position[i]
        return r


class StatusWriteSpills(Unit):
    """SW n also writes word n+1 (GVE64 §13.5.12: one word)."""

    def _cmd_SW(self, args: tuple, t: float) -> Any:
        r = super()._cmd_SW(args, t)
        n, value = args
        if r == OK and n + 1 in self._words and n + 1 < 6:
            self._st[n + 1] = value
        return r


class ResetKeepsPolarity(Unit):
    """J resets everything but the polarity word ST2 (GVE64 §13.4: the reset state)."""

    def _cmd_J(self, args: tuple, t: float) -> Any:
        st2 = self._st[2]
        r = super()._cmd_J(args, t)
        self._st[2] = st2
        return r


class ChecksumOffClearsCauses(Unit):
    """%- also clears the interrupt causes (GVE64 §13.3.2: it switches checksums only)."""

    def _cmd_checksum(self, args: tuple, t: float) -> Any:
        r = super()._cmd_checksum(args, t)
        self._st[4] = 0
        return r


class DeleteKeepsIntcom(Unit):
    """D clears INTA but leaves INTCOM (GVE64 §13.5.9: D clears ST4..ST6)."""

    def _cmd_D(self, args: tuple, t: float) -> Any:
        intcom = self._intcom
        r = super()._cmd_D(args, t)
        self._intcom = intcom
        return r


class GoKeepsIntcom(Unit):
    """G clears INTA but leaves INTCOM (GVE64 §13.5.9: G clears INTA, INTCOM, ST4, ST5)."""

    def _cmd_G(self, args: tuple, t: float) -> Any:
        intcom = self._intcom
        r = super()._cmd_G(args, t)
        self._intcom = intcom
        return r


class KeepTwice(Unit):
    """A second K without R is taken (0) and parks again, losing the first K's flags
    (GVE64 §13.5.9: K once without R)."""

    def _cmd_K(self, args: tuple, t: float) -> Any:
        self._kept = None
        return super()._cmd_K(args, t)


class RestoreNothingClears(Unit):
    """R with nothing kept clears the interrupt causes (GVE64 §13.5.9: R restores what K kept;
    with nothing kept there is nothing to restore)."""

    def _cmd_R(self, args: tuple, t: float) -> Any:
        if self._kept is None:
            self._st[4] = self._st[5] = 0
        return super()._cmd_R(args, t)


class HaltHeldDropsQueue(Unit):
    """H with a vector already held drops the held queue (GVE64 §13.5.9: H stops the running
    vector; the rest of the queue waits for G, D or K)."""

    def _cmd_H(self, args: tuple, t: float) -> Any:
        if self._inta and self._exec.queue_len > 0:
            self._exec.clear()
        return super()._cmd_H(args, t)


@dataclass(frozen=True)
class Mutant:
    name: str
    cls: type
    variants: tuple[str, ...]  # variants it applies to (empty: all)
    catches: tuple[str, ...]  # check keys (id without variant and clause) that must FAIL
    fault: str


MUTANTS: dict[str, Mutant] = {m.name: m for m in (
    Mutant("v-range-code", WrongRangeCodeV, (), ("V/range/pps/hi+1",),
           "V out of range answers 4, not 5"),
    Mutant("queue-one-short", QueueOneShort, (), ("C/queue-full",),
           "the queue holds one C vector too few"),
    Mutant("index-stuck", IndexStuck, (), ("@/advance",), "@ stops advancing"),
    Mutant("answer-checksum", BadAnswerChecksum, (), ("checksum-on",),
           "answer checksums are wrong"),
    Mutant("no-inta", NoIntaInAnswers, (), ("inta",), "INTA missing from answers"),
    Mutant("go-nothing-ok", GoWithoutWork, (), ("G/nothing-left",),
           "G answers 0 with nothing to start"),
    Mutant("v10-accepts-vl", V10AcceptsVL, ("gve64-v10",), ("VL/absent",),
           "a v10 that accepts VL"),
    Mutant("answer-no-cr", FlagsWithoutCR, (), ("F/valid",), "the answer to F has no CR"),
    Mutant("axes-swapped", SwappedAxes, (), ("position", "L/position-1"),
           "positions with X and Y swapped"),
    Mutant("queue-edge-drop", QueueEdgeDrop, (), ("C/queue-full", "C/queue-zero"),
           "a vector beyond the queue's capacity is answered 0 and lost"),
    Mutant("lower-case-4", LowerCaseSyntax, (), ("question/A21",),
           "a lower-case mnemonic answers 4"),
    Mutant("answer-crlf", AnswersCrLf, (), ("framing/answers",),
           "answers end with CR LF"),
    Mutant("no-queue-full-flag", NoQueueFullFlag, (), ("C/queue-zero",),
           "F never shows the queue-full bit"),
    Mutant("position-off-at-rest", PositionOffAtRest, (), ("position", "P/valid"),
           "X reads 300 steps off at rest"),
    Mutant("d-keeps-st5", DeleteKeepsSt5, ("gve64-v19",), ("D/from-state",),
           "D leaves ST5's interrupt causes set"),
    Mutant("d-zeroes-counters", DeleteZeroesCounters, (), ("D/from-state",),
           "D zeroes the position counters"),
    Mutant("r-forgets-st4", RestoreForgetsSt4, (), ("R/from-state",),
           "R does not restore ST4"),
    Mutant("k-zeroes-counters", KeepZeroesCounters, (), ("K/from-state",),
           "K zeroes the position counters"),
    Mutant("h-clears-causes", HaltClearsCauses, (), ("H/from-state",),
           "H clears the interrupt causes"),
    Mutant("g-clears-polarity", GoClearsPolarity, (), ("G/from-state",),
           "G clears the polarity words as well as the causes"),
    Mutant("n-skips-last-axis", ZeroSkipsLastAxis, (), ("N/from-state",),
           "N leaves the last axis's counter"),
    Mutant("n-axis-zeroes-next", SetAxisZeroesNext, (), ("N<axis>/from-state",),
           "N<axis> zeroes the next axis's counter"),
    Mutant("sw-spills", StatusWriteSpills, (), ("SW/from-state",),
           "SW writes the next status word too"),
    Mutant("j-keeps-polarity", ResetKeepsPolarity, (), ("J/from-state",),
           "J keeps ST2"),
    Mutant("checksum-off-clears-causes", ChecksumOffClearsCauses, (), ("%/from-state",),
           "%- clears the interrupt causes"),
    Mutant("d-keeps-intcom", DeleteKeepsIntcom, (), ("D/from-held",), "D leaves INTCOM set"),
    Mutant("g-keeps-intcom", GoKeepsIntcom, (), ("G/from-state", "G/from-held"),
           "G leaves INTCOM set"),
    Mutant("k-twice", KeepTwice, (), ("K/twice",), "a second K without R is taken"),
    Mutant("r-nothing-clears", RestoreNothingClears, (), ("R/nothing-kept",),
           "R with nothing kept clears the interrupt causes"),
    Mutant("h-held-drops-queue", HaltHeldDropsQueue, (), ("H/from-held",),
           "H with a vector held drops the queue"),
)}


def mutant_targets(variant_ids: Sequence[str]) -> list[tuple[Mutant, str]]:
    """(mutant, variant) pairs to run: each mutant on the first variant it applies to."""
    out = []
    for m in MUTANTS.values():
        vs = [v for v in variant_ids if not m.variants or v in m.variants]
        if not vs and m.variants:
            vs = [m.variants[0]]
        if vs:
            out.append((m, vs[0]))
    return out

