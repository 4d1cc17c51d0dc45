"""check-sender's rules for Marlin senders, graded from the unit's ground truth (what ran, how
often) and the recorded traffic; each cites the source behaviour it rests on.

A rule returns (grade, expected, actual); grades are the engine's (PASS, FAIL,
NOT-APPLICABLE). A SHOULD rule that fails is reported as a DEVIATION.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from typing import Any

from conform.families.marlin.unit.unit import _after_number

MUST, SHOULD = "MUST", "SHOULD"
PASS, FAIL, NA = "PASS", "FAIL", "NOT-APPLICABLE"
Q = "queue.cpp get_serial_commands"


def _ran(r: Any) -> Counter[str]:
    job = set(r.job)
    return Counter(t for t in (_after_number(x) for _, _, x in r.log) if t in job)


def _restart(r: Any) -> float | None:
    """When the unit restarted: a reset, or the cable pulled (a USB board restarts with it)."""
    if r.resets:
        return r.resets[0]
    pulled = [e["t_unit"] for e in r.events if e["request"].startswith("fault unplug")]
    return pulled[0] if pulled else None


def numbered(r: Any) -> tuple[str, str, str]:
    """Unnumbered lines are not checked at all (a damaged one runs damaged)."""
    job = set(r.job)
    bare = [x for x in r.analysis.lines if x.n is None and x.text in job]
    return (FAIL if bare else PASS, "every job line numbered and checksummed",
            f"{len(bare)} job lines sent without N/checksum" + (f", first {bare[0].text!r}"
                                                                if bare else ""))


def resend_exact(r: Any) -> tuple[str, str, str]:
    """After Resend: N the next numbered line sent must be N (an off-by-one sender loops)."""
    from conform.families.marlin.analysis.analyze import timed_lines

    asks = [(t, int(x.split(b":")[1])) for t, x in timed_lines(_unit_chunks(r))
            if x.startswith(b"Resend:") and x.split(b":")[1].strip().lstrip(b"-").isdigit()]
    if not asks:
        return NA, "the line asked for, after each Resend:", "no Resend: in this session"
    host = [x for x in r.analysis.lines if x.n is not None]
    wrong = []
    for t, n in asks:
        nxt = next((x for x in host if x.t > t), None)
        if nxt is not None and nxt.n != n and not nxt.text.startswith("M110"):
            wrong.append(f"Resend: {n} answered with N{nxt.n}")
    return (FAIL if wrong else PASS, "the line asked for, after each Resend:",
            "; ".join(wrong[:3]) or f"{len(asks)} resends answered with the line asked for")


def _unit_chunks(r: Any) -> list[tuple[float, bytes]]:
    from conform.analysis.stream import read_raw

    raw = read_raw(r.analysis.path)
    data = raw.unit.data.tobytes()
    return [(float(t), data[s:s + n]) for s, n, t in
            zip(raw.unit.start.tolist(), raw.unit.length.tolist(), raw.unit.t_read.tolist(),
                strict=True)]


def none_twice(r: Any) -> tuple[str, str, str]:
    """A job line run twice moves or extrudes twice: the unit's ground truth says how often
    each job line ran."""
    twice = [(x, n) for x, n in _ran(r).items() if n > 1 and r.job.count(x) < n]
    return (FAIL if twice else PASS, "no job line run twice",
            f"{len(twice)} job lines ran twice" + (f", e.g. {twice[0][0]!r} x{twice[0][1]}"
                                                   if twice else ""))


def none_skipped(r: Any) -> tuple[str, str, str]:
    if "restart" in r.scenario.tags:
        return NA, "every job line run", "the unit restarted: the job cannot complete"
    ran = _ran(r)
    missing = [x for x in r.job if ran[x] == 0]
    return (FAIL if missing else PASS, "every job line run",
            f"{len(missing)} job lines never ran" + (f", first {missing[0]!r}" if missing
                                                      else f" ({sum(ran.values())} ran)"))


def finishes(r: Any) -> tuple[str, str, str]:
    """The program ends by itself: after a lost ok Marlin says nothing more, so a sender that
    only waits for ok waits for ever; one that times out (or asks M105/M114) goes on."""
    if r.hung:
        ran = sum(_ran(r).values())
        return FAIL, f"the program ends within {r.scenario.timeout:g} s", \
            f"still running at the timeout ({ran} of {len(r.job)} job lines ran)"
    return PASS, "the program ends by itself", f"exit status {r.returncode}"


def stops_after_reset(r: Any) -> tuple[str, str, str]:
    """After a reset the unit has lost its position, heaters and queue (MarlinCore setup()):
    a sender must not go on with the job (nor start it again) as if nothing happened."""
    t = _restart(r)
    if t is None:
        return NA, "no job line after a reset", "no reset in this session"
    after = [x for tt, _, x in r.log if tt > t and _after_number(x) in set(r.job)]
    return (FAIL if after else PASS, "no job line runs after the unit restarted",
            f"{len(after)} job lines ran after the restart" + (f", first {_after_number(after[0])!r}"
                                                               if after else ""))


def waits_while_busy(r: Any) -> tuple[str, str, str]:
    """busy: processing says the unit is alive (gcode.cpp host_keepalive): a sender should not
    give up on its line or send it again meanwhile."""
    if "busy" not in r.scenario.tags:
        return NA, "no line repeated while busy:", "not graded in this scenario"
    repeats = [x for x in r.analysis.lines if x.repeat]
    return (FAIL if repeats else PASS, "no line sent again while the unit says busy",
            f"{len(repeats)} lines sent again" + (f", first N{repeats[0].n}" if repeats else ""))


def checksums_right(r: Any) -> tuple[str, str, str]:
    if r.scenario.faults:
        return NA, "no checksum error", "the scenario damages lines on purpose"
    m = r.analysis.metrics
    bad = m["checksum_errors"] + m["no_checksum_errors"]
    return (FAIL if bad else PASS, "no checksum error on a clean line",
            f"{bad} checksum errors")


Rule = tuple[str, str, str, str, Callable[[Any], tuple[str, str, str]]]
RULES: list[Rule] = [
    ("numbered", "job lines numbered and checksummed", Q + " (a line without N is not checked)",
     SHOULD, numbered),
    ("checksums-right", "checksums computed right", Q + " (XOR of the bytes before '*')", MUST,
     checksums_right),
    ("resend-exact", "sends the line Resend: asks for", "queue.cpp flush_and_request_resend",
     MUST, resend_exact),
    ("none-twice", "no job line run twice", Q + " (a line is taken once per number)", MUST,
     none_twice),
    ("none-skipped", "no job line skipped", Q, MUST, none_skipped),
    ("finishes", "recovers from a lost ok (ends by itself)", "queue.cpp ok_to_send (one ok per "
     "line, never repeated)", MUST, finishes),
    ("stops-after-reset", "stops the job after the unit restarted", "MarlinCore.cpp setup() "
     "(start: position, heaters and queue lost)", MUST, stops_after_reset),
    ("waits-while-busy", "keeps waiting while busy:", "gcode.cpp host_keepalive", SHOULD,
     waits_while_busy),
]
