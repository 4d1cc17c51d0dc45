"""One run of a sender program in one scenario: the Marlin reference unit (with its ground
truth and faults) served on a real pty in a thread, the session recorded, the program run
with ``{port}`` and ``{job}`` filled in, the scenario's actions fired once a share of the job
has run, a program still running at the timeout stopped (SIGTERM, then SIGKILL to its process
group). Afterwards the capture is analysed and the ground truth written beside it."""

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
from conform.families.marlin.sendercheck.scenarios import Scenario

POLL = 0.02


@dataclass
class SenderRun:
    """Everything the rules look at for one scenario."""

    scenario: Scenario
    job: list[str]
    analysis: Any
    log: list[tuple[float, int | None, str]]     # every command the unit ran (t, N, text)
    resets: list[float]                          # unit times of resets / restarts
    returncode: int | None
    hung: bool
    output: str
    events: list[dict[str, Any]] = field(default_factory=list)
    faults: dict[str, int] = field(default_factory=dict)
    directory: Path | None = None
    t0: float = 0.0


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
               variant: str = "marlin-2.1", baud: int = 250000, timeout: float | None = None,
               seed: int = 1) -> SenderRun:
    from conform.capture import Recorder
    from conform.emulator.serve import Emulator
    from conform.families.marlin.analysis.analyze import analyze_capture
    from conform.families.marlin.unit.control import MarlinControl
    from conform.families.marlin.unit.serve import build, reopen_with_reset
    from conform.link.pty import PtyEndpoint

    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{directory}: cannot create: {exc.strerror or exc}") from None
    job_path, link, capture = directory / "job.gcode", directory / "port", directory / "session.mcap"
    job_path.write_text("\n".join(job) + "\n", encoding="ascii")
    t0 = time.monotonic()
    unit, faults = build(variant, t0=t0, baud=baud, faults=scenario.faults or None, seed=seed,
                         lose=scenario.lose)
    endpoint = PtyEndpoint(link=link)
    recorder = Recorder(capture, {
        "capture_method": "check-sender", "variant": unit.v.id, "family": "marlin",
        "line_baud": baud, "unit_port": str(link), "scenario": scenario.name}, decode=False)
    control = LocalControl()
    emulator = Emulator(unit, endpoint, baud=baud, injector=faults, recorder=recorder,
                        control=control,
                        reopen=reopen_with_reset(lambda: PtyEndpoint(link=link), unit, faults),
                        control_handler=MarlinControl(faults))
    died: list[str] = []

    def serve() -> None:
        try:
            emulator.run()
        except Exception as exc:  # noqa: BLE001 - the reference unit failing is reported
            died.append(f"the emulator stopped: {type(exc).__name__}: {exc}")

    thread = threading.Thread(target=serve, name="marlin-check-sender", daemon=True)
    thread.start()
    argv = [a.replace("{port}", str(link)).replace("{job}", str(job_path)) for a in command]
    env = dict(os.environ, CONFORM_PORT=str(link), CONFORM_JOB=str(job_path),
               CONFORM_VARIANT=unit.v.id, CONFORM_SCENARIO=scenario.name, CONFORM_BAUD=str(baud))
    events: list[dict[str, Any]] = []
    limit = timeout or scenario.timeout
    code: int | None = None
    hung = False
    try:
        with open(directory / "program.out", "wb") as out:
            try:
                proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=out,
                                        stderr=subprocess.STDOUT, env=env,
                                        start_new_session=True)
            except OSError as exc:
                raise UserError(f"cannot run {argv[0]!r}: {exc.strerror or exc}") from None
            code, hung = _supervise(proc, scenario, unit, set(job), control, recorder, events,
                                    limit)
        time.sleep(0.2)
    finally:
        emulator.stop()
        thread.join(5)
        recorder.close({"bytes_in": emulator.bytes_in, "bytes_out": emulator.bytes_out,
                        "bytes_lost": unit.lost})
    if died:
        raise UserError(f"scenario {scenario.name}: {died[0]}")
    output = (directory / "program.out").read_bytes()[-3000:].decode(errors="replace")
    a = analyze_capture(str(capture), variant=unit.v.id, detected="recorded by check-sender")
    run = SenderRun(scenario, job, a, list(unit.truth.log), list(unit.truth.resets), code, hung,
                    output, events, dict(faults.counts), directory, t0)
    (directory / "truth.json").write_text(json.dumps({
        **unit.truth.to_dict(), "log": [[round(t - t0, 6), n, x] for t, n, x in run.log],
        "events": events, "faults": run.faults, "returncode": code, "hung": hung}, indent=1),
        "utf-8")
    return run


def job_lines_run(unit: Any, job: set[str]) -> int:
    """How many commands the unit ran that are job lines (as the unit stores them: the text
    after N, before the checksum)."""
    from conform.families.marlin.unit.unit import _after_number

    return sum(1 for _, _, x in unit.truth.log if _after_number(x) in job)


def _supervise(proc: subprocess.Popen, scenario: Scenario, unit: Any, job: set[str],
               control: LocalControl, recorder: Any, events: list[dict[str, Any]],
               limit: float) -> tuple[int | None, bool]:
    start = time.monotonic()
    pending = sorted(scenario.actions, key=lambda a: a.at)
    while True:
        try:
            return proc.wait(POLL), False
        except subprocess.TimeoutExpired:
            pass
        if time.monotonic() - start > limit:
            _kill_group(proc)
            return proc.returncode, True
        while pending and job_lines_run(unit, job) >= pending[0].at * len(job):
            a = pending.pop(0)
            line = {"reset": "reset", "unplug": f"fault unplug {a.hold:g}",
                    "busy": f"fault busy {a.hold:g}", "lose": f"fault lose {int(a.hold)}"}[a.kind]
            reply = control.ask(line)
            events.append({"t": recorder.clock(), "t_run": round(time.monotonic() - start, 3),
                           "t_unit": time.monotonic(), "request": line, "reply": reply})
            recorder.log("info", f"check-sender: {line} ({reply})")
