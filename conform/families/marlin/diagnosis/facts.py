"""The Marlin analysis of a capture as the diagnosis's neutral facts.

Every host line is one exchange, answered by the ``ok`` the analysis paired with it (queue.cpp
answers each line it takes, in order), or refused (``Error:`` + ``Resend:``, the line sent
again later under its number: a later try answers it). What the findings become:

* a resend storm (many ``Resend:`` requests, few lines taken) and checksum errors: damaged
  bytes (``noise``);
* a numbered line never taken though the session went on: a proven loss (``loss``);
* lines run twice, numbers skipped or repeated without a request: the host's ``misuse``;
* ``Error:Printer halted. kill() called!``: the unit's own kill (``alarm``) unless the host
  sent M112 just before (its emergency stop: ``halt``, as is M410 quickstop);
* a number sent again that the unit did not take is no answered line: it was dropped silently;
  when the first copy was taken and its ``ok`` never came, that silence proves the ``ok`` lost;
* ``echo:busy:`` keepalives: the unit says it is working (``running``); ``M400`` answered
  ``ok``: every move has ended (gcode M400 ``planner.synchronize()``): ``idle``;
* a host that numbered its lines and then sends job lines without a number (``unguarded``):
  queue.cpp checks the number and checksum only of a line that starts with ``N``, so from then
  on a line lost or damaged on the way is taken (or missed) without a word and never asked
  again. Queries and emergency commands sent unnumbered beside a numbered job are no such run
  (printcore's ``send_now`` M105; M108/M112/M410 act at once only unnumbered).
"""

from __future__ import annotations

from typing import Any

from conform.diagnosis.facts import Event, Exchange, Facts

MOTION = ("G0", "G1", "G2", "G3", "G5", "G28")
HALTS = ("M112", "M410")
# lines a host sends beside its numbered job without a number, rightly: queries, the
# emergency commands (queue.cpp acts on them early only when unnumbered) and M110 itself
OUT_OF_BAND = ("M105", "M114", "M115", "M119", "M27", "M31", "M155", "M876", "M108", "M112",
               "M410", "M110")
NUMBERED_FIRST = 2          # numbered lines before unnumbered ones count as numbering stopped
KILL_AFTER_HALT_S = 2.0     # a kill this soon after the host's M112 is that M112's
ALONGSIDE_MAX = 200_000     # host lines up to which `conform analyze` also diagnoses
EVENT_OF = {"resend-storm": "noise", "never-ran": "loss", "ran-twice": "misuse",
            "number-gap": "misuse", "repeat-unasked": "misuse", "reset": "reset"}


def _word(text: str) -> str:
    head = text.split()[0] if text.split() else ""
    return head.upper()


def facts(raw: Any, path: str, *, variant: str | None = None, analysis: Any = None) -> Facts:
    from conform.families.marlin.analysis.analyze import analyze_capture
    from conform.families.marlin.spec import load_marlin

    if analysis is not None and not getattr(analysis, "lines_kept", False) and \
            int(analysis.metrics.get("host_lines", 0)) > ALONGSIDE_MAX:
        from conform.errors import UserError

        # `conform analyze` streamed it in bounded memory: keeping every line now would undo
        # that; `conform diagnose` reads it whole on its own
        raise UserError(f"not made alongside the analysis of a capture this long "
                        f"(`conform diagnose {path}`)")
    a = analysis if analysis is not None and getattr(analysis, "lines_kept", False) else \
        analyze_capture(path, variant=variant, keep_lines=True)
    firsts = [float(d.t_read[0]) for d in (raw.host, raw.unit) if len(d.t_read)]
    t0 = min(firsts, default=0.0)
    ex: list[Exchange] = []
    events: list[Event] = []
    for x in a.lines:
        word = _word(x.text)
        # refused: answered by Error/Resend; a number sent again that it did not take was
        # ignored without a word (queue.cpp: the last numbers again are dropped silently)
        answered = x.t_ok is not None or (not x.accepted and not x.repeat)
        e = Exchange(x.seq, x.text if x.n is None else f"N{x.n} {x.text}", x.t - t0,
                     None if not answered else ((x.t_ok or x.t) - t0),
                     None if not answered else ("ok" if x.accepted else "Resend"),
                     None if not answered else bool(x.accepted), word in MOTION)
        ex.append(e)
        if word in HALTS:
            events.append(Event(e.t_sent, "halt", f"the host sent `{x.text}` ("
                                + ("emergency stop: kill()" if word == "M112" else
                                   "quickstop: the planner emptied") + ")",
                                "gcode/control M112 kill(), M410 quickstop_stepper",
                                line=e.n))
        if word == "M400" and x.t_ok is not None:
            events.append(Event(x.t_ok - t0, "idle", "`M400` answered ok: every move has "
                                "ended", "gcode M400 planner.synchronize()", line=e.n))
    events += _lost_oks(a.lines, ex)
    events += _unnumbered(a.lines, ex)
    halts = [ev.t for ev in events if ev.kind == "halt"]
    offset = (a.lines[0].t - t0) if a.lines else 0.0     # findings count from the first line
    for f in a.findings:
        t = float(f.t) + offset
        if f.kind == "halted":
            by_host = any(0 <= t - h <= KILL_AFTER_HALT_S for h in halts)
            if not by_host:
                events.append(Event(t, "alarm", "the unit halted: kill() called, it answers "
                                    "nothing until reset", f.clause))
            continue
        if f.kind == "never-ran" and not f.extra.get("confirmed"):
            continue        # the capture ends first: not proven
        kind = EVENT_OF.get(f.kind)
        if kind is None:
            continue
        extra = {"proof": "never taken"} if kind == "loss" else {}
        if f.kind == "resend-storm":
            extra = {"count": int(f.extra.get("requests", 1))}
        t_end = float(f.extra["end"]) + offset if "end" in f.extra else None
        events.append(Event(t, kind, f.message, f.clause, t_end=t_end, extra=extra))
    events += _busy(raw, t0)
    spec = load_marlin()
    v = spec.variant(a.variant)
    return Facts("marlin", a.variant, path, float(a.metrics["duration_s"]) + offset, ex,
                 events, t0=t0, rx_capacity=v.rx_buffer, queue_capacity=v.bufsize,
                 queue_unit="commands", answer_time=0.5, notes=list(a.notes))


def _lost_oks(lines: list[Any], ex: list[Exchange]) -> list[Event]:
    """Proof of a lost ``ok``: a number the unit took, whose ``ok`` never came, sent again and
    met with silence. queue.cpp drops a number it has already taken without a word, so the
    silence says the unit had the line: its answer was lost on the way back."""
    out: list[Event] = []
    first: dict[tuple[int, int], Any] = {}
    for x, e in zip(lines, ex, strict=True):
        if x.n is None:
            continue
        key = (x.epoch, x.n)
        if key not in first:
            first[key] = x
            continue
        orig = first[key]
        if x.repeat and not x.accepted and x.t_ok is None and orig.accepted and \
                orig.t_ok is None:
            out.append(Event(e.t_sent, "loss", f"N{x.n} sent again got no answer: the unit "
                             "had taken it (it drops a number it has taken silently), so its "
                             "`ok` was lost on the way back", "queue.cpp get_serial_commands",
                             line=e.n, extra={"proof": "ok lost"}))
            first[key] = x          # one proof per number
    return out


def _unnumbered(lines: list[Any], ex: list[Exchange]) -> list[Event]:
    """Runs of job lines sent without a number after the host had numbered its own
    (``unguarded``, one event per run): the numbering stopped, for good or for a while."""
    out: list[Event] = []
    numbered: list[Exchange] = []
    run: list[Exchange] = []

    def close() -> None:
        if not run:
            return
        last, first = numbered[-1], run[0]
        moves = sum(e.motion for e in run)
        out.append(Event(
            first.t_sent, "unguarded",
            f"the host numbered its lines up to line {last.n + 1} `{last.text}` at "
            f"{last.t_sent:.3f} s, then sent {len(run)} job line(s) without a number, from "
            f"line {first.n + 1} `{first.text}` at {first.t_sent:.3f} s ({moves} move(s)): "
            "Marlin cannot ask for one of them again (no Resend without a number), so a line "
            "lost or damaged on the way goes unnoticed",
            "queue.cpp get_serial_commands (only a line starting with N has its number and "
            "checksum checked)", t_end=run[-1].t_sent, line=first.n,
            extra={"count": len(run), "moves": moves, "last_numbered": last.n}))
        run.clear()

    for x, e in zip(lines, ex, strict=True):
        if x.n is not None:
            close()
            numbered.append(e)
        elif len(numbered) >= NUMBERED_FIRST and _word(x.text) not in OUT_OF_BAND:
            run.append(e)
    close()
    return out


def _busy(raw: Any, t0: float) -> list[Event]:
    """``echo:busy:`` keepalives (gcode.cpp host_keepalive, every 2 s while a command blocks):
    the unit is working. One event per keepalive."""
    from conform.families.marlin.analysis.records import iter_lines

    data = raw.unit.data.tobytes()
    chunks = ((float(r), data[s:s + n]) for s, n, r in
              zip(raw.unit.start.tolist(), raw.unit.length.tolist(), raw.unit.t_read.tolist(),
                  strict=True))
    return [Event(t - t0, "running", f"the unit says `{line.decode('latin-1').strip()}`",
                  "gcode.cpp host_keepalive") for t, line in iter_lines(chunks)
            if line.startswith(b"echo:busy:")]
