"""Marlin conformance checks, graded per clause in the engine's runner.

A check id reads ``<variant>/<source file>/<group>/<name>``, e.g.
``marlin-2.1/queue.cpp/checksum/comment-before-star``; its clause is the function of Marlin's
source (specs/marlin) whose behaviour it holds the unit to. Groups: ``line`` (numbers, M110,
repeats), ``checksum``, ``reply`` (ok, unknown command), ``report`` (M105, M114, M115, M155),
``keepalive``, ``buffer`` (MAX_CMD_SIZE, the receive buffer emptied on an error, ADVANCED_OK),
``halt`` (M112 and the emergency parser), ``reset``, ``motion``.

On a real unit: checks that move need ``--allow-motion``, checks that heat need
``CONFORM_MARLIN_ALLOW_HEATERS=1``, and M112 (the unit stays dead until reset) needs
``--allow-motion`` too; otherwise they are SKIPPED. Ctrl-C, SIGTERM and a harness error halt the
unit: M108 (break a heating wait), M410 (stop the steppers), heaters off, until an ok.
"""

from __future__ import annotations

import fnmatch
import os
import time
from collections.abc import Callable, Sequence
from typing import Any

from conform.conformance.results import INFO, CheckResult, Grade, TargetRun
from conform.conformance.runner import RunAborted, Runner, RunOptions
from conform.conformance.target import HarnessError
from conform.families.marlin.conformance.check import MarlinCheck, Outcome, ok_kind
from conform.families.marlin.conformance.heaters import (
    _countdown,
    _residency_problems,
    _wait_for_temperature,
)
from conform.families.marlin.conformance.session import Session, Talk
from conform.families.marlin.spec import MarlinSpec, load_marlin

HEATERS_ENV = "CONFORM_MARLIN_ALLOW_HEATERS"
Q = "queue.cpp"
_ok_kind = ok_kind


def _error_then_resend(s: Session, got: Talk, error: str, last: int) -> Outcome:
    want = [f"Error:{error}, Last Line: {last}", f"Resend: {last + 1}", "ok"]
    return got.lines[:3] == want, " | ".join(want), got.text()


def _expect_ok(s: Session, got: Talk, n: int | None = None) -> bool:
    """One ok for one line (ADVANCED_OK: ``ok N<n> P.. B..``)."""
    if len(got.lines) != 1 or not _ok_kind(s, got.lines[0]):
        return False
    if s.v.on("ADVANCED_OK"):
        return got.lines[0].startswith(f"ok N{n} " if n is not None else "ok P")
    return got.lines[0] == "ok"


def _ok_text(s: Session, n: int | None = None) -> str:
    if not s.v.on("ADVANCED_OK"):
        return "ok"
    return f"ok N{n} P<n> B<n>" if n is not None else "ok P<n> B<n>"


def numbered_ok(s: Session) -> Outcome:
    got = s.talk(s.numbered("G90"))
    return _expect_ok(s, got, 1), _ok_text(s, 1), got.text()


def _damaged(s: Session, command: str, n: int) -> bytes:
    """``N<n> <command>`` with a checksum one off the right one."""
    from conform.families.marlin.protocol.codec import checksum

    return s.numbered(command, n, cs=checksum(f"N{n} {command}".encode()) ^ 1)


def checksum_mismatch(s: Session) -> Outcome:
    return _error_then_resend(s, s.talk(_damaged(s, "G90", 1)), "checksum mismatch", 0)


def no_checksum(s: Session) -> Outcome:
    return _error_then_resend(s, s.talk(b"N1 G90\n"), "No Checksum with line number", 0)


def comment_before_star(s: Session) -> Outcome:
    """The checksum is right for the whole line, but ';' cut it off with the comment."""
    body = b"N1 G90 ; absolute"
    from conform.families.marlin.protocol.codec import checksum

    got = s.talk(body + b"*%d\n" % checksum(body))
    return _error_then_resend(s, got, "No Checksum with line number", 0)


def checksum_without_number(s: Session) -> Outcome:
    got = s.talk(b"M114*99\n", answers=1)
    pos = [x for x in got.lines if s.spec.classify(x)[0] == "position"]
    ok = len(pos) == 1 and s.oks(got.lines) == 1
    return ok, "executed: the position, then ok (no line number: nothing checked)", got.text()


def skip_ahead(s: Session) -> Outcome:
    s.talk(s.numbered("G90"))
    return _error_then_resend(s, s.talk(s.numbered("G90", 3)), "Line Number is not Last Line "
                              "Number+1", 1)


def repeat_silent(s: Session) -> Outcome:
    a = s.talk(s.numbered("G90"))
    b = s.talk(s.numbered("G90"))
    again = s.talk(s.numbered("G90", 2), timeout=0.6)
    older = s.talk(s.numbered("G90", 1), timeout=0.6)
    nxt = s.talk(s.numbered("G90", 3))
    ok = (_expect_ok(s, a, 1) and _expect_ok(s, b, 2) and not again.lines and not older.lines
          and _expect_ok(s, nxt, 3))
    return ok, f"N2 again: silence; N1 again: silence; N3: {_ok_text(s, 3)}", \
        f"{again.text()}; {older.text()}; {nxt.text()}"


def older_is_error(s: Session) -> Outcome:
    for _ in range(3):
        s.talk(s.numbered("G90"))
    return _error_then_resend(s, s.talk(s.numbered("G90", 1)), "Line Number is not Last Line "
                              "Number+1", 3)


def m110_plain(s: Session) -> Outcome:
    a = s.talk(b"M110 N10\n")
    b = s.talk(s.numbered("G90", 11))
    return s.oks(a.lines) == 1 and _expect_ok(s, b, 11), f"ok; N11: {_ok_text(s, 11)}", \
        f"{a.text()}; {b.text()}"


def m110_numbered(s: Session) -> Outcome:
    """N1 M110 N20: the number taken is the last N on the line, with no sequence check."""
    a = s.talk(s.numbered("M110 N20", 7))
    b = s.talk(s.numbered("G90", 21))
    return s.oks(a.lines) == 1 and _expect_ok(s, b, 21), f"ok; N21: {_ok_text(s, 21)}", \
        f"{a.text()}; {b.text()}"


def unknown_command(s: Session) -> Outcome:
    got = s.talk(s.numbered("M9999 P1"))
    want = 'echo:Unknown command: "M9999 P1"'
    return (got.lines[:1] == [want] and len(got.lines) == 2 and _ok_kind(s, got.lines[1]),
            f"{want} | {_ok_text(s, 1)}", got.text())


def crlf_one_answer(s: Session) -> Outcome:
    got = s.talk(b"G90\r\n", answers=1, linger=0.3)
    return _expect_ok(s, got), _ok_text(s) + " (the empty line between CR and LF is ignored)", \
        got.text()


def m105(s: Session) -> Outcome:
    got = s.talk(b"M105\n")
    line = got.lines[0] if len(got.lines) == 1 else ""
    hit = s.spec.messages["ok_temp"].pattern.match(line)
    temps = hit and s.spec.messages["temps"].pattern.match(hit.group("temps"))
    ok = bool(temps and temps.group("b") is not None)
    return ok, "ok T:<t> /<target> B:<t> /<target> @:<p> B@:<p> (one line)", got.text()


def m114(s: Session) -> Outcome:
    got = s.talk(b"M114\n")
    kinds = got.kinds(s.spec)
    return kinds[:1] == ["position"] and len(kinds) == 2 and kinds[1].startswith("ok"), \
        "X:.. Y:.. Z:.. E:.. Count X:.. Y:.. Z:.. | ok", got.text()


def m115(s: Session) -> Outcome:
    got = s.talk(b"M115\n")
    v, spec = s.v, s.spec
    first = spec.messages["firmware"].pattern.match(got.lines[0]) if got.lines else None
    caps = [x for x in got.lines if spec.classify(x)[0] == "cap"]
    want_caps = [f"Cap:{c.name}:{c.value(v)}" for c in spec.caps] if v.on(
        "EXTENDED_CAPABILITIES_REPORT") else []
    problems = []
    if not first:
        problems.append("no FIRMWARE_NAME line first")
    else:
        if not first.group("name").startswith(f"Marlin {v.firmware}"):
            problems.append(f"firmware {first.group('name')!r}")
        if first.group("proto") != v.protocol_version:
            problems.append(f"PROTOCOL_VERSION:{first.group('proto')}")
        if first.group("extruders") != str(v.extruders):
            problems.append(f"EXTRUDER_COUNT:{first.group('extruders')}")
    wrong = sorted(set(want_caps) ^ set(caps))
    if wrong:
        problems.append("capabilities differ: " + ", ".join(wrong[:8]))
    if not got.lines or not _ok_kind(s, got.lines[-1]):
        problems.append("no ok at the end")
    return not problems, f"FIRMWARE_NAME:Marlin {v.firmware} ... PROTOCOL_VERSION:" \
        f"{v.protocol_version} ..., {len(want_caps)} Cap: lines as configured, ok", \
        "; ".join(problems) or f"as expected ({len(caps)} Cap: lines)"


def m155(s: Session) -> Outcome:
    a = s.talk(b"M155 S1\n")
    reports = [x for x in s.wait(2.5).lines if s.spec.classify(x)[0] == "temps"]
    b = s.talk(b"M155 S0\n")
    quiet = [x for x in s.wait(1.5).lines if s.spec.classify(x)[0] == "temps"]
    ok = s.oks(a.lines) == 1 and len(reports) >= 2 and s.oks(b.lines) == 1 and not quiet
    return ok, "ok; a temperature report every second; ok; then none", \
        f"{a.text()}; {len(reports)} reports in 2.5 s; {b.text()}; {len(quiet)} after S0"


def keepalive(s: Session) -> Outcome:
    """G4 S5 blocks the handler for 5 s: busy: processing every DEFAULT_KEEPALIVE_INTERVAL,
    the first one interval after the dwell began (gcode.cpp host_keepalive): exactly
    5 // interval of them, each at its time (a unit with a 4 s keepalive says one, at 4 s)."""
    got = s.talk(b"G4 S5\n", timeout=8.0)
    times = [t - got.t0 for t, x in zip(got.times, got.lines, strict=True)
             if s.spec.classify(x)[0] == "busy"]
    k = s.v.keepalive
    want = int(5 // k) if k else 0
    late = [f"{t:.1f} s" for i, t in enumerate(times) if not k * (i + 1) - 0.5 <= t <= k * (i + 1)
            + 0.5]
    ok = (len(times) == want and want > 0 and not late and got.lines
          and _ok_kind(s, got.lines[-1]))
    return bool(ok), f"{want} x echo:busy: processing (at {k} s, {2 * k} s …), then ok", \
        f"{len(times)} busy lines at {', '.join(f'{t:.1f}' for t in times) or '-'} s; " \
        f"{got.text()[-60:]}"


def max_cmd_size(s: Session) -> Outcome:
    """A line longer than MAX_CMD_SIZE - 2 characters loses its tail, the checksum with it."""
    room = s.v.max_cmd_size - 2
    fit = s.numbered("M117 " + "A" * (room - len("N1 M117 ") - len("*000")))
    fit_text = fit.rstrip(b"\n")
    a = s.talk(fit)
    body = b"N2 M117 " + b"B" * room
    from conform.families.marlin.protocol.codec import checksum

    b = s.talk(body + b"*%d\n" % checksum(body))
    ok = _expect_ok(s, a, 1) and b.lines[:3] == ["Error:No Checksum with line number, Last "
                                                 "Line: 1", "Resend: 2", "ok"]
    return ok, f"{len(fit_text)} characters: ok; {len(body) + 4}: No Checksum, Resend: 2, ok", \
        f"{a.text()}; {b.text()}"


def error_empties_rx(s: Session) -> Outcome:
    """gcode_line_error reads the receive buffer empty: a good line behind a bad one in the
    same write is gone too (only the one Resend:)."""
    got = s.talk(_damaged(s, "G90", 1) + s.numbered("G90", 2), answers=1, linger=0.5)
    want = ["Error:checksum mismatch, Last Line: 0", "Resend: 1", "ok"]
    return got.lines == want, " | ".join(want) + " (N2 discarded with the buffer)", got.text()


def advanced_ok(s: Session) -> Outcome:
    got = s.talk(s.numbered("G90"))
    m = s.spec.messages["ok_adv"].pattern.match(got.lines[0]) if got.lines else None
    want = f"ok N1 P{s.v.planner_blocks} B{s.v.bufsize - 1}"
    return bool(m) and got.lines[0] == want, want, got.text()


KILLED = ["echo:M112 Shutdown", "Error:Printer halted. kill() called!"]


def m112_halt(s: Session) -> Outcome:
    """MarlinCore.cpp kill(M112_KILL_STR): the LCD message echoed, the halt, then nothing
    (recorded: halt.transcript)."""
    s.target.send(b"M112\n")
    a = s.wait(1.0)
    b = s.talk(b"M105\n", answers=1, timeout=1.5)
    return a.lines == KILLED and not b.lines, " | ".join(KILLED) + "; then silence", \
        f"{a.text()}; {b.text()}"


def m112_while_busy(s: Session) -> Outcome:
    """An unnumbered M112 during a dwell halts as soon as it is read, before the dwell's ok:
    with EMERGENCY_PARSER as its bytes arrive, without it because the idle loop reads lines
    while the dwell blocks and get_serial_commands acts on a critical command as it is read
    (recorded: blocking-reads.transcript)."""
    s.target.send(b"G4 S3\n")
    s.wait(0.3)
    s.target.send(b"M112\n")
    got = s.collect(until=lambda ls: any(s.spec.classify(x)[0] == "halted" for x in ls),
                    timeout=4.5, linger=0.0)
    halted = next((i for i, x in enumerate(got.lines) if s.spec.classify(x)[0] == "halted"), None)
    if halted is None:
        return False, "Error:Printer halted. kill() called!", got.text()
    return s.oks(got.lines[:halted]) == 0 and got.t - got.t0 < 1.0, \
        "halted within 1 s, before the dwell's ok", got.text()


def m112_numbered_while_busy(s: Session) -> Outcome:
    """A numbered M112 during a dwell: the emergency parser skips the N and acts as the bytes
    arrive; without it the line starts with N, is no critical command, and halts in its
    turn, right after the dwell's ok (recorded: blocking-reads.transcript, N14 M112)."""
    s.target.send(s.numbered("G4 S3"))
    s.wait(0.3)
    s.target.send(s.numbered("M112"))
    got = s.collect(until=lambda ls: any(s.spec.classify(x)[0] == "halted" for x in ls),
                    timeout=4.5, linger=0.0)
    halted = next((i for i, x in enumerate(got.lines) if s.spec.classify(x)[0] == "halted"), None)
    if halted is None:
        return False, "Error:Printer halted. kill() called!", got.text()
    before = s.oks(got.lines[:halted])
    if s.v.on("EMERGENCY_PARSER"):
        return before == 0, "halted at once, before the dwell's ok", got.text()
    return before == 1 and got.lines[halted - 1:halted + 1] == KILLED, \
        "the dwell's ok, then " + " | ".join(KILLED), got.text()


def checked_while_busy(s: Session) -> Outcome:
    """MarlinCore.cpp idle() -> manage_inactivity() -> queue.get_available_commands(): a
    damaged line sent during a dwell is answered during it (Error, Resend:, ok within 1 s),
    a good line waits in the queue and runs after the dwell's ok (recorded:
    blocking-reads.transcript, answered 5-10 ms after it was written)."""
    s.target.send(s.numbered("G4 S3"))
    s.wait(0.3)
    err = s.talk(_damaged(s, "G90", 2), timeout=1.0)
    good = s.talk(s.numbered("M105", 2), answers=2, timeout=4.0)
    want = ["Error:checksum mismatch, Last Line: 1", "Resend: 2", "ok"]
    in_time = err.t - err.t0 < 1.0
    order = [k for k in good.kinds(s.spec) if k.startswith("ok")]
    ok = err.lines[:3] == want and in_time and order[:2] in (["ok", "ok_temp"],
                                                             ["ok_adv", "ok_temp"])
    return ok, " | ".join(want) + " within 1 s (during the dwell); then the dwell's ok and " \
        "N2's ok T:", f"{err.text()} ({err.t - err.t0:.1f} s); {good.text()}"


def m108_ends_m109(s: Session) -> Outcome:
    """Without EMERGENCY_PARSER an unnumbered M108 still ends M109's wait at once: the idle
    loop reads it during the wait and get_serial_commands clears wait_for_heatup as it is
    read; M109's ok, then M108's own ok in its turn."""
    got, why = _wait_for_temperature(s, "M109", m108_after=1.5)
    want = "M109's ok within 1 s of M108, then M108's ok"
    if got is None:
        return False, want, why
    _, ok_t = _countdown(s, got)
    sent = got.t0 + 1.5
    ok = ok_t is not None and ok_t - sent < 1.0 and s.oks(got.lines) == 2
    return ok, want, f"M109's ok {ok_t - sent:.1f} s after M108; {s.oks(got.lines)} ok" \
        if ok_t is not None else got.text()[-80:]


def m108_breaks_m109(s: Session) -> Outcome:
    """EMERGENCY_PARSER: a numbered M108 ends a heating wait as it arrives (without the
    parser a numbered M108 waits its turn behind M109); the heater is switched off after."""
    s.target.send(s.numbered("M109 S200"))
    s.wait(0.5)
    s.target.send(s.numbered("M108"))
    got = s.collect(until=lambda ls: s.oks(ls) >= 2, timeout=2.0, linger=0.1)
    s.talk(b"M104 S0\n")
    return s.oks(got.lines) == 2, "M109's ok and M108's ok within 2 s", got.text()



def waits_residency(code: str) -> Callable[[Session], Outcome]:
    def run(s: Session) -> Outcome:
        """M109 / M190 S: a temperature report with W: every second, ok only when the
        temperature stayed TEMP_(BED_)RESIDENCY_TIME s within the window."""
        got, why = _wait_for_temperature(s, code)
        residency = s.v.temp_residency if code == "M109" else s.v.temp_bed_residency
        want = (f" T:.. /.. B:.. /.. @:.. B@:.. W:? every second, then W:{residency - 1} (up to "
                f"{-(-residency * 4 // 3)}) counting down to W:0, then ok")
        if got is None:
            return False, want, why
        reports, ok_t = _countdown(s, got)
        problems = _residency_problems(s, code, reports, ok_t)
        return not problems, want, "; ".join(problems) or \
            f"{len(reports)} reports, W:{reports[0][1]}..W:{reports[-1][1]}, then ok"
    run.__name__ = f"{code.lower()}_waits_residency"
    return run


def busy_while_heating(s: Session) -> Outcome:
    """BUSY_WHILE_HEATING (on by default): busy: processing goes on during M109's wait; off,
    wait_for_hotend sets KEEPALIVE_STATE(NOT_BUSY) and the wait says nothing but reports."""
    got, why = _wait_for_temperature(s, "M109")
    on = s.v.on("BUSY_WHILE_HEATING") and s.v.on("HOST_KEEPALIVE_FEATURE") and s.v.keepalive
    want = (f"echo:busy: processing every {s.v.keepalive} s while waiting" if on else
            "no busy: processing while waiting")
    if got is None:
        return False, want, why
    reports, ok_t = _countdown(s, got)
    said = [x for t, x in zip(got.times, got.lines, strict=True)
            if s.spec.classify(x)[0] == "busy" and (ok_t is None or t <= ok_t)]
    busy = len(said)
    # the wait's busy state is IN_HANDLER (gcode.cpp host_keepalive: processing); paused
    # for user is M0/M1's (PAUSED_FOR_USER), never a heater wait's
    other = sorted(set(said) - {"echo:busy: processing"})
    span = (ok_t or got.t) - got.t0
    expect = int(span // s.v.keepalive) if on else 0
    ok = (busy >= max(1, expect - 1) if on else busy == 0) and not other
    return ok, want, f"{busy} busy lines in a {span:.1f} s wait" + \
        (f" ({', '.join(other)})" if other else "")


def m0_user_wait(s: Session) -> Outcome:
    """M0 exists only with HAS_RESUME_CONTINUE (no display: EMERGENCY_PARSER). With it, M0 S3
    waits, ``busy: paused for user`` while it does, and M108 (acted on by the emergency
    parser as it arrives) ends the wait at once; without it M0 is an unknown command."""
    t0 = s.target.now()
    if not s.v.on("EMERGENCY_PARSER"):
        got = s.talk(s.numbered("M0 S3"))
        want = 'echo:Unknown command: "M0 S3"'
        return (got.lines[:1] == [want] and len(got.lines) == 2 and _ok_kind(s, got.lines[1]),
                f"{want} | {_ok_text(s, 1)}", got.text())
    s.target.send(s.numbered("M0 S3"))
    first = s.collect(timeout=2.5, linger=2.5)
    s.target.send(b"M108\n")
    rest = s.collect(until=lambda ls: s.oks(ls) >= 2, timeout=3.0)
    took = rest.t - t0
    busy = [x for x in first.lines if x == "echo:busy: paused for user"]
    ok = s.oks(first.lines) == 0 and len(busy) == 1 and s.oks(rest.lines) == 2 and took < 2.9
    return ok, "no ok for 2.5 s, one echo:busy: paused for user at 2 s, then M108: two oks " \
        "before the 3 s are up", f"{first.text()} ; M108 ; {rest.text()} ({took:.1f} s)"


def m876(s: Session) -> Outcome:
    """M876 (host prompt response) exists only with HOST_PROMPT_SUPPORT; without it the line
    is an unknown command, also where EMERGENCY_PARSER is on (its M876 states are compiled
    only with HOST_PROMPT_SUPPORT)."""
    got = s.talk(s.numbered("M876 S1"))
    if s.v.on("HOST_PROMPT_SUPPORT"):
        return _expect_ok(s, got, 1), f"{_ok_text(s, 1)} (the prompt answered, no output)", \
            got.text()
    want = 'echo:Unknown command: "M876 S1"'
    return (got.lines[:1] == [want] and len(got.lines) == 2 and _ok_kind(s, got.lines[1]),
            f"{want} | {_ok_text(s, 1)}", got.text())


def reset_banner(s: Session) -> Outcome:
    s.talk(s.numbered("G90"))
    s.target.reset()
    got = s.collect(until=lambda ls: "start" in ls, timeout=2.0, linger=0.2)
    s.n = 0
    b = s.talk(s.numbered("G90"))
    first = ["x86_64 Initialized", "start"] if s.v.on("HAL_LINUX") else ["start"]
    ok = got.lines[:len(first)] == first and _expect_ok(s, b, 1)
    return ok, "start, echo: lines; then N1 accepted (line number back to 0)", \
        f"{got.text()[:60]}; {b.text()}"


def move_and_wait(s: Session) -> Outcome:
    s.talk(b"G28\n", timeout=30.0)
    s.talk(b"G1 X10 F3000\n")
    w = s.talk(b"M400\n", timeout=10.0)
    got = s.talk(b"M114\n")
    pos = next((x for x in got.lines if s.spec.classify(x)[0] == "position"), "")
    want = f"X:10.00 Y:0.00 Z:0.00 E:0.00 Count X:{round(10 * s.v.steps_per_mm[0])} Y:0 Z:0"
    return s.oks(w.lines) == 1 and pos == want, f"M400 ok after the move; {want}", pos or got.text()


def generate(spec: MarlinSpec, vid: str, profile: str = "quick") -> list[MarlinCheck]:
    v = spec.variant(vid)
    c = {m.kind: m.cite for m in spec.messages.values()}
    cmd = {k: x.cite for k, x in spec.commands.items()}
    out = [
        MarlinCheck(f"{vid}/{Q}/line/numbered-ok", c["ok"], "a numbered, checksummed line: ok",
                    numbered_ok),
        MarlinCheck(f"{vid}/{Q}/checksum/mismatch", c["err_checksum"],
                    "a wrong checksum: Error, Resend: N, ok", checksum_mismatch),
        MarlinCheck(f"{vid}/{Q}/checksum/missing", c["err_no_checksum"],
                    "N without *: No Checksum with line number", no_checksum),
        MarlinCheck(f"{vid}/{Q}/checksum/comment-before-star", c["err_no_checksum"] +
                    "; process_stream_char ';'", "a ';' comment before '*' drops the checksum",
                    comment_before_star),
        MarlinCheck(f"{vid}/{Q}/checksum/without-number", c["err_no_line"],
                    "a checksum without N is simply executed", checksum_without_number),
        MarlinCheck(f"{vid}/{Q}/line/skip-ahead", c["err_line_no"],
                    "a skipped number: Line Number error, Resend of the next", skip_ahead),
        MarlinCheck(f"{vid}/{Q}/line/repeat-silent", c["err_line_no"] + " (WITHIN last_N - 1, "
                    "last_N: continue)", "the last two numbers again: no answer at all",
                    repeat_silent),
        MarlinCheck(f"{vid}/{Q}/line/older-error", c["err_line_no"],
                    "a number older than the last two: Line Number error", older_is_error),
        MarlinCheck(f"{vid}/M110.cpp/line/m110-plain", cmd["M110"], "M110 N10 sets the number",
                    m110_plain),
        MarlinCheck(f"{vid}/M110.cpp/line/m110-numbered", cmd["M110"],
                    "N7 M110 N20: the last N counts, no sequence check", m110_numbered),
        MarlinCheck(f"{vid}/gcode.cpp/reply/unknown", c["unknown"],
                    "an unknown command is named, then ok", unknown_command),
        MarlinCheck(f"{vid}/{Q}/reply/crlf", "queue.cpp get_serial_commands (ISEOL: CR and LF; "
                    "process_line_done: an empty line is skipped)", "CR LF: one line, one ok",
                    crlf_one_answer),
        MarlinCheck(f"{vid}/M105.cpp/report/m105", c["ok_temp"], "M105: temperatures in the ok",
                    m105),
        MarlinCheck(f"{vid}/M114.cpp/report/m114", c["position"], "M114: position, then ok",
                    m114),
        MarlinCheck(f"{vid}/M115.cpp/report/m115", c["firmware"] + "; " + c["cap"],
                    "M115: firmware, protocol, capabilities as configured", m115),
        MarlinCheck(f"{vid}/gcode.cpp/keepalive/busy", c["busy"],
                    "a blocking command: busy: processing every interval", keepalive),
        MarlinCheck(f"{vid}/{Q}/buffer/max-cmd-size", v.cite["max_cmd_size"],
                    "a line past MAX_CMD_SIZE loses its checksum", max_cmd_size),
        MarlinCheck(f"{vid}/{Q}/buffer/error-empties-rx", "queue.cpp gcode_line_error (while "
                    "(read_serial(..) != -1))", "an error empties the receive buffer",
                    error_empties_rx, level=INFO),
        MarlinCheck(f"{vid}/MarlinCore.cpp/halt/m112", c["halted"] + "; MarlinCore.cpp kill() "
                    "(if (lcd_error) SERIAL_ECHO_START + the message: echo:M112 Shutdown)",
                    "M112: echo:M112 Shutdown, Error:Printer halted, then nothing answered",
                    m112_halt, motion=True, kills=True),
        MarlinCheck(f"{vid}/{'e_parser.h' if v.on('EMERGENCY_PARSER') else Q}/halt/m112-while-busy",
                    v.cite["options"] if v.on("EMERGENCY_PARSER") else
                    "queue.cpp get_serial_commands (critical commands: a line starting M112 "
                    "calls kill() as it is read); MarlinCore.cpp idle() -> manage_inactivity() "
                    "-> queue.get_available_commands() (read while a command blocks)",
                    "an unnumbered M112 during a dwell halts at once", m112_while_busy,
                    motion=True, kills=True),
        MarlinCheck(f"{vid}/{'e_parser.h' if v.on('EMERGENCY_PARSER') else Q}/halt/"
                    "m112-numbered-while-busy", v.cite["options"] if v.on("EMERGENCY_PARSER")
                    else "queue.cpp get_serial_commands (critical commands look at the line's "
                    "first letters: a numbered line starts with N and waits its turn)",
                    "a numbered M112 during a dwell: at once with the emergency parser, after "
                    "the dwell without", m112_numbered_while_busy, motion=True, kills=True),
        MarlinCheck(f"{vid}/MarlinCore.cpp/line/checked-while-busy", "MarlinCore.cpp idle() -> "
                    "manage_inactivity() -> queue.get_available_commands(); " +
                    c["err_checksum"], "a bad line during a dwell is answered during it, a "
                    "good one waits its turn", checked_while_busy),
        MarlinCheck(f"{vid}/MarlinCore.cpp/reset/banner", c["start"],
                    "a reset: start and the banner, line number 0", reset_banner,
                    emulator_only=True),
        MarlinCheck(f"{vid}/G0_G1.cpp/motion/move-m400-m114", cmd["M400"] + "; " + cmd["M114"],
                    "G1 X10, M400 waits, M114 shows it", move_and_wait, motion=True),
    ]
    temp = v.cite["temp_residency"]
    out += [
        MarlinCheck(f"{vid}/temperature.cpp/heat/m109-residency", cmd["M109"] + "; " + temp,
                    "M109 S: W: reports every second, ok after the residency",
                    waits_residency("M109"), heat=True),
        MarlinCheck(f"{vid}/temperature.cpp/heat/m190-residency", cmd["M190"] + "; " +
                    v.cite["temp_bed_residency"], "M190 S: W: reports every second, ok after "
                    "the residency", waits_residency("M190"), heat=True),
        MarlinCheck(f"{vid}/temperature.cpp/keepalive/busy-while-heating", v.cite["options"] +
                    "; " + c["busy"], "busy: processing during M109's wait as BUSY_WHILE_HEATING"
                    " says", busy_while_heating, heat=True),
        MarlinCheck(f"{vid}/{'e_parser.h' if v.on('EMERGENCY_PARSER') else 'gcode.cpp'}/reply/"
                    f"m876-{'prompt' if v.on('HOST_PROMPT_SUPPORT') else 'unknown'}",
                    cmd["M876"], "M876 S1 as HOST_PROMPT_SUPPORT says", m876),
    ]
    if not v.on("EMERGENCY_PARSER"):
        out.append(MarlinCheck(f"{vid}/{Q}/heat/m108-ends-m109", "queue.cpp "
                               "get_serial_commands (critical commands: a line starting M108 "
                               "clears wait_for_heatup as it is read; wait_for_hotend's idle() "
                               "reads it); " + cmd["M108"],
                               "an unnumbered M108 ends M109's wait without the emergency "
                               "parser", m108_ends_m109, heat=True))
    # M112 leaves a unit dead until it is reset: the halt checks come last (stable sort)
    if v.on("AUTO_REPORT_TEMPERATURES"):
        out.append(MarlinCheck(f"{vid}/M155.cpp/report/m155", cmd["M155"],
                               "M155 S1 reports every second, S0 stops", m155))
    if v.on("EMERGENCY_PARSER"):
        out.append(MarlinCheck(f"{vid}/e_parser.h/halt/m108-breaks-m109", v.cite["options"] +
                               "; " + cmd["M108"], "M108 ends M109's wait at once",
                               m108_breaks_m109, heat=True))
    out.append(MarlinCheck(f"{vid}/{'e_parser.h' if v.on('EMERGENCY_PARSER') else 'gcode.cpp'}"
                           f"/reply/m0-{'m108-ends' if v.on('EMERGENCY_PARSER') else 'unknown'}",
                           cmd["M0"], "M0 S3 as HAS_RESUME_CONTINUE says (M108 ends it)",
                           m0_user_wait))
    if v.on("ADVANCED_OK"):
        out.append(MarlinCheck(f"{vid}/{Q}/reply/advanced-ok", c["ok_adv"],
                               "ok N<n> P<planner free> B<queue free>", advanced_ok))
    from conform.families.marlin.conformance import depth, edges, fromstate, reader

    out += depth.generate(spec, vid, profile)
    out += fromstate.generate(spec, vid, profile)
    out += reader.generate(spec, vid, profile)
    out += edges.generate(spec, vid, profile)
    return sorted(out, key=lambda c: ("/halt/" in c.id, c.kills))


def select(checks: list[MarlinCheck], patterns: Sequence[str]) -> list[MarlinCheck]:
    if not patterns:
        return checks
    return [c for c in checks if any(fnmatch.fnmatchcase(c.id, p) for p in patterns)]


HALT = (b"M108\n", b"M410\n", b"M104 S0\n", b"M140 S0\n")
HALT_MARK = b"M9999 conform-halt"
"""Sent after the halt's own lines: no Marlin knows it, so its answer (gcode.cpp
unknown_command_warning names it) comes only after each halt line was run and answered (one
queue, in order). An ok of a line the host had in flight before the halt is then never
taken for one of the halt's."""


def halt(target: Any, attempts: int = 3) -> str:
    """Stop a Marlin unit: M108 ends a heating wait, M410 stops the steppers at once, the
    heaters are switched off (all unnumbered: they act as they are read, during a blocking
    command too); acknowledged when the answer to HALT_MARK, behind them, came."""
    notes = []
    mark = b'echo:Unknown command: "' + HALT_MARK + b'"'
    for _ in range(attempts):
        try:
            for line in HALT:
                target.send(line)
            target.send(HALT_MARK + b"\n")
            deadline = target.now() + 3.0
            buf = b""
            while target.now() < deadline and not _answered_after(buf, mark):
                buf += target.receive(deadline)
            if _answered_after(buf, mark):
                return "stopped: M108, M410 (quickstop), heaters off, each answered ok"
            oks = sum(1 for x in buf.split(b"\n") if x == b"ok" or x.startswith(b"ok "))
            notes.append(f"{oks} ok heard, the halt's lines not all answered")
        except Exception as exc:  # noqa: BLE001 - report, try again
            notes.append(f"not sent ({exc})")
    return "stop NOT acknowledged: " + "; ".join(notes)


def _answered_after(buf: bytes, mark: bytes) -> bool:
    """The mark's echo and the ok after it came."""
    at = buf.find(mark)
    return at >= 0 and b"\nok" in buf[at:]


class MarlinRunner(Runner):
    """Marlin's part of the engine's runner: a fresh state per check, grading by the check's
    own comparison, checks beyond what the run may do SKIPPED, and the halt."""

    def __init__(self, target: Any, vid: str, *, spec: MarlinSpec | None = None,
                 allow_motion: bool = False, allow_heaters: bool | None = None,
                 allow_eeprom: bool = False, options: RunOptions | None = None,
                 **_ignored: Any) -> None:
        super().__init__(target, vid, options)
        self.spec = spec or load_marlin()
        self.session = Session(target, self.spec, self.spec.variant(vid))
        self.motion_ok = allow_motion or target.emulated
        if allow_heaters is None:
            allow_heaters = os.environ.get(HEATERS_ENV, "") == "1"
        self.heat_ok = allow_heaters or target.emulated
        self.eeprom_ok = allow_eeprom or target.emulated
        self.killer: str | None = None      # the one check that may halt a real unit

    def run(self, checks: Sequence[Any], progress: Any = None) -> TargetRun:
        """A real unit is halted by M112 until it is reset (and the harness cannot reset a
        board): of the checks that halt it only the last one planned runs, once, after every
        other check; the others are SKIPPED and say which one ran."""
        may = [c for c in checks if getattr(c, "kills", False)
               and (self.motion_ok or not c.motion)]
        self.killer = may[-1].id if may else None
        return super().run(checks, progress)

    def run_check(self, check: MarlinCheck) -> CheckResult:
        base = dict(id=check.id, clause=check.clause, level=check.level, title=check.title,
                    variant=self.variant_id, target=self.target.name)
        if check.emulator_only and not self.target.emulated:
            return CheckResult(grade=Grade.NOT_APPLICABLE, detail="needs a reset the harness "
                               "can only give the emulator (DTR)", **base)
        if check.motion and not self.motion_ok:
            return CheckResult(grade=Grade.SKIPPED, detail="moves the machine or halts it: "
                               "needs --allow-motion", **base)
        if check.eeprom and not self.eeprom_ok:
            return CheckResult(grade=Grade.SKIPPED, detail="writes the EEPROM (M500): needs "
                               "--allow-eeprom", **base)
        if check.heat and not self.heat_ok:
            return CheckResult(grade=Grade.SKIPPED, detail=f"heats: needs {HEATERS_ENV}=1",
                               **base)
        if check.kills and not self.target.emulated and check.id != self.killer:
            return CheckResult(grade=Grade.SKIPPED, detail="a reset after each M112 (it "
                               "halts the unit; on a real unit only one such check runs, the "
                               f"last: {self.killer})", **base)
        t0 = time.perf_counter()
        s = self.session
        try:
            s.fresh()
            passed, expected, actual = check.run(s)
            grade = Grade.PASS if passed else (Grade.DEVIATION if check.level == INFO
                                               else Grade.FAIL)
            detail = ""
            if passed is None:
                grade, detail = Grade.NOT_APPLICABLE, "not applicable here"
        except HarnessError as exc:
            grade, expected, actual, detail = Grade.ERROR, "", "", f"HarnessError: {exc}"
        if grade is not Grade.PASS and not self.target.emulated and (check.motion or check.heat):
            detail = (detail + "; " if detail else "") + halt(self.target)
        if check.kills and not self.target.emulated:
            detail = (detail + "; " if detail else "") + "the unit is left halted (M112): " \
                "reset it (power, the reset button or reopening the port) before using it"
        return CheckResult(grade=grade, expected=expected, actual=actual, detail=detail,
                           log=list(self.target.log), duration=time.perf_counter() - t0, **base)

    def halt(self, after_silence: bool = False) -> str:
        return halt(self.target)

    def stop_at_end(self) -> bool:
        return not self.target.emulated and (self.motion_ok or self.heat_ok)


def run_checks(target: Any, vid: str, *, patterns: Sequence[str] = (), profile: str = "quick",
               allow_motion: bool = False, notes: list[str] | None = None,
               progress: Callable[[CheckResult], None] | None = None,
               spec: MarlinSpec | None = None, announce: Callable[[str], None] | None = None,
               **_ignored: Any) -> TargetRun:
    runner = MarlinRunner(target, vid, spec=spec, allow_motion=allow_motion,
                          options=RunOptions(profile=profile, notes=list(notes or []),
                                             announce=announce))
    try:
        return runner.run(select(generate(runner.spec, vid), patterns), progress)
    except RunAborted as exc:
        return exc.run

