"""GVE targets: the generic in-process and link targets (conform.conformance.target) with GVE's
framing (checksums, ``!0@`` readiness polls), J with the readiness measured on a link, the stop
sequence H, D, O0,FF, and opening a target by name (``emu:VARIANT[:MUTANT]`` or a port) with
the variant identified by ``?``.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

from conform.conformance.target import (
    DEFAULT_TIMEOUT,
    EmuTarget,
    HarnessError,
    LinkSilent,
    LinkTarget,
    Reply,
    Target,
    parse_target,
)
from conform.errors import LinkError, UserError
from conform.families.gve.conformance.readiness import POLL_LINE, QUIET_MARGIN, StateStats, power_up
from conform.families.gve.conformance.safety import STOP_SEQUENCE, Guard, SafetyRefusal
from conform.families.gve.protocol.checksum import append_checksum

DEFAULT_VARIANT = "gve64-v19"
# how long the line must stay quiet after an answer's CR before the answer is judged whole
# (GVE64 §13.7: an answer is one code, its fields and Enter (0Dh), nothing after it): a few
# characters' time at the baud, and at least QUIET_FLOOR_S for a host's scheduling
QUIET_CHARS = 3
QUIET_FLOOR_S = 0.002
_CHECKSUM_CMD = re.compile(rb"^![07]%([+-])")


@dataclass
class GveReply(Reply):
    """A reply judged whole: ``trailing`` holds what came after the last answer line's CR
    before the line went quiet (nothing, for a unit that frames its answers as §13.7 says)."""

    trailing: bytes = b""


class GveTarget(Target):
    """What a host knows of a GVE line: the checksum state, and how to halt the unit."""

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self.checksum_on = False
        self.keeper: Any = None  # a link's StateKeeper (conform.families.gve.conformance.state)

    def reset(self) -> None:
        super().reset()
        self.checksum_on = False

    def reset_polled(self) -> Reply:
        """J, then ``!0@`` until the unit answers (its readiness); the answer. What follows
        starts from power-up and one ``@`` (which A10 does not count)."""
        self.reset()
        return self.exchange(POLL_LINE)

    def exchanged(self, line: bytes, reply: Reply) -> None:
        self._track_checksum(line, reply)

    def exchange(self, line: bytes, timeout: float = DEFAULT_TIMEOUT, lines: int = 1,
                 linger: float = 0.05) -> GveReply:
        """The engine's exchange, then read on until the line is quiet: whatever follows the
        answer's CR (an LF, a second answer) belongs to this answer and is judged with it,
        instead of being cleared as stray before the next line."""
        reply = super().exchange(line, timeout, lines, linger)
        out = GveReply(**{f.name: getattr(reply, f.name) for f in fields(Reply)})
        if reply.lines and not reply.partial:
            out.trailing = self.until_quiet()
        return out

    def until_quiet(self, most: int = 256) -> bytes:
        """Bytes pending and arriving until nothing has come for the quiet time."""
        quiet = max(QUIET_CHARS * 10.0 / self.baud, QUIET_FLOOR_S)
        got = self._buffer
        self._buffer = b""
        while len(got) < most:
            chunk = self._read(self.now() + quiet)
            if not chunk:
                break
            self._note("rx", chunk)
            got += chunk
        return got

    def _track_checksum(self, line: bytes, reply: Reply) -> None:
        """What the host believes about checksums changes only with a command the unit took:
        ``%±`` answered 0, or ``J`` not refused (silence or 0: A17)."""
        accepted = not reply.lines or reply.lines[0][:1] in (b"0", b"8")
        m = _CHECKSUM_CMD.match(line)
        if m and reply.lines and accepted:
            self.checksum_on = m.group(1) == b"+"
        elif line[2:3] == b"J" and line[:2] in (b"!0", b"!7") and accepted and not reply.partial:
            self.checksum_on = False

    def frame(self, body: str, checksum: bool | None = None) -> bytes:
        """``"!0H"`` → the line to send in the current checksum state."""
        raw = body.encode("ascii")
        use = self.checksum_on if checksum is None else checksum
        return (append_checksum(raw) if use else raw) + b"\r"

    def safe_stop(self, h_bound: float = 7.0, h_every: float = 0.25) -> str:
        """Halt, delete the queue and switch every output off: H, D, O0,FF (GVE64 §13.5.9).

        H is sent again every ``h_every`` s until the unit is known to have heard one (it may
        be deaf after a J, or an answer lost) — an answer to H, then F answered, then H once
        more answered — for at most ``h_bound`` s (the deaf time, the longest brake and a
        margin); a line refused as a syntax error is tried in the other checksum framing."""
        sent = []
        for body in STOP_SEQUENCE:
            try:
                self.drain()  # answers still on their way (J's, a held line's) are not these
                self._note("note", b"abort: " + self.frame("!0" + body))
                if body == "H":
                    answer = self._halt(h_bound, h_every)
                else:
                    answer = self._stop_line(body, 1.0)
                sent.append(f"{body} → {answer}")
            except (LinkError, OSError, HarnessError) as exc:
                sent.append(f"{body} → not sent ({exc})")
        if self.checksum_on:   # a run stopped mid-way leaves the unit as a sender expects it
            leave_checksums(self, False)
            sent.append("%- → " + ("checksums off" if not self.checksum_on else
                                   "not acknowledged: checksums may still be on"))
        return "sent " + ", ".join(sent)

    def _line_within(self, line: bytes, seconds: float) -> bytes | None:
        """Send ``line``; the first answer line within ``seconds``, or None."""
        self._note("tx", line)
        self._write(line)
        until = self.now() + seconds
        buf = self._buffer
        self._buffer = b""
        while b"\r" not in buf and self.now() < until:
            chunk = self._read(until)
            if chunk:
                self._note("rx", chunk)
                buf += chunk
        if b"\r" not in buf:
            return None
        answer, _, self._buffer = buf.partition(b"\r")
        if answer[:1] in (b"4", b"C"):  # a syntax error: the other checksum framing
            self.checksum_on = not self.checksum_on
        return answer

    def _halt(self, bound: float, every: float) -> str:
        deadline = self.now() + bound
        tries = 0
        while self.now() < deadline:
            tries += 1
            if self._line_within(self.frame("!0H"), every) is None:
                continue  # deaf, braking or lost: again
            if self._line_within(self.frame("!0F"), every) is None:
                continue
            tries += 1  # the unit hears: this H is executed, its answer comes after the brake
            answer = self._line_within(self.frame("!0H"), max(0.5, deadline - self.now()))
            if answer is not None:
                return f"{answer.decode('latin-1')} (after {tries} tries)"
        return f"no answer after {tries} tries in {bound:g} s"

    def _stop_line(self, body: str, timeout: float) -> str:
        for _ in range(2):
            answer = self._line_within(self.frame("!0" + body), timeout)
            if answer is None:
                return f"no answer in {timeout:g} s"
            if answer[:1] not in (b"4", b"C"):
                break
        return answer.decode("latin-1")



class GveEmuTarget(GveTarget, EmuTarget):
    """The GVE reference unit (or a deviant subclass) in-process, on a virtual clock."""

    def __init__(self, factory: Callable[[], Any], name: str, guard: Guard | None = None,
                 baud: int = 115200) -> None:
        super().__init__(factory, name, guard or Guard.emulated(), baud=baud)

    def exchange(self, line: bytes, timeout: float = DEFAULT_TIMEOUT, lines: int = 1,
                 linger: float = 0.05) -> GveReply:
        reply = super().exchange(line, timeout, lines, linger)
        try:
            reply.moving = bool(self.unit.moving)
        except AttributeError:
            pass
        return reply

    def state(self) -> dict[str, Any]:
        u = self.unit
        try:
            return {"position": list(u.position), "queue": u.queue_len, "inta": u.inta,
                    "run": u.run, "checksum": u.checksum_on}
        except AttributeError:
            return {}


class GveLinkTarget(GveTarget, LinkTarget):
    """A GVE unit behind a serial port, pty or network URL, on the wall clock."""

    def __init__(self, endpoint: Any, name: str, guard: Guard, baud: int,
                 ready_after: float = 2.0) -> None:
        super().__init__(endpoint, name, guard, baud)
        self.ready_after = ready_after
        self.reset_stats: Any = None  # J's readiness measured (conform.families.gve.conformance.state)

    def prepare(self, script: Any) -> None:
        if self.keeper is not None:
            self.keeper.prepare(script)
        else:
            self.reset()

    def reset(self) -> None:
        if self.keeper is not None:  # J with the readiness measured (nothing else shows)
            self.keeper.power_up(quiet=True)
            self._buffer = b""
        else:
            super().reset()

    def reset_polled(self) -> Reply:
        if self.keeper is None:
            return super().reset_polled()
        reply = self.keeper.power_up(quiet=False)
        assert reply is not None
        self._buffer = b""
        return reply

    def ready_wait(self, seconds: float) -> float:
        ready = self.keeper.stats.readiness if self.keeper is not None else None
        return seconds if ready is None else max(seconds, ready + QUIET_MARGIN)

    def resync(self, quiet: float = 0.03, bound: float = 1.0) -> bytes:
        """End any line in progress (an empty line gets no answer) and drain until the link has
        been quiet for ``quiet`` s (at most ``bound`` s)."""
        got = self.drain()
        if got:
            self._write(b"\r")
            self._note("tx", b"\r")
            end = self.now() + bound
            while self.now() < end:
                chunk = self._read(min(end, self.now() + quiet))
                if not chunk:
                    break
                self._note("rx", chunk)
                got += chunk
        return got

    def _fresh(self) -> None:
        """J, then the ~2 s the unit needs (GVE64 §13.4): polled the first time, then the
        readiness measured (what follows may be about @ or >, which a poll would change)."""
        if self.reset_stats is None:
            self.reset_stats = StateStats()
        power_up(self, self.reset_stats, self.ready_after, quiet=True)
        self._buffer = b""


def unit_class() -> Any:
    """The reference unit class (``conform.families.gve.unit.Unit``)."""
    try:
        from conform.families.gve.unit import Unit
    except ImportError:
        from conform.families.gve.unit.model import Unit
    return Unit


def emulator_factory(spec: Any, variant_id: str, dialect: Any = None,
                     mutant: str | None = None) -> Callable[[], Any]:
    """A callable that builds a fresh reference unit (or named mutant) of ``variant_id``."""
    variant = spec.variant(variant_id)
    dialect = dialect if dialect is not None else spec.dialect()
    cls: Any = unit_class()
    if mutant is not None:
        from conform.families.gve.conformance.mutants import MUTANTS

        if mutant not in MUTANTS:
            raise UserError(f"unknown mutant {mutant!r} (known: {', '.join(MUTANTS)})")
        cls = MUTANTS[mutant].cls
    return lambda: cls(variant, dialect)


def open_target(text: str, spec: Any, *, baud: int = 115200, guard: Guard | None = None,
                dialect: Any = None, timeout: float = 0.1) -> tuple[GveTarget, str | None]:
    """Open a target; returns it and the variant its name implies (emulators only)."""
    kind, what, mutant = parse_target(text)
    if kind == "emu":
        variant_id = what or DEFAULT_VARIANT
        factory = emulator_factory(spec, variant_id, dialect, mutant)
        return GveEmuTarget(factory, text if what else f"emu:{variant_id}", guard,
                            baud=baud), variant_id
    from conform.link import open_port

    assert what is not None
    endpoint = open_port(what, baud, timeout)
    return GveLinkTarget(endpoint, what, guard or Guard(False, None, False), baud), None


def identify(target: GveTarget, spec: Any, attempts: int = 3) -> tuple[str, str]:
    """Ask ``?`` and map the firmware string to a variant; (variant id, how it was decided).

    A previous session may have left a line half-sent in the unit or answers on their way: the
    line is ended and the link drained before each ``?``, and an answer naming no firmware of
    the tables is asked again (``attempts`` times in all) before a default is assumed."""
    found = DEFAULT_VARIANT, f"no answer to '?'; assumed {DEFAULT_VARIANT}"
    for _attempt in range(attempts):
        _quiet(target)
        try:
            reply = target.exchange(target.frame("!0?"), timeout=1.0)
        except HarnessError as exc:
            found = DEFAULT_VARIANT, f"'?' failed ({exc}); assumed {DEFAULT_VARIANT}"
            continue
        text = reply.lines[0].decode("latin-1") if reply.lines else ""
        firmware = text.split(",", 1)[1] if "," in text else ""
        firmware = re.sub(r",[0-9A-Fa-f]{2}$", "", firmware) if target.checksum_on else firmware
        found = variant_for_firmware(spec, firmware)
        if _known(spec, firmware):
            break
        if reply.lines and not target.checksum_on and _summed(reply.lines[0]):
            target.checksum_on = True   # a previous session left checksums on: ask in kind
    else:
        _other_family(target)
    return found


def _other_family(target: GveTarget) -> None:
    """No answer named a firmware: when what came back is another family's traffic, say so
    (one line) instead of running this family's checks into a lost link."""
    from conform.families import detect_family

    tx = b"".join(e.data for e in target.log if e.dir == "tx")
    rx = b"".join(e.data for e in target.log if e.dir == "rx")
    seen = detect_family(tx, rx, {})
    if seen.family not in ("unknown", "gve"):
        from conform.families import family

        ids = ", ".join(v.id for v in family(seen.family).variants())
        raise UserError(f"{target.name}: the unit answers as {seen.family} ({seen.why}), "
                        f"not as a GVE unit: give --variant ({ids})")


def _summed(line: bytes) -> bool:
    """An answer in the checksummed form (the unit's checksum mode is on)."""
    from conform.families.gve.protocol import Answer, parse_answer

    summed = parse_answer(line, True)
    return isinstance(summed, Answer) and bool(summed.checksum_ok)


def _quiet(target: GveTarget, quiet: float = 0.1, bound: float = 1.0) -> None:
    """End a line a previous session left unfinished (an empty line gets no answer) and drop
    whatever arrives until the link has been quiet for ``quiet`` s (at most ``bound`` s)."""
    target.send(b"\r")
    end = target.now() + bound
    while target.now() < end and target.receive(min(end, target.now() + quiet)):
        pass
    target.drain()


def _known(spec: Any, firmware: str) -> bool:
    fw = firmware.strip()
    return bool(fw) and any(fw.startswith(v.firmware) or v.firmware.startswith(fw)
                            for v in spec.variants.values())


def variant_for_firmware(spec: Any, firmware: str) -> tuple[str, str]:
    fw = firmware.strip()
    if not fw:
        return DEFAULT_VARIANT, f"no firmware string; assumed {DEFAULT_VARIANT}"
    for v in spec.variants.values():
        if v.firmware == fw:
            return v.id, f"firmware {fw!r} is {v.id}"
    best = None
    for v in spec.variants.values():
        if fw.startswith(v.firmware) or v.firmware.startswith(fw):
            if best is None or len(v.firmware) > len(best.firmware):
                best = v
    if best is not None:
        return best.id, f"firmware {fw!r} is closest to {best.id}"
    return DEFAULT_VARIANT, f"firmware {fw!r} is not in the tables; assumed {DEFAULT_VARIANT}"


def leave_checksums(target: GveTarget, on: bool, tries: int = 3) -> None:
    """Put the checksum mode back as it was found (probes for A11/A29 turn it on), so that a
    sender that follows does not meet a unit answering 4 to every plain line (GVE64 §13.3.2)."""
    for _ in range(tries):
        if target.checksum_on == on:
            return
        try:
            target.exchange(target.frame("!0%+" if on else "!0%-", checksum=target.checksum_on))
        except HarnessError:
            return


def could_not(exc: BaseException) -> str:
    """Why a check could not be run, in words (not the exception's class name)."""
    if isinstance(exc, LinkSilent):
        return f"the unit stopped answering: {exc}"
    if isinstance(exc, SafetyRefusal):
        return f"not sent, for safety: {exc}"
    if isinstance(exc, LinkError | OSError):
        return f"the link failed: {exc}"
    return f"could not be run: {exc}"

