"""One run of the user's program in one scenario, on a real pty, on the wall clock.

    emulator thread (reference unit + scripted faults, ground truth)  <- its pty ->
    proxy (conform proxy's Forwarder + Recorder: the capture)          <- its pty ->
    the program (any language), given the proxy's pty as {port} / CONFORM_PORT

The scenario's actions (press stop, kill the link) fire when a share of the job's vectors
has been accepted. A program still running at the timeout is stopped (SIGTERM, then
SIGKILL to its process group). Afterwards the unit's remaining queue is run out in virtual
time, the ground truth is written beside the capture, and the capture is analysed — each by
the family's hooks (``observe``, ``settle``, ``analyze``: conform.sendercheck.family).
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from conform.capture.live import ProxyCapture
from conform.emulator.control import LocalControl
from conform.emulator.serve import Emulator
from conform.link.faults import FaultConfig
from conform.link.pty import PtyEndpoint
from conform.sendercheck.family import Family, Scenario
from conform.sendercheck.faults import ScriptedFaults

POLL = 0.02  # how often the runner looks at the program and the scenario's triggers
KILL_GRACE = 2.0  # seconds between SIGTERM and SIGKILL


@dataclass
class Session:
    """Everything the rules look at for one scenario."""

    scenario: Scenario
    family: Family
    variant: Any
    command: list[str]
    directory: Path
    capture: Path
    job_lines: list[str]
    job: list[tuple[str, tuple[int, ...]]]
    exit_code: int | None = None
    hung: bool = False
    duration: float = 0.0
    timeout: float = 0.0
    truth: dict[str, Any] = field(default_factory=dict)
    events: list[dict[str, Any]] = field(default_factory=list)
    analysis: Any = None
    analysis_error: str = ""
    comparison: Any = None  # the family's job-against-truth comparison (``summary()``)
    faults: dict[str, int] = field(default_factory=dict)
    error: str = ""  # the harness failed (not the program)
    started: float = 0.0  # monotonic time the program was started

    @property
    def findings(self) -> list[Any]:
        return list(self.analysis.findings) if self.analysis is not None else []

    def count(self, kind: str) -> int:
        if self.analysis is None:
            return 0
        return int(self.analysis.metrics.get("finding_counts", {}).get(kind, 0))

    def of_kind(self, kind: str) -> list[Any]:
        return [f for f in self.findings if f.kind == kind]


def _argv(command: list[str], port: str, job: Path, variant: str) -> list[str]:
    subst = {"{port}": port, "{job}": str(job), "{variant}": variant}
    out = []
    for arg in command:
        for k, v in subst.items():
            arg = arg.replace(k, v)
        out.append(arg)
    return out


def _stop(proc: subprocess.Popen) -> None:
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


def run_session(family: Family, scn: Scenario, variant: Any, dialect: Any,
                command: list[str], directory: Path, *, timeout: float | None = None,
                seed: int = 1, baud: int = 115200, job_lines: list[str] | None = None
                ) -> Session:
    """Run ``command`` once against the reference unit in scenario ``scn``."""
    directory.mkdir(parents=True, exist_ok=True)
    lines = job_lines if job_lines is not None else family.job(scn, variant)
    job_path = directory / "job.txt"
    job_path.write_text("\n".join(lines) + "\n", encoding="ascii")
    s = Session(scn, family, variant, list(command), directory, directory / "session.mcap", lines,
                family.vectors(lines), timeout=timeout if timeout is not None else scn.timeout)
    t0 = time.monotonic()
    unit = family.make_unit(variant, dialect, t0)
    truth = family.observe(unit, t0)
    family.prepare(unit, scn, t0)
    cfg = FaultConfig.parse(scn.faults) if scn.faults else FaultConfig()
    faults = ScriptedFaults(cfg, seed, t0, lose=scn.lose)
    control = LocalControl()
    endpoint = PtyEndpoint()
    emulator = Emulator(unit, endpoint, baud=baud, injector=faults, control=control,
                        control_handler=family.commands)
    died: list[str] = []

    def serve() -> None:
        try:
            emulator.run()
        except Exception as exc:  # noqa: BLE001 - the reference unit failing is a harness ERROR
            died.append(f"the emulator stopped: {type(exc).__name__}: {exc}")

    thread = threading.Thread(target=serve, name="check-sender-unit", daemon=True)
    thread.start()
    proxy = None
    try:
        proxy = ProxyCapture(endpoint.path, s.capture, baud=baud, variant=variant.id)
        proxy.recorder.log("info", f"check-sender scenario {scn.name}: {scn.title}")
        _run_program(s, proxy, control, faults, truth, job_path)
    except Exception as exc:  # noqa: BLE001 - the harness failing is graded ERROR, not a crash
        s.error = f"{type(exc).__name__}: {exc}"
    finally:
        if proxy is not None:
            proxy.stop()
            proxy.close()
        emulator.stop()
        thread.join(5.0)
    if died and not s.error:
        s.error = died[0]
    s.faults = dict(faults.counts)
    family.settle(s, unit, truth)
    if s.capture.exists():
        try:
            s.analysis = family.analyze(s.capture, variant.id)
        except Exception as exc:  # noqa: BLE001 - reported, the truth still grades
            s.analysis_error = f"{type(exc).__name__}: {exc}"
    return s


def _run_program(s: Session, proxy: ProxyCapture, control: LocalControl, faults: ScriptedFaults,
                 truth: Any, job_path: Path) -> None:
    scn = s.scenario
    env = dict(os.environ, CONFORM_PORT=proxy.host_path, CONFORM_JOB=str(job_path),
               CONFORM_VARIANT=s.variant.id, CONFORM_SCENARIO=scn.name)
    argv = _argv(s.command, proxy.host_path, job_path, s.variant.id)
    n_job = max(1, len(s.job))
    pending = sorted(scn.actions, key=lambda a: a.at)
    undo: list[tuple[float, str]] = []
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
            _supervise(s, proc, start, truth, n_job, pending, undo, control, faults, proxy)
        except BaseException:   # check-sender itself stopped (Ctrl-C, SIGTERM): so is the program
            _stop(proc)
            raise
    for _t, kind in undo:
        _act(s, kind, False, time.monotonic(), control, faults, proxy, 0.0)
    s.duration = time.monotonic() - start


def _supervise(s: Session, proc: subprocess.Popen, start: float, truth: Any, n_job: int,
               pending: list, undo: list[tuple[float, str]], control: LocalControl,
               faults: ScriptedFaults, proxy: ProxyCapture) -> None:
    """Wait for the program, firing the scenario's actions as the job progresses."""
    while True:
        try:
            s.exit_code = proc.wait(POLL)
            return
        except subprocess.TimeoutExpired:
            pass
        now = time.monotonic()
        if now - start > s.timeout:
            s.hung = True
            _stop(proc)
            s.exit_code = proc.returncode
            return
        done = len(truth.accepted) / n_job
        while pending and done >= pending[0].at:
            act = pending.pop(0)
            undo.append((now + act.hold, act.kind))
            _act(s, act.kind, True, now, control, faults, proxy, act.hold)
        for item in [u for u in undo if u[0] <= now]:
            undo.remove(item)
            _act(s, item[1], False, now, control, faults, proxy, 0.0)


def _act(s: Session, kind: str, on: bool, now: float, control: LocalControl,
         faults: ScriptedFaults, proxy: ProxyCapture, hold: float) -> None:
    t = round(now - s.started, 6)
    if kind == "stop":
        reply = control.ask(s.family.control_line(kind, on, s.variant))
        if not reply.startswith("ok") and not s.error:
            s.error = f"the scenario's input could not be set: {reply}"
        what = "stop input pressed" if on else "stop input released"
    else:
        if on:
            faults.kill_link(now, hold)
        reply = "ok"
        what = f"line dead for {hold:g} s" if on else "line back"
        proxy.recorder.link_event("disconnect" if on else "reconnect",
                                  f"check-sender: {what}", side="unit")
    proxy.recorder.log("info", f"check-sender: {what} ({reply})")
    s.events.append({"t_abs": now, "t": t, "event": what, "reply": reply})
