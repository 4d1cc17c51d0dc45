"""Judging a grbl sender program: the scenarios (what is done to the link and the unit, the
job), run through the engine's check-sender supervisor (conform.sendercheck) and graded by the
rules of :mod:`.rules`.

    conform check-sender --variant grbl-1.1f [--scenario NAME] [--report DIR] -- COMMAND ...

``{port}`` in the arguments becomes the device path (also ``CONFORM_PORT``: a symlink made
again after an unplugged cable), ``{job}`` a g-code file to stream (``CONFORM_JOB``).
Each scenario's directory under the report holds ``session.mcap``, ``truth.json``,
``job.gcode`` and ``program.out``.

The emulated machine is faster than grbl's generic defaults (``MACHINE``: 5000 mm/min,
500 mm/s²) so that a job takes seconds.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

from conform.conformance.results import TargetRun
from conform.families.grbl.sendercheck.session import SenderRun
from conform.sendercheck.family import Action, Scenario

__all__ = ["SCENARIOS", "SenderRun", "Scenario", "check_sender", "run_scenarios"]


def _scenario(name: str, title: str, inject: dict[float, str] | None = None, *,
              garble: float = 0.0, **common: Any) -> Scenario:
    """A scenario with grbl's own knobs in ``params``: ``inject`` (share of the job -> a line
    put there) and ``garble`` (probability that an answer arrives damaged)."""
    return Scenario(name, title, params={"inject": dict(inject or {}), "garble": garble},
                    **common)


SCENARIOS = {s.name: s for s in (
    _scenario("stream", "a clean job of short moves"),
    _scenario("error", "one line of the job is rejected (error:20)", {0.3: "G5"},
              tags=frozenset({"may-stop"})),
    _scenario("alarm", "a probing move without contact raises ALARM:5",
              {0.3: "G38.2Z-0.5F200"}, tags=frozenset({"may-stop"})),
    _scenario("lost-answers", "5 % of the answers (ok / error:N) never arrive", lose=0.05,
              tags=frozenset({"answers"})),
    _scenario("garbled-answers", "5 % of the answers arrive damaged", garble=0.05,
              tags=frozenset({"answers"})),
    _scenario("slow-link", "a wireless serial bridge: 40-80 ms each way",
              faults="latency=40-80", tags=frozenset({"fed"})),
    _scenario("feed-hold", "the machine's feed-hold button a third into the job, cycle start "
              "0.6 s later", actions=(Action("hold", 0.3, 0.6),), tags=frozenset({"hold"})),
    _scenario("link-loss", "the cable pulled a third into the job for 1 s: the port closes, "
              "and grbl has restarted when it is back", actions=(Action("unplug", 0.3, 1.0),),
              tags=frozenset({"restart", "may-stop"})),
)}

# the machine behind the emulator: a nimble one, so a job takes seconds (settings $110-$122)
MACHINE = {110: 5000.0, 111: 5000.0, 112: 5000.0, 120: 500.0, 121: 500.0, 122: 500.0}
PRESS = 0.05  # s a button is held down


def default_job(n: int = 100) -> list[str]:
    return ["G21G90", *(f"G1X{-(i % 20 + 1) * 0.25:.3f}Y{-(i % 7) * 0.15:.3f}F3000"
                        for i in range(n)), "M2"]


def scenario_job(scenario: Scenario, job: list[str] | None = None) -> list[str]:
    lines = list(job or default_job())
    for share, extra in sorted(scenario.params.get("inject", {}).items()):
        lines.insert(max(1, int(len(lines) * share)), extra)
    return lines


def scenario_job_for(scenario: Scenario, _variant: Any, given: list[str] | None) -> list[str]:
    """The job for ``scenario``: the user's lines (or the default job) with the scenario's
    lines put in."""
    return scenario_job(scenario, given)


def steps(action: Action, _variant: Any) -> list[tuple[float, str]]:
    """A scenario action as timed control requests (unit/control.py): ``hold`` presses the
    machine's feed-hold button and, ``hold`` s later, cycle start; ``unplug`` pulls the cable
    for ``hold`` s."""
    if action.kind == "hold":
        return [(0.0, "press hold"), (PRESS, "release hold"), (action.hold, "press start"),
                (action.hold + PRESS, "release start")]
    if action.kind == "unplug":
        return [(0.0, f"fault unplug {action.hold:g}")]
    raise ValueError(f"action {action.kind!r}: not a grbl scenario action (hold, unplug)")


def check_sender(command: list[str], **options: Any) -> TargetRun:
    """Every scenario, graded: one TargetRun for the engine's reports (options as for
    :func:`run_scenarios`)."""
    return run_scenarios(command, **options)[0]


def run_scenarios(command: list[str], *, variant: str = "grbl-1.1f",
                  scenarios: list[str] | None = None, job: list[str] | None = None,
                  timeout: float | None = None, directory: str | Path | None = None,
                  seed: int = 1, progress: Any = None) -> tuple[TargetRun, list[SenderRun]]:
    """Run and grade every scenario through the engine's supervisor; the graded run and what
    the rules read of each session. Sessions go under ``directory`` (a temporary one, removed
    afterwards, when None)."""
    from conform.families.grbl.sendercheck.session import sender_run
    from conform.sendercheck.grade import check

    with tempfile.TemporaryDirectory(prefix="conform-grbl-") as tmp:
        root = Path(directory) if directory is not None else Path(tmp)
        r = check(command, variant=variant, names=scenarios, directory=root, timeout=timeout,
                  seed=seed, job_lines=job, progress=progress)
        facts = [sender_run(s.session) if not s.session.error else None for s in r.scenarios]
    return r.target_run(), [f for f in facts if f is not None]
