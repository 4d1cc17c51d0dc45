"""Sessions with a known cause of trouble, made in-process: a scripted sender drives a
family's reference unit on a virtual clock over a modelled serial line (bytes take 10 bits
at the baud rate), with the fault injected where it belongs: the sender killed, the unit's
answers cut off, the line dead for a while (both directions lost, the emulator's link events
recorded as `conform emulate --faults disconnect=…` records them), bits flipped on the way to
the unit, realtime bytes from a pendant. The capture is written as the proxy would record it
at the sender's side: what the sender wrote when it wrote it, what reached the sender."""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from conform.capture import Recorder
from conform.families import family

BAUD = 115200
START = 0.05            # the sender begins after the unit's start-up message
T_BASE = 1000.0


@dataclass
class Faults:
    kill_after: int | None = None            # the sender dies after this many lines
    mute_unit_at: float | None = None        # the unit's answers are lost from then on
    cut: tuple[float, float] | None = None   # both directions dead in this window
    cut_events: bool = True                  # the emulator records the drop and the return
    noise: tuple[float, float] | None = None  # one bit flipped in each host line sent then
    realtime: dict[float, bytes] = field(default_factory=dict)   # bytes a pendant injects
    alter: dict[int, bytes] = field(default_factory=dict)   # the unit gets these instead of
    # the n-th line written (counting resends)
    pause: dict[int, float] = field(default_factory=dict)   # the n-th line written in two
    # halves this many seconds apart (a converter that holds bytes back)
    drop_answer: set[int] = field(default_factory=set)   # the k-th `ok` the unit sends (from
    # 0) is lost on the way back
    unit_calls: dict[float, Callable] = field(default_factory=dict)   # at t: call(unit, t),
    # a fault inside the unit (its own kill, a command that never ends)
    seed: int = 1


@dataclass
class Sender:
    """How the scripted sender streams: ``window`` None waits for each answer (simplex);
    a number counts bytes in flight against it. ``gap``: idle seconds before each line;
    ``poll``: (interval, bytes) sent out of band; ``retry(answer)``: resend the line."""

    terminator: bytes
    is_answer: Callable[[bytes], bool]
    window: int | None = None
    gap: float = 0.0
    poll: tuple[float, bytes] | None = None
    retry: Callable[[bytes], bool] = lambda _a: False
    timeout: float | None = None              # resend after this long without an answer
    stop_on: Callable[[bytes], bool] = lambda _a: False   # stop sending (an error dialog)


@dataclass
class Session:
    host: list[tuple[float, bytes]]
    unit: list[tuple[float, bytes]]
    links: list[tuple[float, str, str, str]]
    unit_model: object
    sent: list[bytes]                         # lines in the order written (resends too)


def drive(unit, lines: list[bytes], s: Sender, faults: Faults | None = None, *,
          tail: float = 1.0, dt: float = 0.0005, t_max: float = 60.0) -> Session:
    f = faults or Faults()
    rng = random.Random(f.seed)
    byte_t = 10.0 / BAUD
    host, out, links, sent = [], [], [], []
    inbox = bytearray()
    on_wire: list[tuple[float, bytes]] = []
    unit_wire = 0.0
    in_flight: list[int] = []
    t = 0.0
    i = 0
    wire_free = 0.0          # when the host's line is free again
    waiting_since: float | None = None
    for due, data in unit.poll(0.0):       # the unit's start-up message, before the sender
        out.append((due + len(data) * byte_t, data))
    t = START
    next_send = t + s.gap
    next_poll = START + s.poll[0] if s.poll else None
    pending_rt = sorted(f.realtime.items())
    pending_calls = sorted(f.unit_calls.items(), key=lambda kv: kv[0])
    dead = False
    stopped = False
    done_at: float | None = None
    cut_state = False
    oks = 0

    def down(at: float) -> bool:
        return f.cut is not None and f.cut[0] <= at < f.cut[1]

    def write(data: bytes, at: float, arrives: bytes | None = None) -> None:
        nonlocal wire_free
        start = max(at, wire_free)
        end = start + len(data) * byte_t
        wire_free = end
        host.append((end, data))
        if down(end):
            return
        if arrives is not None:
            data = arrives
        if f.noise and f.noise[0] <= end < f.noise[1] and len(data) > 3:
            k = rng.randrange(1, len(data) - 1)
            data = data[:k] + bytes([data[k] ^ (1 << rng.randrange(7))]) + data[k + 1:]
        unit.receive(data, end)

    while t < t_max:
        t += dt
        if f.cut is not None and f.cut_events and down(t) != cut_state:
            cut_state = down(t)
            links.append((t, "disconnect" if cut_state else "reconnect", "unit",
                          "fault injection: link dropped" if cut_state else
                          "fault injection: link restored"))
        for due, data in unit.poll(t):
            if (f.mute_unit_at is not None and due >= f.mute_unit_at) or down(due):
                continue
            if data.startswith(b"ok"):
                oks += 1
                if oks - 1 in f.drop_answer:
                    continue
            on_wire.append((max(due, unit_wire) + len(data) * byte_t, data))
            unit_wire = on_wire[-1][0]
        while on_wire and on_wire[0][0] <= t:      # what has reached the sender by now
            out.append(on_wire.pop(0))
            inbox.extend(out[-1][1])
        while s.terminator in inbox:
            k = inbox.index(s.terminator)
            answer, inbox[:] = bytes(inbox[:k]), inbox[k + 1:]
            if not s.is_answer(answer) or dead:
                continue
            if s.stop_on(answer):
                stopped = True
            if s.window is not None:
                if in_flight:
                    in_flight.pop(0)
            elif waiting_since is not None:
                if s.retry(answer):
                    i -= 1
                waiting_since = None
                next_send = t + s.gap
        while pending_rt and pending_rt[0][0] <= t:
            write(pending_rt.pop(0)[1], t)
        while pending_calls and pending_calls[0][0] <= t:
            pending_calls.pop(0)[1](unit, t)
        if dead or stopped:
            pass
        elif s.timeout is not None and waiting_since is not None and \
                t - waiting_since > s.timeout:
            i -= 1
            waiting_since = None
        if not dead and next_poll is not None and t >= next_poll:
            write(s.poll[1], t)
            next_poll += s.poll[0]
        if not dead and not stopped and i < len(lines) and t >= next_send and \
                waiting_since is None:
            line = lines[i]
            room = s.window is None or sum(in_flight) + len(line) <= s.window
            if room:
                k = len(sent)
                if k in f.pause:
                    half = len(line) // 2
                    write(line[:half], t)
                    wire_free += f.pause[k]
                    write(line[half:], t)
                else:
                    write(line, t, f.alter.get(k))
                sent.append(line)
                i += 1
                if s.window is None:
                    waiting_since = t
                else:
                    in_flight.append(len(line))
                    next_send = t + s.gap
                if f.kill_after is not None and i >= f.kill_after:
                    dead = True
        finished = i >= len(lines) and not in_flight and waiting_since is None
        if (dead or stopped or finished) and done_at is None:
            done_at = t
        if done_at is None and i >= len(lines) and s.window is None and waiting_since is None:
            done_at = t
        quiet = t - max(out[-1][0] if out else 0.0, host[-1][0] if host else 0.0)
        if quiet >= max(tail, 3.0):
            break               # nothing moves any more on either side
        if done_at is not None and t - done_at >= tail and (quiet >= tail or not dead):
            break
        if done_at is None and waiting_since is not None and s.timeout is None and \
                f.mute_unit_at is not None and t > f.mute_unit_at + tail:
            break
    links.append((t, "close", "session", "capture finished"))
    return Session(host, sorted(out), links, unit, sent)


def record(path: Path, ses: Session, variant: str, method: str = "proxy",
           sender_closed: float | None = None) -> Path:
    """The session as ``conform proxy`` records it (optionally the sender's pty closing)."""
    rec = Recorder(path, {"capture_method": method}, variant=variant, baud=BAUD, decode=False,
                   clock=lambda: T_BASE)
    items = [(t, 0, "host", d) for t, d in ses.host] + [(t, 1, "unit", d) for t, d in ses.unit]
    for t, _o, direction, d in sorted(items):
        rec.chunk(direction, d, t_read=T_BASE + t, t_first=T_BASE + t - (len(d) - 1) * 10 / BAUD)
    for t, kind, side, detail in ses.links:
        rec.link_event(kind, detail, side=side, t=T_BASE + t)
    if sender_closed is not None:
        rec.link_event("disconnect", "sender pty closed", side="host",
                       t=T_BASE + sender_closed)
    rec.close()
    return path


def from_transcript(src: Path, path: Path, variant: str, family_name: str) -> Path:
    """A recorded text transcript (conform/emulator/judge.py reads them) as a capture: each
    host write and each unit line a read at its recorded time, the unit's lines given the
    family's line ending (the text form cannot hold a CR)."""
    from conform.emulator.judge import read_transcript, with_line_ending

    tr = with_line_ending(read_transcript(src), family(family_name).line_ending)
    rec = Recorder(path, {"capture_method": "transcript", "source": src.name}, variant=variant,
                   baud=BAUD, decode=False, clock=lambda: T_BASE)
    for e in tr.events:
        rec.chunk("host" if e.host else "unit", e.data, t_read=T_BASE + e.t,
                  t_first=T_BASE + e.t - (len(e.data) - 1) * 10 / BAUD)
    rec.close()
    return path


# ---------------------------------------------------------------- the two families' senders


def grbl_unit(**kw):
    return family("grbl").make_unit("grbl-1.1f", truth=True, **kw)


def gve_unit():
    return family("gve").make_unit("gve64-v19")


def grbl_sender(**kw) -> Sender:
    return Sender(b"\n", lambda a: a.strip() == b"ok" or a.startswith(b"error:"),
                  **({"window": 127} | kw))


def gve_sender(**kw) -> Sender:
    def retry(a: bytes) -> bool:        # queue full (1) or damaged (2, 4): send it again
        code = int(a[:1], 16) & 7 if a[:1] and a[:1] in b"0123456789ABCDEF" else 0
        return code in (1, 2, 4)           # bit 3 is INTA, not part of the code (§13.7)
    return Sender(b"\r", lambda a: a[:1] in b"0123456789ABCDEF" and len(a) > 0,
                  retry=retry, **kw)


def grbl_job(n: int = 60) -> list[bytes]:
    """``n`` short moves, then the program end a job file ends with."""
    return [b"G21G90G54F3000\n"] + [b"G1X%.3fY%.3f\n" % ((i % 10) * 0.5, (i % 7) * 0.3)
                                    for i in range(n)] + [b"M2\n"]


def gve_job(n: int = 60, size: int = 400, checksums: bool = False) -> list[bytes]:
    from conform.families.gve.protocol import append_checksum

    body = [b"!0V5000", b"!0A50"] + [b"!0C%d,%d,0,0" % (size if i % 2 else -size, size // 2)
                                     for i in range(n)]
    if checksums:
        return [b"!0%+\r"] + [append_checksum(b) + b"\r" for b in body]
    return [b + b"\r" for b in body]


def marlin_unit():
    return family("marlin").make_unit("marlin-2.1")


def marlin_sender(**kw) -> Sender:
    """Ok-paced, as printcore and ``conform send`` stream: the answer is the ``ok``; a
    ``Resend:`` asks for the line again (its ``ok`` that follows is then not the answer)."""
    return Sender(b"\n", lambda a: a.startswith(b"ok") or a.startswith(b"Resend:"),
                  retry=lambda a: a.startswith(b"Resend:"), **kw)


def marlin_job(n: int = 60, numbered: bool = True, until: int | None = None,
               report: bool = False) -> list[bytes]:
    """``n`` moves ending with M400 (wait for the moves to end), numbered with checksums
    after an M110 as printcore numbers them, or plain; ``until``: only the first lines
    numbered, the rest sent plain (a sender that stops numbering); ``report``: M155 S1 first
    (the unit reports its temperatures every second on its own)."""
    body = [b"G90"] + [b"G1 X%d Y%d F6000" % (i % 30, i % 7) for i in range(n)] + [b"M400"]
    if report:
        body.insert(0, b"M155 S1")
    if not numbered:
        return [b + b"\n" for b in body]
    from functools import reduce
    from operator import xor

    out = []
    for k, b in enumerate([b"M110 N0", *body]):
        if until is not None and k >= until:
            out.append(b + b"\n")
            continue
        line = b"N%d %s" % (k, b)
        out.append(line + b"*%d\n" % reduce(xor, line, 0))
    return out
