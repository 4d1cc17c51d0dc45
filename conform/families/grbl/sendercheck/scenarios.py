"""Judging a grbl sender program: run it against the grbl reference unit on a real pty under
scenarios (:mod:`.session`), record each session (an MCAP capture ``conform analyze``
reads), keep what the unit really did (ground truth) and grade rules citing their source
(:mod:`.rules`).

    conform check-sender --variant grbl-1.1f [--scenario NAME] [--report DIR] -- COMMAND ...

``{port}`` in the arguments becomes the device path (also ``CONFORM_PORT``: a symlink made
again after an unplugged cable), ``{job}`` a g-code file to stream (``CONFORM_JOB``).
Exit status: 0 no MUST rule failed, 1 one did, 2 usage. Each scenario's directory under the
report holds ``session.mcap``, ``truth.json``, ``job.gcode`` and ``program.out``.

The emulated machine is faster than grbl's generic defaults (``MACHINE``: 5000 mm/min,
500 mm/s²) so that a job takes seconds.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from conform.conformance.results import MUST, CheckResult, Grade, TargetRun
from conform.errors import UserError
from conform.families.grbl.sendercheck.rules import RULES, SHOULD
from conform.families.grbl.sendercheck.session import Action, Scenario, SenderRun, run_sender
from conform.families.grbl.spec.load import load_grbl
from conform.stops import interrupted_by

__all__ = ["SCENARIOS", "SenderRun", "Scenario", "check_sender", "grade", "run_cli"]

SCENARIOS = {s.name: s for s in (
    Scenario("stream", "a clean job of short moves"),
    Scenario("error", "one line of the job is rejected (error:20)", {0.3: "G5"},
             tags=frozenset({"may-stop"})),
    Scenario("alarm", "a probing move without contact raises ALARM:5",
             {0.3: "G38.2Z-0.5F200"}, tags=frozenset({"may-stop"})),
    Scenario("lost-answers", "5 % of the answers (ok / error:N) never arrive", lose=0.05,
             tags=frozenset({"answers"})),
    Scenario("garbled-answers", "5 % of the answers arrive damaged", garble=0.05,
             tags=frozenset({"answers"})),
    Scenario("slow-link", "a wireless serial bridge: 40-80 ms each way", faults="latency=40-80",
             tags=frozenset({"fed"})),
    Scenario("feed-hold", "the machine's feed-hold button a third into the job, cycle start "
             "0.6 s later", actions=(Action("hold", 0.3, 0.6),), tags=frozenset({"hold"})),
    Scenario("link-loss", "the cable pulled a third into the job for 1 s: the port closes, "
             "and grbl has restarted when it is back", actions=(Action("unplug", 0.3, 1.0),),
             tags=frozenset({"restart", "may-stop"})),
)}

# the machine behind the emulator: a nimble one, so a job takes seconds (settings $110-$122)
MACHINE = {110: 5000.0, 111: 5000.0, 112: 5000.0, 120: 500.0, 121: 500.0, 122: 500.0}


def default_job(n: int = 100) -> list[str]:
    return ["G21G90", *(f"G1X{-(i % 20 + 1) * 0.25:.3f}Y{-(i % 7) * 0.15:.3f}F3000"
                        for i in range(n)), "M2"]


def scenario_job(scenario: Scenario, job: list[str] | None = None) -> list[str]:
    lines = list(job or default_job())
    for share, extra in sorted(scenario.inject.items()):
        lines.insert(max(1, int(len(lines) * share)), extra)
    return lines


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


def check_sender(command: list[str], **options: Any) -> TargetRun:
    """Every scenario, graded: one TargetRun for the engine's reports (options as for
    :func:`run_scenarios`)."""
    return run_scenarios(command, **options)[0]


def run_scenarios(command: list[str], *, variant: str = "grbl-1.1f",
                  scenarios: list[str] | None = None, job: list[str] | None = None,
                  timeout: float | None = None, directory: str | Path | None = None,
                  seed: int = 1, progress: Any = None) -> tuple[TargetRun, list[SenderRun]]:
    """Run and grade every scenario; the graded run and each session. Sessions go under
    ``directory`` (a temporary one, removed afterwards, when None)."""
    from datetime import UTC, datetime

    names = scenarios or list(SCENARIOS)
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        raise UserError(f"--scenario {unknown[0]!r}: unknown; choose from "
                        f"{', '.join(SCENARIOS)}")
    run = TargetRun(" ".join(command), variant, True, "check-sender",
                    datetime.now(UTC).isoformat(timespec="seconds"))
    t0 = time.perf_counter()
    sessions = []
    with tempfile.TemporaryDirectory(prefix="conform-grbl-") as tmp:
        root = Path(directory) if directory is not None else Path(tmp)
        for name in names:
            sc = SCENARIOS[name]
            if progress:
                progress(f"{name}: {sc.title} ...")
            try:
                r = run_sender(command, sc, scenario_job(sc, job), root / name,
                               variant=variant, settings=MACHINE, timeout=timeout, seed=seed)
            except KeyboardInterrupt as exc:   # Ctrl-C, SIGTERM, SIGHUP: grade what finished
                run.aborted = (f"interrupted ({interrupted_by(exc)}) during {name}; not run: "
                               f"{', '.join(names[len(sessions):])}")
                if progress:
                    progress(run.aborted)
                break
            run.checks += grade(r, variant)
            sessions.append(r)
    run.duration = time.perf_counter() - t0
    return run, sessions


def run_cli(command: list[str], variant: str, scenarios: list[str], report_dir: str | None,
            timeout: float | None, job_file: str | None, as_json: bool,
            echo: Any = print, seed: int = 1, progress: Any = None,
            command_line: str | None = None) -> int:
    """``conform check-sender --variant grbl-… -- COMMAND``: exit status 0, 1 or 2."""
    import json

    from conform.conformance.suite import results_of
    from conform.report.render import write_reports
    from conform.sendercheck.options import (
        check_timeout,
        job_of_family,
        read_job,
        report_folder,
        require_program,
    )
    from conform.stops import shield

    names = [n for x in scenarios for n in x.split(",") if n]
    if "list" in names:
        for sc in SCENARIOS.values():
            echo(f"{sc.name:16} {sc.title}")
        return 0
    require_program(command)
    check_timeout(timeout)
    load_grbl().variant(variant)
    job = read_job(job_file)
    job_of_family(job, job_file, sum(map(_moves, job or [])), "grbl")
    out = report_folder(report_dir)
    run = check_sender(command, variant=variant, scenarios=names or None, job=job,
                       timeout=timeout, directory=out, seed=seed, progress=progress)
    results = results_of([run], command_line or "conform check-sender " + " ".join(command))
    with shield():   # the report of what finished, even while a signal stops us
        write_reports(results, out)
    if as_json:
        echo(json.dumps(results.to_json(), indent=1, default=str))
    else:
        for c in run.checks:   # what needs reading; every verdict is in the report
            if c.grade not in (Grade.PASS, Grade.NOT_APPLICABLE):
                echo(f"  {c.grade.value} {c.id} — {c.actual}")
        counts = ", ".join(f"{k} {n}" for k, n in run.counts().items() if n)
        echo(f"{len(names or SCENARIOS)} scenario(s) in {run.duration:.1f} s: {counts}")
        if run.aborted:
            echo(f"INCOMPLETE: {run.aborted}")
        echo(f"report: {out / 'index.html'}")
    return 1 if results.failed() else 0


def _moves(line: str) -> bool:
    """A line of g-code with a motion, axis or machine word (what a grbl job is made of)."""
    from conform.families.grbl.protocol.gcode import GcodeError, strip_line, words

    try:
        return any(w[0] in "GMXYZ" for w in words(strip_line(line.encode("latin-1"))[0]))
    except (GcodeError, UnicodeEncodeError):
        return False


def main(argv: list[str] | None = None) -> int:
    import argparse

    p = argparse.ArgumentParser(prog="python -m conform.families.grbl.sendercheck.scenarios")
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
