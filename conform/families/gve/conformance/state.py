"""The unit's state between checks on a link: what each check needs, and the cheapest way there.

Every check is written against the power-up state (GVE64 §13.4, GVE124 §12.4): its expected
answers are the reference unit's from a fresh unit. On the emulator that state is free (a new
unit). On a link, ``J`` costs the ~2 s the unit is deaf after it, so the runner reaches a state
*equivalent for that check* with ordinary commands where it can:

- what the previous check left behind is read off the reference unit that ran the same script
  (model-derived, never read from the unit under test);
- each difference from power-up that a command restores gets that command (``%-``, ``H``, ``D``,
  ``N``, the modal values of the reset table, ``SW0..3``, ``O0,FF``, ``!7V0``); values whose
  reset value is an open question (T: A25, VK: A26), the MPG mode, a K without R and an open
  packet have no such command;
- the reference then runs *previous script → those commands → the confirming reads → this
  check's script*: if this check's answers are exactly those from a fresh unit, the commands
  suffice, otherwise (the ``@`` index, the line ``>`` repeats, a reset-only value) the check
  needs ``J``;
- on the unit the commands are sent, then ``F`` and the position are read and compared with the
  reference's answers (a mismatch falls back to ``J``).

After ``J`` readiness is polled with ``@`` (which neither counts nor, for most checks, shows),
bounded by the table's deaf time plus a margin; for checks the poll would show (the model says),
the unit is given the readiness measured by earlier polls plus a margin instead.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

from conform.conformance.target import Reply
from conform.families.gve.conformance.expect import first_mismatch
from conform.families.gve.conformance.readiness import (
    POLL_LINE,
    READY_MARGIN,
    StateStats,
    power_up,
)
from conform.families.gve.conformance.script import Script, run_steps
from conform.families.gve.conformance.target import GveEmuTarget
from conform.families.gve.protocol.checksum import append_checksum

if TYPE_CHECKING:
    from conform.families.gve.conformance.expect import Reference
    from conform.families.gve.conformance.target import GveTarget as Target



def _fresh_target(ref: Reference) -> GveEmuTarget:
    variant, cls, d = ref.variant, ref.unit_cls, ref.dialect
    return GveEmuTarget(lambda: cls(variant, d), "reference")


def _line(body: str, checksum: bool = False) -> bytes:
    raw = body.encode("ascii")
    return (append_checksum(raw) if checksum else raw) + b"\r"


class StateKeeper:
    """Brings a link target to each check's starting state (see the module doc)."""

    def __init__(self, ref: Reference, target: Target) -> None:
        self.ref = ref
        self.target = target
        self.v = ref.variant
        # the reference mirroring the unit since its last J (None: the unit's state is unknown)
        self.shadow: GveEmuTarget | None = None
        self.pending: GveEmuTarget | None = None  # the shadow once the check being run passes
        self.stats = StateStats()
        fresh = _fresh_target(ref).unit
        self._fresh = fresh
        self._confirm = [_line("!0F"), _line("!0P4" if "P4" in self.v.commands else "!0PF")]
        probe = _fresh_target(ref)
        self._confirm_expected = [probe.exchange(line).lines for line in self._confirm]
        self._ready_after = float(self.v.reset.get("ready_after_s", 2.0))
        self._poll_shows: dict[Script, bool] = {}
        self._moved = False  # the last check moved an axis (see tidy_lines)
        self._start_position: tuple[int, ...] = ()

    # -- what the reference says ---------------------------------------------------------------
    def _body(self, script: Script) -> Script:
        return script[1:] if script and script[0].reset else script

    def _same_as_fresh(self, script: Script, t: GveEmuTarget) -> bool:
        """Run ``script``'s steps on ``t`` as it is: are the answers a fresh unit's?"""
        body = self._body(script)
        got = run_steps(t, body)
        want = self.ref.transcript(script)[len(script) - len(body):]
        return first_mismatch(body, want, got, False, lambda e, a: 0.0) is None

    def tidy_lines(self, unit: Any, moved: bool = False) -> tuple[list[bytes], list[str]]:
        """Commands that restore what ``unit`` differs in from power-up; and what they cannot.

        ``moved``: the last check moved an axis; a move that ends within a few ms of the
        reference's end may still run on the unit (the link's latency), so H and D go anyway."""
        f = self._fresh
        lines: list[bytes] = []
        cannot: list[str] = []
        if unit.checksum_on:
            lines.append(_line("!0%-", True))
        if unit.queue_len or unit.run or moved:
            lines.append(_line("!0H"))
        if (unit.queue_len or unit.inta or unit.run or moved
                or any(unit.status(n) != f.status(n) for n in (4, 5, 6))):
            lines.append(_line("!0D"))
        if tuple(unit.position) != tuple(f.position):
            lines.append(_line("!0N"))
        mu, mf = unit.modal, f.modal
        for key, body in (("A", "A{}"), ("V", "V{}"), ("B", "B{}"), ("$", "${}"),
                          ("XM", "XM{}")):
            if mu[key] != mf[key]:
                cid = "$" if key == "$" else key
                if cid in self.v.commands:
                    lines.append(_line("!0" + body.format(mf[key])))
                else:
                    cannot.append(key)
        if mu["VL"] != mf["VL"]:
            if "VL" in self.v.commands:
                lines.append(_line("!0VL" + ",".join(str(x) for x in mf["VL"])))
            else:
                cannot.append("VL")
        for key in ("T", "VK"):  # reset values are open questions (A25, A26): no command
            if mu[key] != mf[key]:
                cannot.append(key)
        for n in range(4):
            if n in self.v.status_words and unit.status(n) != f.status(n):
                lines.append(_line(f"!0SW{n},{f.status(n):02X}"))
        if unit.spindle != f.spindle and "7V" in self.v.commands:
            lines.append(_line(f"!{self.v.spindle_address}V0"))
        if unit.outputs != f.outputs or unit.spindle != f.spindle:
            lines.append(_line(f"!0O0,{f.outputs:02X}"))
        if unit.mpg != f.mpg:
            cannot.append("mpg")
        if getattr(unit, "_kept", None) is not None:
            cannot.append("K")
        if getattr(unit, "_packet", None) is not None:
            cannot.append("packet")
        return lines, cannot

    def plan(self, script: Script) -> tuple[list[bytes] | None, str]:
        """The tidy lines that give ``script`` its power-up answers, or None and why J.

        The reference that mirrors the unit (``shadow``: everything since the last J) runs the
        lines, the confirming reads and the script; what it ends in is the unit's state once
        the check has passed (``pending``)."""
        self.pending = None
        if self.shadow is not None:
            sim = self.shadow
            self.shadow = None  # run on: it will be the state after this check
            lines, cannot = self.tidy_lines(sim.unit, self._moved)
            for line in lines + self._confirm:
                sim.exchange(line, 5.0)
            self._start_position = sim.unit.executor.position
            if self._same_as_fresh(script, sim):
                self.pending = sim
                return lines, ""
            why = ("restores no " + "/".join(cannot)) if cannot else "depends on @ or >"
        else:
            why = "state unknown"
        self.pending = self._after_reset(script)
        return None, why

    def _after_reset(self, script: Script) -> GveEmuTarget:
        """The reference as the unit will be after J (and its poll, if any) and the script."""
        sim = _fresh_target(self.ref)
        if not self.poll_shows(script):
            sim.exchange(POLL_LINE)
        self._start_position = sim.unit.executor.position
        run_steps(sim, self._body(script))
        return sim

    def poll_shows(self, script: Script) -> bool:
        """Would a readiness poll after J change this check's answers?"""
        hit = self._poll_shows.get(script)
        if hit is None:
            t = _fresh_target(self.ref)
            t.exchange(POLL_LINE)
            hit = self._poll_shows[script] = not self._same_as_fresh(script, t)
        return hit

    # -- on the unit ------------------------------------------------------------------------------
    def prepare(self, script: Script) -> None:
        """Reach the state ``script`` starts from (its leading reset step)."""
        t0 = time.perf_counter()
        try:
            lines, why = self.plan(script)
            if lines is not None and self._tidy(lines):
                self.stats.tidy += 1
                return
            if lines is not None:
                self.stats.fallbacks += 1
                why = "tidy not confirmed"
                self.pending = self._after_reset(script)
            self.stats.reasons[why] = self.stats.reasons.get(why, 0) + 1
            self.power_up(quiet=self.poll_shows(script))
        finally:
            self.stats.seconds += time.perf_counter() - t0

    def done(self, state_known: bool) -> None:
        """The check ran; its answers were the reference's (``state_known``) or not."""
        self.shadow = self.pending if state_known else None
        self._moved = self.shadow is not None and (
            self.shadow.unit.executor.position != self._start_position)
        self.pending = None

    def link_lost(self, every: float = 0.5) -> str | None:
        """After a check that met silence: does the unit still answer (F, in either checksum
        framing, for the deaf time after a J and a margin)? None if it does; else why the link
        counts as lost."""
        tg = self.target
        tg.resync()
        tries = int((self._ready_after + READY_MARGIN) / every)
        for _ in range(tries):
            if tg.exchange(tg.frame("!0F"), every).lines:
                return None
            tg.checksum_on = not tg.checksum_on
        return f"{tg.name}: no answer to F in {tries} tries after the check met silence (link lost)"

    def _answer_within(self, line: bytes) -> float:
        """How long the table lets ``line``'s command take to answer (its longest mnemonic)."""
        body = line[2:].decode("ascii", "replace")
        rows = [c for c in self.v.commands.values() if body.startswith(c.mnemonic)]
        return max(rows, key=lambda c: len(c.mnemonic)).answer_within if rows else 0.5

    def _tidy(self, lines: list[bytes]) -> bool:
        tg = self.target
        tg.resync()
        for line in lines:
            reply = tg.exchange(line, self._answer_within(line))
            if not reply.lines:
                return False
        tg.checksum_on = False
        for line, want in zip(self._confirm, self._confirm_expected, strict=True):
            if tg.exchange(line).lines != want:
                return False
        tg.idle = True  # F read back: queue empty, nothing runs
        return True

    def power_up(self, quiet: bool = False) -> Reply | None:
        """J; then wait until the unit hears again (polled, bounded); the poll's answer."""
        return power_up(self.target, self.stats, self._ready_after, quiet)
