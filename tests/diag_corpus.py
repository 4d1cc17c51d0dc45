"""The diagnosis's labelled corpus: sessions whose ending is known because the test made it.

Each entry is (name, family, label, capture): ``label`` is ``completed`` for a session that
ran to its end and shows it (a program end, the unit idle), ``ended`` for one whose every line
was answered but whose end the wire cannot show (a job without an end word; a sender stopped
between lines leaves the same trace): for both no stop cause may lead and no loss may be
claimed. Otherwise the label is the cause kind that must lead (the stop cause, or the first
hazard of a session that completed despite the fault).

* ``fast()``: in-process on the virtual clock (tests/diag_sessions.py): clean sessions of the
  scripted senders of each family, and each injected fault;
* ``samples()``: the project's own captures/ and the real-firmware recordings in
  ../shared/recordings (Marlin 2.1.2.4: ``conform send`` and printcore, completed);
* ``proxied()``: real programs through ``conform proxy`` over ptys (tests/diag_proxy.py):
  ``conform send`` (grbl both methods, GVE, Marlin), grbl-streamer both modes, a stream.py-like
  sender, printcore, and ``conform send`` stopped by SIGTERM (its own halt).
"""

from __future__ import annotations

import os
import signal
import tempfile
from pathlib import Path

from diag_sessions import (
    Faults,
    drive,
    grbl_job,
    grbl_sender,
    grbl_unit,
    gve_job,
    gve_sender,
    gve_unit,
    marlin_job,
    marlin_sender,
    marlin_unit,
    record,
)

REPO = Path(__file__).resolve().parents[1]
RECORDINGS = Path(os.environ.get("CONFORM_RECORDINGS",
                                 REPO.parent.parent / "shared" / "recordings"))
if not RECORDINGS.exists():
    RECORDINGS = Path("/work/shared/recordings")
GRBL, GVE, MARLIN = "grbl-1.1f", "gve64-v19", "marlin-2.1"

Entry = tuple[str, str, str, Path]


def fast(d: Path) -> list[Entry]:
    """In-process sessions, labelled."""
    d.mkdir(parents=True, exist_ok=True)
    out: list[Entry] = []

    def add(name: str, family: str, label: str, ses, variant: str, **kw) -> None:
        out.append((name, family, label, record(d / f"{name}.mcap", ses, variant, **kw)))

    poll = (0.2, b"?")
    # clean sessions; a sender that finished closes its port too (the proxy records it): once
    # read as "sender-stopped (0.95) ... it closed its port"
    ses = drive(grbl_unit(), grbl_job(40), grbl_sender(poll=poll), tail=1.5)
    add("grbl-counting", "grbl", "completed", ses, GRBL, sender_closed=ses.host[-1][0] + 0.2)
    ses = drive(grbl_unit(), grbl_job(30), grbl_sender(window=None, poll=poll), tail=1.5)
    add("grbl-send-response", "grbl", "completed", ses, GRBL,
        sender_closed=ses.host[-1][0] + 0.2)
    add("grbl-no-polls", "grbl", "completed", drive(grbl_unit(), grbl_job(8), grbl_sender(),
                                                     tail=1.0), GRBL)
    ses = drive(gve_unit(), gve_job(60), gve_sender(), tail=1.0)
    add("gve-simplex", "gve", "ended", ses, GVE)      # the scripted sender asks no F at the end
    ses = drive(gve_unit(), gve_job(60, checksums=True), gve_sender(), tail=1.0)
    add("gve-checksums", "gve", "ended", ses, GVE)
    # injected faults
    ses = drive(grbl_unit(), grbl_job(80), grbl_sender(poll=poll), Faults(kill_after=40),
                tail=3.0)
    add("grbl-sender-killed", "grbl", "sender-stopped", ses, GRBL)
    ses = drive(gve_unit(), gve_job(30), gve_sender(), Faults(kill_after=20), tail=2.0)
    add("gve-sender-killed", "gve", "ended", ses, GVE,      # between lines: no trace
        sender_closed=ses.host[-1][0] + 0.01)
    add("gve-unit-frozen", "gve", "unit-silent",
        drive(gve_unit(), gve_job(80), gve_sender(), Faults(mute_unit_at=0.08), tail=3.0), GVE)
    add("grbl-unit-frozen", "grbl", "unit-silent",
        drive(grbl_unit(), grbl_job(80), grbl_sender(), Faults(mute_unit_at=0.3), tail=3.0),
        GRBL)
    add("gve-cable-pulled", "gve", "link-lost",
        drive(gve_unit(), gve_job(300), gve_sender(timeout=0.3), Faults(cut=(0.1, 2.1)),
              tail=1.0), GVE)
    add("gve-cable-pulled-sniffed", "gve", "link-lost",
        drive(gve_unit(), gve_job(300), gve_sender(timeout=0.3),
              Faults(cut=(0.1, 2.1), cut_events=False), tail=1.0), GVE)
    add("grbl-cable-pulled", "grbl", "link-lost",
        drive(grbl_unit(), grbl_job(80), grbl_sender(poll=poll),
              Faults(cut=(1.0, 3.0), cut_events=False), tail=3.0, t_max=8.0), GRBL)
    add("gve-noise", "gve", "noise", drive(gve_unit(), gve_job(200, checksums=True),
                                           gve_sender(), Faults(noise=(0.3, 0.6)), tail=0.5),
        GVE)
    job = [b"G21G90G54F3000\n"] + [b"G1X%gY%g\n" % ((i % 10) * 0.5, (i % 7) * 0.25)
                                   for i in range(600)]
    add("grbl-overflow", "grbl", "buffer-overflow",
        drive(grbl_unit(settings={120: 2000.0, 121: 2000.0, 122: 2000.0}), job,
              grbl_sender(window=10**9), tail=1.0), GRBL)
    job = grbl_job(30)
    job.insert(12, b"G38.2Z-5F100\n")
    add("grbl-alarm", "grbl", "unit-alarm",
        drive(grbl_unit(), job, grbl_sender(poll=poll,
                                            stop_on=lambda a: a.startswith(b"error")),
              tail=3.0), GRBL)
    add("grbl-deadlock", "grbl", "deadlock",
        drive(grbl_unit(), grbl_job(80), grbl_sender(poll=poll), Faults(realtime={0.6: b"!"}),
              tail=3.0, t_max=6.0), GRBL)
    # the sender's own halt: feed hold and soft reset, then it stops (what `conform send`
    # does on SIGTERM)
    ses = drive(grbl_unit(), grbl_job(80), grbl_sender(poll=poll),
                Faults(kill_after=30, realtime={0.5: b"!", 0.6: b"\x18"}), tail=2.0)
    add("grbl-sender-halt", "grbl", "sender-stopped", ses, GRBL,
        sender_closed=ses.host[-1][0] + 0.05)
    ses = drive(gve_unit(), gve_job(60, size=3000) + [b"!0H\r"], gve_sender(), tail=2.0)
    add("gve-sender-halt", "gve", "sender-stopped", ses, GVE,
        sender_closed=ses.host[-1][0] + 0.05)
    # Marlin: ok-paced, numbered with checksums (as printcore) or plain
    ses = drive(marlin_unit(), marlin_job(60), marlin_sender(), tail=1.0)
    add("marlin-numbered", "marlin", "completed", ses, MARLIN,
        sender_closed=ses.host[-1][0] + 0.1)
    add("marlin-plain", "marlin", "completed",
        drive(marlin_unit(), marlin_job(60, numbered=False), marlin_sender(), tail=1.0), MARLIN)
    add("marlin-noise", "marlin", "noise",
        drive(marlin_unit(), marlin_job(200), marlin_sender(), Faults(noise=(0.3, 0.8)),
              tail=3.0, t_max=30.0), MARLIN)
    ses = drive(marlin_unit(), marlin_job(100), marlin_sender(), Faults(kill_after=40),
                tail=3.0)
    add("marlin-sender-killed", "marlin", "ended", ses, MARLIN,    # between lines
        sender_closed=ses.host[-1][0] + 0.05)
    add("marlin-unit-frozen", "marlin", "unit-silent",
        drive(marlin_unit(), marlin_job(100), marlin_sender(), Faults(mute_unit_at=0.3),
              tail=3.0), MARLIN)
    add("marlin-busy-forever", "marlin", "unit-busy",
        drive(marlin_unit(), marlin_job(100), marlin_sender(),
              Faults(unit_calls={0.3: lambda u, t: u.stall(t, 1e4)}), tail=3.0, t_max=12.0),
        MARLIN)
    add("marlin-unit-kill", "marlin", "unit-alarm",
        drive(marlin_unit(), marlin_job(100), marlin_sender(),
              Faults(unit_calls={0.3: lambda u, t: u._kill(t)}), tail=3.0), MARLIN)
    job = marlin_job(100, numbered=False)
    job.insert(40, b"M112\n")
    ses = drive(marlin_unit(), job, marlin_sender(), tail=2.0)
    add("marlin-sender-m112", "marlin", "sender-stopped", ses, MARLIN,
        sender_closed=ses.host[-1][0] + 0.5)
    # an ok lost on the way back; the sender asks again after 1 s and meets silence
    add("marlin-lost-ok", "marlin", "lost-line",
        drive(marlin_unit(), marlin_job(60), marlin_sender(timeout=1.0),
              Faults(drop_answer={20}), tail=3.0, t_max=8.0), MARLIN)
    add("marlin-cable-pulled", "marlin", "link-lost",
        drive(marlin_unit(), marlin_job(300), marlin_sender(timeout=1.0),
              Faults(cut=(0.3, 2.3)), tail=1.0, t_max=12.0), MARLIN)
    # a sender that stops numbering part way: a hazard while every line is answered; the
    # stop cause once an unnumbered line goes missing (the unit, reporting its temperatures,
    # alive, never asks for it)
    add("marlin-numbering-stopped", "marlin", "numbering-stopped",
        drive(marlin_unit(), marlin_job(60, until=25), marlin_sender(), tail=1.0), MARLIN)
    add("marlin-unnumbered-line-lost", "marlin", "numbering-stopped",
        drive(marlin_unit(), marlin_job(60, until=25, report=True), marlin_sender(),
              Faults(alter={40: b""}), tail=3.0, t_max=8.0), MARLIN)
    return out


def varied(d: Path, k: int = 3, seed: int = 7) -> list[Entry]:
    """``k`` more sessions of each kind, their parameters drawn at random (seeded) rather than
    the ones the rules were written against: job lengths, polling, when the fault strikes and
    for how long. A held-out check of ``fast``."""
    import random

    rng = random.Random(seed)
    later = random.Random(seed + 1)     # kinds added later draw apart: the others stay put
    d.mkdir(parents=True, exist_ok=True)
    out: list[Entry] = []

    def add(name: str, family: str, label: str, ses, variant: str, closed: float | None = None
            ) -> None:
        path = record(d / f"{name}.mcap", ses, variant,
                      sender_closed=None if closed is None else ses.host[-1][0] + closed)
        out.append((name, family, label, path))

    def u(a: float, b: float) -> float:
        return round(rng.uniform(a, b), 3)

    for i in range(k):
        n = rng.randrange(20, 90)
        poll = (u(0.1, 0.5), b"?")
        add(f"v{i}-grbl-clean", "grbl", "completed",
            drive(grbl_unit(), grbl_job(n), grbl_sender(window=rng.randrange(40, 128),
                                                        poll=poll), tail=1.5), GRBL)
        add(f"v{i}-gve-clean", "gve", "ended",
            drive(gve_unit(), gve_job(n, checksums=rng.random() < 0.5), gve_sender(),
                  tail=1.0), GVE)
        add(f"v{i}-marlin-clean", "marlin", "completed",
            drive(marlin_unit(), marlin_job(n, numbered=rng.random() < 0.5), marlin_sender(),
                  tail=1.0), MARLIN)
        # killed once its polls show the unit running (before that: no trace, as above)
        add(f"v{i}-grbl-killed", "grbl", "sender-stopped",
            drive(grbl_unit(), grbl_job(80), grbl_sender(poll=(u(0.05, 0.2), b"?")),
                  Faults(kill_after=rng.randrange(30, 70)), tail=3.0), GRBL)
        add(f"v{i}-gve-killed", "gve", "ended",
            drive(gve_unit(), gve_job(60), gve_sender(), Faults(kill_after=rng.randrange(5, 55)),
                  tail=2.0), GVE, closed=u(0.005, 0.5))
        add(f"v{i}-marlin-killed", "marlin", "ended",
            drive(marlin_unit(), marlin_job(100), marlin_sender(),
                  Faults(kill_after=rng.randrange(10, 90)), tail=3.0), MARLIN,
            closed=u(0.005, 0.5))
        add(f"v{i}-gve-frozen", "gve", "unit-silent",
            drive(gve_unit(), gve_job(200), gve_sender(), Faults(mute_unit_at=u(0.05, 0.4)),
                  tail=3.0), GVE)
        add(f"v{i}-grbl-frozen", "grbl", "unit-silent",
            drive(grbl_unit(), grbl_job(80), grbl_sender(), Faults(mute_unit_at=u(0.1, 1.0)),
                  tail=3.0), GRBL)
        add(f"v{i}-marlin-frozen", "marlin", "unit-silent",
            drive(marlin_unit(), marlin_job(100), marlin_sender(),
                  Faults(mute_unit_at=u(0.1, 1.0)), tail=3.0), MARLIN)
        t, span = u(0.1, 1.0), u(1.5, 3.0)
        g = u(0.05, 0.3)        # while the GVE job runs (300 lines take about 0.5 s)
        add(f"v{i}-gve-cut", "gve", "link-lost",
            drive(gve_unit(), gve_job(300), gve_sender(timeout=0.3),
                  Faults(cut=(g, g + span), cut_events=rng.random() < 0.5), tail=1.0), GVE)
        add(f"v{i}-grbl-cut", "grbl", "link-lost",
            drive(grbl_unit(), grbl_job(80), grbl_sender(poll=poll),
                  Faults(cut=(t, t + span), cut_events=False), tail=3.0, t_max=8.0), GRBL)
        add(f"v{i}-marlin-cut", "marlin", "link-lost",
            drive(marlin_unit(), marlin_job(300), marlin_sender(timeout=1.0),
                  Faults(cut=(t, t + span)), tail=1.0, t_max=12.0), MARLIN)
        t = u(0.05, 0.25)       # while the job runs
        add(f"v{i}-gve-noise", "gve", "noise",
            drive(gve_unit(), gve_job(200, checksums=True), gve_sender(),
                  Faults(noise=(t, t + u(0.2, 0.5)), seed=rng.randrange(100)), tail=0.5), GVE)
        add(f"v{i}-marlin-noise", "marlin", "noise",
            drive(marlin_unit(), marlin_job(200), marlin_sender(),
                  Faults(noise=(t, t + u(0.2, 0.5)), seed=rng.randrange(100)), tail=3.0,
                  t_max=30.0), MARLIN)
        job = [b"G21G90G54F3000\n"] + [b"G1X%gY%g\n" % ((j % 10) * 0.5, (j % 7) * 0.25)
                                       for j in range(rng.randrange(300, 700))]
        add(f"v{i}-grbl-overflow", "grbl", "buffer-overflow",
            drive(grbl_unit(settings={120: 2000.0, 121: 2000.0, 122: 2000.0}), job,
                  grbl_sender(window=10**9), tail=1.0), GRBL)
        job = grbl_job(30)
        job.insert(rng.randrange(3, 28), b"G38.2Z-5F100\n")
        add(f"v{i}-grbl-alarm", "grbl", "unit-alarm",
            drive(grbl_unit(), job, grbl_sender(poll=poll,
                                                stop_on=lambda a: a.startswith(b"error")),
                  tail=3.0), GRBL)
        add(f"v{i}-grbl-deadlock", "grbl", "deadlock",
            drive(grbl_unit(), grbl_job(80), grbl_sender(poll=poll),
                  Faults(realtime={u(0.3, 1.5): b"!"}), tail=3.0, t_max=6.0), GRBL)
        t = u(0.3, 1.5)
        add(f"v{i}-grbl-halt", "grbl", "sender-stopped",
            drive(grbl_unit(), grbl_job(80), grbl_sender(poll=poll),
                  Faults(kill_after=80, realtime={t: b"!", t + 0.1: b"\x18"}),
                  tail=2.0, t_max=t + 3.0), GRBL, closed=0.05)
        add(f"v{i}-gve-halt", "gve", "sender-stopped",
            drive(gve_unit(), gve_job(rng.randrange(10, 80), size=3000) + [b"!0H\r"],
                  gve_sender(), tail=2.0), GVE, closed=u(0.05, 0.5))
        job = marlin_job(100, numbered=False)
        job.insert(rng.randrange(5, 95), b"M112\n")
        add(f"v{i}-marlin-m112", "marlin", "sender-stopped",
            drive(marlin_unit(), job, marlin_sender(), tail=2.0), MARLIN, closed=u(0.05, 0.5))
        add(f"v{i}-marlin-lost-ok", "marlin", "lost-line",
            drive(marlin_unit(), marlin_job(80), marlin_sender(timeout=u(0.5, 2.0)),
                  Faults(drop_answer={rng.randrange(3, 70)}), tail=3.0, t_max=10.0), MARLIN)
        t = u(0.1, 1.0)
        add(f"v{i}-marlin-kill", "marlin", "unit-alarm",
            drive(marlin_unit(), marlin_job(100), marlin_sender(),
                  Faults(unit_calls={t: lambda unit, at: unit._kill(at)}), tail=3.0), MARLIN)
        until = later.randrange(3, 60)
        add(f"v{i}-marlin-numbering", "marlin", "numbering-stopped",
            drive(marlin_unit(), marlin_job(later.randrange(until + 1, 90), until=until),
                  marlin_sender(), tail=1.0), MARLIN)
        add(f"v{i}-marlin-unnumbered-lost", "marlin", "numbering-stopped",
            drive(marlin_unit(), marlin_job(80, until=until, report=True), marlin_sender(),
                  Faults(alter={later.randrange(until + 1, 80): b""}), tail=3.0,
                  t_max=round(later.uniform(6.0, 12.0), 3)), MARLIN)
        add(f"v{i}-marlin-busy", "marlin", "unit-busy",
            drive(marlin_unit(), marlin_job(100), marlin_sender(),
                  Faults(unit_calls={t: lambda unit, at: unit.stall(at, 1e4)}), tail=3.0,
                  t_max=t + 12.0), MARLIN)
    return out


def samples(d: Path | None = None) -> list[Entry]:
    """The project's sample captures and the real firmware's recorded sessions (the grbl
    transcripts made captures in ``d``, a new temporary folder by default)."""
    cap = REPO / "captures"
    out: list[Entry] = [(p.stem, "gve", "completed", p) for p in sorted(cap.glob("*.mcap"))
                        if not p.stem.startswith("grbl-")]
    out += [(p.stem, "grbl", "completed", p) for p in sorted(cap.glob("grbl-*.mcap"))]
    marlin = RECORDINGS / "marlin-2.1.2.4"
    out += [(f"marlin-2.1.2.4-{p.stem}", "marlin", "completed", p)
            for p in sorted(marlin.glob("*.mcap"))]
    return out + grbl_recordings(d or Path(tempfile.mkdtemp(prefix="conform-diag-grbl-")))


# what each real grbl 1.1f recording (a session of probes, no job file) really was, read from
# the transcript: every line answered, the unit Idle at the end (``completed``), or every line
# answered with no status report after the last (``ended``)
GRBL_RECORDED = {
    "errors": "completed",          # error codes provoked; resets mid-move (ALARM:3), $X
    "modal-reset": "completed",     # modal groups set, soft resets while Idle, M2/M30
    "settings-edges": "ended",      # every $N setting tried; no status poll at all
    "status-fields": "completed",   # status report fields; ends Idle after M2
    "system": "completed",          # $ commands, sleep then a reset, $X; ends Idle
}


def grbl_recordings(d: Path) -> list[Entry]:
    """The real grbl 1.1f's recorded transcripts (recordings/grbl-1.1f) as captures,
    labelled with how each session really went (``GRBL_RECORDED``)."""
    from diag_sessions import from_transcript

    folder = RECORDINGS / "grbl-1.1f"
    if not folder.is_dir():
        return []
    d.mkdir(parents=True, exist_ok=True)
    return [(f"grbl-1.1f-{p.stem}", "grbl", GRBL_RECORDED[p.stem],
             from_transcript(p, d / f"{p.stem}.mcap", GRBL, "grbl"))
            for p in sorted(folder.glob("*.transcript"))]


# the proxied sessions in parts that can run side by side (each in its own directory, through
# its own proxies): ``proxied(d, part)`` runs one, ``proxied(d)`` all
PROXIED_PARTS = ("grbl-conform-send", "grbl-streamer", "grbl-other-senders",
                 "gve-marlin-conform-send", "marlin-senders")


def proxied(d: Path, part: str | None = None) -> list[Entry]:
    """Real programs through ``conform proxy`` (a minute or two of wall clock; a part of
    ``PROXIED_PARTS`` alone, a quarter of that)."""
    import importlib.util
    import sys

    from diag_proxy import conform_send, script
    from diag_proxy import proxied as run

    from conform.families.grbl.sendercheck.scenarios import default_job

    d.mkdir(parents=True, exist_ok=True)
    job = d / "job.gcode"
    job.write_text("\n".join(default_job(60)) + "\n")
    out: list[Entry] = []

    def add(name: str, family: str, label: str, variant: str, cmd: list[str], **kw) -> None:
        if part is not None and _proxied_part(name) != part:
            return
        cap, _r = run(d, variant, cmd, name=name, **kw)
        out.append((name, family, label, cap))

    add("grbl-conform-send-counting", "grbl", "completed", GRBL, conform_send(job))
    add("grbl-conform-send-send-response", "grbl", "completed", GRBL,
        conform_send(job, "--method", "send-response"))
    add("grbl-stream-py-like", "grbl", "completed", GRBL,
        script("stream_like.py", str(job), "settings"))
    if importlib.util.find_spec("grbl_streamer") is not None:
        for mode in ("incremental", "default"):
            add(f"grbl-streamer-{mode}", "grbl", "completed", GRBL,
                script("grbl_streamer_sender.py", str(job), mode))
    bcnc = _interpreter("CONFORM_BCNC_PYTHON", "bcnc", "bCNC")
    if bcnc:
        add("grbl-bcnc", "grbl", "completed", GRBL, script("bcnc_sender.py", str(job),
                                                           python=bcnc))
    big = d / "big.gcode"
    big.write_text("\n".join(default_job(2000)) + "\n")
    add("grbl-conform-send-sigterm", "grbl", "sender-stopped", GRBL, conform_send(big),
        signal_after=(4.0, signal.SIGTERM))
    gjob = REPO / "captures" / "jobs" / "part.nc"
    add("gve-conform-send", "gve", "completed", GVE, conform_send(gjob, "--accel", "3000"))
    mjob = d / "marlin.gcode"
    mjob.write_text("G90\n" + "".join(f"G1 X{i % 30}.{i % 10} Y{i % 7} F6000\n"
                                      for i in range(1, 120)) + "M400\n")
    add("marlin-conform-send", "marlin", "completed", "marlin-2.1", conform_send(mjob),
        baud=250000)
    if importlib.util.find_spec("printrun") is not None:
        add("marlin-printcore", "marlin", "completed", "marlin-2.1",
            [sys.executable, str(REPO / "tests" / "senders" / "marlin_printcore.py"), "{port}",
             str(mjob)], baud=250000)
    octo = _interpreter("CONFORM_OCTOPRINT_PYTHON", "octoprint", "octoprint.util.comm")
    if octo:
        add("marlin-octoprint", "marlin", "completed", "marlin-2.1",
            script("marlin_octoprint.py", str(mjob), python=octo), baud=250000)
    return out


def _proxied_part(name: str) -> str:
    """Which of ``PROXIED_PARTS`` the proxied session ``name`` belongs to."""
    for prefix in ("grbl-conform-send", "grbl-streamer"):
        if name.startswith(prefix):
            return prefix
    if name.startswith("grbl-"):
        return "grbl-other-senders"
    if name.endswith("-conform-send"):
        return "gve-marlin-conform-send"
    return "marlin-senders"


def _interpreter(env: str, venv: str, module: str) -> str | None:
    """An interpreter that has ``module``: $``env``, else /tmp/conform-senders/``venv``."""
    import subprocess

    path = os.environ.get(env) or f"/tmp/conform-senders/{venv}/bin/python"
    if not Path(path).exists():
        return None
    ok = subprocess.run([path, "-c", f"import {module}"], capture_output=True).returncode == 0
    return path if ok else None


CLEAN = ("completed", "ended")


def lead_of(doc: dict, label: str) -> str:
    """What the diagnosis puts first, against ``label``: for a clean session its outcome
    (``completed`` or ``ended``) when no stop cause leads (hazards may follow); for an
    injected one the leading cause's kind (the stop cause, or the first hazard of a session
    that completed despite the fault)."""
    if label in CLEAN and doc["outcome"]["kind"] in CLEAN and not doc["causes"]:
        return doc["outcome"]["kind"]
    lead = (doc["causes"] or doc["hazards"] or [{"kind": doc["outcome"]["kind"]}])[0]
    return lead["kind"]


# sessions whose lines really went unanswered: captures/README.md, a vector lost there on
# purpose; the real grbl's system recording puts it to sleep ($SLP) and sends $G and $X,
# which a sleeping grbl never answers (until the reset that follows)
def agreed(doc: dict, label: str) -> bool:
    """Whether what leads, taken as the diagnosis gives it whatever the label (the stop
    cause, else the outcome), agrees with ``label``: the cause is the labelled one; the outcome
    is the session's own, or it completed and its first hazard names the labelled fault."""
    if doc["causes"]:
        return doc["causes"][0]["kind"] == label
    kind = doc["outcome"]["kind"]
    if label in CLEAN:
        return kind == label
    return kind in CLEAN and bool(doc["hazards"]) and doc["hazards"][0]["kind"] == label


CALIBRATION_CORPUS = "fast + samples + varied(3, seed 7)"


def calibration_corpus(d: Path) -> list[Entry]:
    """The corpus the confidence table is measured on (conform/diagnosis/calibration.py)."""
    return fast(d / "fast") + samples(d / "samples") + varied(d / "varied", 3, seed=7)


REAL_LOSSES = {"careless-noisy", "grbl-1.1f-system"}


LOSS_WORDS = ("were lost", "was lost", "never answered", "never came", "bytes lost")


def false_claims(doc: dict) -> list[str]:
    """Sentences of a completed session's diagnosis that claim a loss or an unanswered line."""
    said = [doc["headline"], *(c["summary"] for c in doc["causes"] + doc["hazards"])]
    return [s for s in said if any(w in s for w in LOSS_WORDS)]


def judge(entries: list[Entry]) -> list[dict]:
    """Each entry diagnosed: name, family, label, what led, the claims it should not make."""
    from conform.diagnosis import diagnose

    rows = []
    for name, family, label, path in entries:
        doc = diagnose(str(path)).to_json()
        rows.append({"name": name, "family": family, "label": label,
                     "got": lead_of(doc, label), "key": doc["lead"]["key"],
                     "agreed": agreed(doc, label),
                     "outcome": doc["outcome"]["kind"], "headline": doc["headline"],
                     "false_claims": false_claims(doc) if label in CLEAN and
                     name not in REAL_LOSSES else [],
                     "resume": doc["resume"] is not None})
    return rows


def matrix(rows: list[dict]) -> dict[str, dict[str, int]]:
    """Confusion matrix: label -> what led -> count."""
    m: dict[str, dict[str, int]] = {}
    for r in rows:
        m.setdefault(r["label"], {}).setdefault(r["got"], 0)
        m[r["label"]][r["got"]] += 1
    return m
