"""Targets a conformance run talks to: the in-process emulator on a virtual clock, or anything
pyserial opens (device path, pty, ``socket://``, ``rfc2217://``) on the wall clock.

Both offer the same small interface — ``exchange(line)`` returns a :class:`Reply` with the
answer lines and timestamps, ``wait(s)``, ``reset()``, ``set_input()`` — and keep a raw tx/rx log
with timestamps. The checks never know which kind they drive, except through ``emulated``.
"""

from __future__ import annotations

import re
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from conform.conformance.results import LogEntry
from conform.errors import LinkError, UserError
from conform.families.gve.conformance.safety import STOP_SEQUENCE, Guard, hazards
from conform.families.gve.protocol.checksum import append_checksum

DEFAULT_VARIANT = "gve64-v19"
DEFAULT_TIMEOUT = 0.5
POLL_LINE = b"!0@\r"  # readiness after J: answered once the unit hears; not counted (A10)


class HarnessError(Exception):
    """The harness or the link failed (graded ERROR, never the unit's fault)."""


class LinkSilent(HarnessError):
    """Nothing comes back any more: the link is lost (a unit would answer something)."""


@dataclass
class Reply:
    """What came back for one line sent."""

    tx: bytes
    t_tx: float
    lines: list[bytes] = field(default_factory=list)  # complete lines, without their CR
    partial: bytes = b""  # bytes of an unterminated line when the wait ended
    t_rx: float | None = None
    stray: bytes = b""  # bytes that came unasked before this line was sent
    moving: bool = False  # the (reference) unit was moving when it answered

    @property
    def silent(self) -> bool:
        return not self.lines and not self.partial

    def text(self) -> str:
        """The answer as a reader sees it: ``0,5C``; ``(silence)``; a cut line with its bytes."""
        parts = [ln.decode("latin-1") for ln in self.lines]
        if self.partial:
            parts.append(f"{self.partial.decode('latin-1')} (no CR)")
        return " | ".join(parts) if parts else "(silence)"


_CHECKSUM_CMD = re.compile(rb"^![07]%([+-])")


class Target(ABC):
    """One unit behind a link (or in-process). Subclasses move the bytes and tell the time."""

    name: str = "target"
    emulated: bool = False
    baud: int = 115200

    def __init__(self, guard: Guard) -> None:
        self.guard = guard
        self.log: list[LogEntry] = []
        self.checksum_on = False
        self._buffer = b""
        self.t_log0 = 0.0
        self.keeper: Any = None  # a link's StateKeeper (conform.families.gve.conformance.state)
        # the host knows nothing moves and the queue is empty (read back after reaching a
        # check's state; nothing that moves sent since): G has nothing to start
        self.idle = False

    # -- what subclasses provide ------------------------------------------------------------
    @abstractmethod
    def now(self) -> float:
        """Seconds on this target's clock."""

    @abstractmethod
    def _write(self, data: bytes) -> None: ...

    @abstractmethod
    def _read(self, deadline: float) -> bytes:
        """Bytes that arrive before ``deadline`` (returns early as soon as some do)."""

    @abstractmethod
    def wait(self, seconds: float) -> None: ...

    def _fresh(self) -> None:
        """Return the unit to its power-up state (emulator: a new unit)."""
        raise HarnessError(f"{self.name}: reset is not available")

    def set_input(self, port: int, bit: int, active: bool) -> None:
        raise HarnessError(f"{self.name}: inputs can only be driven on the emulator")

    def close(self) -> None:  # noqa: B027 - nothing to release by default
        pass

    def state(self) -> dict[str, Any]:
        """Internal state for reports (emulator only)."""
        return {}

    # -- shared behaviour --------------------------------------------------------------------
    def reset(self) -> None:
        self._fresh()
        self.checksum_on = False
        self._buffer = b""

    def reset_polled(self) -> Reply:
        """J, then ``!0@`` until the unit answers (its readiness); the answer. What follows
        starts from power-up and one ``@`` (which A10 does not count)."""
        self.reset()
        return self.exchange(POLL_LINE)

    @property
    def drives_inputs(self) -> bool:
        """Can the harness switch this unit's inputs (``set_input``)?"""
        return self.emulated

    def prepare(self, script: Any) -> None:
        """Reach the state ``script`` starts from (its reset step): by default a reset."""
        self.reset()

    def ready_wait(self, seconds: float) -> float:
        """How long to wait for the unit to hear again after J (a script asked ``seconds``)."""
        return seconds

    def resync(self) -> bytes:
        """Drop whatever is pending so the next exchange starts clean; returns it."""
        return self.drain()

    def begin_log(self, keep: bool = False) -> None:
        """Times from now on count from here; ``keep`` the entries so far (negative times)."""
        t = self.now()
        if keep:
            for e in self.log:
                e.t -= t - self.t_log0
        else:
            self.log = []
        self.t_log0 = t

    def _note(self, direction: str, data: bytes) -> None:
        self.log.append(LogEntry(self.now() - self.t_log0, direction, data))

    def drain(self) -> bytes:
        """Whatever the unit sent unasked (MPG reports, late lines); logged as rx."""
        new = self._read(self.now())
        if new:
            self._note("rx", new)
        data = self._buffer + new
        self._buffer = b""
        return data

    def receive(self, deadline: float) -> bytes:
        """Bytes that arrive before ``deadline`` (as soon as some do), logged as rx: for
        families that frame the stream themselves (grbl) instead of ``exchange``."""
        data = self._read(deadline)
        if data:
            self._note("rx", data)
        return data

    def send(self, data: bytes) -> tuple[float, bytes]:
        """Send bytes without waiting for an answer; returns the time and what came unasked."""
        self.guard.check(data, idle=self.idle)
        if "motion" in hazards(data):
            self.idle = False
        stray = self.drain()
        t = self.now()
        self._note("tx", data)
        self._write(data)
        return t, stray

    def exchange(self, line: bytes, timeout: float = DEFAULT_TIMEOUT, lines: int = 1,
                 linger: float = 0.05) -> Reply:
        """Send ``line``; collect ``lines`` CR-terminated lines, or what came by ``timeout``.

        Once one line is in, further lines are waited for at most ``linger`` seconds.
        """
        t_tx, stray = self.send(line)
        reply = Reply(line, t_tx - self.t_log0, stray=stray)
        deadline = self.now() + timeout
        buf = b""
        while True:
            if reply.lines and len(reply.lines) < lines:
                deadline = min(deadline, self.now() + linger)
            chunk = self._read(deadline)
            if chunk:
                self._note("rx", chunk)
                buf += chunk
                while b"\r" in buf and len(reply.lines) < lines:
                    head, _, buf = buf.partition(b"\r")
                    reply.lines.append(head)
                    reply.t_rx = self.now() - self.t_log0
                if len(reply.lines) >= lines:
                    break
            elif self.now() >= deadline:
                break
        if buf:
            if len(reply.lines) >= lines:
                self._buffer = buf
            else:
                reply.partial = buf
                reply.t_rx = self.now() - self.t_log0
        self._track_checksum(line, reply)
        return reply

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


class EmuTarget(Target):
    """The reference unit (or a deviant subclass) in-process, on a virtual clock."""

    emulated = True

    def __init__(self, factory: Callable[[], Any], name: str, guard: Guard | None = None,
                 baud: int = 115200) -> None:
        super().__init__(guard or Guard.emulated())
        self.factory = factory
        self.name = name
        self.baud = baud
        self.unit = factory()
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def _wire(self, n: int) -> float:
        return n * 10.0 / self.baud

    def _fresh(self) -> None:
        self.unit = self.factory()
        self.t = 0.0

    def _write(self, data: bytes) -> None:
        self.t += self._wire(len(data))
        self.unit.receive(data, self.t)

    def _read(self, deadline: float) -> bytes:
        out = bytearray()
        idle = 0
        while True:
            for due, data in self.unit.poll(self.t):
                self.t = max(self.t, due)
                out += data
            if out:
                self.t += self._wire(len(out))
                return bytes(out)
            nxt = self.unit.next_deadline()
            if nxt is None or nxt > deadline:
                self.t = max(self.t, deadline)
                return b""
            if nxt <= self.t:
                # poll(t) at the unit's own "now" may not run what is due then: nudge time
                idle += 1
                if idle > 5:
                    raise HarnessError(f"{self.name}: unit deadline stuck at t={nxt}")
                self.t += 1e-9
                continue
            self.t = max(self.t, nxt)

    def wait(self, seconds: float) -> None:
        end = self.t + seconds
        while self.t < end:
            data = self._read(end)
            if not data:
                break
            self._note("rx", data)
            self._buffer += data
        self.t = max(self.t, end)

    def set_input(self, port: int, bit: int, active: bool) -> None:
        self.unit.set_input(port, bit, active, self.t)

    def exchange(self, line: bytes, timeout: float = DEFAULT_TIMEOUT, lines: int = 1,
                 linger: float = 0.05) -> Reply:
        reply = super().exchange(line, timeout, lines, linger)
        try:
            reply.moving = bool(self.unit.run) or self.unit.queue_len > 0
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


class LinkTarget(Target):
    """A unit behind a serial port, pty or network URL, on the wall clock."""

    emulated = False

    def __init__(self, endpoint: Any, name: str, guard: Guard, baud: int,
                 ready_after: float = 2.0) -> None:
        super().__init__(guard)
        self.endpoint = endpoint
        self.name = name
        self.baud = baud
        self.ready_after = ready_after
        self._t0 = time.monotonic()
        self.reset_stats: Any = None  # J's readiness measured (conform.families.gve.conformance.state)
        self.inputs: str | None = None  # an emulator's control socket that drives its inputs

    @property
    def drives_inputs(self) -> bool:
        return self.inputs is not None

    def set_input(self, port: int, bit: int, active: bool) -> None:
        """Inputs of an emulator behind the link, through its control socket (``inputs``)."""
        if self.inputs is None:
            super().set_input(port, bit, active)
        from conform.emulator.control import send_control

        word = "press" if active else "release"
        try:
            reply = send_control(self.inputs, f"{word} {port}.{bit}")
        except OSError as exc:
            raise HarnessError(f"--inputs-control {self.inputs}: {exc}") from None
        self._note("note", f"input {port}.{bit} {word}: {reply}".encode())
        if not reply.startswith("ok"):
            raise HarnessError(f"--inputs-control {self.inputs}: {reply}")

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
        from conform.families.gve.conformance.state import QUIET_MARGIN

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

    def now(self) -> float:
        return time.monotonic() - self._t0

    def _write(self, data: bytes) -> None:
        try:
            self.endpoint.write(data)
        except LinkError as exc:
            raise HarnessError(f"{self.name}: {exc}") from None

    def _read(self, deadline: float) -> bytes:
        left = max(0.0, deadline - self.now())
        try:
            return self.endpoint.read(4096, left)
        except LinkError as exc:
            raise HarnessError(f"{self.name}: {exc}") from None

    def wait(self, seconds: float) -> None:
        end = self.now() + seconds
        while self.now() < end:
            data = self._read(end)
            if data:
                self._note("rx", data)
                self._buffer += data

    def _fresh(self) -> None:
        """J, then the ~2 s the unit needs (GVE64 §13.4): polled the first time, then the
        readiness measured (what follows may be about @ or >, which a poll would change)."""
        from conform.families.gve.conformance.state import StateStats, power_up

        if self.reset_stats is None:
            self.reset_stats = StateStats()
        power_up(self, self.reset_stats, self.ready_after, quiet=True)
        self._buffer = b""

    def close(self) -> None:
        self.endpoint.close()


def parse_target(text: str) -> tuple[str, str | None, str | None]:
    """``emu:gve64-v10`` → ("emu", "gve64-v10", None); ``emu:gve64-v19:queue-short`` names a
    mutant; anything else is a port (kind ``link``)."""
    if text == "emu" or text.startswith("emu:"):
        parts = text.split(":")
        variant = parts[1] if len(parts) > 1 and parts[1] else None
        mutant = parts[2] if len(parts) > 2 and parts[2] else None
        if len(parts) > 3:
            raise UserError(f"target {text!r}: expected emu:VARIANT[:MUTANT]")
        return "emu", variant, mutant
    return "link", text, None


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
                dialect: Any = None, timeout: float = 0.1) -> tuple[Target, str | None]:
    """Open a target; returns it and the variant its name implies (emulators only)."""
    kind, what, mutant = parse_target(text)
    if kind == "emu":
        variant_id = what or DEFAULT_VARIANT
        factory = emulator_factory(spec, variant_id, dialect, mutant)
        return EmuTarget(factory, text if what else f"emu:{variant_id}", guard,
                         baud=baud), variant_id
    from conform.link import open_port

    assert what is not None
    endpoint = open_port(what, baud, timeout)
    return LinkTarget(endpoint, what, guard or Guard(False, None, False), baud), None


def identify(target: Target, spec: Any) -> tuple[str, str]:
    """Ask ``?`` and map the firmware string to a variant; (variant id, how it was decided)."""
    try:
        reply = target.exchange(target.frame("!0?"), timeout=1.0)
    except HarnessError as exc:
        return DEFAULT_VARIANT, f"'?' failed ({exc}); assumed {DEFAULT_VARIANT}"
    text = reply.lines[0].decode("latin-1") if reply.lines else ""
    firmware = text.split(",", 1)[1] if "," in text else ""
    firmware = re.sub(r",[0-9A-Fa-f]{2}$", "", firmware) if target.checksum_on else firmware
    return variant_for_firmware(spec, firmware)


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
