"""``conform characterize`` for Marlin: which build configuration this unit runs.

Marlin's protocol is fixed by its source, but what a sender may assume depends on the build:
the firmware and protocol version and the capabilities M115 reports, ADVANCED_OK (and through
its ``P``/``B`` the planner and command-queue sizes), MAX_CMD_SIZE, the host keepalive
interval, the emergency parser, and how this version treats a repeated line number. Each probe is harmless: no
motion, no heat, no EEPROM write (M115, G4 dwells, an unknown command, numbered M105s, M0
with a time limit ended by M108)."""

from __future__ import annotations

import re
import statistics
from typing import Any

from conform.conformance.observed import Observation
from conform.families.marlin.conformance.session import Session
from conform.families.marlin.protocol.codec import split_lines
from conform.families.marlin.spec import MarlinSpec, Variant, load_marlin

KEEPALIVE_DWELL = 4.5
"""Seconds of the dwell during which ``busy: processing`` lines are timed."""

_ADV = re.compile(r"^ok(?: N-?\d+)? P(\d+) B(\d+)$")


def _m115(s: Session, v: Variant, spec: MarlinSpec) -> list[Observation]:
    got = s.talk(s.numbered("M115"), timeout=3.0)
    first = next((x for x in got.lines if x.startswith("FIRMWARE_NAME:")), "")
    name = re.search(r"FIRMWARE_NAME:Marlin (\S+)", first)
    proto = re.search(r"PROTOCOL_VERSION:(\S+)", first)
    out = [Observation("firmware", v.firmware, name.group(1) if name else None,
                       first[:80] or f"(no FIRMWARE_NAME line: {got.text()[:60]})"),
           Observation("protocol_version", v.protocol_version, proto.group(1) if proto else None,
                       "M115 PROTOCOL_VERSION:")]
    caps = dict(re.findall(r"^Cap:([A-Z0-9_]+):(\d)$", "\n".join(got.lines), re.M))
    if not v.on("EXTENDED_CAPABILITIES_REPORT") and not caps:
        return out
    for cap in spec.caps:
        seen = caps.pop(cap.name, None)
        out.append(Observation(f"cap.{cap.name}", cap.value(v),
                               int(seen) if seen is not None else None,
                               f"Cap:{cap.name}:{seen}" if seen is not None else "not reported"))
    for name_, seen in caps.items():        # reported, not in the tables
        out.append(Observation(f"cap.{name_}", None, int(seen), f"Cap:{name_}:{seen}"))
    return out


def _ok_format(s: Session, v: Variant) -> list[Observation]:
    """queue.cpp ok_to_send: with ADVANCED_OK the ok of an idle unit says the planner's free
    blocks (all usable ones) and the queue's free slots (BUFSIZE less the line itself)."""
    got = s.talk(s.numbered("G4 P0"), timeout=3.0)
    ok = next((x for x in got.lines if x.startswith("ok")), "")
    m = _ADV.match(ok)
    out = [Observation("advanced_ok", v.on("ADVANCED_OK"), bool(m) if ok else None,
                       f"the ok of an idle unit: {ok or got.text()[:60]!r}")]
    if m:
        out += [Observation("planner_blocks", v.planner_blocks, int(m.group(1)),
                            f"P{m.group(1)} when idle (BLOCK_BUFFER_SIZE - 1)"),
                Observation("bufsize", v.bufsize, int(m.group(2)) + 1,
                            f"B{m.group(2)} with this line in the queue (BUFSIZE - 1)")]
    return out


def _max_cmd_size(s: Session, v: Variant) -> Observation:
    """process_stream_char keeps MAX_CMD_SIZE - 1 characters of a line; the unknown command's
    echo shows what was kept. The line stays shorter than the receive buffer, so no byte of it
    can be lost while the unit is busy."""
    length = v.rx_buffer - 8
    line = "Q" + "9" * (length - 1)
    got = s.talk(line.encode() + b"\n", timeout=3.0)
    echo = next((x for x in got.lines if x.startswith('echo:Unknown command: "')), "")
    kept = echo[len('echo:Unknown command: "'):].rstrip('"')
    observed: Any = len(kept) + 1 if kept else None
    if kept and len(kept) >= length:
        observed = f">{length}"
    return Observation("max_cmd_size", v.max_cmd_size, observed,
                       f"{len(kept)} of {length} characters echoed" if kept else
                       f"no echo of the unknown command ({got.text()[:60]})")


def _keepalive(s: Session, v: Variant) -> Observation:
    """gcode.cpp host_keepalive: ``busy: processing`` every DEFAULT_KEEPALIVE_INTERVAL
    seconds while a command blocks (0: HOST_KEEPALIVE_FEATURE off)."""
    table = v.keepalive if v.on("HOST_KEEPALIVE_FEATURE") else 0
    target = s.target
    target.send(s.numbered(f"G4 P{int(KEEPALIVE_DWELL * 1000)}"))
    t0 = target.now()
    deadline = t0 + KEEPALIVE_DWELL + 2.0
    times: list[float] = []
    rest, done = b"", False
    while not done and target.now() < deadline:
        chunk = target.receive(deadline)
        now = target.now() - t0
        lines, rest = split_lines(rest + chunk)
        for raw in lines:
            kind = s.spec.classify(raw.decode("latin-1"))[0]
            if kind == "busy":
                times.append(now)
            done = done or kind.startswith("ok")
    if not times:
        return Observation("keepalive", table, 0, f"no busy: line in a {KEEPALIVE_DWELL} s dwell")
    gaps = [b - a for a, b in zip([0.0, *times], times, strict=False)]
    return Observation("keepalive", table, round(statistics.median(gaps)),
                       f"{len(times)} busy: lines at " + ", ".join(f"{t:.1f}" for t in times)
                       + " s of the dwell")


def _repeat(s: Session) -> Observation:
    """2.1.x's get_serial_commands ignores a number within last-1 … last (a resend already in
    transit); older versions answered it with a line-number error."""
    s.talk(s.numbered("M105"), timeout=3.0)
    again = s.talk(s.numbered("M105", s.n), timeout=1.0)
    return Observation("repeat_is_silent", True, not again.lines,
                       f"the same numbered line again: {again.text()[:60]}")


def _emergency_parser(s: Session, v: Variant) -> Observation:
    """M0 S3, then M108 half a second later. M0 exists only with HAS_RESUME_CONTINUE (with no
    display: EMERGENCY_PARSER); the emergency parser acts on M108 as its bytes arrive and ends
    the wait at once (e_parser.h, MarlinCore.cpp wait_for_user_response); without it M108
    waits in the queue behind M0."""
    target = s.target
    target.send(s.numbered("M0 S3"))
    t0 = target.now()
    first = s.collect(timeout=0.5, linger=0.5)
    target.send(b"M108\n")
    rest = s.collect(until=lambda ls: s.oks(first.lines + ls) >= 2, timeout=5.0)
    lines = first.lines + rest.lines
    if any(x.startswith('echo:Unknown command: "M0') for x in lines):
        return Observation("emergency_parser", v.on("EMERGENCY_PARSER"), False,
                           "M0 is unknown: no HAS_RESUME_CONTINUE, so no emergency parser")
    if s.oks(lines) < 2:
        return Observation("emergency_parser", v.on("EMERGENCY_PARSER"), None,
                           f"M0 S3 then M108: {' | '.join(lines)[:60] or '(silence)'}")
    took = rest.t - t0 if s.oks(first.lines) == 0 else first.t - t0
    ended = took < 2.0
    return Observation("emergency_parser", v.on("EMERGENCY_PARSER"), ended,
                       f"M0 S3 ended {took:.1f} s after it was sent (M108 sent at 0.5 s)")


ITEMS = ("firmware", "protocol_version", "cap.*", "advanced_ok", "max_cmd_size", "keepalive",
         "repeat_is_silent", "emergency_parser")
"""What is probed, in order (``cap.*``: every Cap: line; ADVANCED_OK adds planner_blocks and
bufsize)."""


def characterize(target: Any, vid: str, out: list[Observation] | None = None
                 ) -> list[Observation]:
    """Probe every item of :data:`ITEMS`; ``out`` (the caller's) fills as they are found, so
    an interrupted characterisation still has them."""
    spec = load_marlin()
    v = spec.variant(vid)
    s = Session(target, spec, v)
    s.fresh()
    out = [] if out is None else out
    out.extend(_m115(s, v, spec))
    out.extend(_ok_format(s, v))
    out.append(_max_cmd_size(s, v))
    out.append(_keepalive(s, v))
    out.append(_repeat(s))
    out.append(_emergency_parser(s, v))
    return out
