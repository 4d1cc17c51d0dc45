"""The reference unit: the GVE protocol state machine, sans-I/O, on an injected clock.

``Unit`` takes the bytes a host sends and the time they arrive, and produces the answer bytes
with the time each is due (GVE64 §13, GVE124 §12). It never reads a clock, never sleeps and
never touches a port: the emulator (``conform.emulator.serve``) drives it on wall-clock time, tests
and simulations on virtual time. Everything variant-specific comes from the spec tables and
every open question (A1...) from the dialect; ``docs/unit-model.md`` is the prose version.

Motion and timing are delegated to :class:`conform.families.gve.unit.motion.MotionExecutor`; this module
adds what the protocol layers on top: answers and their codes, ST0..ST6, INTA/RUN, K/R, the
interrupt inputs, EEPROM, checksums, packets, the ``@`` index, ``>``, ``J``, the watchdog.

Command handling is dispatched per command id to methods named in :data:`HANDLER_NAMES`, so a
deviant unit ("mutant") is a subclass that overrides one handler or :meth:`Unit.encode`.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from conform.families.gve.protocol.answers import encode_answer
from conform.families.gve.protocol.checksum import split_checksum
from conform.families.gve.protocol.commands import Command, CommandParser, Rejection
from conform.families.gve.protocol.lines import LineSplitter
from conform.families.gve.spec import Dialect, Spec, Variant, load_spec
from conform.families.gve.unit.eeprom import Eeprom, format_float
from conform.families.gve.unit.motion import (
    MIN_SPEED,
    MotionExecutor,
    MotionParams,
    MotionStateError,
    speed_xa,
    speed_xd,
    speed_xm,
    speed_xu,
)

OK, QUEUE_FULL, WATCHDOG, UNKNOWN, SYNTAX, RANGE, NOTHING_TO_GO, RUNNING = range(8)


class _Defer:
    """A handler's reply meaning "the answer comes later" (HALT, W); the handler arranged it."""

    __repr__ = lambda self: "DEFER"  # noqa: E731


DEFER = _Defer()
"""Reply sentinel: the handler scheduled its answer itself."""

Reply = int | tuple[int, Sequence[object]] | bytes | None | _Defer
"""What a handler returns: an error code; (code, answer fields); raw bytes to send verbatim
(``>``, ``J``); None for no answer (``*S``, a silent ``J``); or :data:`DEFER`."""

HANDLER_NAMES: Mapping[str, str] = {
    "?": "_cmd_version", "Q": "_cmd_Q", "L": "_cmd_L", "C": "_cmd_C", "T": "_cmd_T",
    "$": "_cmd_short", "A": "_cmd_A", "V": "_cmd_V", "VL": "_cmd_VL", "B": "_cmd_B",
    "VK": "_cmd_VK", "VN": "_cmd_VN", "XA": "_cmd_XA", "XU": "_cmd_XU", "XD": "_cmd_XD",
    "XM": "_cmd_XM", "P": "_cmd_P", "PF": "_cmd_PF", "P4": "_cmd_P4", "N": "_cmd_N",
    "N<axis>": "_cmd_N_axis", "W": "_cmd_W", "Y": "_cmd_Y", "K": "_cmd_K", "R": "_cmd_R",
    "H": "_cmd_H", "D": "_cmd_D", "G": "_cmd_G", "ER": "_cmd_ER", "EW": "_cmd_EW",
    "EFR": "_cmd_EFR", "EUR": "_cmd_EUR", "EFW": "_cmd_EFW", "EUW": "_cmd_EUW",
    "O": "_cmd_O", "I1": "_cmd_I1", "I2": "_cmd_I2", "SR": "_cmd_SR", "SW": "_cmd_SW",
    "F": "_cmd_F", "@": "_cmd_index", ">": "_cmd_repeat", "J": "_cmd_J", "%": "_cmd_checksum",
    "*S": "_cmd_packet_start", "*E": "_cmd_packet_end", "7V": "_cmd_spindle",
}

WATCHDOG_S: Mapping[str, float | None] = {"100ms": 0.1, "20ms": 0.02, "1s": 1.0, "off": None}
_A10 = {"answered-except-recovery": 0, "every-line": 1, "executed-only": 2}
_RECOVERY = frozenset(("@", ">"))
_PACKET_OK = frozenset(("C", "B"))
_INF = float("inf")
_HEX_EW = re.compile(rb"!(\d)(E[FU]W)([0-9A-Fa-f]+),([0-9A-Fa-f]{8})\Z")

DEFAULT_SWITCH_DISTANCE = 3000
"""Pulses from where a W starts to its axis's reference switch (in the W's direction)."""
DEFAULT_SWITCH_RELEASE = 200
"""Pulses a W backs off from the switch before it opens again."""

_parser_cache: dict[tuple, CommandParser] = {}
_MEMO_LINE = 80  # longest line whose reading a unit keeps
_MEMO_SIZE = 4096  # readings kept (then forgotten all at once)


def _parser_for(variant: Variant, dialect: Dialect, spec: Spec) -> CommandParser:
    key = (id(spec), variant.id, tuple(sorted(dialect.choices.items())))
    parser = _parser_cache.get(key)
    if parser is None:
        parser = CommandParser(variant, dialect, dict(spec.commands))
        if len(_parser_cache) > 64:
            _parser_cache.clear()
        _parser_cache[key] = parser
    return parser


def _wrap32(x: int) -> int:
    """A 32-bit signed position counter."""
    return ((x + 0x80000000) & 0xFFFFFFFF) - 0x80000000


class _Packet:
    __slots__ = ("count", "error", "stopped")

    def __init__(self) -> None:
        self.count = 0
        self.error: int | None = None
        self.stopped = False


class Unit:
    """One emulated GVE unit (see the module docstring and ``notes/unit-api.md``).

    ``switches`` maps an axis letter to the distance (pulses) from a W's start to that axis's
    reference switch (default :data:`DEFAULT_SWITCH_DISTANCE`); ``switch_release`` is how far
    W backs off before the switch opens. ``answer_delay`` is the unit's processing time added
    to every immediate answer (0 by default). ``fast_path`` parses plain C/L lines with one
    precompiled regex instead of the general parser (same results, see the tests).
    """

    def __init__(
        self,
        variant: Variant,
        dialect: Dialect | None = None,
        *,
        t0: float = 0.0,
        spec: Spec | None = None,
        answer_delay: float = 0.0,
        switches: Mapping[str, int] | None = None,
        switch_release: int = DEFAULT_SWITCH_RELEASE,
        fast_path: bool = True,
    ) -> None:
        self.spec = spec if spec is not None else load_spec()
        self.variant = variant
        self.dialect = dialect if dialect is not None else self.spec.dialect()
        d = self.dialect
        self.answer_delay = float(answer_delay)
        self.switches = {a: DEFAULT_SWITCH_DISTANCE for a in variant.axes}
        for axis, dist in (switches or {}).items():
            if axis.upper() not in self.switches:
                raise ValueError(f"switch for unknown axis {axis!r} ({variant.id})")
            self.switches[axis.upper()] = int(dist)
        self.switch_release = int(switch_release)
        self._parser = _parser_for(variant, d, self.spec)
        self._parsed: tuple[dict, dict] = ({}, {})  # line -> reading, checksums off / on
        self._specs = variant.commands
        self._naxes = len(variant.axes)
        self._capacity = variant.queue

        # open questions, resolved once
        self._a4_queued = d["A4"] == "queued"
        self._a5_excl = d["A5"] == "excludes-running"
        self._a7_rate = d["A7"] == "rate-limited"
        self._a9 = d["A9"]
        self._a10 = _A10[d["A10"]]
        # A29: does a line rejected for its checksum become the line `>` repeats?
        self._a29_store_bad = self.dialect["A29"] == "every-line"
        self._a12 = d["A12"]
        self._watchdog_s = WATCHDOG_S[d["A13"]]
        self._a14_blocks = d["A14"] == "reset-blocks"
        self._a15_zero = d["A15"] == "no-effect-0"
        self._hold = d["A16"] == "buffered"
        self._a17_answer = d["A17"] == "answer-then-deaf"
        self._hex_floats = d["A18"] == "hex-bytes"
        self._a20_zero = d["A20"] == "missing-reads-0"
        self._inta_all = d["A24"] == "every-answer"
        self._always_allowed = (frozenset(("W", "Y", "N<axis>")) if d["A27"] == "all-allowed"
                                else frozenset(("N<axis>",)))
        self._t_reset = int(d["A25"].removesuffix("ms"))
        self._vk_reset = d["A26"].startswith("vk")
        eeprom_image = (variant.eeprom.image() if d["A28"] == "table-defaults"
                        else bytes([0xFF]) * 256)
        self._eeprom = Eeprom(eeprom_image)

        # tables
        st = self.spec.status
        self._bit_stop = 1 << st.bit("STOP")
        self._bit_free = 1 << st.bit("FREE")
        self._bit_intcom = 1 << st.bit("INTCOM")
        self._bit_run = 1 << st.bit("RUN")
        self._bit_inta = 1 << st.bit("INTA")
        self._bit_full = 1 << st.queue_full_bit
        self._words = frozenset(variant.status_words)
        self._mask1 = sum(1 << b for b in variant.input_bits.get("port1", ()))
        self._mask2 = sum(1 << b for b in variant.input_bits.get("port2", ()))
        self._in1 = self._mask1  # electrical levels; idle inputs read 1 (pulled up)
        self._in2 = self._mask2
        self._velocity_args = self._velocity_arg_indexes() if self._a7_rate else {}

        self.handlers: dict[str, Callable[[tuple, float], Reply]] = {}
        for cid in self.spec.commands:
            name = HANDLER_NAMES.get(cid)
            fn = getattr(self, name, None) if name else None
            self.handlers[cid] = fn if fn is not None else self._cmd_unimplemented

        self._splitter = LineSplitter(d["A1"])
        cls = type(self)
        overridden = (cls._parse is not Unit._parse or cls._process_line is not Unit._process_line
                      or cls._answer is not Unit._answer or cls.receive is not Unit.receive)
        self._fast = fast_path and d["A1"] != "crlf" and not overridden
        self._compile_fast_path()
        self._enc_cache: list[bytes | None] = [None] * 32
        self._outbox: list[tuple[float, bytes]] = []
        self._now = float(t0)
        self._deaf_until = -_INF
        self._power_up(self._now)

    # ================================================================ public API
    def receive(self, data: bytes, t: float) -> None:
        """Bytes from the host that arrived at time ``t`` (seconds)."""
        if not data:
            return
        self._advance(t)
        t = self._now
        if t < self._deaf_until:
            return
        if self._awaiting:
            if self._hold:
                self._held_chunks.append(bytes(data))
            return
        if self._fast and not self._partial and self._packet is None:
            m = (self._fast_cs if self._checksum_on else self._fast_plain).match(data)
            if m is not None and self._fast_vector(m, data, t):
                return
        self._feed(bytes(data), t)

    def poll(self, t: float) -> list[tuple[float, bytes]]:
        """Everything the unit sends up to ``t``: a list of (time due, bytes)."""
        self._advance(t)
        out = self._outbox
        if not out:
            return []
        if out[-1][0] <= t:
            self._outbox = []
            return out
        n = 0
        while n < len(out) and out[n][0] <= t:
            n += 1
        due = out[:n]
        del out[:n]
        return due

    def next_deadline(self) -> float | None:
        """The next time something happens: an answer due, a vector ending, the watchdog,
        the end of J's deaf time."""
        best = _INF
        if self._outbox:
            best = self._outbox[0][0]
        te = self._next_timer()[0]
        if te < best:
            best = te
        if self._deaf_until > self._now and self._deaf_until < best:
            best = self._deaf_until
        ev = self._exec.next_event_time()
        if ev is not None and ev < best:
            best = ev if ev > self._now else self._now
        return None if best == _INF else best

    def exchange(self, line: bytes, t: float) -> tuple[float, bytes]:
        """Send ``line`` at ``t`` and run virtual time until its complete answer.

        Returns (time the answer is due, answer bytes); ``(t, b"")`` for the documented
        silence. HALT and W answer late; ``>`` may answer two lines (returned together).
        """
        if (self._fast and not self._timers and not self._partial and not self._outbox
                and self._packet is None and t >= self._now and t >= self._deaf_until):
            cs_on = self._checksum_on
            m = (self._fast_cs if cs_on else self._fast_plain).match(line)
            if m is not None and (not cs_on or (sum(line[:-3]) & 0xFF) == int(m.group(3), 16)):
                kind, nums = m.group(1, 2)
                d = tuple(map(int, nums.split(b",")))
                if min(d) >= self._pulse_lo and max(d) <= self._pulse_hi:
                    if len(d) < self._naxes:
                        d += self._pad[len(d)]
                    self._exec.advance(t)
                    self._now = t
                    name = "C" if kind == b"C" else "L"
                    reply = self.handlers[name](d, t)
                    if reply.__class__ is int:
                        ans = self.encode(reply)  # type: ignore[arg-type]
                        self._last_line = line[:-1]
                        self._last_answer = ans
                        if reply == OK or self._a10 != 2:  # never 2 nor a checksum error
                            self._index = (self._index + 1) & 0xFF
                        return (t + self.answer_delay, ans)
                    self._answer(line[:-1], reply, t, name, None)
                    return self._exchange_wait(t)
        self.receive(line, t)
        out = self._outbox
        if (len(out) == 1 and not self._awaiting and self._wd == _INF
                and out[0][0] <= self._now):
            self._outbox = []
            return out[0]
        return self._exchange_wait(t)

    def set_input(self, port: int, bit: int, active: bool, t: float) -> None:
        """Assert (``active``) or release input ``bit`` of ``port`` (1: I1, 2: I2) at ``t``.

        "Asserted" follows the polarity in ST2/ST3 at this moment: with the reset polarity
        (0 = active low) asserting pulls the pin to 0. An enabled input that becomes asserted
        raises an interrupt. :meth:`set_level` sets the electrical level instead.
        """
        level = self._polarity_bit(port, bit) if active else not self._polarity_bit(port, bit)
        self.set_level(port, bit, bool(level), t)

    def set_level(self, port: int, bit: int, level: bool, t: float) -> None:
        """Set the electrical level of an input (what I1/I2 read) at ``t``."""
        mask = self._port_mask(port)
        if not 0 <= bit <= 7 or not mask & (1 << bit):
            raise ValueError(f"{self.variant.id} has no input bit {bit} on port {port}")
        self._advance(t)
        if port == 1:
            self._in1 = (self._in1 | (1 << bit)) if level else (self._in1 & ~(1 << bit))
        else:
            self._in2 = (self._in2 | (1 << bit)) if level else (self._in2 & ~(1 << bit))
        self._eval_interrupts(self._now)

    def input_level(self, port: int) -> int:
        """The byte I1 (port 1) or I2 (port 2) reads."""
        return self._in1 if port == 1 else self._in2

    # read-only views ----------------------------------------------------------------
    @property
    def now(self) -> float:
        return self._now

    @property
    def position(self) -> tuple[int, ...]:
        pos = self._exec.position
        return tuple(_wrap32(p + o) for p, o in zip(pos, self._offsets, strict=True))

    @property
    def queue_len(self) -> int:
        return self._exec.queue_len

    def status(self, n: int) -> int:
        """ST0..ST6 as SR would read it (0 for a word the variant lacks)."""
        if n == 6:
            return self._st6()
        return self._st[n] if n in self._words else 0

    @property
    def inta(self) -> bool:
        return self._inta

    @property
    def run(self) -> bool:
        return self._exec.queue_len > 0 or self._mpg_run

    @property
    def checksum_on(self) -> bool:
        return self._checksum_on

    @property
    def index(self) -> int:
        return self._index

    @property
    def eeprom(self) -> bytes:
        return bytes(self._eeprom.data)

    @property
    def outputs(self) -> int:
        return self._outputs

    @property
    def spindle(self) -> int:
        return self._spindle

    @property
    def modal(self) -> dict[str, Any]:
        return {"A": self._A, "V": self._V, "B": self._B, "T": self._T, "$": self._short,
                "VL": self._VL, "XM": self._XM, "VK": self._VK}

    @property
    def deaf(self) -> bool:
        """True during the ~2 s after J."""
        return self._now < self._deaf_until

    @property
    def mpg(self) -> str:
        """The MPG mode: ``+``, ``&``, ``-`` (``none`` on units without Y)."""
        return self._mpg

    @property
    def executor(self) -> MotionExecutor:
        return self._exec

    @property
    def last_exchange(self) -> tuple[bytes | None, bytes | None]:
        """(last command line, its answer) as ``>`` would repeat them."""
        return self._last_line, self._last_answer

    # ================================================================ answers
    def encode(self, code: int, fields: Sequence[object] = ()) -> bytes:
        """One answer line: code digit (INTA per A24), fields, checksum when on, CR."""
        inta = self._inta and (self._inta_all or code == 0)
        if not fields:
            key = code | (8 if inta else 0) | (16 if self._checksum_on else 0)
            cached = self._enc_cache[key]
            if cached is None:
                cached = self._enc_cache[key] = encode_answer(
                    code, inta, (), checksum_on=self._checksum_on)
            return cached
        return encode_answer(code, inta, fields, checksum_on=self._checksum_on)

    # ================================================================ time
    def _advance(self, t: float) -> None:
        if t < self._now:
            t = self._now
        while self._timers:
            te, kind = self._next_timer()
            if te > t:
                break
            if te < self._now:
                te = self._now
            self._exec.advance(te)
            self._now = te
            self._fire(kind, te)
        self._exec.advance(t)
        self._now = t

    def _next_timer(self) -> tuple[float, str]:
        if not self._timers:
            return _INF, ""
        best, kind = self._wd, "wd"
        if self._defer_t < best:
            best, kind = self._defer_t, "defer"
        if self._w_pending:
            if not self._exec.running:
                te: float | None = self._now
            else:
                te = self._exec.next_event_time()
            if te is not None and te < best:
                best, kind = te, "w"
        return best, kind

    def _update_timers(self) -> None:
        self._timers = self._wd != _INF or self._defer_t != _INF or self._w_pending

    def _fire(self, kind: str, t: float) -> None:
        if kind == "wd":
            self._watchdog(t)
        elif kind == "defer":
            code, fields = self._defer_reply
            self._defer_t = _INF
            self._send_late(code, fields, t)
        elif kind == "w" and not self._exec.running:
            self._w_pending = False
            self._send_late(OK, (), t)
        self._update_timers()

    def _send_late(self, code: int, fields: Sequence[object], t: float) -> None:
        """A deferred answer (HALT, W) goes out; then the bytes held meanwhile (A16)."""
        ans = self.encode(code, fields)
        self._outbox.append((t, ans))
        self._last_answer = ans
        self._awaiting = False
        self._update_timers()
        lines, self._held_lines = self._held_lines, []
        chunks, self._held_chunks = self._held_chunks, []
        for i, line in enumerate(lines):
            if t < self._deaf_until:
                return
            if self._awaiting:
                self._held_lines.extend(lines[i:])
                self._held_chunks.extend(chunks)
                return
            self._process_line(line, t)
        for i, chunk in enumerate(chunks):
            if t < self._deaf_until:
                return
            if self._awaiting:
                self._held_chunks.extend(chunks[i:])
                return
            self._feed(chunk, t)
        self._start_watchdog(t)

    def _exchange_wait(self, t: float) -> tuple[float, bytes]:
        got: list[tuple[float, bytes]] = []
        now = self._now
        while True:
            got.extend(self.poll(now))
            if not (self._awaiting or self._wd != _INF or self._outbox):
                break
            te = self._next_timer()[0]
            if self._outbox and self._outbox[0][0] < te:
                te = self._outbox[0][0]
            if te == _INF:
                break
            now = te if te > now else now
            self._advance(now)
        if not got:
            return (t, b"")
        return (got[0][0], b"".join(b for _, b in got))

    # ================================================================ lines
    def _feed(self, data: bytes, t: float) -> None:
        lines = self._splitter.feed(data)
        if lines:
            self._wd = _INF
            for i, line in enumerate(lines):
                self._process_line(line, t)
                if t < self._deaf_until:
                    self._splitter.clear()
                    break
                if self._awaiting:
                    if self._hold:
                        self._held_lines.extend(lines[i + 1:])
                    else:
                        self._splitter.clear()
                    break
        self._start_watchdog(t)

    def _start_watchdog(self, t: float) -> None:
        pending = self._splitter.unfinished
        self._partial = bool(pending)
        if not pending:
            self._wd = _INF
        elif (self._wd == _INF and self._watchdog_s is not None and not self._awaiting
              and b"!" in pending):
            self._wd = t + self._watchdog_s
        self._update_timers()

    def _watchdog(self, t: float) -> None:
        """The line begun with ``!`` did not complete in time (A13): answer 2, drop it."""
        pending = self._splitter.clear()
        self._partial = False
        self._wd = _INF
        start = pending.rfind(b"!")
        line = pending[start:]
        if len(line) < 2 or not 0x30 <= line[1] <= 0x39:
            return
        if line[1] - 0x30 not in self._parser.addresses:
            return
        if self._packet is not None:
            self._packet_error(WATCHDOG)
            return
        self._answer(line, WATCHDOG, t, None, "watchdog")

    def _parse(self, line: bytes) -> Command | Rejection:
        """The line's reading (a pure function of the line and the checksum state: readings
        of short lines are kept, a host repeats its lines)."""
        memo = self._parsed[1 if self._checksum_on else 0]
        r = memo.get(line)
        if r is not None:
            return r
        r = self._parser.parse(line, self._checksum_on)
        if self._hex_floats and r.name in ("EFW", "EUW"):
            if r.__class__ is Command or r.kind in ("syntax", "range"):
                r = self._parse_hex_write(line, r)
        if len(line) <= _MEMO_LINE:
            if len(memo) >= _MEMO_SIZE:
                memo.clear()
            memo[line] = r
        return r

    def _parse_hex_write(self, line: bytes, r: Command | Rejection) -> Command | Rejection:
        """A18 hex-bytes: ``EFWaa,xxxxxxxx`` / ``EUWaa,xxxxxxxx``, 4 bytes little-endian."""
        body = line
        with_sum = False
        if self._checksum_on:
            body, value = split_checksum(line)
            with_sum = value is not None
        m = _HEX_EW.match(body)
        if m is None:
            return Rejection("syntax", SYNTAX, f"{r.name}: expected aa,xxxxxxxx (A18 hex-bytes)",
                             line, r.name, line[1] - 0x30)
        address = int(m.group(3), 16)
        if address > 252:
            return Rejection("range", RANGE, f"{r.name}: address {address:X} > FC", line, r.name,
                             line[1] - 0x30)
        return Command(line[1] - 0x30, r.name, (address, bytes.fromhex(m.group(4).decode())),
                       with_sum, line)

    def _process_line(self, line: bytes, t: float) -> None:
        if self._packet is not None:
            self._packet_line(line, t)
            return
        r = self._parse(line)
        if r.__class__ is Rejection:
            if r.code is None:
                return
            self._answer(line, r.code, t, r.name, r.kind)
            return
        self._answer(line, self._execute(r, t), t, r.name, None)

    def _execute(self, cmd: Command, t: float) -> Reply:
        name = cmd.name
        if not self._specs[name].while_running and self._busy_for(name):
            return RUNNING
        if self._velocity_args:
            for i in self._velocity_args.get(name, ()):
                if cmd.args[i] > self.variant.max_rate:
                    return RANGE
        return self.handlers[name](cmd.args, t)

    def _busy_for(self, name: str) -> bool:
        if name in self._always_allowed:
            return False
        if name == "Y":
            return self._exec.running
        return self._exec.running or self._mpg_run

    def _answer(self, line: bytes, reply: Reply, t: float, name: str | None,
                kind: str | None) -> None:
        """Send the reply to ``line`` and keep the books (``>``, the ``@`` index, A10)."""
        if reply.__class__ is int:
            ans = self.encode(reply)
            code = reply
        elif reply.__class__ is tuple:
            code, fields = reply  # type: ignore[misc]
            ans = self.encode(code, fields)
        elif reply is DEFER:
            self._last_line = line
            self._last_answer = None
            self._count(name, OK, kind)
            return
        elif reply is None:
            self._count(name, OK, kind)
            return
        else:  # raw bytes: ">" and "J"
            self._outbox.append((t + self.answer_delay, reply))  # type: ignore[arg-type]
            if name == ">" and self._a10 == 1:
                self._index = (self._index + 1) & 0xFF
            return
        self._outbox.append((t + self.answer_delay, ans))
        if kind != "checksum" or self._a29_store_bad:
            self._last_line = line
            self._last_answer = ans
        self._count(name, code, kind)

    def _count(self, name: str | None, code: int, kind: str | None) -> None:
        """A10: does this line advance the ``@`` index?"""
        a10 = self._a10
        if name == "J":  # the reset zeroed the index
            return
        if a10 == 1:
            pass
        elif name in _RECOVERY:
            return
        elif a10 == 0:
            if code == WATCHDOG or kind == "checksum":
                return
        elif code != OK:
            return
        self._index = (self._index + 1) & 0xFF

    # ---------------------------------------------------------------- fast path
    def _compile_fast_path(self) -> None:
        """One regex for a plain C/L line (the parser's strict form, a subset of lenient)."""
        spec_l = self._specs["L"].params[0]
        self._pulse_lo, self._pulse_hi = spec_l.lo, spec_l.hi
        need = spec_l.min_count or self._naxes
        # at most 20 digits: a longer numeral goes to the parser, which answers it (5) without
        # converting it (int() refuses more than 4 300 digits)
        fields = rb"(-?[0-9]{1,20}(?:,-?[0-9]{1,20}){%d,%d})" % (need - 1, self._naxes - 1)
        head = b"!%d([CL])" % self.variant.interpolator_address
        self._fast_plain = re.compile(head + fields + rb"\r\Z")
        self._fast_cs = re.compile(head + fields + rb",([0-9A-Fa-f]{2})\r\Z")
        self._pad = [(0,) * (self._naxes - k) for k in range(self._naxes + 1)]

    def _fast_args(self, m: re.Match[bytes], data: bytes) -> tuple[int, ...] | None:
        """The vector of a fast-path match, or None to let the parser give the rejection."""
        if self._checksum_on and (sum(data[:-3]) & 0xFF) != int(m.group(3), 16):
            return None
        d = tuple(map(int, m.group(2).split(b",")))
        if min(d) < self._pulse_lo or max(d) > self._pulse_hi:
            return None
        if len(d) < self._naxes:
            d += self._pad[len(d)]
        return d

    def _fast_vector(self, m: re.Match[bytes], data: bytes, t: float) -> bool:
        d = self._fast_args(m, data)
        if d is None:
            return False
        name = "C" if m.group(1) == b"C" else "L"
        reply = self.handlers[name](d, t)
        self._answer(data[:-1], reply, t, name, None)
        return True

    # ---------------------------------------------------------------- packets
    def _packet_line(self, line: bytes, t: float) -> None:
        """A line inside ``*S`` ... ``*E`` (GVE64 §13.3.3; errors: A12)."""
        pk = self._packet
        assert pk is not None
        r = self._parse(line)
        if r.name == "*E":
            if r.__class__ is Rejection:
                self._packet = None
                self._answer(line, r.code, t, "*E", r.kind)
                return
            self._packet = None
            n = r.args[0]  # type: ignore[union-attr]
            if pk.error is not None:
                code = pk.error
            else:
                code = OK if n == pk.count else SYNTAX
            self._answer(line, (code, (pk.count,)), t, "*E", None)
            return
        if r.__class__ is Rejection:
            if r.code is None:
                return
            if self._a10 == 1:
                self._index = (self._index + 1) & 0xFF
            self._packet_error(r.code)
            return
        if self._a10 == 1:
            self._index = (self._index + 1) & 0xFF
        if pk.stopped:
            return
        if r.name not in _PACKET_OK and (self._a12 != "accept-any" or r.name == "*S"):
            self._packet_error(SYNTAX)
            return
        reply = self._execute(r, t)
        if reply is DEFER:  # a halt or reference move inside a packet: no answer of its own
            self._awaiting = False
            self._defer_t = _INF
            self._w_pending = False
            self._update_timers()
            reply = OK
        if self._packet is None:  # J inside an accept-any packet reset the unit
            return
        code = reply if reply.__class__ is int else (reply[0] if reply.__class__ is tuple else OK)
        if code == OK:
            pk.count += 1
            if self._a10 != 1:
                self._index = (self._index + 1) & 0xFF
        else:
            self._packet_error(code)  # type: ignore[arg-type]

    def _packet_error(self, code: int) -> None:
        pk = self._packet
        assert pk is not None
        if self._a12 == "skip-bad":
            pk.error = code
            return
        if pk.error is None:
            pk.error = code
        pk.stopped = True

    # ================================================================ state
    def _power_up(self, t: float) -> None:
        """The reset state of GVE64 §13.4 / GVE124 §12.4 (tables + A14, A25, A26)."""
        v = self.variant
        r = v.reset
        self._exec = MotionExecutor(axes=self._naxes, capacity=v.queue, max_rate=v.max_rate)
        self._exec.advance(t)
        self._offsets = [0] * self._naxes
        self._A = int(r.get("A", 20))
        self._V = int(r.get("V", 1000))
        self._B = int(r.get("B", 35000))
        self._short = int(r.get("$", 512))
        self._T = self._t_reset
        self._VL = (int(r.get("VL", v.max_rate)),) * self._naxes
        self._XM = int(r.get("XM", 100))
        self._VK = self._vk_reset
        self._rebuild_params()
        status = int(r.get("status", 0))
        self._st = [status] * 6
        self._inta = False
        self._intcom = False
        self._st6_extra = 0
        self._live1 = self._live2 = 0
        self._eval_live()
        self._outputs = int(r.get("outputs", 0xFF))
        self._spindle = int(r.get("spindle", 0))
        self._checksum_on = bool(r.get("checksum", False))
        self._index = int(r.get("index", 0)) & 0xFF
        mpg = str(r.get("mpg", "none")) if v.has("Y") else "none"
        self._mpg = mpg
        self._mpg_run = self._a14_blocks and mpg in ("+", "&")
        self._ready_after = float(r.get("ready_after_s", 2.0))
        self._packet: _Packet | None = None
        self._last_line: bytes | None = None
        self._last_answer: bytes | None = None
        self._kept: tuple | None = None
        self._awaiting = False
        self._defer_t = _INF
        self._defer_reply: tuple[int, Sequence[object]] = (OK, ())
        self._w_pending = False
        self._held_lines: list[bytes] = []
        self._held_chunks: list[bytes] = []
        self._wd = _INF
        self._partial = False
        self._timers = False
        self._splitter.clear()

    def _rebuild_params(self) -> None:
        v = self._V * self._XM / 100.0
        vl = None
        if any(x < self.variant.max_rate for x in self._VL):
            vl = tuple(float(x) for x in self._VL)
        self._exec.params = MotionParams(
            v=v if v > MIN_SPEED else MIN_SPEED, a=self._A * 1000.0, b=float(self._B),
            short=self._short, pause=self._T / 1000.0, vk=self._VK, vl=vl)

    def _st6(self) -> int:
        v = self._st6_extra
        if self._exec.braking:
            v |= self._bit_stop
        if self._intcom:
            v |= self._bit_intcom
        if self._exec.queue_len > 0 or self._mpg_run:
            v |= self._bit_run
        if self._inta:
            v |= self._bit_inta
        return v

    def _queue_full(self) -> bool:
        ex = self._exec
        if self._kept is not None:
            return ex.queue_len >= 1
        limit = ex.capacity
        if self._a5_excl and ex.running:
            limit += 1
        return ex.queue_len >= limit

    # interrupts ------------------------------------------------------------------------
    def _port_mask(self, port: int) -> int:
        if port == 1:
            return self._mask1
        if port == 2:
            return self._mask2
        raise ValueError(f"input port {port} is not 1 or 2")

    def _polarity_bit(self, port: int, bit: int) -> bool:
        self._port_mask(port)
        return bool(self._st[2 if port == 1 else 3] & (1 << bit))

    def _eval_live(self) -> tuple[int, int]:
        st = self._st
        live1 = ~(self._in1 ^ st[2]) & self._mask1 & st[0]
        live2 = ~(self._in2 ^ st[3]) & self._mask2 & st[1]
        new1 = live1 & ~self._live1
        new2 = live2 & ~self._live2
        self._live1, self._live2 = live1, live2
        return new1, new2

    def _eval_interrupts(self, t: float) -> None:
        """An enabled input that becomes asserted sets its cause bit and INTA and brakes."""
        new1, new2 = self._eval_live()
        if new1 or new2:
            self._st[4] |= new1
            self._st[5] |= new2
            self._inta = True
            self._exec.halt(t)

    def _velocity_arg_indexes(self) -> dict[str, tuple[int, ...]]:
        out = {}
        for cid, spec in self._specs.items():
            idx: list[int] = []
            i = 0
            for p in spec.params:
                width = self._naxes if p.per_axis else 1
                if p.range_name == "velocity":
                    idx.extend(range(i, i + width))
                i += width
            if idx:
                out[cid] = tuple(idx)
        return out

    # ================================================================ handlers
    def _cmd_unimplemented(self, args: tuple, t: float) -> Reply:
        return UNKNOWN

    # identification
    def _cmd_version(self, args: tuple, t: float) -> Reply:
        return (OK, (self.variant.firmware,))

    def _cmd_Q(self, args: tuple, t: float) -> Reply:
        return (OK, (self.variant.processor_id,))

    # vectors
    def _cmd_C(self, args: tuple, t: float) -> Reply:
        if self._mpg_run:
            return RUNNING
        if self._kept is not None:
            return QUEUE_FULL  # after K only one L vector fits (GVE64 §13.5.9)
        ex = self._exec
        n = ex.queue_len
        if n >= self._capacity and not (self._a5_excl and n == self._capacity and ex.running):
            return QUEUE_FULL
        ex.push(args, True)
        return OK

    def _cmd_L(self, args: tuple, t: float) -> Reply:
        if self._mpg_run:
            return RUNNING
        ex = self._exec
        if self._kept is not None or not self._a4_queued:
            if ex.queue_len:
                return QUEUE_FULL
        elif self._queue_full():
            return QUEUE_FULL
        ex.push(args, False)
        return OK

    # modal
    def _cmd_T(self, args: tuple, t: float) -> Reply:
        self._T = args[0]
        self._rebuild_params()
        return OK

    def _cmd_short(self, args: tuple, t: float) -> Reply:
        self._short = args[0]
        self._rebuild_params()
        return OK

    def _cmd_A(self, args: tuple, t: float) -> Reply:
        self._A = args[0]
        self._rebuild_params()
        return OK

    def _cmd_V(self, args: tuple, t: float) -> Reply:
        self._V = args[0]
        self._rebuild_params()
        return OK

    def _cmd_VL(self, args: tuple, t: float) -> Reply:
        self._VL = tuple(args)
        self._rebuild_params()
        return OK

    def _cmd_B(self, args: tuple, t: float) -> Reply:
        self._B = args[0]
        self._rebuild_params()
        return OK

    def _cmd_VK(self, args: tuple, t: float) -> Reply:
        self._VK = True
        self._rebuild_params()
        return OK

    def _cmd_VN(self, args: tuple, t: float) -> Reply:
        self._VK = False
        self._rebuild_params()
        return OK

    # speed changes of queued vectors
    def _cmd_XA(self, args: tuple, t: float) -> Reply:
        self._exec.apply_speed(t, speed_xa(self._exec.params.v), accel=self._A * 1000.0)
        return OK

    def _cmd_XU(self, args: tuple, t: float) -> Reply:
        self._exec.apply_speed(t, speed_xu)
        return OK

    def _cmd_XD(self, args: tuple, t: float) -> Reply:
        self._exec.apply_speed(t, speed_xd)
        return OK

    def _cmd_XM(self, args: tuple, t: float) -> Reply:
        self._XM = args[0]
        self._rebuild_params()
        self._exec.apply_speed(t, speed_xm(float(self._V), float(self._XM)))
        return OK

    # position
    def _cmd_P(self, args: tuple, t: float) -> Reply:
        return (OK, self.position[:2])

    def _cmd_PF(self, args: tuple, t: float) -> Reply:
        return (OK, self.position[:3])

    def _cmd_P4(self, args: tuple, t: float) -> Reply:
        return (OK, self.position[:4])

    def _cmd_N(self, args: tuple, t: float) -> Reply:
        self._offsets = [-p for p in self._exec.position]
        return OK

    def _cmd_N_axis(self, args: tuple, t: float) -> Reply:
        axis, value = args
        i = self.variant.axes.index(axis)
        self._offsets[i] = value - self._exec.position[i]
        return OK

    # reference move
    def _cmd_W(self, args: tuple, t: float) -> Reply:
        axis, to_switch, speed_to, from_switch, speed_from = args
        if self._inta:
            return RUNNING  # an interrupted unit would not start the move before G
        if to_switch == 0:
            return OK
        i = self.variant.axes.index(axis)
        direction = 1 if to_switch > 0 else -1
        dist = self.switches[axis]
        found = abs(to_switch) >= dist
        legs = [(min(abs(to_switch), dist) * direction, speed_to)]
        back = min(from_switch, self.switch_release) if found else 0
        if back:
            legs.append((-direction * back, speed_from))
        ex = self._exec
        params = ex.params
        for length, speed in legs:
            d = [0] * self._naxes
            d[i] = length
            ex.params = params.replace(v=float(max(speed, MIN_SPEED)), vl=None)
            ex.push(tuple(d), False)
        ex.params = params
        self._awaiting = True
        self._w_pending = True
        self._update_timers()
        return DEFER

    # MPG
    def _cmd_Y(self, args: tuple, t: float) -> Reply:
        mode = args[0]
        self._mpg = mode
        self._mpg_run = mode != "-"
        return (OK, ("Y" + mode,))

    # queue handling
    def _cmd_K(self, args: tuple, t: float) -> Reply:
        if self._kept is not None:
            return RUNNING  # KEEP only once without RESTORE (GVE64 §13.5.9)
        try:
            self._exec.park()
        except MotionStateError:
            return RUNNING
        self._kept = (self._st[4], self._st[5], self._inta, self._intcom, self._st6_extra)
        self._st[4] = self._st[5] = 0
        self._inta = self._intcom = False
        self._st6_extra = 0
        return OK

    def _cmd_R(self, args: tuple, t: float) -> Reply:
        if self._kept is None:
            return OK  # nothing kept: without effect
        try:
            self._exec.restore()
        except MotionStateError:
            return RUNNING
        self._st[4], self._st[5], self._inta, self._intcom, self._st6_extra = self._kept
        self._kept = None
        return OK

    def _cmd_H(self, args: tuple, t: float) -> Reply:
        t_stop = self._exec.halt(t)
        self._inta = True
        self._intcom = True
        if t_stop <= t:
            return OK
        self._awaiting = True
        self._defer_t = t_stop
        self._defer_reply = (OK, ())
        self._update_timers()
        return DEFER

    def _cmd_D(self, args: tuple, t: float) -> Reply:
        try:
            self._exec.clear()
        except MotionStateError:
            return RUNNING
        self._st[4] = self._st[5] = 0
        self._inta = self._intcom = False
        self._st6_extra = 0
        return OK

    def _cmd_G(self, args: tuple, t: float) -> Reply:
        if not self._inta:
            return OK if self._a15_zero else NOTHING_TO_GO
        something = self._exec.queue_len > 0
        self._exec.resume(t)
        self._inta = self._intcom = False
        self._st[4] = self._st[5] = 0
        return OK if something else NOTHING_TO_GO

    # EEPROM
    def _cmd_ER(self, args: tuple, t: float) -> Reply:
        return (OK, ("%02X" % self._eeprom.read_byte(args[0]),))

    def _cmd_EW(self, args: tuple, t: float) -> Reply:
        self._eeprom.write_byte(args[0], args[1])
        return OK

    def _cmd_EFR(self, args: tuple, t: float) -> Reply:
        return (OK, (format_float(self._eeprom.read_float(args[0])),))

    def _cmd_EUR(self, args: tuple, t: float) -> Reply:
        return (OK, (str(self._eeprom.read_uint(args[0])),))

    def _cmd_EFW(self, args: tuple, t: float) -> Reply:
        address, value = args
        if isinstance(value, bytes):
            self._eeprom.write_raw(address, value)
        else:
            try:
                self._eeprom.write_float(address, value)
            except (OverflowError, ValueError):
                return RANGE
        return OK

    def _cmd_EUW(self, args: tuple, t: float) -> Reply:
        address, value = args
        if isinstance(value, bytes):
            self._eeprom.write_raw(address, value)
        else:
            self._eeprom.write_uint(address, value)
        return OK

    # inputs, outputs, status
    def _cmd_O(self, args: tuple, t: float) -> Reply:
        self._outputs = args[1]
        return OK

    def _cmd_I1(self, args: tuple, t: float) -> Reply:
        return (OK, ("%02X" % self._in1,))

    def _cmd_I2(self, args: tuple, t: float) -> Reply:
        return (OK, ("%02X" % self._in2,))

    def _cmd_SR(self, args: tuple, t: float) -> Reply:
        n = args[0]
        if n not in self._words:
            return (OK, ("00",)) if self._a20_zero else RANGE
        return (OK, ("%02X" % self.status(n),))

    def _cmd_SW(self, args: tuple, t: float) -> Reply:
        n, value = args
        if n not in self._words:
            return OK if self._a20_zero else RANGE
        if n == 6:
            self._write_st6(value, t)
            return OK
        self._st[n] = value
        if n < 4:
            self._eval_interrupts(t)
        return OK

    def _write_st6(self, value: int, t: float) -> None:
        """SW6 (discouraged by the manual): STOP, FREE, INTCOM stored; INTA 0->1 halts,
        1->0 resumes; RUN follows the queue and cannot be written."""
        self._st6_extra = value & (self._bit_stop | self._bit_free)
        self._intcom = bool(value & self._bit_intcom)
        inta = bool(value & self._bit_inta)
        if inta and not self._inta:
            self._inta = True
            self._exec.halt(t)
        elif not inta and self._inta:
            self._inta = False
            self._exec.resume(t)

    def _cmd_F(self, args: tuple, t: float) -> Reply:
        v = self._st6() | (self._bit_full if self._queue_full() else 0)
        return (OK, ("%02X" % v,))

    # recovery, reset, checksum
    def _cmd_index(self, args: tuple, t: float) -> Reply:
        index = (self._index + 1) & 0xFF if self._a10 == 1 else self._index
        return (OK, ("%02X" % index if self._a9 == "hex-index" else str(index),))

    def _cmd_repeat(self, args: tuple, t: float) -> Reply:
        answer = self._last_answer if self._last_answer is not None else self.encode(OK)
        if self._a9 == "repeat-answer-only" or self._last_line is None:
            return answer
        # the repeated line is one line of the answer: a lone CR it held (possible only under
        # A1=crlf) would end it early and turn its tail into a bogus answer, so it is left out
        return self._last_line.replace(b"\r", b"") + b"\r" + answer

    def _cmd_J(self, args: tuple, t: float) -> Reply:
        answer = self.encode(OK) if self._a17_answer else None
        self._power_up(t)
        self._deaf_until = t + self._ready_after
        return answer

    def _cmd_checksum(self, args: tuple, t: float) -> Reply:
        self._checksum_on = args[0] == "+"
        return OK

    def _cmd_packet_start(self, args: tuple, t: float) -> Reply:
        self._packet = _Packet()
        return None

    def _cmd_packet_end(self, args: tuple, t: float) -> Reply:
        return SYNTAX  # *E without *S

    # spindle (address 7)
    def _cmd_spindle(self, args: tuple, t: float) -> Reply:
        self._spindle = args[0]
        if args[0]:
            self._outputs &= ~1 & 0xFF
        else:
            self._outputs |= 1
        return OK


def run_until_idle(unit: Unit, t: float, limit: float = 1e9) -> float:
    """Advance ``unit`` in virtual time until its queue is empty (or ``limit``); return then."""
    while unit.queue_len and unit.executor.running:
        te = unit.next_deadline()
        if te is None or te > limit:
            break
        t = max(t, te)
        unit.poll(t)
    return t
