"""The state every part of the reference unit shares, declared in one place.

:class:`conform.families.gve.unit.model.Unit` is assembled from one mixin per command
family (see ``docs/unit-model.md``, "Module layout"); they all read and write the attributes
declared here on the one unit object. The constructor (``model.py``) sets the configuration, the reset
(``reset.py``) everything a ``J`` or power-up clears. Declarations only: no behaviour.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from conform.families.gve.protocol.commands import CommandParser
    from conform.families.gve.protocol.lines import LineSplitter
    from conform.families.gve.spec import Dialect, Spec, Variant
    from conform.families.gve.spec.model import CommandSpec
    from conform.families.gve.unit.eeprom import Eeprom
    from conform.families.gve.unit.motion import MotionExecutor
    from conform.families.gve.unit.packets import Packet
    from conform.families.gve.unit.replies import Reply


class UnitState:
    """Attribute declarations shared by the unit's mixins (set by ``Unit`` and ``_power_up``)."""

    # configuration (constructor)
    spec: Spec
    variant: Variant
    dialect: Dialect
    answer_delay: float
    switches: dict[str, int]
    switch_release: int
    handlers: dict[str, Callable[[tuple, float], Reply]]
    _specs: dict[str, CommandSpec]
    _naxes: int
    _capacity: int
    _parser: CommandParser
    _parsed: tuple[dict, dict]  # line -> reading, checksums off / on
    _splitter: LineSplitter
    _fast: bool
    _fast_plain: re.Pattern[bytes]
    _fast_cs: re.Pattern[bytes]
    _pulse_lo: int
    _pulse_hi: int
    _pad: list[tuple[int, ...]]
    _enc_cache: list[bytes | None]
    _velocity_args: dict[str, tuple[int, ...]]
    _eeprom: Eeprom  # kept across J
    # open questions, resolved once
    _a4_queued: bool
    _a5_excl: bool
    _a7_rate: bool
    _a9: str
    _a10: int
    _a12: str
    _a14_blocks: bool
    _a15_zero: bool
    _a17_answer: bool
    _a20_zero: bool
    _a29_store_bad: bool
    _watchdog_s: float | None
    _hold: bool
    _hex_floats: bool
    _inta_all: bool
    _always_allowed: frozenset[str]
    _t_reset: int
    _vk_reset: bool
    # tables
    _bit_stop: int
    _bit_free: int
    _bit_intcom: int
    _bit_run: int
    _bit_inta: int
    _bit_full: int
    _words: frozenset[int]
    _mask1: int
    _mask2: int
    _in1: int  # electrical input levels (kept across J)
    _in2: int

    # time and answers
    _now: float
    _deaf_until: float
    _outbox: list[tuple[float, bytes]]
    _awaiting: bool  # a late answer (H, W) is due: input is held or dropped (A16)
    _defer_t: float
    _defer_reply: tuple[int, Sequence[object]]
    _w_pending: bool
    _held_lines: list[bytes]
    _held_chunks: list[bytes]
    _wd: float  # watchdog deadline of a begun line (A13)
    _partial: bool
    _timers: bool

    # the reset state (``_power_up``)
    _exec: MotionExecutor
    _offsets: list[int]
    _A: int
    _V: int
    _B: int
    _short: int
    _T: int
    _VL: tuple[int, ...]
    _XM: int
    _VK: bool
    _st: list[int]  # ST0..ST5
    _inta: bool
    _intcom: bool
    _st6_extra: int
    _live1: int
    _live2: int
    _outputs: int
    _spindle: int
    _checksum_on: bool
    _index: int
    _mpg: str
    _mpg_run: bool
    _ready_after: float
    _packet: Packet | None
    _last_line: bytes | None
    _last_answer: bytes | None
    _kept: tuple | None
