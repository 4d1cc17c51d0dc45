"""One run of a grbl sender program in one scenario, on a real pty, on the wall clock.

    emulator thread (GrblUnit with ground truth + GrblFaults, recording session.mcap)
        <- its pty, reached through the symlink DIR/port ->  the program

The scenario's actions fire once a share of the job's lines has been taken by the unit:
``hold`` presses the machine's feed-hold button and, ``hold`` seconds later, cycle start;
``unplug`` pulls the cable for ``hold`` seconds (the pty closes; when it is back the board has
restarted). A program still running at the timeout is stopped (SIGTERM, then SIGKILL to its
process group). Afterwards the capture is analysed and the ground truth written beside it.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from conform.emulator.control import LocalControl
from conform.errors import UserError
from conform.families.grbl.analysis.analyze import GrblAnalysis, analyze_capture

POLL = 0.02   # how often the runner looks at the program and the scenario's triggers


@dataclass(frozen=True)
class Action:
    kind: str      # "hold" | "unplug"
    at: float      # share of the job's lines taken by the unit, 0..1
    hold: float    # seconds until cycle start / the cable is back


@dataclass(frozen=True)
class Scenario:
    name: str
    title: str
    inject: dict[float, str] = field(default_factory=dict)   # share of the job -> line
    lose: float = 0.0         # probability that an answer line (ok/error:N) is lost
    garble: float = 0.0       # ... that it arrives damaged
    faults: str = ""          # the link's own faults (conform.link.faults spec)
    actions: tuple[Action, ...] = ()
    tags: frozenset[str] = frozenset()   # answers, hold, restart, may-stop
    timeout: float = 30.0


@dataclass
class SenderRun:
    """Everything the rules look at for one scenario."""

    scenario: Scenario
    job: list[str]
    analysis: GrblAnalysis
    lost: int                                  # bytes the unit's receive ring dropped
    returncode: int | None
    hung: bool
    output: str
    taken: list[list[Any]] = field(default_factory=list)   # [line, answer code] in order
    restarts: list[int] = field(default_factory=list)      # len(taken) at each power cycle
    events: list[dict[str, Any]] = field(default_factory=list)
    faults: dict[str, int] = field(default_factory=dict)
    directory: Path | None = None
    timeout: float = 0.0                                   # s the program was given


def _kill_group(proc: subprocess.Popen) -> None:
    for sig, grace in ((signal.SIGTERM, 2.0), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
            proc.wait(grace)
            return
        except (ProcessLookupError, PermissionError):
            return
        except subprocess.TimeoutExpired:
            continue


def run_sender(command: list[str], scenario: Scenario, job: list[str], directory: Path, *,
               variant: str = "grbl-1.1f", settings: dict[int, float] | None = None,
               baud: int = 115200, timeout: float | None = None, seed: int = 1) -> SenderRun:
    """Run ``command`` once against the emulator in ``scenario``; the traffic analysed."""
    from conform.capture import Recorder
    from conform.emulator.serve import Emulator
    from conform.families.grbl.serve import reopen_with_power_cycle
    from conform.families.grbl.spec.load import load_grbl
    from conform.families.grbl.unit.control import GrblControl
    from conform.families.grbl.unit.faults import GrblFaults
    from conform.families.grbl.unit.model import GrblUnit
    from conform.link.faults import FaultConfig
    from conform.link.pty import PtyEndpoint

    spec = load_grbl()
    v = spec.variant(variant)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{directory}: cannot create: {exc.strerror or exc}") from None
    job_path, link, capture = directory / "job.gcode", directory / "port", directory / "session.mcap"
    job_path.write_text("\n".join(job) + "\n", encoding="ascii")
    t0 = time.monotonic()
    unit = GrblUnit(v, spec, t0=t0, settings=settings, truth=True)
    faults = GrblFaults(FaultConfig.parse(scenario.faults) if scenario.faults else None, seed,
                        t0, lose=scenario.lose, garble=scenario.garble)
    endpoint = PtyEndpoint(link=link)
    restarts: list[int] = []
    power_cycled = reopen_with_power_cycle(lambda: PtyEndpoint(link=link), unit, faults)

    def reopen() -> Any:
        n = len(unit.taken or ())
        was = faults.unplugged
        new = power_cycled()
        if was:
            restarts.append(n)
        return new

    # no "baud": the recorder would date each host chunk's first byte a wire time before the
    # emulator read it, but on a pty the bytes were all there at once (the emulator paces them
    # after reading), so lines would seem sent before the answer they waited for
    recorder = Recorder(capture, {
        "capture_method": "check-sender", "variant": v.id, "family": "grbl", "line_baud": baud,
        "unit_port": str(link), "scenario": scenario.name}, decode=False)
    control = LocalControl()
    emulator = Emulator(unit, endpoint, baud=baud, injector=faults, recorder=recorder,
                        control=control, reopen=reopen, control_handler=GrblControl(faults))
    died: list[str] = []

    def serve() -> None:
        try:
            emulator.run()
        except Exception as exc:  # noqa: BLE001 - the reference unit failing is reported
            died.append(f"the emulator stopped: {type(exc).__name__}: {exc}")

    thread = threading.Thread(target=serve, name="grbl-check-sender", daemon=True)
    thread.start()
    argv = [a.replace("{port}", str(link)).replace("{job}", str(job_path)) for a in command]
    env = dict(os.environ, CONFORM_PORT=str(link), CONFORM_JOB=str(job_path),
               CONFORM_VARIANT=v.id, CONFORM_SCENARIO=scenario.name)
    events: list[dict[str, Any]] = []
    code: int | None = None
    hung = False
    limit = timeout or scenario.timeout
    try:
        with open(directory / "program.out", "wb") as out:
            try:
                proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=out,
                                        stderr=subprocess.STDOUT, env=env,
                                        start_new_session=True)
            except OSError as exc:
                raise UserError(f"cannot run {argv[0]!r}: {exc.strerror or exc}") from None
            try:
                code, hung = _supervise(proc, scenario, unit, len(job), control, recorder,
                                        events, limit)
            except BaseException:   # check-sender itself stopped (Ctrl-C, SIGTERM): so is it
                _kill_group(proc)
                raise
        time.sleep(0.2)
    finally:
        emulator.stop()
        thread.join(5)
        recorder.close({"bytes_in": emulator.bytes_in, "bytes_out": emulator.bytes_out,
                        "bytes_lost": unit.lost})
    if died:
        raise UserError(f"scenario {scenario.name}: {died[0]}")
    output = (directory / "program.out").read_bytes()[-2000:].decode(errors="replace")
    a = analyze_capture(str(capture), variant=v.id, detected="recorded by check-sender")
    run = SenderRun(scenario, job, a, unit.lost, code, hung, output, list(unit.taken or ()),
                    restarts, events, dict(faults.counts), directory, limit)
    (directory / "truth.json").write_text(json.dumps({
        "taken": run.taken, "bytes_lost": run.lost, "restarts_after_line": restarts,
        "events": events, "faults": run.faults}, indent=1), "utf-8")
    return run


def _supervise(proc: subprocess.Popen, scenario: Scenario, unit: Any, n_job: int,
               control: LocalControl, recorder: Any, events: list[dict[str, Any]],
               limit: float) -> tuple[int | None, bool]:
    """Wait for the program, firing the scenario's actions; (exit status, hung)."""
    start = time.monotonic()
    pending = sorted(scenario.actions, key=lambda a: a.at)
    later: list[tuple[float, str]] = []

    def act(line: str) -> None:
        reply = control.ask(line)
        events.append({"t": recorder.clock(), "t_run": round(time.monotonic() - start, 3),
                       "request": line, "reply": reply})
        recorder.log("info", f"check-sender: {line} ({reply})")

    while True:
        try:
            return proc.wait(POLL), False
        except subprocess.TimeoutExpired:
            pass
        now = time.monotonic()
        if now - start > limit:
            _kill_group(proc)
            return proc.returncode, True
        while pending and len(unit.taken or ()) >= pending[0].at * n_job:
            a = pending.pop(0)
            if a.kind == "hold":
                act("press hold")
                later += [(now + 0.05, "release hold"), (now + a.hold, "press start"),
                          (now + a.hold + 0.05, "release start")]
            else:
                act(f"fault unplug {a.hold:g}")
        for item in sorted(x for x in later if x[0] <= now):
            later.remove(item)
            act(item[1])
