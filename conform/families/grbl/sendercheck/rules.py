"""The rules a grbl sender is graded on, each citing where grbl's documents say it.

A rule is a function of a :class:`.session.SenderRun` returning (grade, expected,
actual). The wire (the analysed capture) shows what the sender did; the ground truth (the
lines the unit's parser took and how it answered them, bytes its receive ring dropped, when
it restarted) shows what that did to the machine.

What grbl leaves to a sender when an answer is lost or damaged: grbl 1.1 has no line numbers
it checks, no checksums and no way to ask for an answer again (interface.md §Grbl Response
Messages: every line gets exactly one ``ok`` or ``error:X``; §Message Summary: every message
can be told by its form alone). A character-counting sender that misses an ``ok`` keeps those
bytes in its count for ever: it grows slower and finally waits for ever, but never overflows.
It must not send the line again (grbl would run it twice: a second move) and must not hang:
once the status report says grbl is Idle with nothing answered for a while, every line it was
sent has been taken, so the count can be cleared (the ``Bf:`` field, interface.md §Buffer
State, says the same when ``$10`` enables it) — or it stops and says why. After grbl restarts
(the banner, §Start Up Message: everything starts out the same) the job's state is gone: a
sender must not go on streaming the job.
"""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from conform.families.grbl.protocol.gcode import GcodeError, words

Result = tuple[str, str, str]   # grade, expected, actual
SHOULD = "SHOULD"
POLL_MIN_INTERVAL = 0.1   # s: interface.md recommends at most 5 Hz; 10 Hz "may be possible"


def norm(line: str) -> str:
    """A line as grbl's parser takes it: comments and blanks dropped, upper case."""
    line = re.sub(r"\([^)]*\)", "", line.split(";", 1)[0])
    return "".join(line.split()).upper()


def blocks(line: str) -> list[str]:
    """What grbl executes for one line, as canonical blocks: the words as gcode.c reads them
    (``G01`` is ``G1``, ``X1.0`` is ``X1``); a line of modal G/M words only (``G21G90``) is
    the same program as one line per word, so it is split into them. A '$' line or a line
    the parser cannot read stays as its text."""
    text = norm(line)
    if not text or text.startswith("$"):
        return [text] if text else []
    try:
        ws = words(text)
    except GcodeError:
        return [text]
    canon = [f"{letter}{value:g}" for letter, value, _ in ws]
    if all(letter in "GM" for letter, _v, _t in ws) and not any(
            letter == "G" and value in _NON_MODAL for letter, value, _t in ws):
        return canon
    return ["".join(canon)]


_NON_MODAL = {4.0, 10.0, 28.0, 28.1, 30.0, 30.1, 53.0, 92.0, 92.1}


def program(lines: list[str]) -> list[str]:
    """The canonical blocks of lines in order (:func:`blocks`)."""
    return [b for x in lines for b in blocks(x)]


def numbered(job: list[str]) -> list[tuple[int, str]]:
    """The job's canonical blocks, each with the number (from 1) of the job line it is in."""
    return [(n, b) for n, x in enumerate(job, 1) for b in blocks(x)]


def job_line(job: list[str], line: str) -> str:
    """The job line that holds ``line`` (a block, or a line as sent or as grbl took it), named
    by its number and text; "not a job line" when none does."""
    want = blocks(line)
    for n, x in enumerate(job, 1):
        have = blocks(x)
        if want and (want == have or (len(want) == 1 and want[0] in have)):
            return f"job line {n} {x.strip()!r}"
    return "not a job line"


def on_wire(e: Any, job: list[str]) -> str:
    """An exchange named as the wire has it (its line number there, from 1) and as the job."""
    return f"wire line {e.line + 1} {e.text!r} ({job_line(job, e.text)})"


@dataclass
class Truth:
    """The job against what the unit executed (lines answered ok, '$' commands left out)."""

    job: list[str]
    executed: list[str]
    doubles: list[str] = field(default_factory=list)   # job lines executed more often than
    extras: list[str] = field(default_factory=list)    # the job has them; lines not the job's
    missing: list[str] = field(default_factory=list)   # job lines executed less often

    @property
    def whole(self) -> bool:
        return not (self.doubles or self.missing)

    def summary(self) -> str:
        parts = [f"{len(self.executed)} lines executed for a job of {len(self.job)}"]
        for name, items in (("twice", self.doubles), ("not the job's", self.extras),
                            ("never executed", self.missing)):
            if items:
                parts.append(f"{len(items)} {name}")
        return ", ".join(parts)


def compare(job: list[str], taken: list[list[Any]]) -> Truth:
    """Counts, not positions: a line sent again runs again wherever it lands."""
    jobn = [x for x in program(job) if not x.startswith("$")]
    done = [b for t, code in taken if code == 0 and t and not t.startswith("$")
            for b in blocks(t)]
    want, got = Counter(jobn), Counter(done)
    tr = Truth(jobn, done)
    for x in dict.fromkeys(done):
        if x not in want:
            tr.extras += [x] * got[x]
        elif got[x] > want[x]:
            tr.doubles += [x] * (got[x] - want[x])
    tr.missing = [x for x in dict.fromkeys(jobn) for _ in range(max(0, want[x] - got[x]))]
    return tr


def _answer_faults(r: Any) -> bool:
    return bool({"answers", "restart"} & r.scenario.tags)


def terminates(r: Any) -> Result:
    if r.hung:
        return "FAIL", "the program ends by itself", f"still running after {r.timeout:g} s"
    return "PASS", "the program ends by itself", f"exit status {r.returncode}"


def nothing_lost(r: Any) -> Result:
    m = r.analysis.metrics
    want = "no byte lost in grbl's receive buffer" + ("" if _answer_faults(r) else
                                                      ", every line answered")
    tail = _unanswered_tail(r.analysis.exchanges) if any(
        f.kind == "alarm" for f in r.analysis.findings) else 0
    ok = r.lost == 0 and (_answer_faults(r) or m["answered"] + tail == m["lines"])
    note = (f" ({tail} sent before the alarm were still in grbl's buffer when the program "
            "stopped: grbl answers nothing for 0.5 s after ALARM:N, report.c)") if tail else ""
    silent = [e for e in r.analysis.exchanges if e.answer is None]
    if not ok and silent:
        note += f"; the first without an answer: {on_wire(silent[0], r.job)}"
    return ("PASS" if ok else "FAIL", want,
            f"{r.lost} bytes lost, {m['answered']} of {m['lines']} lines answered on the wire"
            + note)


def _unanswered_tail(exchanges: list[Any]) -> int:
    """Lines at the end of the capture with no answer and no answered line after them."""
    n = 0
    for e in reversed(exchanges):
        if e.answer is not None:
            break
        n += 1
    return n


def within_buffer(r: Any) -> Result:
    m = r.analysis.metrics
    wire = f"{m['max_bytes_in_flight']} bytes in flight on the wire ({m['streaming_method']})"
    if _answer_faults(r):
        # answers lost on the way leave their lines "in flight" on the wire for ever; what
        # grbl's buffer really held is the truth: did it drop a byte?
        return ("PASS" if r.lost == 0 else "FAIL", f"at most {m['rx_buffer']} bytes in grbl's "
                "buffer (ground truth: no byte dropped)", f"{r.lost} bytes dropped; {wire}")
    ok = m["max_bytes_in_flight"] <= m["rx_buffer"]
    if not ok and r.analysis.exchanges:
        worst = max(r.analysis.exchanges, key=lambda e: e.bytes_in_flight)
        wire += f", the most when {on_wire(worst, r.job)} went out"
    return "PASS" if ok else "FAIL", f"at most {m['rx_buffer']} bytes in flight", wire


def realtime_not_lines(r: Any) -> Result:
    """A realtime byte sent as a line ("?\n") leaves an empty line grbl answers with ok: an
    empty line right after a realtime byte is the evidence. A sender that writes "?\n" does
    so with its polls (at least two, and half of its realtime bytes); one empty line of its
    own (a job's blank line) that follows another thread's '?' is not. Empty lines on their
    own (grbl's own stream.py wakes grbl with "\r\n\r\n") are lines, and fine."""
    after = sum(1 for e in r.analysis.exchanges if e.after_realtime)
    n_rt = len(r.analysis.realtime)
    ok = after < 2 or after * 2 < n_rt
    return ("PASS" if ok else "FAIL", "realtime bytes sent alone, not as lines",
            f"{after} of {n_rt} realtime bytes followed by a newline (each an extra empty "
            "line grbl answers with ok)" if after else "no realtime byte followed by a newline")


def in_order(r: Any) -> Result:
    """The job's lines go out once each, in order; where the sender may stop early a prefix
    is right. Lines that are not the job's ($G polls and the like) are left out."""
    jobn = numbered(r.job)
    known = {b for _n, b in jobn}
    sent = [(e, b) for e in r.analysis.exchanges for b in blocks(e.text) if b in known]
    want_blocks, got = [b for _n, b in jobn], [b for _e, b in sent]
    whole = "may-stop" not in r.scenario.tags and "answers" not in r.scenario.tags
    ok = got == want_blocks if whole else got == want_blocks[:len(got)]
    want = "the whole job, in order" if whole else "a prefix of the job, in order"
    said = f"{len(got)} of the job's {len(jobn)} lines sent"
    return "PASS" if ok else "FAIL", want, said + ("" if ok else "; " + _first_out_of_order(
        r.job, jobn, sent))


def _first_out_of_order(job: list[str], jobn: list[tuple[int, str]],
                        sent: list[tuple[Any, str]]) -> str:
    """Where the wire first leaves the job: the job line due there and what was sent instead."""
    d = next((i for i, (a, b) in enumerate(zip(jobn, sent, strict=False))
              if a[1] != b[1]),
             min(len(jobn), len(sent)))
    if d >= len(jobn):
        return (f"after the job's last line {on_wire(sent[d][0], job)} was sent again "
                "(a line sent again)")
    n, _b = jobn[d]
    due = f"job line {n} {job[n - 1].strip()!r}"
    if d >= len(sent):
        rest = len({m for m, _ in jobn[d:]}) - 1
        return f"{due} never went on the wire" + (f", nor the {rest} after it" if rest else "")
    e, block = sent[d]
    if block in {b for _m, b in jobn[d + 1:]}:
        return f"{due} was skipped: in its place the wire had {on_wire(e, job)}"
    return f"{due} was due, but the wire had {on_wire(e, job)} again (a line sent again)"


def executed_once(r: Any) -> Result:
    tr = compare(r.job, r.taken)
    if tr.doubles:
        return ("FAIL", "every job line executed at most once (ground truth)",
                f"{tr.summary()}: {job_line(r.job, tr.doubles[0])} ran twice (a line sent "
                "again after its answer was lost moves the machine twice)")
    return "PASS", "every job line executed at most once (ground truth)", tr.summary()


def honest_exit(r: Any) -> Result:
    if r.hung:
        return "NOT-APPLICABLE", "", "the program was stopped"
    tr = compare(r.job, r.taken)
    if tr.whole and not tr.extras:
        return "PASS", "exit status 0 only when the whole job ran", \
            f"{tr.summary()}; exit status {r.returncode}"
    ok = r.returncode != 0
    first = (f" (the first never executed: {job_line(r.job, tr.missing[0])})" if tr.missing else
             f" ({job_line(r.job, tr.doubles[0])} ran twice)" if tr.doubles else "")
    return ("PASS" if ok else "FAIL", "a non-zero exit status when the job did not run whole",
            f"{tr.summary()}{first}; exit status {r.returncode}")


def after_error(r: Any) -> Result:
    errs = [f for f in r.analysis.findings if f.kind == "error-response"]
    if not errs:
        return "NOT-APPLICABLE", "", "no error:N in this run"
    went_on = "went on" in errs[0].message
    rejected = next((e for e in r.analysis.exchanges if (e.answer or "").startswith("error:")),
                    None)
    said = errs[0].message
    if rejected is not None:   # the finding names the wire's line; name the job's too
        said = f"{on_wire(rejected, r.job)}: {said.split(': ', 1)[-1]}"
    return ("FAIL" if went_on else "PASS", "stop (or let the user decide) after error:N", said)


def after_alarm(r: Any) -> Result:
    alarms = [f for f in r.analysis.findings if f.kind == "alarm"]
    if not alarms:
        return "NOT-APPLICABLE", "", "no alarm in this run"
    seen = alarms[0].extra["t_abs"]
    # lines already on their way when the alarm came are not the sender's fault
    locked = [e for e in r.analysis.exchanges if e.answer == "error:9" and e.t_sent > seen]
    return ("FAIL" if locked else "PASS", "no g-code sent after the alarm arrived",
            f"{len(locked)} lines sent after {alarms[0].message} were answered error:9, the "
            f"first {on_wire(locked[0], r.job)}" if locked else alarms[0].message)


def restart_stops(r: Any) -> Result:
    if not r.restarts:
        return "NOT-APPLICABLE", "", "grbl did not restart in this run"
    known = {norm(x) for x in r.job}
    after = [t for t, code in r.taken[r.restarts[0]:] if code == 0 and t in known]
    if after:
        return ("FAIL", "no job line run after grbl restarted",
                f"{len(after)} job lines executed after the restart, the first "
                f"{job_line(r.job, after[0])}: the job went on from a machine that had lost "
                "its state and position")
    return "PASS", "no job line run after grbl restarted", "the sender stopped the job"


def hold_respected(r: Any) -> Result:
    """A feed hold from the machine's button is the operator's: only cycle start ends it."""
    press = [e["t"] for e in r.events if e["request"] == "press hold"]
    start = [e["t"] for e in r.events if e["request"] == "press start"]
    if not press:
        return "NOT-APPLICABLE", "", "no feed hold in this run"
    end = start[0] if start else float("inf")
    resumed = [t for t, b in r.analysis.realtime if b == 0x7E and press[0] < t < end]
    if resumed:
        return ("FAIL", "no cycle start (~) sent while the operator holds",
                f"{len(resumed)} '~' sent {resumed[0] - press[0]:.2f} s into the hold")
    return "PASS", "no cycle start (~) sent while the operator holds", \
        "the sender waited for the machine's cycle start"


def poll_rate(r: Any) -> Result:
    m = r.analysis.metrics
    med = m.get("poll_interval_median_s")
    if not m.get("status_polls") or med is None:
        return "NOT-APPLICABLE", "", "no status polls"
    ok = med >= POLL_MIN_INTERVAL
    return ("PASS" if ok else "FAIL", f"'?' at most every {POLL_MIN_INTERVAL:g} s (10 Hz)",
            f"{m['status_polls']} polls, median interval {med * 1000:.0f} ms")


def planner_fed(r: Any) -> Result:
    """Where the link is slow, a sender that waits for each answer leaves the planner dry
    between lines; character counting keeps lines waiting in grbl's buffer instead."""
    if "fed" not in r.scenario.tags:
        return "NOT-APPLICABLE", "", "graded only where the link is slow"
    if not r.analysis.metrics.get("status_reports"):
        return "NOT-APPLICABLE", "", "no status reports to see the planner by"
    dry = [f for f in r.analysis.findings if f.kind == "planner-starved"]
    if dry:
        return ("FAIL", "the planner kept fed mid-job",
                f"{r.analysis.metrics['finding_counts']['planner-starved']} status reports saw "
                f"it dry ({r.analysis.metrics['streaming_method']}); the first: {dry[0].message}")
    return "PASS", "the planner kept fed mid-job", \
        f"{r.analysis.metrics['status_reports']} status reports, none of a dry planner"


MUST = "MUST"
RULES = [
    ("terminates", "the program ends by itself", "docs/grbl.md §Judging a sender (harness rule)",
     MUST, terminates),
    ("nothing-lost", "no byte lost, every line answered",
     "interface.md §Grbl Response Messages; serial.h RX_BUFFER_SIZE", MUST, nothing_lost),
    ("within-buffer", "character counting within the receive buffer",
     "serial.h RX_BUFFER_SIZE; wiki Interfacing with Grbl §Streaming Protocol: "
     "Character-Counting", MUST,
     within_buffer),
    ("realtime-out-of-band", "realtime bytes are not lines",
     "realtime_cmds.md (no line feed needed); interface.md §Real-time Status reports", MUST,
     realtime_not_lines),
    ("job-in-order", "the job's lines are sent in order", "interface.md §Grbl Response Messages",
     MUST, in_order),
    ("executed-once", "no job line executed twice (ground truth)",
     "interface.md §Grbl Response Messages (one answer per line, no resend in the protocol)",
     MUST, executed_once),
    ("honest-exit", "exit status says whether the job ran",
     "docs/grbl.md §Judging a sender", SHOULD, honest_exit),
    ("error-recovery", "after error:N the sender stops", "error_codes_en_US.csv; interface.md "
     "§Grbl Response Messages (the line was not executed)", SHOULD, after_error),
    ("alarm-stops", "no g-code after an alarm", "interface.md §Alarm Message; error_codes#9",
     MUST, after_alarm),
    ("restart-stops", "no job line after grbl restarted",
     "interface.md §Start Up Message (everything starts out the same)", MUST, restart_stops),
    ("hold-respected", "a machine feed hold is ended by the machine",
     "realtime_cmds.md (~ cycle start, ! feed hold); interface.md §Machine State Hold", MUST,
     hold_respected),
    ("planner-fed", "the planner is kept fed on a slow link",
     "wiki Interfacing with Grbl §Streaming Protocol: Character-Counting (send-response "
     "starves the planner); planner.h BLOCK_BUFFER_SIZE", SHOULD, planner_fed),
    ("poll-rate", "status polls at most 10 Hz",
     "wiki Interfacing with Grbl §Status Reporting (at most 5 Hz recommended, 10 Hz may "
     "be possible)", SHOULD,
     poll_rate),
]
