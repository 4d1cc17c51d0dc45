"""The reference unit: the GVE protocol state machine, sans-I/O, on an injected clock.

``Unit`` takes the bytes a host sends and the time they arrive, and produces the answer bytes
with the time each is due (GVE64 §13, GVE124 §12). It never reads a clock, never sleeps and
never touches a port: the emulator (``conform.emulator.serve``) drives it on wall-clock time,
tests and simulations on virtual time. Everything variant-specific comes from the spec tables
and every open question (A1...) from the dialect; ``docs/unit-model.md`` is the prose version.

Motion and timing are delegated to :class:`conform.families.gve.unit.motion.MotionExecutor`;
the protocol on top of it is assembled here from one module per command family
(``docs/unit-model.md``, "Module layout"): reception (lines, watchdog, checksums), answers (encoding, ``>``/``@``
books), timing (virtual time, late answers), the fast path and ``exchange``, packets, vectors
and the queue, parameters and EEPROM, read-back, signals (inputs, interrupts, outputs, MPG),
reset, and the dispatch from command id to handler. They share one state (``state.py``).

Command handling is dispatched per command id to methods named in :data:`HANDLER_NAMES`, so a
deviant unit ("mutant") is a subclass that overrides one handler or :meth:`Unit.encode`.
"""

from __future__ import annotations

from collections.abc import Mapping

from conform.families.gve.protocol.lines import LineSplitter
from conform.families.gve.spec import Dialect, Spec, Variant, load_spec
from conform.families.gve.unit.answers import Answers
from conform.families.gve.unit.dispatch import HANDLER_NAMES, CommandDispatch
from conform.families.gve.unit.eeprom import Eeprom
from conform.families.gve.unit.fastpath import FastPath
from conform.families.gve.unit.motion import MotionExecutor
from conform.families.gve.unit.packets import PacketCommands
from conform.families.gve.unit.parameters import ParameterCommands
from conform.families.gve.unit.readback import ReadbackCommands
from conform.families.gve.unit.reception import WATCHDOG_S, LineReception, parser_for
from conform.families.gve.unit.replies import (
    DEFER,
    INF,
    NOTHING_TO_GO,
    OK,
    QUEUE_FULL,
    RANGE,
    RUNNING,
    SYNTAX,
    UNKNOWN,
    WATCHDOG,
    Reply,
)
from conform.families.gve.unit.reset import ResetCommands
from conform.families.gve.unit.signals import SignalCommands
from conform.families.gve.unit.timing import Timing
from conform.families.gve.unit.vectors import VectorCommands

__all__ = [
    "DEFAULT_SWITCH_DISTANCE", "DEFAULT_SWITCH_RELEASE", "DEFER", "HANDLER_NAMES", "NOTHING_TO_GO",
    "OK", "QUEUE_FULL", "RANGE", "RUNNING", "SYNTAX", "UNKNOWN", "WATCHDOG", "WATCHDOG_S",
    "Reply", "Unit", "run_until_idle",
]

_A10 = {"answered-except-recovery": 0, "every-line": 1, "executed-only": 2}

DEFAULT_SWITCH_DISTANCE = 3000
"""Pulses from where a W starts to its axis's reference switch (in the W's direction)."""
DEFAULT_SWITCH_RELEASE = 200
"""Pulses a W backs off from the switch before it opens again."""


class Unit(LineReception, FastPath, Answers, Timing, PacketCommands, VectorCommands,
           ParameterCommands, ReadbackCommands, SignalCommands, ResetCommands, CommandDispatch):
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
        self._parser = parser_for(variant, d, self.spec)
        self._parsed = ({}, {})
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

        self._bind_handlers()

        self._splitter = LineSplitter(d["A1"])
        cls = type(self)
        overridden = (cls._parse is not Unit._parse or cls._process_line is not Unit._process_line
                      or cls._answer is not Unit._answer or cls.receive is not Unit.receive)
        self._fast = fast_path and d["A1"] != "crlf" and not overridden
        self._compile_fast_path()
        self._enc_cache = [None] * 32
        self._outbox = []
        self._now = float(t0)
        self._deaf_until = -INF
        self._power_up(self._now)

    @property
    def now(self) -> float:
        return self._now

    @property
    def executor(self) -> MotionExecutor:
        return self._exec


def run_until_idle(unit: Unit, t: float, limit: float = 1e9) -> float:
    """Advance ``unit`` in virtual time until its queue is empty (or ``limit``); return then."""
    while unit.queue_len and unit.executor.running:
        te = unit.next_deadline()
        if te is None or te > limit:
            break
        t = max(t, te)
        unit.poll(t)
    return t
