"""A scripted host streaming a job to a sans-I/O Marlin unit on a virtual clock, with the
link's faults in between: how tests and benchmarks make Marlin traffic (both directions as
timed chunks) without a pty.

``ahead`` lines may be unanswered at once (1: wait for each ok); on ``Resend: N`` the host
goes back to N. ``resend_ahead`` keeps streaming ahead after a resend instead of waiting, the
behaviour that turns one damaged line into a resend storm. ``restart_at`` resets the unit after
that many oks and the host starts the job again from N1 (``M110 N0``) as a careless sender
would. ``wrong_resends``: that many times the host answers ``Resend: N`` with N + 1 (an
off-by-one sender), each answered by another resend request.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from conform.families.marlin.protocol.codec import frame


@dataclass
class SimResult:
    host: list[tuple[float, bytes]] = field(default_factory=list)
    unit: list[tuple[float, bytes]] = field(default_factory=list)
    oks: int = 0
    end: float = 0.0


def stream(unit: Any, job: list[str], *, faults: Any = None, baud: int = 250000,
           ahead: int = 1, restart_at: int | None = None, wrong_resends: int = 0,
           t0: float = 0.0,
           timeout: float = 5.0, limit: float = 3600.0) -> SimResult:
    bit = 10.0 / baud
    r = SimResult()
    t = t0 + 1.0
    unit.poll(t)
    nxt = 1                 # the next job line (its number)
    sent_upto = 0
    unanswered = 0
    restarted = False
    rest = b""
    last_progress = t

    def send(data: bytes) -> None:
        nonlocal t
        r.host.append((t, data))
        deliveries = faults.feed("host", data, t) if faults else [(t, data)]
        for when, chunk in deliveries:
            unit.receive(chunk, max(when, t) + len(chunk) * bit)
        t += len(data) * bit

    while nxt <= len(job) or unanswered:
        while unanswered < ahead and nxt <= len(job):
            send(frame(nxt, job[nxt - 1]))
            sent_upto = max(sent_upto, nxt)
            nxt += 1
            unanswered += 1
        deadline = unit.next_deadline()
        if deadline is None or deadline > t + timeout:
            if t - last_progress > timeout:      # no answer: assume the ok was lost
                unanswered = max(0, unanswered - 1)
                last_progress = t
                if nxt > len(job) and not unanswered:
                    break
            t += 0.01
            continue
        t = max(t, deadline)
        if t > t0 + limit:
            break
        for when, data in unit.poll(t):
            if faults:
                outs = faults.feed("unit", data, when)
            else:
                outs = [(when, data)]
            for w, chunk in outs:
                r.unit.append((w, chunk))
                rest += chunk
        *lines, rest = rest.split(b"\n")
        for line in lines:
            if line.startswith(b"Resend:"):
                try:
                    nxt = int(line.split(b":")[1])
                except ValueError:
                    continue
                if wrong_resends:               # a sender bug: one past the line asked for
                    wrong_resends -= 1
                    nxt += 1
                unanswered = 0 if ahead == 1 else max(0, unanswered - 1)
                last_progress = t
            elif line.startswith(b"ok"):
                r.oks += 1
                unanswered = max(0, unanswered - 1)
                last_progress = t
                if restart_at is not None and r.oks == restart_at and not restarted:
                    restarted = True
                    unit.power_cycle(t)
                    t += 0.5
                    r.unit += unit.poll(t)
                    send(b"M110 N0\n")
                    nxt, unanswered = 1, 1
    r.end = t
    return r


def write_capture(path: str, r: SimResult, metadata: dict[str, Any] | None = None) -> None:
    """The simulated session as a capture file (both directions, their times kept)."""
    from conform.capture import Recorder

    events = sorted([(t, 0, "host", d) for t, d in r.host] + [(t, 1, "unit", d) for t, d in r.unit],
                    key=lambda e: (e[0], e[1]))
    clock = [events[0][0] if events else 0.0]
    rec = Recorder(path, {"capture_method": "simulation", **(metadata or {})}, decode=False,
                   clock=lambda: clock[0])
    for t, _, direction, data in events:
        clock[0] = t
        rec.chunk(direction, data, t_read=t)
    rec.close({})
