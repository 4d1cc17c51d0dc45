"""Marlin checks of the serial reader (queue.cpp ``get_serial_commands`` and
``process_stream_char``, feature/e_parser.h) from states where a wrong reader shows: a queue
that is full while a command blocks, a write longer than the receive ring, a backslash-escaped
';', a numbered M110 followed at once by the next line, an M-code with a space inside it, and
the bed's cooling wait that can never reach its target.

Each check compares what the host sees (which answers, in which order, when) with what the
cited source does; none moves an axis or writes the EEPROM, and the bed check heats only with
the heaters' opt-in.
"""

from __future__ import annotations

from conform.families.marlin.conformance.check import MarlinCheck, Outcome
from conform.families.marlin.conformance.check import ok_kind as _ok_kind
from conform.families.marlin.conformance.fromstate import r_below_reach
from conform.families.marlin.conformance.session import Session
from conform.families.marlin.protocol.codec import checksum
from conform.families.marlin.spec import MarlinSpec

Q = "queue.cpp"
DWELL = 1.5     # s of the blocking G4 (shorter than the 2 s keepalive: no busy: line between)


def _oks(s: Session, lines: list[str]) -> list[int]:
    return [i for i, x in enumerate(lines) if _ok_kind(s, x)]


def queue_full_while_busy(s: Session) -> Outcome:
    """G4 blocks with three good lines queued behind it: the queue (BUFSIZE 4, the running
    command keeps its slot until it ends: GCodeQueue::advance calls advance_pos after
    process_next_command) is full, so get_serial_commands returns before it reads the
    damaged fifth line (``if (ring_buffer.full()) return``). Its Error comes only after the
    dwell's ok, then the three queued lines run."""
    behind = s.v.bufsize - 1
    n_bad = behind + 2
    data = s.numbered(f"G4 P{round(DWELL * 1000)}") + b"".join(
        s.numbered("G90") for _ in range(behind))
    bad = f"N{n_bad} G90".encode()
    data += bad + b"*%d\n" % (checksum(bad) ^ 1)
    got = s.talk(data, answers=behind + 2, timeout=DWELL + 3.0, linger=0.3)
    want_err = [f"Error:checksum mismatch, Last Line: {n_bad - 1}", f"Resend: {n_bad}"]
    err = next((i for i, x in enumerate(got.lines) if x.startswith("Error:")), None)
    oks = _oks(s, got.lines)
    problems = []
    if err is None or got.lines[err:err + 2] != want_err:
        problems.append("no " + " | ".join(want_err))
    else:
        if not oks or oks[0] > err:
            problems.append("the Error before the dwell's ok")
        if got.times[err] - got.t0 < DWELL - 0.3:
            problems.append(f"the Error {got.times[err] - got.t0:.2f} s after the write "
                            f"(during the {DWELL:g} s dwell)")
    if len(oks) != behind + 2:
        problems.append(f"{len(oks)} ok")
    return not problems, f"the dwell's ok after {DWELL:g} s, then " + " | ".join(want_err) + \
        f" | ok, then {behind} ok for the queued lines", \
        "; ".join(problems) + f" ({got.text()[:160]})" if problems else got.text()[:160]


def burst_over_ring(s: Session) -> Outcome:
    """One write of more bytes than the receive ring holds: the reader takes the rest as the
    ring empties (HAL/LINUX read_serial_thread moves only what fits, the rest waits in the
    port), so every line is answered. A ';' comment is dropped by process_stream_char, so the
    long lines do not overflow MAX_CMD_SIZE."""
    lines = 6
    pad = max(8, (s.v.rx_buffer * 2) // lines)
    one = b"G90 ;" + b"x" * pad + b"\n"
    got = s.talk(one * lines, answers=lines, timeout=3.0, linger=0.3)
    n = len(_oks(s, got.lines))
    return n == lines and len(got.lines) == lines, \
        f"{lines} ok for {lines} lines in one write of {len(one) * lines} bytes " \
        f"(receive ring {s.v.rx_buffer})", f"{n} ok: {got.text()[:120]}"


def escaped_semicolon(s: Session) -> Outcome:
    """process_stream_char: a backslash is dropped and the next character kept as it is
    (PS_ESC), so an escaped ';' starts no comment and the checksum after it stays; the
    checksum is over the line as stored (without the backslashes). Two escapes in one line:
    the state returns to normal after each."""
    stored = "M117 a;b;c"
    cs = checksum(f"N1 {stored}".encode())
    got = s.talk(s.numbered("M117 a\\;b\\;c", 1, cs=cs))
    nxt = s.talk(s.numbered("G90", 2))
    ok = (len(got.lines) == 1 and _ok_kind(s, got.lines[0]) and len(nxt.lines) == 1
          and _ok_kind(s, nxt.lines[0]))
    return ok, "ok (the line taken, its checksum over N1 M117 a;b;c); N2: ok", \
        f"{got.text()}; {nxt.text()}"


def m110_then_next(s: Session) -> Outcome:
    """get_serial_commands takes the number of a numbered M110 from its last N
    (``strchr(command + 4, 'N')``) as the line is read, before M110 runs: N7 M110 N20 and
    N21 in one write are both taken, no Line Number error."""
    got = s.talk(s.numbered("M110 N20", 7) + s.numbered("G90", 21), answers=2, linger=0.3)
    bad = [x for x in got.lines if x.startswith(("Error:", "Resend:"))]
    return len(_oks(s, got.lines)) == 2 and not bad and len(got.lines) == 2, \
        "ok | ok (N21 follows N7 M110 N20 in the same write)", got.text()


def spaced_code(s: Session) -> Outcome:
    """``M11 2`` is not M112: the emergency parser (e_parser.h EmergencyParser::update)
    allows spaces only between N/M and the first digit (EP_M ' ': stay; EP_M11 anything but
    '2': EP_IGNORE), and without it the critical commands look at command[1..3] ('1', '1',
    ' '). The line is an unknown command and the unit answers on."""
    got = s.talk(b"M11 2\n", linger=0.3)
    after = s.talk(b"M105\n")
    want = 'echo:Unknown command: "M11 2"'
    ok = (got.lines[:1] == [want] and len(got.lines) == 2 and _ok_kind(s, got.lines[1])
          and len(after.lines) == 1 and _ok_kind(s, after.lines[0]))
    return ok, f"{want} | ok; M105: ok T:..", f"{got.text()}; {after.text()}"


def bed_r_slope(s: Session) -> Outcome:
    """M190 R below what the bed can reach: wait_for_bed's wants_to_cool check gives up
    after MIN_COOLING_SLOPE_TIME_BED (60 s) as wait_for_hotend's does."""
    return r_below_reach(s, "M190")


def generate(spec: MarlinSpec, vid: str, profile: str = "quick") -> list[MarlinCheck]:
    v = spec.variant(vid)
    c = {m.kind: m.cite for m in spec.messages.values()}
    cmd = {k: x.cite for k, x in spec.commands.items()}
    ep = "e_parser.h" if v.on("EMERGENCY_PARSER") else Q
    out = [
        MarlinCheck(f"{vid}/{Q}/buffer/queue-full-while-busy", v.cite["bufsize"] + "; queue.cpp "
                    "get_serial_commands (if (ring_buffer.full()) return), GCodeQueue::advance "
                    "(advance_pos after the command ran); " + c["err_checksum"],
                    "a damaged line behind a full queue is read only when the blocking command "
                    "ends", queue_full_while_busy),
        MarlinCheck(f"{vid}/{Q}/buffer/burst-over-ring", v.cite["rx_buffer"] + "; HAL/LINUX/main.cpp "
                    "read_serial_thread (only what fits is moved into the ring)", "one write longer than the receive "
                    "ring: every line answered", burst_over_ring),
        MarlinCheck(f"{vid}/{Q}/checksum/escaped-semicolon", "queue.cpp process_stream_char "
                    "(PS_ESC: '\\\\' dropped, the next character kept; ';' PS_EOL); " +
                    c["err_no_checksum"], "N1 M117 a\\;b\\;c: the escaped ';' keep the "
                    "checksum", escaped_semicolon),
        MarlinCheck(f"{vid}/{Q}/line/m110-then-next", cmd["M110"], "N7 M110 N20 and N21 in "
                    "one write: both taken", m110_then_next),
        MarlinCheck(f"{vid}/{ep}/halt/spaced-code-not-m112", "feature/e_parser.h "
                    "EmergencyParser::update (EP_M: ' ' stays; EP_M11: only '2' goes on); "
                    "queue.cpp get_serial_commands (critical commands: command[1..3]); " +
                    c["unknown"], "M11 2 is an unknown command, not M112", spaced_code),
    ]
    # the slope period is a minute of waiting: the full profile only
    slope = MarlinCheck(f"{vid}/temperature.cpp/heat/m190-r-slope", f"{cmd['M190']}; "
                        "temperature.cpp wait_for_bed (wants_to_cool: break when old_temp - "
                        "temp < MIN_COOLING_SLOPE_DEG_BED after MIN_COOLING_SLOPE_TIME_BED "
                        "60 s)", "M190 R below what the bed can reach: ok after the 60 s "
                        "slope period", bed_r_slope, heat=True)
    return out + ([slope] if profile == "full" else [])
