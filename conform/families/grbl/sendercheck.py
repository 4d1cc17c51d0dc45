"""Judging a grbl sender program: run it against the grbl reference unit on a pty, record the
traffic, analyse it (:mod:`.analysis`) and grade rules, each citing its source.

    conform check-sender --variant grbl-1.1f [--scenario NAME] [--report DIR] -- COMMAND ...

``{port}`` in the arguments becomes the device path (also ``CONFORM_PORT``), ``{job}`` a
g-code file to stream (``CONFORM_JOB``). Exit status: 0 no MUST rule failed, 1 one did, 2 usage.

The emulated machine is faster than grbl's generic defaults (``MACHINE``: 5000 mm/min,
500 mm/s²) so that a job takes seconds. Scenarios: ``stream`` (a clean job), ``error`` (one
line of the job is rejected with error:20), ``alarm`` (a probing move without contact raises
ALARM:5 mid-job).
Rules (ids as the check ids of a TargetRun): the program ends by itself; every line is
answered and no byte is lost; bytes in flight stay within the 128-byte receive buffer
(character counting done right, realtime bytes outside the count); no line is an empty line
made of a realtime byte and a newline; the job's lines are sent in order; after error:N the
sender stops or says it went on (SHOULD); after an alarm it sends no more g-code.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from conform.conformance.results import MUST, CheckResult, Grade, TargetRun
from conform.errors import UserError
from conform.families.grbl.analysis import GrblAnalysis, analyze_streams
from conform.families.grbl.tables import load_grbl

SHOULD = "SHOULD"


@dataclass(frozen=True)
class Scenario:
    name: str
    title: str
    inject: dict[float, str] = field(default_factory=dict)   # share of the job → line
    timeout: float = 30.0


SCENARIOS = {
    "stream": Scenario("stream", "a clean job of short moves"),
    "error": Scenario("error", "one line of the job is rejected (error:20)", {0.3: "G5"}),
    "alarm": Scenario("alarm", "a probing move without contact raises ALARM:5",
                      {0.3: "G38.2Z-0.5F200"}),
}


# the machine behind the emulator: a nimble one, so a job takes seconds (settings $110-$122)
MACHINE = {110: 5000.0, 111: 5000.0, 112: 5000.0, 120: 500.0, 121: 500.0, 122: 500.0}


def default_job(n: int = 100) -> list[str]:
    return ["G21G90", *(f"G1X{-(i % 20) * 0.25:.3f}Y{-(i % 7) * 0.15:.3f}F3000"
                        for i in range(n)), "M2"]


class _Tap:
    """Stands in for a Recorder: keeps what crosses the emulator's port, with times."""

    def __init__(self) -> None:
        self.host: list[tuple[float, bytes]] = []
        self.unit: list[tuple[float, bytes]] = []
        self.lock = threading.Lock()

    def chunk(self, direction: str, data: bytes, *_a: Any, **_k: Any) -> None:
        with self.lock:
            (self.host if direction == "host" else self.unit).append((time.monotonic(), data))

    def link_event(self, *_a: Any, **_k: Any) -> None:
        pass


@dataclass
class SenderRun:
    scenario: Scenario
    job: list[str]
    analysis: GrblAnalysis
    lost: int
    returncode: int | None
    hung: bool
    output: str


def run_sender(command: list[str], scenario: Scenario, *, variant: str = "grbl-1.1f",
               job: list[str] | None = None, baud: int = 115200,
               timeout: float | None = None) -> SenderRun:
    """Run ``command`` once against the emulator; the traffic analysed."""
    from conform.emulator.serve import Emulator
    from conform.families.grbl.unit import GrblUnit
    from conform.link.pty import PtyEndpoint

    spec = load_grbl()
    v = spec.variant(variant)
    lines = list(job or default_job())
    for share, extra in sorted(scenario.inject.items()):
        lines.insert(max(1, int(len(lines) * share)), extra)
    unit = GrblUnit(v, spec, t0=time.monotonic(), settings=MACHINE)
    endpoint = PtyEndpoint()
    tap = _Tap()
    emulator = Emulator(unit, endpoint, baud=baud, recorder=tap)
    thread = threading.Thread(target=emulator.run, name="grbl-emulator", daemon=True)
    thread.start()
    with tempfile.TemporaryDirectory() as tmp:
        job_path = Path(tmp) / "job.gcode"
        job_path.write_text("\n".join(lines) + "\n", encoding="ascii")
        argv = [a.replace("{port}", endpoint.name).replace("{job}", str(job_path))
                for a in command]
        env = dict(os.environ, CONFORM_PORT=endpoint.name, CONFORM_JOB=str(job_path))
        hung = False
        try:
            proc = subprocess.run(argv, env=env, capture_output=True, text=True,
                                  timeout=timeout or scenario.timeout)
            code, output = proc.returncode, (proc.stdout + proc.stderr)[-2000:]
        except subprocess.TimeoutExpired as exc:
            hung, code = True, None
            output = ((exc.stdout or b"") + (exc.stderr or b"")).decode(errors="replace")[-2000:] \
                if isinstance(exc.stdout, bytes) else str(exc.stdout or "")[-2000:]
        except OSError as exc:
            emulator.stop()
            thread.join(5)
            raise UserError(f"cannot run {argv[0]!r}: {exc.strerror or exc}") from None
        time.sleep(0.2)
        emulator.stop()
        thread.join(5)
    a = analyze_streams(tap.host, tap.unit, variant=v.id, spec=spec, path=f"scenario {scenario.name}")
    return SenderRun(scenario, lines, a, unit.lost, code, hung, output)


# ---- rules ------------------------------------------------------------------------------
Result = tuple[str, str, str]   # grade, expected, actual


def _terminates(r: SenderRun) -> Result:
    if r.hung:
        return "FAIL", "the program ends by itself", f"still running after {r.scenario.timeout:g} s"
    return "PASS", "the program ends by itself", f"exit status {r.returncode}"


def _nothing_lost(r: SenderRun) -> Result:
    m = r.analysis.metrics
    ok = r.lost == 0 and m["answered"] == m["lines"]
    return ("PASS" if ok else "FAIL", "every line answered, no byte lost",
            f"{r.lost} bytes lost, {m['answered']} of {m['lines']} lines answered")


def _within_buffer(r: SenderRun) -> Result:
    m = r.analysis.metrics
    ok = m["max_bytes_in_flight"] <= m["rx_buffer"]
    return ("PASS" if ok else "FAIL", f"at most {m['rx_buffer']} bytes in flight",
            f"{m['max_bytes_in_flight']} bytes in flight ({m['streaming_method']})")


def _realtime_not_lines(r: SenderRun) -> Result:
    empty = sum(1 for e in r.analysis.exchanges if e.text == "")
    job_empty = sum(1 for x in r.job if not x.strip())
    ok = empty <= job_empty
    return ("PASS" if ok else "FAIL", "realtime bytes sent alone, not as lines",
            f"{empty - job_empty} empty lines (a realtime byte followed by a newline is an extra "
            "line grbl answers with ok)" if not ok else "no extra empty lines")


def _in_order(r: SenderRun) -> Result:
    """The job's lines go out once each, in order; in the error and alarm scenarios the sender
    may stop early, so a prefix of the job is right there. Lines that are not the job's
    ($G polls and the like) are left out of the comparison."""
    norm = [x.replace(" ", "").upper() for x in r.job if x.strip()]
    known = set(norm)
    sent = [t for t in (e.text.replace(" ", "").upper() for e in r.analysis.exchanges)
            if t in known]
    whole = r.scenario.name == "stream"
    ok = sent == norm if whole else sent == norm[:len(sent)]
    want = "the whole job, in order" if whole else "a prefix of the job, in order"
    return ("PASS" if ok else "FAIL", want, f"{len(sent)} of the job's {len(norm)} lines sent"
            + ("" if ok else ", not in the job's order"))


def _after_error(r: SenderRun) -> Result:
    errs = [f for f in r.analysis.findings if f.kind == "error-response"]
    if not errs:
        return "NOT-APPLICABLE", "", "no error:N in this run"
    went_on = "went on" in errs[0].message
    return ("DEVIATION" if went_on else "PASS", "stop (or let the user decide) after error:N",
            errs[0].message)


def _after_alarm(r: SenderRun) -> Result:
    alarms = [f for f in r.analysis.findings if f.kind == "alarm"]
    if not alarms:
        return "NOT-APPLICABLE", "", "no alarm in this run"
    seen = alarms[0].extra["t_abs"]
    # lines already on their way when the alarm came are not the sender's fault
    locked = [e for e in r.analysis.exchanges if e.answer == "error:9" and e.t_sent > seen]
    return ("FAIL" if locked else "PASS", "no g-code sent after the alarm arrived",
            f"{len(locked)} lines sent after {alarms[0].message} were answered error:9" if locked
            else alarms[0].message)


RULES = [
    ("terminates", "the program ends by itself", "docs/grbl.md §check-sender", MUST, _terminates),
    ("nothing-lost", "every line answered, no byte lost",
     "interface.md §Grbl Response Messages; serial.h RX_BUFFER_SIZE", MUST, _nothing_lost),
    ("within-buffer", "character counting within the receive buffer",
     "serial.h RX_BUFFER_SIZE; interface.md §Buffer State", MUST, _within_buffer),
    ("realtime-out-of-band", "realtime bytes are not lines",
     "realtime_cmds.md (no line feed needed); interface.md §Real-time Status reports", MUST,
     _realtime_not_lines),
    ("job-in-order", "the job's lines are sent in order", "interface.md §Grbl Response Messages",
     MUST, _in_order),
    ("error-recovery", "after error:N the sender stops", "error_codes_en_US.csv", SHOULD,
     _after_error),
    ("alarm-stops", "no g-code after an alarm", "interface.md §Alarm Message; error_codes#9",
     MUST, _after_alarm),
]


def grade(r: SenderRun, variant: str = "grbl-1.1f") -> list[CheckResult]:
    out = []
    for rid, title, clause, level, rule in RULES:
        g, expected, actual = rule(r)
        grade_ = Grade(g)
        if grade_ is Grade.FAIL and level == SHOULD:
            grade_ = Grade.DEVIATION
        out.append(CheckResult(f"{variant}/check-sender/{r.scenario.name}/{rid}", grade_, clause,
                               level=level if level == MUST else "INFO", title=title,
                               expected=expected, actual=actual, variant=variant,
                               target=f"sender:{r.scenario.name}"))
    return out


def check_sender(command: list[str], *, variant: str = "grbl-1.1f",
                 scenarios: list[str] | None = None, job: list[str] | None = None,
                 timeout: float | None = None) -> TargetRun:
    """Every scenario, graded: one TargetRun for the engine's reports."""
    from datetime import UTC, datetime

    names = scenarios or list(SCENARIOS)
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        raise UserError(f"unknown scenario {unknown[0]!r} (known: {', '.join(SCENARIOS)})")
    run = TargetRun(" ".join(command), variant, True, "check-sender",
                    datetime.now(UTC).isoformat(timespec="seconds"))
    t0 = time.perf_counter()
    for name in names:
        r = run_sender(command, SCENARIOS[name], variant=variant, job=job, timeout=timeout)
        run.checks += grade(r, variant)
    run.duration = time.perf_counter() - t0
    return run


def run_cli(command: list[str], variant: str, scenarios: list[str], report_dir: str | None,
            timeout: float | None, job_file: str | None, as_json: bool,
            echo: Any = print) -> int:
    """``conform check-sender --variant grbl-… -- COMMAND``: exit status 0, 1 or 2."""
    import json

    from conform.conformance.suite import results_of
    from conform.errors import read_user_text
    from conform.report.render import default_dir, write_reports

    names = [n for x in scenarios for n in x.split(",") if n]
    if "list" in names:
        for sc in SCENARIOS.values():
            echo(f"{sc.name:14} {sc.title}")
        return 0
    if not command:
        raise UserError("no program given: conform check-sender --variant grbl-1.1f -- COMMAND "
                        "ARGS... (`{port}` in ARGS becomes the device path)")
    if timeout is not None and not 0 < timeout <= 86400:
        raise UserError(f"--timeout {timeout:g}: must be between 0 and 86400 seconds")
    load_grbl().variant(variant)
    job = None
    if job_file is not None:
        job = [x for x in read_user_text(job_file).splitlines() if x.strip()]
        if not job:
            raise UserError(f"{job_file}: no lines in the file")
    run = check_sender(command, variant=variant, scenarios=names or None, job=job,
                       timeout=timeout)
    results = results_of([run], "conform check-sender " + " ".join(command))
    out = Path(report_dir) if report_dir else default_dir().with_name(
        "check-sender-" + default_dir().name)
    write_reports(results, out)
    if as_json:
        echo(json.dumps(results.to_json(), indent=1, default=str))
    else:
        for c in run.checks:
            echo(f"{c.grade.value:15} {c.id} — {c.actual}")
        counts = ", ".join(f"{k} {n}" for k, n in run.counts().items() if n)
        echo(f"{len(names or SCENARIOS)} scenario(s) in {run.duration:.1f} s: {counts}")
        echo(f"report: {out / 'index.html'}")
    return 1 if results.failed() else 0


def main(argv: list[str] | None = None) -> int:
    import argparse

    p = argparse.ArgumentParser(prog="python -m conform.families.grbl.sendercheck")
    p.add_argument("--variant", default="grbl-1.1f")
    p.add_argument("--scenario", action="append", default=[])
    p.add_argument("--report", default=None)
    p.add_argument("--timeout", type=float, default=None)
    p.add_argument("--job", default=None)
    p.add_argument("command", nargs=argparse.REMAINDER)
    ns = p.parse_args(argv)
    command = ns.command[1:] if ns.command[:1] == ["--"] else ns.command
    try:
        return run_cli(command, ns.variant, ns.scenario, ns.report, ns.timeout, ns.job, False)
    except UserError as exc:
        print(f"check-sender: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
