"""One run of the user's program in one scenario, on a real pty, on the wall clock: the
supervisor every family's check-sender runs through.

    emulator thread (the family's reference unit + fault injector, ground truth, recording)
        <- its pty, reached through the symlink DIR/port ->  the program (any language)

The program gets the port as ``{port}`` / ``CONFORM_PORT`` (a symlink made again when the
emulator reopens the port) and the job as ``{job}`` / ``CONFORM_JOB``. The scenario's actions
fire when a share of the job's units has been taken by the unit (the family's ``steps`` turn
each into timed control requests). A program still running at the timeout is stopped (SIGTERM,
then SIGKILL to its process group); so is one still running when the run is interrupted. Afterwards
the family's hooks run the unit out and write the ground truth (``settle``), and analyse the
capture (``analyze``). A failure of the harness (not of the program) is kept in ``error``: every
rule of that scenario is then graded ERROR.
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from conform.capture.session import wire_time
from conform.emulator.control import LocalControl
from conform.emulator.launch import open_endpoint
from conform.errors import UserError
from conform.link.faults import FaultConfig
from conform.sendercheck.family import Analysis, Comparison, Family, Scenario, Variant
from conform.sendercheck.faults import ScriptedFaults

if TYPE_CHECKING:
    from conform.analysis.result import Finding
    from conform.capture.recorder import Recorder
    from conform.emulator.control import ControlHandler
    from conform.emulator.serve import SansIOUnit
    from conform.link.faults import FaultInjector

POLL = 0.02  # how often the runner looks at the program and the scenario's triggers
KILL_GRACE = 2.0  # seconds between SIGTERM and SIGKILL


@dataclass
class Session:
    """Everything the rules look at for one scenario (through the family's ``facts``)."""

    scenario: Scenario
    family: Family[Any, Any, Any]   # the family's own variant, context and truth types
    variant: Variant
    command: list[str]
    directory: Path
    capture: Path
    job_lines: list[str]
    job: Sequence[object]  # the job's units (the family's ``units`` of its lines)
    exit_code: int | None = None
    hung: bool = False
    duration: float = 0.0
    timeout: float = 0.0
    truth: object = field(default_factory=dict)  # the ground truth as written to truth.json
    events: list[dict[str, object]] = field(default_factory=list)  # the scenario's requests
    analysis: Analysis | None = None
    analysis_error: str = ""
    comparison: Comparison | None = None  # the family's job against the truth
    faults: dict[str, int] = field(default_factory=dict)
    error: str = ""  # the harness failed (not the program)
    started: float = 0.0  # monotonic time the program was started
    port: str = ""  # the path the program was given

    @property
    def findings(self) -> list[Finding]:
        return list(self.analysis.findings) if self.analysis is not None else []

    def count(self, kind: str) -> int:
        if self.analysis is None:
            return 0
        return int(self.analysis.metrics.get("finding_counts", {}).get(kind, 0))

    def of_kind(self, kind: str) -> list[Finding]:
        return [f for f in self.findings if f.kind == kind]


class PtyStamps:
    """The recorder as the emulator on a pty should use it: a host chunk's first byte is dated
    when it was read (the program wrote it at once), a unit chunk's a wire time before it was
    written (the emulator writes an answer once its last byte would have left the line), never
    before the last chunk either way (an answer cannot begin before the command was read).
    With ``baud`` 0 every chunk is dated when it was read or written."""

    def __init__(self, recorder: Recorder, baud: int) -> None:
        self.recorder = recorder
        self.baud = baud
        self._last = float("-inf")

    def chunk(self, direction: str, data: bytes, t_read: float | None = None,
              t_first: float | None = None) -> None:
        t = self.recorder.now() if t_read is None else t_read
        if t_first is None:
            t_first = t if direction == "host" else \
                max(t - wire_time(len(data), self.baud), min(self._last, t))
        self._last = t
        self.recorder.chunk(direction, data, t, t_first)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.recorder, name)


def argv_for(command: list[str], port: str, job: Path, variant: str) -> list[str]:
    """``{port}``, ``{job}`` and ``{variant}`` in the program's arguments filled in."""
    subst = {"{port}": port, "{job}": str(job), "{variant}": variant}
    out = []
    for arg in command:
        for k, v in subst.items():
            arg = arg.replace(k, v)
        out.append(arg)
    return out


def stop_program(proc: subprocess.Popen) -> None:
    """SIGTERM to its process group, SIGKILL after ``KILL_GRACE`` s."""
    for sig, wait in ((signal.SIGTERM, KILL_GRACE), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
        except (ProcessLookupError, PermissionError):
            return
        try:
            proc.wait(wait)
            return
        except subprocess.TimeoutExpired:
            continue


class _Control:
    """The emulator's control handler for a session: ``link dead S`` / ``link back`` (the
    engine's dead line, recorded as a disconnect and a reconnect), else the family's."""

    def __init__(self, family_handler: ControlHandler | None, faults: FaultInjector,
                 recorder: Recorder) -> None:
        self.family_handler = family_handler
        self.faults = faults
        self.recorder = recorder

    def __call__(self, unit: SansIOUnit, line: str, t: float) -> str:
        words = line.split()
        if words[:2] == ["link", "dead"] and len(words) == 3:
            if not hasattr(self.faults, "kill_link"):
                return "error: this scenario's faults cannot kill the line"
            hold = float(words[2])
            self.faults.kill_link(t, hold)
            self.recorder.link_event("disconnect", f"check-sender: line dead for {hold:g} s",
                                     side="unit")
            return "ok"
        if words == ["link", "back"]:
            self.recorder.link_event("reconnect", "check-sender: line back", side="unit")
            return "ok"
        if self.family_handler is None:
            return f"error: unknown request {line!r}"
        return self.family_handler(unit, line, t)


def run_session(family: Family[Any, Any, Any], scn: Scenario, variant: Variant, context: object,
                command: list[str], directory: Path, *, timeout: float | None = None,
                seed: int = 1, baud: int | None = None, job_lines: list[str] | None = None
                ) -> Session:
    """Run ``command`` once against the family's reference unit in scenario ``scn``, paced at
    ``baud`` (the family's line speed unless given)."""
    from conform.capture import Recorder
    from conform.emulator.serve import Emulator

    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{directory}: cannot create: {exc.strerror or exc}") from None
    baud = baud or family.baud
    lines = family.job(scn, variant, job_lines)
    job_path = directory / family.job_name
    job_path.write_text("\n".join(lines) + "\n", encoding="ascii")
    link = directory / "port"
    s = Session(scn, family, variant, list(command), directory, directory / "session.mcap",
                lines, family.units(lines),
                timeout=timeout if timeout is not None else scn.timeout, port=str(link))
    t0 = time.monotonic()
    unit = truth = faults = endpoint = recorder = None
    died: list[str] = []
    try:
        unit = family.make_unit(variant, context, t0, scn)
        truth = family.observe(unit, t0)
        family.prepare(unit, scn, t0)
        if family.injector is not None:
            faults = family.injector(scn, seed, t0)
        else:
            cfg = FaultConfig.parse(scn.faults) if scn.faults else FaultConfig()
            faults = ScriptedFaults(cfg, seed, t0, lose=scn.lose)
        endpoint, reopen_plain = open_endpoint(None, str(link))
        reopen = family.reopen(reopen_plain, unit, faults, truth) if family.reopen else \
            reopen_plain
        recorder = Recorder(s.capture, {
            "capture_method": "check-sender", "family": family.name, "variant": variant.id,
            "baud": baud, "unit_port": str(link), "scenario": scn.name, "seed": seed,
            "faults": scn.faults}, decode=family.decode, backdate=False)
        stamps = PtyStamps(recorder, baud if family.backdate else 0)
        control = LocalControl()
        emulator = Emulator(unit, endpoint, baud=baud, injector=faults, recorder=stamps,
                            control=control, reopen=reopen,
                            control_handler=_Control(family.control(faults), faults, recorder))
    except Exception as exc:  # noqa: BLE001 - the harness failing is graded ERROR, not a crash
        s.error = f"{type(exc).__name__}: {exc}"
        for opened in (endpoint, recorder):
            if opened is not None:
                opened.close()
        return s

    def serve() -> None:
        try:
            emulator.run()
        except Exception as exc:  # noqa: BLE001 - the reference unit failing is a harness ERROR
            died.append(f"the emulator stopped: {type(exc).__name__}: {exc}")

    thread = threading.Thread(target=serve, name="check-sender-unit", daemon=True)
    thread.start()
    try:
        recorder.log("info", f"check-sender scenario {scn.name}: {scn.title}")
        _run_program(s, recorder, control, truth, job_path, baud)
        if family.linger:
            time.sleep(family.linger)
    except Exception as exc:  # noqa: BLE001 - the harness failing is graded ERROR, not a crash
        s.error = s.error or f"{type(exc).__name__}: {exc}"
    finally:
        emulator.stop()
        thread.join(5.0)
        try:
            recorder.close({"bytes_in": emulator.bytes_in, "bytes_out": emulator.bytes_out,
                            **family.end_counts(unit)})
        except Exception as exc:  # noqa: BLE001 - a capture that could not be closed is an ERROR
            s.error = s.error or f"the recording failed: {type(exc).__name__}: {exc}"
    if died and not s.error:
        s.error = died[0]
    s.faults = dict(getattr(faults, "counts", {}))
    try:
        family.settle(s, unit, truth)
    except Exception as exc:  # noqa: BLE001 - no ground truth: the harness failed
        s.error = s.error or f"the ground truth failed: {type(exc).__name__}: {exc}"
    if s.capture.exists():
        try:
            s.analysis = family.analyze(s.capture, variant.id)
        except Exception as exc:  # noqa: BLE001 - reported, the truth still grades
            s.analysis_error = f"{type(exc).__name__}: {exc}"
    return s


def _run_program(s: Session, recorder: Recorder, control: LocalControl, truth: object,
                 job_path: Path, baud: int) -> None:
    scn = s.scenario
    env = dict(os.environ, CONFORM_PORT=s.port, CONFORM_JOB=str(job_path),
               CONFORM_VARIANT=s.variant.id, CONFORM_SCENARIO=scn.name,
               CONFORM_BAUD=str(baud))
    argv = argv_for(s.command, s.port, job_path, s.variant.id)
    n_job = max(1, len(s.job))
    pending = sorted(scn.actions, key=lambda a: a.at)
    due: list[tuple[float, str]] = []  # (monotonic time, control request)
    start = s.started = time.monotonic()
    with open(s.directory / "program.out", "wb") as out, \
            open(s.directory / "program.err", "wb") as err:
        try:
            proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=out, stderr=err,
                                    env=env, start_new_session=True)
        except OSError as exc:
            s.error = f"cannot start {argv[0]!r}: {exc.strerror or exc}"
            return
        try:
            while True:
                try:
                    s.exit_code = proc.wait(POLL)
                    break
                except subprocess.TimeoutExpired:
                    pass
                now = time.monotonic()
                if now - start > s.timeout:
                    s.hung = True
                    stop_program(proc)
                    s.exit_code = proc.returncode
                    break
                while pending and s.family.taken(truth) >= pending[0].at * n_job:
                    act = pending.pop(0)
                    due += [(now + dt, req) for dt, req in s.family.steps(act, s.variant)]
                    due.sort(key=lambda x: x[0])
                while due and due[0][0] <= now:
                    _ask(s, control, recorder, due.pop(0)[1], start)
        finally:  # an interrupted run (Ctrl-C) leaves no program behind
            if proc.poll() is None:
                stop_program(proc)
                s.exit_code = proc.returncode
            s.duration = time.monotonic() - start


def _ask(s: Session, control: LocalControl, recorder: Recorder, request: str, start: float) -> None:
    reply = control.ask(request)
    s.events.append({"t": recorder.now(), "t_run": round(time.monotonic() - start, 3),
                     "request": request, "reply": reply})
    recorder.log("info", f"check-sender: {request} ({reply})")
    if not reply.startswith("ok") and not s.error:
        s.error = f"the scenario's request {request!r} was refused: {reply}"
