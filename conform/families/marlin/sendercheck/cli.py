"""``conform check-sender --variant marlin-… -- COMMAND ...``: run a sender program against
the Marlin reference unit on a real pty in every scenario (:mod:`.scenarios`), record each
session, keep what the unit really ran and grade the rules (:mod:`.rules`).

``{port}`` in the arguments becomes the device path (also ``CONFORM_PORT``: a symlink that
comes back after a pulled cable), ``{job}`` the g-code file to stream (``CONFORM_JOB``); the
program should connect at ``CONFORM_BAUD``. Exit status: 0 no MUST rule failed, 1 one did, 2
usage. Each scenario's folder under the report holds session.mcap, truth.json, job.gcode and
program.out.
"""

from __future__ import annotations

import json
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from conform.conformance.results import MUST, CheckResult, Grade, TargetRun
from conform.errors import UserError
from conform.families.marlin.sendercheck.rules import RULES, SHOULD
from conform.families.marlin.sendercheck.scenarios import SCENARIOS, default_job
from conform.families.marlin.sendercheck.session import SenderRun, run_sender


def grade(r: SenderRun, variant: str) -> list[CheckResult]:
    out = []
    for rid, title, clause, level, rule in RULES:
        g, expected, actual = rule(r)
        result = Grade(g)
        if result is Grade.FAIL and level == SHOULD:
            result = Grade.DEVIATION
        out.append(CheckResult(f"{variant}/check-sender/{r.scenario.name}/{rid}", result, clause,
                               level=level if level == MUST else "INFO", title=title,
                               expected=expected, actual=actual, variant=variant,
                               target=f"sender:{r.scenario.name}"))
    return out


def run_scenarios(command: list[str], *, variant: str = "marlin-2.1",
                  scenarios: list[str] | None = None, job: list[str] | None = None,
                  timeout: float | None = None, directory: str | Path | None = None,
                  seed: int = 1, progress: Any = None) -> tuple[TargetRun, list[SenderRun]]:
    names = scenarios or list(SCENARIOS)
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        raise UserError(f"--scenario {unknown[0]!r}: unknown; choose from {', '.join(SCENARIOS)}")
    run = TargetRun(" ".join(command), variant, True, "check-sender",
                    datetime.now(UTC).isoformat(timespec="seconds"))
    t0 = time.perf_counter()
    sessions = []
    with tempfile.TemporaryDirectory(prefix="conform-marlin-") as tmp:
        root = Path(directory) if directory is not None else Path(tmp)
        for name in names:
            sc = SCENARIOS[name]
            if progress:
                progress(f"{name}: {sc.title} ...")
            r = run_sender(command, sc, list(job or default_job()), root / name, variant=variant,
                           timeout=timeout, seed=seed)
            run.checks += grade(r, variant)
            sessions.append(r)
    run.duration = time.perf_counter() - t0
    return run, sessions


def run_cli(command: list[str], variant: str, scenarios: list[str], report_dir: str | None,
            timeout: float | None, job_file: str | None, as_json: bool, echo: Any = print,
            seed: int = 1, progress: Any = None, command_line: str | None = None) -> int:
    from conform.conformance.suite import results_of
    from conform.families.marlin.spec import load_marlin
    from conform.report.render import write_reports
    from conform.sendercheck.options import check_timeout, read_job, report_folder, require_program

    names = [n for x in scenarios for n in x.split(",") if n]
    if "list" in names:
        for sc in SCENARIOS.values():
            echo(f"{sc.name:16} {sc.title}")
        return 0
    require_program(command)
    check_timeout(timeout)
    load_marlin().variant(variant)
    job = read_job(job_file)
    out = report_folder(report_dir)
    run, _ = run_scenarios(command, variant=variant, scenarios=names or None, job=job,
                           timeout=timeout, directory=out, seed=seed, progress=progress)
    results = results_of([run], command_line or "conform check-sender " + " ".join(command))
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
