"""The grbl 1.1f reference unit: sans-I/O, bytes and a time in, bytes and their due times out.

    unit = GrblUnit(load_grbl().variant("grbl-1.1f"))
    unit.receive(b"$G\\n", 0.0)
    unit.poll(0.01)      # [(t, b"[GC:G0 G54 ...]\\r\\n"), (t, b"ok\\r\\n")]

Like the GVE ``Unit`` it never reads a clock or sleeps: ``receive(data, t)``, ``poll(t)``,
``next_deadline()`` and ``now`` are the whole contract the emulator adapter
(:class:`conform.emulator.serve.Emulator`) and the in-process conformance target use.

What it models (docs/grbl.md): the 128-byte serial receive ring (bytes that find it full are
lost, as on the hardware; realtime bytes and every byte above 0x7F never enter it), the line
filter and the 80-byte line buffer (error:11), the g-code parser with its modal state
(:mod:`.gcode`), the planner and motion in virtual time (:mod:`.planner`), the '$' commands
(:mod:`.system`), states Idle/Run/Hold/Jog/Alarm/Check/Home/Sleep/Door, feed hold and resume,
jog cancel, overrides, soft reset with the banner, alarms, and status reports with the $10
mask and the WCO:/Ov: refresh counters.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

from conform.families.grbl.protocol.gcode import Block, GcodeError, Modal, parse
from conform.families.grbl.spec.load import GrblSpec, Variant, load_grbl
from conform.families.grbl.unit import replies as rp
from conform.families.grbl.unit.planner import Move, Planner

INF = math.inf
ALARM_DELAY = 0.5   # report.c report_alarm_message: delay_ms(500)
MOVING = ("Run", "Jog", "Home")


class GrblUnit:
    """One grbl controller. Times are seconds on the caller's clock."""

    def __init__(self, variant: Variant, spec: GrblSpec | None = None, *, t0: float = 0.0,
                 line_time: float = 0.0005, report_delay: float = 0.002,
                 settings: dict[int, float] | None = None, truth: bool = False,
                 switches: bool = True) -> None:
        self.v = variant
        self.spec = spec or load_grbl()
        self.line_time = line_time
        self.byte_time = 10.0 / variant.baud
        self.report_delay = report_delay
        self.settings = {n: s.default for n, s in self.spec.settings.items()}
        if settings:
            self.settings.update(settings)
        self.startup = [""] * variant.n_startup_lines
        self.build_info = ""
        self.eeprom_coords = Modal()        # G54-G59, G28, G30 survive a reset (EEPROM)
        self._now = float(t0)
        self._out: list[tuple[float, bytes]] = []
        self.lost = 0                       # bytes dropped because the receive ring was full
        self.lines_done = 0
        self.pins: set[str] = set()         # input pins triggered (:mod:`.inputs`): P X Y Z D
        self.door_open = False
        self.switches = switches            # False: no limit switch ever closes ($H seeks on)
        # ground truth (``truth=True``, for check-sender): [line as the parser took it, answer]
        self.taken: list[list[Any]] | None = [] if truth else None
        self._n_coded = 0
        self._quiet_until = -INF   # report.c report_alarm_message: delay_ms(500) after ALARM:N
        self._owed = False         # a line whose answer waits for a reset (critical alarm)
        self.state = "Alarm" if self.settings[22] else "Idle"
        self._reset(self._now, power_up=True)

    # ============================================================ public API
    @property
    def now(self) -> float:
        return self._now

    @property
    def rx_free(self) -> int:
        return self.v.rx_buffer - len(self.rx)

    @property
    def position(self) -> list[float]:
        return self.planner.where(self._now)[0]

    def receive(self, data: bytes, t: float) -> None:
        """Bytes from the sender whose last byte arrived at ``t``.

        A UART hands grbl one byte at a time: byte i of n arrived (n-1-i) byte times before
        ``t`` (10 bits a byte at the variant's baud), never before the unit's present.
        """
        n = len(data)
        for i, b in enumerate(data):
            tb = t - (n - 1 - i) * self.byte_time
            if tb > self._now:
                self._advance(tb)
            tb = self._now
            if b in self.spec.realtime:
                self._realtime(b, tb)
            elif b > 0x7F:
                continue                     # unknown extended byte: dropped by the ISR
            elif len(self.rx) >= self.v.rx_buffer:
                self.lost += 1
            else:
                self.rx.append(b)
                if len(self.rx) == 1 and self._ready_to_parse() and self._parser_free <= tb:
                    self._read_rx(tb)
        self._advance(t)

    def poll(self, t: float) -> list[tuple[float, bytes]]:
        """Everything due by ``t`` as (time, bytes)."""
        self._advance(t)
        due = [o for o in self._out if o[0] <= t]
        self._out = [o for o in self._out if o[0] > t]
        return due

    def next_deadline(self) -> float | None:
        best = min([o[0] for o in self._out] + [self._next_event()])
        return None if best == INF else max(best, self._now)

    def run_until(self, t: float) -> list[tuple[float, bytes]]:
        return self.poll(t)

    # ============================================================ the event loop
    def _advance(self, t: float) -> None:
        for _ in range(100000):
            nxt = self._next_event()
            if nxt > t:
                break
            self._now = max(self._now, nxt)
            self._step(self._now)
        self._now = max(self._now, t)

    def _next_event(self) -> float:
        best = INF
        if self._report_at is not None:
            best = self._report_at
        if self._busy_until is not None:
            best = min(best, self._busy_until)
        pl = self.planner
        if pl.blocks and pl.running:
            best = min(best, pl.blocks[0].t0 + pl.blocks[0].duration)
        if self._ready_to_parse():
            best = min(best, max(self._now, self._parser_free))
        return best

    def _ready_to_parse(self) -> bool:
        # protocol_exec_rt_suspend: while held (feed hold, M0, door) the main loop reads no line
        return (bool(self.rx) and self._pending is None and self._busy is None
                and self._busy_until is None and not self._critical
                and self.state not in ("Sleep", "Hold", "Door"))

    def _step(self, t: float) -> None:
        if self._report_at is not None and self._report_at <= t:
            self._report_at = None
            self._emit(t, self._status_report(t))
        if self._busy_until is not None and self._busy_until <= t:
            self._busy_until = None
            self._finish_busy(t)
        pl = self.planner
        if pl.blocks and pl.running and pl.blocks[0].t0 + pl.blocks[0].duration <= t + 1e-12:
            self._block_done(pl.blocks[0].t0 + pl.blocks[0].duration)
        if self._pending is not None:
            self._try_pending(t)
        if self._ready_to_parse() and self._parser_free <= t:
            self._read_rx(t)

    # ============================================================ output
    def _emit(self, t: float, data: bytes) -> None:
        t = max(t, self._quiet_until)
        if self._out and self._out[-1][0] > t:
            t = self._out[-1][0]
        self._out.append((t, data))

    def _say(self, t: float, *texts: str) -> None:
        for text in texts:
            self._emit(t, rp.line(text))

    def _alarm(self, t: float, code: int) -> None:
        """``ALARM:N``, then grbl sits in report.c's delay_ms(500): nothing else is sent or
        parsed for half a second (report_alarm_message)."""
        self._say(t, f"ALARM:{code}")
        self._quiet_until = t + ALARM_DELAY
        self._parser_free = max(self._parser_free, self._quiet_until)

    def parse(self, text: str, *, jog: bool = False) -> Block:
        """gc_execute_line's checks for ``text`` against the parser state (raises GcodeError)."""
        return parse(text, self.modal, self.parser_position(), jog=jog, tool_max=self.v.tool_max,
                     line_number_max=self.v.line_number_max, mist=self.v.option("ENABLE_M7"))

    def _answer(self, t: float, code: int) -> None:
        self.lines_done += 1
        self._code_taken(code)
        self._say(t, "ok" if code == 0 else f"error:{code}")

    def _code_taken(self, code: int | None) -> None:
        """The ground truth: the oldest line taken and not yet answered got ``code`` (None:
        dropped unanswered by a reset)."""
        if self.taken is not None and self._n_coded < len(self.taken):
            self.taken[self._n_coded][1] = code
            self._n_coded += 1

    # ============================================================ reading lines
    def _read_rx(self, t: float) -> None:
        """Move bytes from the ring into the line buffer until a line ends."""
        while self.rx:
            c = self.rx.popleft()
            after_cr, self._after_cr = self._after_cr, c == 0x0D
            if c == 0x0A and after_cr and not self.v.crlf_is_two_lines:
                continue                     # a build that takes CR LF as one line end
            if c in (0x0A, 0x0D):
                text, overflow = "".join(self._line), self._overflow
                self._line, self._overflow, self._paren, self._semi = [], False, False, False
                done = t + self.line_time
                self._parser_free = done
                self._process(text, overflow, done)
                return
            ch = chr(c)
            if self._paren:
                if ch == ")":
                    self._paren = False
                continue
            if self._semi:
                continue
            if ch <= " " or ch == "/" or c == 0x7F:
                continue
            if ch == "(":
                self._paren = True
            elif ch == ";":
                self._semi = True
            elif len(self._line) >= self.v.line_max:
                self._overflow = True
            else:
                self._line.append(ch.upper() if "a" <= ch <= "z" else ch)

    def _process(self, text: str, overflow: bool, t: float) -> None:
        if self.taken is not None:
            self.taken.append([text, None])
        if overflow:
            self._answer(t, 11)
        elif not text:
            self._answer(t, 0)
        elif text.startswith("$"):
            from conform.families.grbl.unit.system import system_command

            system_command(self, text, t)
        elif self.state in ("Alarm", "Jog"):
            self._answer(t, 9)
        else:
            self._gcode(text, t)

    # ============================================================ g-code
    def parser_position(self) -> list[float]:
        return list(self._check_pos) if self.state == "Check" else list(self.planner.position)

    def _gcode(self, text: str, t: float, *, jog: bool = False) -> None:
        try:
            block = self.parse(text, jog=jog)
        except GcodeError as exc:
            self._answer(t, exc.code)
            return
        self._execute(block, t, jog=jog)

    def _execute(self, block: Block, t: float, *, jog: bool = False, startup: str | None = None
                 ) -> None:
        if jog:
            if block.target is None:
                self._answer(t, 0)
                return
            if self._outside(block.target) and self.settings[20]:
                self._answer(t, 15)
                return
            self._pending = ("plan", block, True, startup)
            self._try_pending(t)
            return
        if block.target is not None and self.settings[20] and self.state != "Check" and (
                self._outside(block.target) or (block.via and self._outside(block.via))):
            self._soft_limit(t)
            return
        if self.state == "Check":
            self._take_modal(block)
            if block.target is not None:
                self._check_pos = list(block.target)
            if block.program_end:
                self._program_end(t)
            self._finish(t, 0, startup)
            return
        if block.sync or block.kind == "probe":
            self._pending = ("sync", block, False, startup)
        else:
            self._pending = ("plan", block, False, startup)
        self._try_pending(t)

    def _outside(self, target: list[float]) -> bool:
        for i, x in enumerate(target):
            travel = self.settings[130 + i]
            if x > 1e-6 or x < -travel - 1e-6:
                return True
        return False

    def _soft_limit(self, t: float) -> None:
        """ALARM:2 and the critical state: nothing but a reset is taken (interface.md)."""
        self._hard_stop(t)
        self.state = "Alarm"
        self._critical = True
        self._owed = True     # mc_line waits in the critical loop; the line's ok comes at reset
        self._alarm(t, 2)
        self._say(t, rp.MSG["reset"])

    def _try_pending(self, t: float) -> None:
        kind, block, jog, startup = self._pending
        pl = self.planner
        if kind == "plan":
            n = self._moves_needed(block)
            if pl.free < n:
                return
            self._pending = None
            if not jog:
                self._take_modal(block)
            self._plan(block, t, jog)
            self._finish(t, 0, startup)
            return
        # sync: wait for every block to finish
        if pl.blocks or self.state in ("Hold", "Door"):
            return
        self._pending = None
        self._take_modal(block)
        if block.kind == "dwell":
            self._busy_until = t + block.dwell
            self._busy = ("dwell", startup)
            return
        if block.kind == "probe":
            from conform.families.grbl.unit.inputs import probe_blocks_start

            if probe_blocks_start(self, block.probe):   # probe already in its end state
                self.state = "Alarm"
                self._alarm(t, 4)          # no [PRB:] (motion_control.c mc_probe_cycle)
                self._finish(t, 0, startup)
                return
            self._plan(block, t, False)
            self._busy_until = None
            self._busy = ("probe", startup, block)   # the parser waits for the probe
            return
        if block.kind in ("line", "arc", "home28", "home30"):
            self._plan(block, t, False)
        if block.coord_write:
            self._store_coords()
        if block.program_end:
            self._program_end(t)
        if block.pause:
            # gcode.c M0: a feed hold, then protocol_execute_realtime suspends the parser inside
            # this line: its ok comes after the cycle start ('~')
            self.state, self.hold_sub = "Hold", 0
            self._busy = ("pause", startup)
            return
        self._finish(t, 0, startup)

    def _take_modal(self, block: Block) -> None:
        """The parser state after ``block`` (gcode.c STEP 4). An offset change forces WCO:
        into the next status report (system_flag_wco_change: G92, G92.1, G10 on the active
        system, a new coordinate system, a new tool length offset); a spindle or coolant
        change (spindle_set_state, coolant_set_state) forces Ov:, except in check mode."""
        old, new = self.modal, block.modal
        self.modal = new
        if block.wco or new.coord != old.coord or new.tlo != old.tlo:
            self._wco_counter = 0
        if self.state == "Check":
            return
        if new.spindle != old.spindle or (new.speed != old.speed and old.spindle != 5):
            self._spindle_sync()
        if new.coolant != old.coolant:
            self._ovr_counter = 0

    def _spindle_sync(self) -> None:
        """spindle_set_state: the speed the status report shows (spindle_compute_pwm_value:
        the programmed speed times the override, $30 at most, $31 at least unless 0), and Ov:
        forced into the next report."""
        self.spindle_rpm = self._spindle_speed()
        self._ovr_counter = 0

    def _spindle_speed(self) -> float:
        m = self.modal
        if m.spindle not in (3, 4) or self.spindle_stopped:
            return 0.0
        self._spindle_update = False
        rpm = m.speed * self.ov_spindle / 100.0
        top, bottom = self.settings[30], self.settings[31]
        if bottom >= top or rpm >= top:
            return top
        if rpm <= bottom:
            return 0.0 if rpm == 0 else bottom
        return rpm

    def _finish(self, t: float, code: int, startup: str | None) -> None:
        if startup is not None:
            self._say(t, f">{startup}:" + ("ok" if code == 0 else f"error:{code}"))
        else:
            self._answer(t, code)

    def _finish_busy(self, t: float) -> None:
        what = self._busy
        self._busy = None
        if what and what[0] in ("dwell", "pause"):
            self._finish(t, 0, what[1])
        elif what and what[0] == "home":
            self.planner.clear([-self.settings[27]] * 3)
            self.state = "Idle"
            self._answer(t, 0)
            self._run_startup(t)

    def _moves_needed(self, block: Block) -> int:
        if block.kind in ("home28", "home30"):
            return 2 if block.via else 1
        return 1 if block.target is not None else 0

    def _plan(self, block: Block, t: float, jog: bool) -> None:
        pl = self.planner
        start = list(pl.position)
        points = []
        if block.via is not None:
            points.append(block.via)
        if block.target is not None:
            points.append(block.target)
        for p in points:
            rate = None if block.rapid else self._feed_rate(block, start, p)
            kind = "jog" if jog else ("probe" if block.kind == "probe" else "line")
            mv = pl.make(start, p, rate, kind, block)
            if mv is not None:
                if block.kind == "arc":
                    mv.length = max(mv.length, block.arc_length)
                if not block.rapid and not jog:
                    mv.rate *= self.ov_feed / 100.0
                elif block.rapid:
                    mv.rate *= self.ov_rapid / 100.0
                pl.push(mv)
            start = list(p)
        self._start_motion(t)

    def _feed_rate(self, block: Block, start: list[float], end: list[float]) -> float:
        if block.inverse_time:
            length = max(math.dist(start, end), block.arc_length)
            return length / (60.0 / block.feed) if block.feed else 1e-6
        return block.feed / 60.0

    def _start_motion(self, t: float) -> None:
        pl = self.planner
        if pl.running or not pl.blocks or self.state in ("Hold", "Door", "Alarm", "Sleep"):
            return
        pl.start_head(t, self._carry_speed)
        self._carry_speed = 0.0
        if self._spindle_update:
            self.spindle_rpm = self._spindle_speed()
        self.state = "Jog" if pl.blocks[0].kind == "jog" else "Run"

    def _homing_failed(self, t: float, code: int) -> None:
        """limits.c: a homing cycle that finds no switch: ALARM:code, the ``$H`` line answered
        ok (after the alarm's half second), then grbl resets into Alarm."""
        self._hard_stop(t)
        self.state = "Alarm"
        self._alarm(t, code)
        self._finish(max(t, self._quiet_until), 0, None)
        self._reset(t)

    def place(self, position: list[float]) -> None:
        """Put a machine that stands still at ``position`` (mm): a judge following a recording
        starts the unit from where the recorded one stood. In a hold, the machine keeps the
        rest of its way: standing short of where it was going, that rest is one block still
        queued (as grbl's is when its hold ends inside the block)."""
        pl = self.planner
        where = [float(x) for x in position]
        if pl.running:
            return
        if pl.blocks:
            head = pl.blocks[0]
            along = sum((w - s) * u for w, s, u in zip(where, head.start, head.unit, strict=True))
            head.s_done = min(max(along, 0.0), head.length)
            return
        end = list(pl.position)
        rest = pl.make(where, end, None, "line") if self.state in ("Hold", "Door") else None
        pl.clear(where)
        if rest is not None:
            pl.push(rest)
        self._check_pos = list(pl.position)

    def _block_done(self, t: float) -> None:
        pl = self.planner
        if pl.blocks and pl.blocks[0].kind == "homeseek":
            self._homing_failed(pl.blocks[0].t0 + pl.blocks[0].duration, 9)
            return
        if pl.holding:
            # the hold's deceleration ended: stand still (Hold:0) until '~'
            self.hold_sub = 0
            pl.holding = False
            if pl.stopped(t):
                return
            done = pl.blocks.popleft()
            if done.kind == "probe":
                self._probe_done(t, done)
            return
        done = pl.blocks.popleft()
        pl.running = False
        v_exit = done.v1
        if done.kind == "probe":
            self._probe_done(t, done)
        if self._jog_cancel and not any(b.kind == "jog" for b in pl.blocks):
            self._jog_cancel = False
        if pl.blocks and self.state not in ("Hold", "Door", "Alarm"):
            self._carry_speed = v_exit if pl.blocks[0].kind == done.kind else 0.0
            self.state = "Idle"
            self._start_motion(t)
        elif not pl.blocks and self.state in MOVING:
            self.state = "Idle"

    def _probe_done(self, t: float, move: Move) -> None:
        """The probe move ended without the probe changing (motion_control.c mc_probe_cycle):
        G38.2/.4 raise ALARM:5 and keep the last probe position; G38.3/.5 take the position
        reached. Either way [PRB:…:0] follows (MESSAGE_PROBE_COORDINATES), then the ok."""
        block = move.tag
        busy = self._busy
        self._busy = None
        self.prb_ok = False
        startup = busy[1] if busy else None
        if isinstance(block, Block) and block.probe in ("38.2", "38.4"):
            self.state = "Alarm"
            self._alarm(t, 5)
        else:
            self.prb = list(move.end)
        if self.v.option("MESSAGE_PROBE_COORDINATES"):
            self._say(t, f"[PRB:{rp.axes(self.prb, bool(self.settings[13]))}:0]")
        self._finish(t, 0, startup)

    def _store_coords(self) -> None:
        m = self.eeprom_coords
        m.coords = [list(c) for c in self.modal.coords]
        m.g28, m.g30 = list(self.modal.g28), list(self.modal.g30)

    def _program_end(self, t: float) -> None:
        """M2/M30: motion G1, plane, distance, feed mode, G54, spindle and coolant back to
        their defaults; units, offsets, tool and feed kept (gcode.c program flow)."""
        m = self.modal
        m.motion, m.plane, m.distance, m.feed_mode, m.coord = "1", "17", "90", "94", 0
        m.spindle, m.coolant, m.program = 5, frozenset(), None
        if self.v.option("RESTORE_OVERRIDES_AFTER_PROGRAM_END"):
            self.ov_feed = self.ov_rapid = self.ov_spindle = 100
        if self.state != "Check":   # the WCO: refresh "just in case", spindle and coolant off
            self._wco_counter = 0
            self._spindle_sync()
        self._say(t, rp.MSG["pgm_end"])

    # ============================================================ realtime bytes
    def _realtime(self, b: int, t: float) -> None:
        effect = self.spec.realtime[b].effect
        if effect == "reset":
            self._soft_reset(t)
        elif effect == "status":
            if not self._critical and self.state != "Home" and self._report_at is None:
                self._report_at = t + self.report_delay
        elif self._critical or self.state == "Sleep":
            return
        elif effect == "hold":
            self._feed_hold(t, "Hold")
        elif effect == "door":
            # protocol_exec_rt_system EXEC_SAFETY_DOOR: [MSG:Check Door] first (report.c
            # MESSAGE_SAFETY_DOOR_AJAR), never in Alarm or check mode; then the door's hold
            if self.state in ("Idle", "Run", "Jog", "Hold", "Door"):
                self._say(t, rp.MSG["door"])
            self._feed_hold(t, "Door")
        elif effect == "resume":
            if self.state in ("Hold", "Door") and self.hold_sub == 0 and not self.door_open:
                self._restore_spindle(t)
                self.state = "Idle"
                if self._busy and self._busy[0] == "pause":
                    self._finish_busy(t)
                if self.planner.blocks:
                    self.planner.resume(t)
                    self.state = "Jog" if self.planner.blocks[0].kind == "jog" else "Run"
        elif effect == "jog-cancel":
            if self.state == "Jog":
                self._cancel_jog(t)
        elif effect == "spindle-stop":
            # protocol.c: only in Hold; stops a running spindle (spindle_set_state, FS:...,0),
            # a second one restores it
            if self.state == "Hold" and self.spindle_stopped:
                self._restore_spindle(t)
            elif self.state == "Hold" and self.modal.spindle in (3, 4):
                self.spindle_stopped = True
                self._spindle_sync()
        elif effect.startswith(("feed", "rapid", "spindle=", "spindle+", "spindle-")):
            self._override(effect)
        elif effect == "flood" and self.state in ("Idle", "Run", "Hold"):
            m = self.modal
            m.coolant = m.coolant - {8} if 8 in m.coolant else m.coolant | {8}
            self._ovr_counter = 0

    def _restore_spindle(self, t: float) -> None:
        """protocol_exec_rt_suspend: a spindle stopped in the hold is restarted, said first."""
        if self.spindle_stopped:
            self.spindle_stopped = False
            self._say(t, rp.MSG["spindle_restore"])
            self._spindle_sync()

    def _feed_hold(self, t: float, to: str) -> None:
        if self.state == "Jog" and to == "Hold":
            self._cancel_jog(t)
            return
        if self.state not in ("Idle", "Run", "Jog", "Hold") and not (to == "Door"
                                                                      and self.state == "Door"):
            return
        if self.state in ("Run", "Jog") and self.planner.running:
            stop = self.planner.hold(t)
            self.state, self.hold_sub = to, (1 if stop > t else 0)
        elif self.state == "Idle":
            self.state, self.hold_sub = to, 0
        elif to == "Door":
            self.state = "Door"

    def _cancel_jog(self, t: float) -> None:
        pl = self.planner
        if pl.running:
            pl.hold(t)
            head = pl.blocks[0]
            pl.blocks.clear()
            pl.blocks.append(head)
            s_end = head.s_done + head.v0 * head.td - head.accel * head.td ** 2 / 2
            head.length = min(head.length, s_end)
            head.end = head.point(head.length)
            pl.position = list(head.end)
            pl.holding = False
        self._jog_cancel = True

    def _override(self, effect: str) -> None:
        """protocol.c: Ov: is forced into the next report only when a value changes; a new
        spindle override reaches the speed shown (FS:) when motion next runs (the stepper's
        STEP_CONTROL_UPDATE_SPINDLE_PWM), not while idle."""
        lims = self.spec.overrides
        before = (self.ov_feed, self.ov_rapid, self.ov_spindle)
        if effect.startswith("feed"):
            self.ov_feed = self._ov(self.ov_feed, effect[4:], lims["feed"])
        elif effect.startswith("rapid"):
            self.ov_rapid = int(effect.split("=")[1])
        else:
            self.ov_spindle = self._ov(self.ov_spindle, effect[7:], lims["spindle"])
            if self.ov_spindle != before[2]:
                self._spindle_update = True
        if (self.ov_feed, self.ov_rapid, self.ov_spindle) != before:
            self._ovr_counter = 0

    @staticmethod
    def _ov(value: int, op: str, lim: dict[str, int]) -> int:
        if op.startswith("="):
            return int(op[1:])
        return max(lim["lo"], min(lim["hi"], value + int(op)))

    # ============================================================ reset
    def _hard_stop(self, t: float) -> None:
        pos = self.planner.where(t)[0] if hasattr(self, "planner") else [0.0] * 3
        self.planner.clear(pos)
        self._pending = None
        self._busy = None
        self._busy_until = None

    def _soft_reset(self, t: float) -> None:
        moving = self.state in MOVING or (self.state in ("Hold", "Door") and self.hold_sub != 0)
        if moving:
            self._alarm(t, 6 if self.state == "Home" else 3)
            self.state = "Alarm"
        if self._owed or self._pending is not None or self._busy is not None:
            # the line grbl was inside returns once sys.abort is set and is answered ok
            # before protocol_main_loop exits to print the banner (protocol.c, main.c)
            busy = self._busy
            startup = (self._pending[3] if self._pending is not None else
                       busy[1] if busy and busy[0] in ("dwell", "probe", "pause") else None)
            self._finish(max(t, self._quiet_until), 0, startup)
        self._owed = False
        self._reset(t)

    def power_cycle(self, t: float, boot: float = 0.0) -> None:
        """Power off and on (a USB cable pulled and plugged back: the board restarts): the
        planner, the receive ring and the parser state are gone, the machine stands where it
        stopped but grbl counts from zero; settings and EEPROM stay. The banner goes out
        ``boot`` seconds later (a bootloader's wait)."""
        self._advance(t)
        self.state = "Idle"
        self.door_open = False
        self.pins.clear()
        self._reset(t, power_up=True, announce=t + boot)

    def _reset(self, t: float, power_up: bool = False, announce: float | None = None) -> None:
        while self._n_coded < len(getattr(self, "taken", None) or ()):
            self._code_taken(None)           # lines parsed but never answered: dropped
        # main.c after a reset: plan_sync_position, gc_sync_position -- the parser and the
        # planner start again from sys_position, the whole steps the motors made
        pos = self._in_steps(self.planner.where(t)[0]) if not power_up else [0.0] * 3
        a = [self.settings[120 + i] for i in range(3)]
        r = [self.settings[110 + i] / 60.0 for i in range(3)]
        self.planner = Planner(self.v.planner_blocks, r, a, self.settings[11])
        self.planner.clear(pos)
        self.rx: deque[int] = deque()
        self._line: list[str] = []
        self._overflow = self._paren = self._semi = self._after_cr = False
        self._pending: tuple[Any, ...] | None = None
        self._busy: tuple[Any, ...] | None = None
        self._busy_until: float | None = None
        self._report_at: float | None = None
        self._parser_free = t
        self._critical = False
        self._carry_speed = 0.0
        self._jog_cancel = False
        self.hold_sub = 0
        ee = self.eeprom_coords
        self.modal = Modal(coords=[list(c) for c in ee.coords], g28=list(ee.g28), g30=list(ee.g30))
        self._check_pos = list(pos)
        self.prb = getattr(self, "prb", [0.0] * 3)
        self.prb_ok = getattr(self, "prb_ok", False)
        self.ov_feed = self.ov_rapid = self.ov_spindle = 100
        self.spindle_stopped = False
        self.spindle_rpm = 0.0            # sys.spindle_speed: what FS: shows
        self._spindle_update = False      # a spindle override not yet applied
        self._wco_counter = self._ovr_counter = 0
        if self.state in ("Alarm", "Sleep") or (power_up and self.settings[22]):
            self.state = "Alarm"
        else:
            self.state = "Idle"
        t = t if announce is None else announce
        self._emit(t, rp.banner(self.v))
        if self.state == "Alarm":
            self._say(t, rp.MSG["locked"])
        else:
            self._run_startup(t)

    def _run_startup(self, t: float) -> None:
        for text in self.startup:
            if text:
                try:
                    block = self.parse(text)
                except GcodeError as exc:
                    self._say(t, f">{text}:error:{exc.code}")
                    continue
                self._execute(block, t, startup=text)

    # ============================================================ status report
    def _in_steps(self, pos: list[float]) -> list[float]:
        """The position as grbl knows it: whole steps of each axis ($100-$102 steps/mm; the
        planner's targets are lround(mm x steps/mm), system_convert_axis_steps_to_mpos)."""
        out = []
        for i, p in enumerate(pos):
            per_mm = self.settings.get(100 + i, 0.0)
            if per_mm <= 0:
                out.append(p)
                continue
            steps = math.floor(abs(p) * per_mm + 0.5)
            out.append(math.copysign(steps, p) / per_mm if steps else 0.0)
        return out

    def _status_report(self, t: float) -> bytes:
        pos, v = self.planner.where(t)   # the machine's position (check mode moves nothing)
        pos = self._in_steps(pos)
        inches = bool(self.settings[13])
        name = self.state
        if self.state in ("Hold", "Door"):
            name = f"{self.state}:{self.hold_sub}"
            if self.state == "Door" and self.door_open:    # ajar: 2 stopping, 1 stopped
                name = f"Door:{2 if self.hold_sub else 1}"
        mask = int(self.settings[10])
        m = self.modal
        wco = m.wco()
        parts = [name]
        if mask & 1:
            parts.append("MPos:" + rp.axes(pos, inches))
        else:
            parts.append("WPos:" + rp.axes([p - w for p, w in zip(pos, wco, strict=True)], inches))
        if mask & 2:
            parts.append(f"Bf:{self.planner.free},{self.rx_free}")
        feed = v * 60.0 / (25.4 if inches else 1.0)
        parts.append(f"FS:{feed:.0f},{self.spindle_rpm:.0f}")
        if self.pins:
            from conform.families.grbl.unit.inputs import pin_field

            parts.append(str(pin_field(self)))
        busy = self.state in ("Run", "Hold", "Jog", "Home", "Door")
        refresh = self.v.status_refresh
        if self._wco_counter > 0:
            self._wco_counter -= 1
        else:
            self._wco_counter = (refresh["wco_busy"] if busy else refresh["wco_idle"]) - 1
            if self._ovr_counter == 0:
                self._ovr_counter = 1
            parts.append("WCO:" + rp.axes(wco, inches))
        if self._ovr_counter > 0:
            self._ovr_counter -= 1
        else:
            self._ovr_counter = (refresh["ovr_busy"] if busy else refresh["ovr_idle"]) - 1
            parts.append(f"Ov:{self.ov_feed},{self.ov_rapid},{self.ov_spindle}")
            on = m.spindle if not self.spindle_stopped else 5
            acc = ("S" if on == 3 else "C" if on == 4 else "") + (
                "F" if 8 in m.coolant else "") + ("M" if 7 in m.coolant else "")
            if acc:
                parts.append("A:" + acc)
        return rp.line("<" + "|".join(parts) + ">")
