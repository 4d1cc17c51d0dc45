"""The Marlin reference unit: sans-I/O (bytes and time in, bytes out when due), on a virtual
clock, modelling what Marlin 2.1.2.4's source does (specs/marlin cite the functions).

Its main loop is MarlinCore's: it reads the serial receive buffer into the command queue
(queue.cpp ``get_serial_commands``: line numbers, checksums, errors and ``Resend:``), then runs
one queued command to its end (``advance``), which may block while the planner is full, a dwell
runs, the axes home or a heater warms up (``busy: processing`` keepalives meanwhile). Reading
goes on while a command blocks: every blocking loop calls ``idle()``, whose
``manage_inactivity()`` calls ``queue.get_available_commands()`` (MarlinCore.cpp). So a line
error is answered during the block, good lines wait in the queue (the running command keeps
its slot, BUFSIZE in all), and an unnumbered M108 / M112 / M410 acts as soon as it is read
(get_serial_commands' "critical commands", without the emergency parser). The recordings of
the real firmware (recordings/marlin-2.1.2.4/blocking-reads.transcript) show all of this.
The emergency parser (where enabled) looks at every byte as it arrives.

Ground truth: ``executed`` counts how many times each numbered line ran, ``log`` lists every
command run (time, N, text).
"""

from __future__ import annotations

import math
import re
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from conform.families.marlin.protocol.codec import checksum
from conform.families.marlin.spec import MarlinSpec, Variant
from conform.families.marlin.unit.settings import Settings, boolval
from conform.families.marlin.unit.settings import words as st_words

EOL = b"\r\n"
BACKSPACE = 0x08
AMBIENT = 25.0
HEAT_RATE = (4.0, 1.5)        # °C/s of the hotend and the bed (an assumption: a fast machine)
COOL_RATE = (1.0, 0.3)
COOLING_SLOPE = ((1.5, 60.0), (1.0, 60.0))   # temperature.cpp MIN_COOLING_SLOPE_DEG/_TIME
                                             # (hotend) and ..._BED: °C that must drop in s
ACCEL = 3000.0                # Configuration.h DEFAULT_ACCELERATION (mm/s²)
MAX_ACCEL = (3000.0, 3000.0, 100.0, 10000.0)   # Configuration.h DEFAULT_MAX_ACCELERATION: the
                              # planner limits a block's acceleration by each axis in it
DEFAULT_FEED = 25.0           # motion.cpp feedrate_mm_s = MMM_TO_MMS(1500)
HOMING = 50.0                 # mm/s, Configuration.h HOMING_FEEDRATE_MM_M {50*60, 50*60, 4*60}
BOOT = 0.1                    # s from reset to "start" (the simulator; a real AVR board waits
                              # ~0.5-2 s in its bootloader)
QUICKSTOP = 1.0               # planner.cpp Planner::quick_stop: cleaning_buffer_counter =
                              # TEMP_TIMER_FREQUENCY, and synchronize() waits it out: M410 takes
                              # 1 s (recorded: 1.01-1.03 s)
FIRST_MOVE_DELAY = 0.1        # planner.h BLOCK_DELAY_FOR_1ST_MOVE (100 ms) before the stepper
                              # takes the first block
HOMING_BUMP = ((5.0, 2.0), (5.0, 2.0), (2.0, 4.0))   # Configuration_adv.h HOMING_BUMP_MM and
                              # HOMING_BUMP_DIVISOR: back off and approach again, slower
_WORD = re.compile(r"([A-Za-z])\s*([-+]?\d*\.?\d+)")


@dataclass
class Queued:
    text: str          # the line as stored in the queue (after N checks), checksum included
    n: int | None      # its line number (None: an unnumbered line)
    t_in: float


@dataclass
class HeatWait:
    """A running M109 / M190 (temperature.cpp wait_for_hotend / wait_for_bed): a report every
    second from its start, the residency timer set at ``set_at`` to start at ``window_at``,
    the end (``ok`` follows). The heater model rises or falls linearly (HEAT_RATE, COOL_RATE)
    and never leaves the window once in it, so TEMP_HYSTERESIS never restarts the timer."""

    h: int
    t0: float
    set_at: float
    window_at: float
    residency: float
    end: float
    reports: int = 0

    def next_report(self) -> float:
        return self.t0 + self.reports

    def w(self, p: float) -> str:
        """The W: field at report time ``p``: ? before the timer is set, else the whole
        seconds left (from ms, as the firmware's integer division)."""
        if p <= self.set_at:
            return "?"
        left = round(self.residency * 1000) - (round(p * 1000) - round(self.window_at * 1000))
        return str(max(left, 0) // 1000)


@dataclass
class Truth:
    """What the unit did: every command run, and how often each numbered line ran."""

    executed: dict[int, int] = field(default_factory=dict)
    log: list[tuple[float, int | None, str]] = field(default_factory=list)
    resends: list[tuple[float, int, str]] = field(default_factory=list)   # (t, asked, why)
    dropped: list[tuple[float, int]] = field(default_factory=list)   # duplicates ignored
    resets: list[float] = field(default_factory=list)
    prompt_responses: list[tuple[float, int]] = field(default_factory=list)   # M876 S<n> taken

    def to_dict(self) -> dict[str, Any]:
        return {"executed": {str(k): v for k, v in sorted(self.executed.items())},
                "twice": sorted(k for k, v in self.executed.items() if v > 1),
                "commands": len(self.log), "resends": self.resends, "dropped": self.dropped,
                "resets": self.resets}


class MarlinUnit:
    settings_class = Settings           # unit/settings.py (a deviant unit may bring its own)
    def __init__(self, v: Variant, spec: MarlinSpec, *, t0: float = 0.0,
                 line_time: float = 0.0005, boot: float = 0.0, **_options: Any) -> None:
        self.v, self.spec = v, spec
        self.line_time = line_time
        self.now = t0
        self.truth = Truth()
        self.lost = 0                       # bytes lost to a full receive buffer
        self.discarded = 0                  # bytes thrown away by gcode_line_error
        self._out: list[tuple[float, bytes]] = []
        self.deaf = False                   # after a deviant unit's choice (mutants)
        self._kind = ""
        self.eeprom: dict[str, Any] = {}    # what M500 stored (kept across resets)
        self._reset_state(t0, boot)

    # -- power -----------------------------------------------------------------------------
    def _reset_state(self, t: float, boot: float) -> None:
        self.rx = bytearray()
        self.sis = 0                        # 0 normal, 1 EOL comment or overflow, 4+ escape
        self.buf = bytearray()
        self.last_n = 0
        self.queue: deque[Queued] = deque()
        self.cur: Queued | None = None
        self.cur_start = self.cur_done = 0.0
        self.cur_busy = False
        self.planner: deque[tuple[float, list[float]]] = deque()   # (end time, end position)
        self.planner_begin = t                       # when the first block's motion begins
        self.position = [0.0, 0.0, 0.0, 0.0]          # where the planner ends (current_position)
        self.stepped = [0.0, 0.0, 0.0, 0.0]           # where the steppers are
        self.relative = self.e_relative = False
        self.feed = DEFAULT_FEED
        self.heat = [(AMBIENT, 0.0, t), (AMBIENT, 0.0, t)]   # (temp at t, target, t)
        self.temp_every = 0.0
        self.next_temp = math.inf
        self.pos_every = 0.0
        self.next_pos = math.inf
        self.next_busy = math.inf
        self.halted = False
        self.booting_until = t + boot
        self.ep_state = ""                  # emergency parser: the command seen so far
        self.wait: HeatWait | None = None   # M109 / M190 waiting
        self.pending = bytearray()          # bytes the host wrote that wait outside the ring
        self.held_until = t                 # an early M410's synchronize() holds the loop
        self.homed = False                  # the axes' place is known (after G28)
        self.settings = self.settings_class(self.v)   # loaded from the EEPROM at boot
        loaded = self.settings.load(self.eeprom, announce=False)
        self._say(self.booting_until, *self._banner(), *loaded)

    def power_off(self, t: float) -> None:
        """The board loses power (its USB cable pulled): it stops where it is and says
        nothing until ``power_cycle``."""
        self._advance(t)
        self._out = [o for o in self._out if o[0] <= t]
        self.queue.clear()
        self.planner.clear()
        self.cur = None
        self.wait = None
        self.rx.clear()
        self.pending.clear()
        self.halted = True

    def power_cycle(self, t: float, boot: float = BOOT) -> None:
        """A reset (DTR on port open, the reset button, a power cycle): the banner, all
        state lost."""
        self._advance(t)
        self.truth.resets.append(t)
        self._out = [o for o in self._out if o[0] <= t]
        self._reset_state(t, boot)

    def stall(self, t: float, seconds: float) -> None:
        """The unit is busy for ``seconds`` more (a fault: a long move or a slow heater)."""
        self._advance(t)
        if self.halted:
            return
        if self.cur is None:
            self.cur, self._kind = Queued("", None, t), "_stall"
            self.cur_start = self.cur_done = t
        self.cur_done += seconds
        every = self.settings.keepalive
        if every and self.v.on("HOST_KEEPALIVE_FEATURE") and not self.cur_busy:
            self.cur_busy, self.next_busy = True, t + every

    def _banner(self) -> list[str]:
        """MarlinCore.cpp setup(): start, the reset cause (PowerUp), the version, the build's
        date and free memory (what settings.load() says follows: on an empty EEPROM the
        version mismatch and the defaults loaded, as recorded). HAL_LINUX (the native build,
        HAL/LINUX/main.cpp main()) greets with ``x86_64 Initialized`` before setup() runs."""
        v = self.v
        lines = ["x86_64 Initialized"] if v.on("HAL_LINUX") else []
        lines += ["start", "PowerUp", f"Marlin {v.firmware}",
                 "echo: Last Updated: 2024-06-16 | Author: (none, default config)",
                 "echo: Compiled: conform emulator",
                 "echo: Free Memory: 4096  PlannerBufferBytes: 1280"]
        return lines

    # -- the sans-I/O interface --------------------------------------------------------------
    def receive(self, data: bytes, t: float) -> None:
        self._advance(t)
        if self.halted or self.deaf:
            return
        if self.v.on("RX_WAITS_OUTSIDE"):
            self.pending += data
            self._fill_rx(t)
        else:
            room = self.v.rx_buffer - len(self.rx)
            if len(data) > room:
                self.lost += len(data) - max(room, 0)
                data = data[:max(room, 0)]
            self._into_rx(data, t)
        self._advance(t)

    def _into_rx(self, data: bytes, t: float) -> None:
        if self.v.on("EMERGENCY_PARSER"):
            for b in data:
                self._e_parser(b, t)
                if self.halted:
                    return
        self.rx += data

    def _fill_rx(self, t: float) -> None:
        """RX_WAITS_OUTSIDE (the native build's reader thread, HAL/LINUX/main.cpp
        read_serial_thread): only what fits in the ring is moved in, the rest waits in the
        pty; nothing is lost."""
        room = self.v.rx_buffer - len(self.rx)
        if room > 0 and self.pending:
            data = bytes(self.pending[:room])
            del self.pending[:room]
            self._into_rx(data, t)

    def poll(self, t: float) -> list[tuple[float, bytes]]:
        self._advance(t)
        due = [o for o in self._out if o[0] <= t]
        if due:
            self._out = [o for o in self._out if o[0] > t]
        return due

    def next_deadline(self) -> float | None:
        times = [o[0] for o in self._out]
        if not self.halted:
            nxt = self._next_event()
            if nxt is not None:
                times.append(nxt)
        return min(times) if times else None

    # -- the main loop -----------------------------------------------------------------------
    def _next_event(self) -> float | None:
        times = [self.next_temp, self.next_pos]
        if self.wait is not None and self.wait.next_report() <= self.wait.end + 1e-9:
            times.append(self.wait.next_report())
        if self.cur is not None:
            times.append(self.cur_done)
            if self.cur_busy:
                times.append(self.next_busy)
        elif (self.queue or self.rx) and self.now < self.booting_until:
            times.append(max(self.now, self.booting_until))
        elif self.queue and self.held_until > self.now:
            times.append(self.held_until)
        t = min(times)
        return None if t == math.inf else t

    def _advance(self, t: float) -> None:
        for _ in range(1_000_000):
            if self.halted:
                break
            if self.now >= self.booting_until:
                self._read_serial()
                if (self.cur is None and self.queue and not self.halted
                        and self.now >= self.held_until):
                    self._start(self.queue.popleft())
            nxt = self._next_event()
            if nxt is None or nxt > t:
                break
            self.now = max(self.now, nxt)
            self._fire()
        self.now = max(self.now, t)

    def _fire(self) -> None:
        t = self.now
        if self.cur is not None and self.cur_busy and self.next_busy <= t < self.cur_done:
            why = "paused for user" if self._kind == "user_wait" else "processing"
            self._say(t, f"echo:busy: {why}")
            self.next_busy = t + self.settings.keepalive
        w = self.wait
        if w is not None and w.next_report() <= min(t, w.end) + 1e-9:   # (the report at the end too)
            self._say(t, f"{self._temps_line()} W:{w.w(t)}")
            w.reports += 1
        if self.next_temp <= t:
            self._say(t, self._temps_line())
            self.next_temp = t + self.temp_every
        if self.next_pos <= t:
            self._say(t, self._position_line())
            self.next_pos = t + self.pos_every
        if self.cur is not None and self.cur_done <= t:
            self._finish()

    def _say(self, t: float, *lines: str) -> None:
        for line in lines:
            self._out.append((t, line.encode("latin-1") + b"\n"))

    # -- reading the serial port (queue.cpp get_serial_commands) -----------------------------
    def _read_serial(self) -> None:
        """Lines into the queue while it has room (the running command keeps its slot:
        RingBuffer holds BUFSIZE commands, the one being run included)."""
        while not self.halted:
            i = 0
            while (i < len(self.rx) and not self.halted
                   and len(self.queue) + (self.cur is not None) < self.v.bufsize):
                c = self.rx[i]
                i += 1
                if c in EOL:
                    line = bytes(self.buf).split(b"\0")[0]   # the line buffer is a C string
                    self.sis = 0
                    self.buf.clear()
                    if line:
                        consumed = self._line_done(line)
                        if consumed is False:     # gcode_line_error emptied the receive buffer
                            self.discarded += len(self.rx) - i
                            i = len(self.rx)
                else:
                    self._stream_char(c)
            del self.rx[:i]
            full = len(self.queue) + (self.cur is not None) >= self.v.bufsize
            before = len(self.pending)
            if self.halted or full or not before:
                break
            self._fill_rx(self.now)
            if len(self.pending) == before:
                break

    def _stream_char(self, c: int) -> None:
        """queue.cpp process_stream_char: ';' starts a comment to the end of the line (a
        checksum after it is gone too), backslash escapes, backspace erases, and beyond
        MAX_CMD_SIZE - 1 characters the rest of the line is skipped."""
        if self.sis == 1:
            return
        if self.sis >= 4:
            self.sis -= 4
        elif c == 0x5C:
            self.sis += 4
            return
        elif c == 0x3B:
            self.sis = 1
            return
        if c == BACKSPACE:
            if self.buf:
                self.buf.pop()
            return
        self.buf.append(c)
        if len(self.buf) >= self.v.max_cmd_size - 1:
            self.sis = 1

    def _line_done(self, line: bytes) -> bool:
        t = self.now
        command = line.lstrip(b" ")
        if command[:1] == b"N":
            m110 = b"M110" in command
            npos = command
            if m110:
                second = command.find(b"N", 4)
                if second >= 0:
                    npos = command[second:]
            n = _strtol(npos[1:])
            if n != self.last_n + 1 and not m110:
                if self.last_n - 1 <= n <= self.last_n:
                    return self._duplicate(n, line)
                return self._line_error("Line Number is not Last Line Number+1", "line-number")
            star = command.rfind(b"*")
            if star < 0:
                return self._line_error("No Checksum with line number", "no-checksum")
            if not self._checksum_ok(command, star):
                return self._line_error("checksum mismatch", "checksum")
            self.last_n = n
            number: int | None = n
        else:
            number = None
        text = line.decode("latin-1")
        if not self.v.on("EMERGENCY_PARSER") and command[:1] == b"M":
            self._critical(command[:4], t)
            if self.halted:
                return True
        self.queue.append(Queued(text, number, t))
        return True

    def _critical(self, code: bytes, t: float) -> None:
        """queue.cpp get_serial_commands, "Process critical commands early" (without the
        emergency parser): a line that STARTS with M108, M112 or M410 acts as it is read,
        then is queued as any line (its ok comes in its turn). A numbered line starts with
        N, so it only acts when its turn comes. M410's quickstop_stepper() ends with
        planner.synchronize(), which holds the loop for the planner's 1 s quick-stop wait."""
        if code == b"M108":
            self._break_wait(t)
        elif code == b"M112":
            self._kill(t)
        elif code == b"M410":
            self._quickstop(t)
            self.held_until = max(self.held_until, t + QUICKSTOP)
            if self.cur is not None:
                self.cur_done = max(self.cur_done, self.held_until)

    def _duplicate(self, n: int, line: bytes) -> bool:
        """queue.cpp: a number within last_N - 1 .. last_N ("A request-for-resend line was
        already in transit so we got two - oops!") is ignored: no answer, no resend."""
        self.truth.dropped.append((self.now, n))
        return True

    def _checksum_ok(self, command: bytes, star: int) -> bool:
        return _strtol(command[star + 1:]) == checksum(command[:star])

    def _line_error(self, message: str, why: str) -> bool:
        """queue.cpp gcode_line_error: Error:..., the receive buffer emptied, Resend: and ok."""
        t = self.now
        self._say(t, f"Error:{message}, Last Line: {self.last_n}", f"Resend: {self.last_n + 1}",
                  "ok")
        self.truth.resends.append((t, self.last_n + 1, why))
        return False

    # -- the emergency parser (feature/e_parser.h) ---------------------------------------------
    def _e_parser(self, b: int, t: float) -> None:
        c = chr(b).upper()
        s = self.ep_state
        if s.startswith("M8") and self.v.on("HOST_PROMPT_SUPPORT"):
            self._e_parser_m876(c, t)
            return
        if c in "\r\n":
            if s in ("M108", "M112", "M410"):
                {"M108": self._break_wait, "M112": self._kill, "M410": self._quickstop}[s](t)
            self.ep_state = ""
        elif s == "!":
            return
        elif s == "" and c == "N":
            self.ep_state = "N"
        elif s in ("", "N") and (c == " " or (s == "N" and (c.isdigit() or c == "-"))):
            return
        elif s in ("", "N") and c == "M":
            self.ep_state = "M"
        elif s == "M" and c == " ":
            return
        elif s == "M" and c == "8" and self.v.on("HOST_PROMPT_SUPPORT"):
            self.ep_state = "M8"
        elif s in ("M108", "M112", "M410"):
            return                       # anything to the end of the line (a checksum)
        elif len(s) < 4 and any(k.startswith(s + c) for k in ("M108", "M112", "M410")):
            self.ep_state = s + c
        else:
            self.ep_state = "!"          # not one of its commands: ignore to the end of line

    def _e_parser_m876(self, c: str, t: float) -> None:
        """e_parser.h with HOST_PROMPT_SUPPORT: M8 -> M87 -> M876 -> M876S -> M876S<digit>.
        As the source has it: an end of line in M8, M87 or M876 leads to ignoring up to the
        next one (it does not reset), in M876S it is not looked at (the state stays), and only
        M876S<digit> acts at the end of its line (hostui.handle_response)."""
        s = self.ep_state
        if s in ("M8", "M87"):
            want = "7" if s == "M8" else "6"
            self.ep_state = s + want if c == want else "!"
        elif s == "M876":
            self.ep_state = s if c == " " else "M876S" if c == "S" else "!"
        elif s == "M876S":
            if c.isdigit():
                self.ep_state = "M876S" + c
        elif c in "\r\n":
            self.truth.prompt_responses.append((t, int(s[5:])))
            self.ep_state = ""

    def _break_wait(self, t: float) -> None:
        """wait_for_heatup = wait_for_user = false: a heating wait or an M0/M1 wait ends."""
        if self.wait is not None and self.cur is not None:
            self.wait.end = min(self.wait.end, t)
            self.cur_done = min(self.cur_done, t + self.line_time)
        elif self.cur is not None and self._kind == "user_wait":     # wait_for_user = false
            self.cur_done = min(self.cur_done, t + self.line_time)

    def _quickstop(self, t: float) -> None:
        """MarlinCore.cpp quickstop_stepper: the planner emptied, the steppers stopped where
        they are, and the position taken from them (whole steps)."""
        self.stepped = self._stepped_at(t)
        self.planner.clear()
        self.position = list(self.stepped)
        # planner.cpp Planner::synchronize (M400) and a move waiting for a free block end
        # once the planner is empty, whether or not busy: lines are being sent (M113)
        if self.cur is not None and self._kind in ("move", "sync"):
            self.cur_done = min(self.cur_done, t + self.line_time)

    def _stepped_at(self, t: float) -> list[float]:
        """Where the steppers are at ``t``, in whole steps (a move in progress is
        interpolated along its block at its cruise speed)."""
        self._settle(t)
        at = list(self.stepped)
        if self.planner:
            begin = self.planner_begin
            end, target = self.planner[0]
            if begin < t < end:
                f = (t - begin) / (end - begin)
                at = [a + (b - a) * f for a, b in zip(self.stepped, target, strict=True)]
        steps = self.v.steps_per_mm
        return [round(at[i] * steps[i]) / steps[i] for i in range(4)]

    def _kill(self, t: float) -> None:
        """MarlinCore.cpp kill(M112_KILL_STR): the heaters off, the LCD message echoed to the
        serial port (``echo:M112 Shutdown``), ``Error:Printer halted. kill() called!``, then
        minkill() loops forever: nothing is read or answered until a reset."""
        self._settle(t)
        self._say(t, "echo:M112 Shutdown", "Error:Printer halted. kill() called!")
        self.halted = True
        self.cur = None
        self.wait = None
        self.queue.clear()
        self.planner.clear()

    # -- running one command (gcode.cpp process_parsed_command) --------------------------------
    def _command(self, code: str) -> Any:
        """The table's command ``code`` when this build has it (None: unknown here); every
        T<n> is T0's row (gcode.cpp: case 'T' calls T(parser.codenum))."""
        return self.spec.command("T0" if code[:1] == "T" else code, self.v)

    def _start(self, q: Queued) -> None:
        t = max(self.now, self.booting_until)
        self.cur, self.cur_start, self.cur_busy = q, t, False
        if self.settings.debug & 1:
            # gcode.cpp process_next_command: DEBUGGING(ECHO) echoes the command with
            # SERIAL_ECHOLN, a println: this one line ends in CR LF (as recorded)
            self._out.append((t, f"echo:{q.text}".encode("latin-1") + b"\r\n"))
        done = t + self.line_time
        code = _code(q.text)
        words = _words(q.text)
        cmd = self._command(code) if code else None
        kind = cmd.kind if cmd else ""
        self._settle(t)
        if kind == "move":
            done = self._move(t, words) + self.line_time
        elif kind in ("dwell", "sync", "home"):
            end = self.planner[-1][0] if self.planner else t
            if kind == "dwell":
                # G4.cpp: P ms, but S s wins when both are given
                end += words["S"] if "S" in words else words.get("P", 0.0) / 1000.0
            elif kind == "home":
                end += self._homing_time()
                self.planner.append((end, [0.0, 0.0, 0.0, self.position[3]]))
                self.position[:3] = [0.0, 0.0, 0.0]
                self.homed = True
            done = end + self.line_time
        elif kind == "user_wait":
            # M0_M1.cpp: P ms or S s (none: until M108), after planner.synchronize();
            # MarlinCore.cpp wait_for_user_response, busy state PAUSED_FOR_USER
            end = self.planner[-1][0] if self.planner else t
            wait = words.get("P", 0.0) / 1000.0 if "P" in words else words.get("S", 0.0)
            done = (end + wait if wait > 0 else math.inf) + self.line_time
        elif kind == "wait_temp" and ("S" in words or "R" in words):
            h = 0 if code == "M109" else 1
            self._set_target(h, words.get("S", words.get("R", 0.0)), t)
            if not ("S" in words and self.heat[h][1] < self.temp(h, t)):   # S: no wait to cool
                self.wait = self._plan_wait(h, t)
                done = self.wait.end + self.line_time
        elif kind == "set_temp":
            self._set_target(0 if code == "M104" else 1, words.get("S", 0.0), t)
        elif kind == "position":
            for i, a in enumerate("XYZE"):
                if a in words:
                    self.position[i] = words[a]
            # G92.cpp sync_plan_position -> planner.cpp set_machine_position_mm: with no block
            # queued the steppers take the new position at once (stepper.set_position), else a
            # sync block behind the queued ones sets them when its turn comes (buffer_sync_block)
            if self.planner:
                self.planner.append((self.planner[-1][0], list(self.position)))
            else:
                self.stepped = list(self.position)
        elif kind == "set" and code in ("G90", "G91", "M82", "M83"):
            if code in ("G90", "G91"):
                self.relative = self.e_relative = code == "G91"
            else:
                self.e_relative = code == "M83"
        elif kind == "autoreport_temp" and "S" in words:
            # M155.cpp: only S with a value (parser.seenval) sets the interval; M155 alone
            # leaves the reports as they are
            self.temp_every = words["S"]
            self.next_temp = t + self.temp_every if self.temp_every > 0 else math.inf
        elif kind == "autoreport_pos":
            self.pos_every = words.get("S", 0.0)
            self.next_pos = t + self.pos_every if self.pos_every > 0 else math.inf
        elif kind == "line_no" and "N" in words:
            self.last_n = int(words["N"])
        elif kind == "quickstop":
            self._quickstop(t)
            done = t + QUICKSTOP + self.line_time

        # gcode.cpp host_keepalive: host_keepalive_interval (M113) 0 says nothing
        if self.settings.keepalive and self.v.on("HOST_KEEPALIVE_FEATURE") and not (
                self.wait is not None and not self.v.on("BUSY_WHILE_HEATING")):
            self.cur_busy = True        # (a heating wait is NOT_BUSY without BUSY_WHILE_HEATING)
            self.next_busy = t + self.settings.keepalive
        self.cur_done = done
        self._kind = kind

    def _finish(self) -> None:
        q, t = self.cur, self.cur_done
        assert q is not None
        self.cur, self.cur_busy = None, False
        self.next_busy = math.inf
        self.wait = None
        self._settle(t)
        if self._kind == "_stall":
            return
        self.truth.log.append((t, q.n, q.text))
        if q.n is not None:
            self.truth.executed[q.n] = self.truth.executed.get(q.n, 0) + 1
        kind = self._kind
        if kind == "halt":
            self._kill(t)
            return
        if kind == "report_temp":
            self._say(t, "ok " + self._temps_line().lstrip())
            return
        if kind in ("report_pos", "home"):      # G28.cpp ends with report_current_position
            self._say(t, self._position_line())
        elif kind == "firmware":
            self._say(t, *self._m115())
        elif kind == "eeprom":
            self._say(t, "echo:Settings Stored (616 bytes; crc 12345)")
        elif kind == "host_prompt" and not self.v.on("EMERGENCY_PARSER"):
            words = _words(q.text)      # M876.cpp: S<n> answers the prompt
            if "S" in words:
                self.truth.prompt_responses.append((t, int(words["S"])))
        elif kind == "home_offset_here":
            self._say(t, *self._m428())
        elif kind == "restart":
            # M999.cpp: marlin_state = MF_RUNNING; S1 returns, else queue.cpp
            # flush_and_request_resend: Resend: last_N + 1 and a plain ok (STR_OK), then the
            # command's own ok below
            if not boolval(st_words(_after_command(q.text)), "S", False):
                self._say(t, f"Resend: {self.last_n + 1}", "ok")
        elif kind == "settings":
            self._say(t, *self.settings.run(_code(q.text), _after_command(q.text),
                                            _after_number(q.text), t, self.eeprom,
                                            self._position_line))
        elif not kind:
            self._unknown(q, t)
        self._ok(q, t)

    def _m428(self) -> list[str]:
        """geometry/M206_M428.cpp GcodeSuite::M428: homing_needed_error first (motion.cpp:
        ``echo:Home XYZ First``, MSG_HOME_FIRST "Home %s%s%s First"); then each axis's
        offset is base_home_pos (0: every axis homes to its minimum) - current_position, and
        one farther than 20 mm is ``Error:Too far from reference point`` (nothing set);
        else every offset is set (set_home_offset) and the position reported."""
        if not self.homed:
            return ["echo:Home XYZ First"]
        diff = [0.0 - x for x in self.position[:3]]
        if any(not -20.0 <= d <= 20.0 for d in diff):
            return ["Error:Too far from reference point"]
        self.settings.home_offset[:] = diff
        return [self._position_line()]

    def _homing_time(self) -> float:
        """G28.cpp / motion.cpp homeaxis per axis: to the switch at HOMING_FEEDRATE, back off
        HOMING_BUMP_MM and approach again at the feedrate / HOMING_BUMP_DIVISOR. Before the
        first homing the firmware does not know where the axes are: that homing takes
        ``first_home_ms`` (the variant's: the native simulator starts its axes at fixed
        pseudo-random places, so 2.1.2.4's first G28 took 16.25 s in every recording)."""
        if not self.homed and self.v.first_home_ms:
            return self.v.first_home_ms / 1000.0
        feed = (HOMING, HOMING, 4.0)    # Configuration.h HOMING_FEEDRATE_MM_M {50*60, 50*60, 4*60}
        total = 0.0
        for i in range(3):
            bump, div = HOMING_BUMP[i]
            total += abs(self.position[i]) / feed[i] + bump / feed[i] + bump * div / feed[i]
        return total

    def _unknown(self, q: Queued, t: float) -> None:
        self._say(t, f'echo:Unknown command: "{_after_number(q.text)}"')

    def _ok(self, q: Queued, t: float) -> None:
        """queue.cpp RingBuffer::ok_to_send (ADVANCED_OK: the line's N, planner and queue free)."""
        if not self.v.on("ADVANCED_OK"):
            self._say(t, "ok")
            return
        head = ""
        if q.text.startswith("N"):
            m = re.match(r"N(-?\d*)", q.text)
            head = f" N{m.group(1) if m else ''}"
        free_planner = self.v.planner_blocks - len(self.planner)
        free_queue = self.v.bufsize - len(self.queue) - 1
        self._say(t, f"ok{head} P{free_planner} B{free_queue}")

    # -- motion ------------------------------------------------------------------------------
    def _settle(self, t: float) -> None:
        while self.planner and self.planner[0][0] <= t:
            self.planner_begin, target = self.planner.popleft()
            self.stepped = list(target)

    def _move(self, t: float, words: dict[str, float]) -> float:
        if "F" in words and words["F"] > 0:
            self.feed = words["F"] / 60.0
        target = list(self.position)
        for i, a in enumerate("XYZE"):
            if a in words:
                rel = self.e_relative if a == "E" else self.relative
                # a logical coordinate: the M206 offset off (motion.h NATIVE_TO_LOGICAL)
                off = self.settings.home_offset[i] if i < 3 else 0.0
                target[i] = (target[i] if rel else -off) + words[a]
        delta = [b - a for a, b in zip(self.position, target, strict=True)]
        if delta[3] and self.settings.too_cold(self.temp(0, t)):   # M302 sets the limit
            # planner.cpp _populate_block (PREVENT_COLD_EXTRUSION): E is taken as reached,
            # nothing extruded
            self._say(t, "echo: cold extrusion prevented")
            delta[3] = 0.0
        dist = math.sqrt(sum(d * d for d in delta[:3])) or abs(delta[3])
        if dist < 1e-9:
            self.position = target
            return t
        speed = self.feed * self.settings.feed_percent / 100.0     # M220
        for i in range(4):
            if delta[i]:
                speed = min(speed, self.settings.max_feed[i] * dist / abs(delta[i]))
        accel = min([ACCEL] + [MAX_ACCEL[i] * dist / abs(delta[i]) for i in range(4) if delta[i]])
        ramp = speed * speed / accel
        duration = dist / speed + speed / accel if dist > ramp else 2 * math.sqrt(dist / accel)
        duration *= self.v.motion_time_pct / 100.0     # the machine's own pace (the variant's)
        start = t
        if len(self.planner) >= self.v.planner_blocks:      # wait for a free block
            start = self.planner[0][0]
            self._settle(start)
        if self.planner:
            begin = max(start, self.planner[-1][0])
        else:
            begin = self.planner_begin = start + FIRST_MOVE_DELAY
        self.planner.append((begin + duration, target))
        self.position = target
        return start

    def _position_line(self) -> str:
        """motion.cpp report_current_position_projected (M114 without D): current_position
        (logical: the M206 offset added), then ``Count`` from planner.position, the steps the
        planner ends at (right after ``G1 X10`` is queued: Count X:800, as recorded), not
        where the steppers are."""
        steps, off = self.settings.steps, self.settings.home_offset
        p = [x + (off[i] if i < 3 else 0.0) for i, x in enumerate(self.position)]  # logical
        counts = [round(self.position[i] * steps[i]) for i in range(3)]
        return (f"X:{p[0]:.2f} Y:{p[1]:.2f} Z:{p[2]:.2f} E:{p[3]:.2f} "
                f"Count X:{counts[0]} Y:{counts[1]} Z:{counts[2]}")

    # -- heaters -----------------------------------------------------------------------------
    def temp(self, h: int, t: float) -> float:
        t0_temp, target, t0 = self.heat[h]
        if target > t0_temp:
            return min(target, t0_temp + HEAT_RATE[h] * (t - t0))
        return max(target, AMBIENT, t0_temp - COOL_RATE[h] * (t - t0))

    def _set_target(self, h: int, target: float, t: float) -> None:
        self.heat[h] = (self.temp(h, t), max(0.0, target), t)

    def _plan_wait(self, h: int, t: float) -> HeatWait:
        """When wait_for_hotend / wait_for_bed started at ``t`` ends on this heater model:
        the residency timer starts when |target - temp| < TEMP_WINDOW (a third of the
        residency later when already so on the first pass), the wait ends a residency after;
        a cooling wait also ends when the temperature fell less than the minimum slope in a
        slope period (a target below what the heater can cool to)."""
        v = self.v
        residency = float(v.temp_residency if h == 0 else v.temp_bed_residency)
        win = float(v.temp_window)
        temp, target = self.temp(h, t), self.heat[h][1]
        if abs(target - temp) < win:
            return HeatWait(h, t, t, t + residency / 3, residency, t + residency * 4 / 3)
        if target > temp:
            at = t + (target - win - temp) / HEAT_RATE[h]
        elif max(target, AMBIENT) < target + win:
            at = t + (temp - target - win) / COOL_RATE[h]
        else:
            at = math.inf
        end = at + residency
        if target < temp:
            slope, period = COOLING_SLOPE[h]
            k = 1
            while t + k * period < end:
                tk = t + k * period
                if self.temp(h, tk - period) - self.temp(h, tk) < slope:
                    end = tk
                    break
                k += 1
        return HeatWait(h, t, at, at, residency, end)

    def _temps_line(self) -> str:
        t = self.now
        (_, th, _), (_, tb, _) = self.heat
        win = float(self.v.temp_window)
        hp = 127 if th > self.temp(0, t) + win else 0
        bp = 127 if tb > self.temp(1, t) + win else 0
        return (f" T:{self.temp(0, t):.2f} /{th:.2f} B:{self.temp(1, t):.2f} /{tb:.2f} "
                f"@:{hp} B@:{bp}")

    def _m115(self) -> list[str]:
        v = self.v
        lines = [f"FIRMWARE_NAME:Marlin {v.firmware} (conform emulator) SOURCE_CODE_URL:"
                 f"{v.source_url} PROTOCOL_VERSION:{v.protocol_version} MACHINE_TYPE:"
                 f"{v.machine_name} EXTRUDER_COUNT:{v.extruders} UUID:{v.uuid}"]
        if v.on("EXTENDED_CAPABILITIES_REPORT"):
            lines += [f"Cap:{c.name}:{c.value(v)}" for c in self.spec.caps]
        return lines


def _strtol(b: bytes) -> int:
    m = re.match(rb"\s*([-+]?\d+)", b)
    return int(m.group(1)) if m else 0


def _after_number(text: str) -> str:
    """parser.cpp parse: the command after N and its spaces, the checksum and the spaces
    before it cut off (what unknown_command_warning echoes)."""
    s = text.lstrip(" ")
    m = re.match(r"N[-\d]\d*\s*", s)
    if m:
        s = s[m.end():]
    star = s.find("*", 1)
    return s[:star].rstrip(" ") if star >= 0 else s


def _code(text: str) -> str:
    """The command letter and number; parser.cpp takes the letter as written: ``m105`` is
    not M105 but an unknown command (as recorded)."""
    m = re.match(r"\s*([GMT])\s*(\d+)", _after_number(text))
    return f"{m.group(1).upper()}{int(m.group(2))}" if m else ""


def _after_command(text: str) -> str:
    s = _after_number(text)
    m = re.match(r"\s*[GMTgmt]\s*\d+", s)
    return s[m.end():] if m else s


def _words(text: str) -> dict[str, float]:
    out: dict[str, float] = {}
    for letter, value in _WORD.findall(_after_command(text)):
        out.setdefault(letter.upper(), float(value))
    return out
