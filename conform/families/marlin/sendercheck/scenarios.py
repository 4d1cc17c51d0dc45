"""check-sender's scenarios for Marlin: what is done to the link and the unit while a sender
program streams a job, and the job itself (every line different, so the ground truth can say
which job line ran how often). They run through the engine's check-sender supervisor
(conform.sendercheck); a scenario's actions fire once a share of the job's moves has run.

    conform check-sender --variant marlin-2.1 [--scenario NAME] [--report DIR] -- COMMAND ...
"""

from __future__ import annotations

from typing import Any

from conform.sendercheck.family import Action, Scenario

TIMEOUT = 40.0  # s a program is given in each scenario (lost-ok needs a sender's own timeout)


def _scenario(name: str, title: str, **common: Any) -> Scenario:
    return Scenario(name, title, timeout=TIMEOUT, **common)


SCENARIOS = {s.name: s for s in (
    _scenario("clean", "a clean job of short moves"),
    _scenario("noisy", "noise on the host's line: damaged lines, Error:checksum and Resend:",
              faults="host.corrupt=1e-3", tags=frozenset({"noise"})),
    _scenario("lost-ok", "two ok lines lost in the middle of the job (the unit says nothing "
              "more)", actions=(Action("lose", 0.5, 2),), tags=frozenset({"lost-ok"})),
    _scenario("busy", "the unit is busy for 6 s a third into the job (busy: processing)",
              actions=(Action("busy", 0.3, 6.0),), tags=frozenset({"busy"})),
    _scenario("reset", "the unit resets a third into the job (start, banner, line number 0)",
              actions=(Action("reset", 0.3, 0.0),), tags=frozenset({"restart"})),
    _scenario("link-lost", "the cable pulled a third into the job for 1 s; the board has "
              "restarted when it is back", actions=(Action("unplug", 0.3, 1.0),),
              tags=frozenset({"restart"})),
)}


def default_job(n: int = 120) -> list[str]:
    """Short moves, every line different (a line's text says which job line it is)."""
    return ["G90", *(f"G1 X{(i % 40) * 0.5 + i / 1000:.3f} Y{(i % 9) * 0.5:.1f} F6000"
                     for i in range(1, n + 1))]


def job_for(_scenario: Scenario, _variant: Any, given: list[str] | None) -> list[str]:
    """The job of every scenario: the user's lines, else :func:`default_job`."""
    return list(given or default_job())


def is_move(text: str) -> bool:
    """A line whose command is a planner move in Marlin's command table (G0, G1, ...)."""
    from conform.families.marlin.spec import load_marlin
    from conform.families.marlin.unit.unit import _code

    cmd = load_marlin().commands.get(_code(text))
    return cmd is not None and cmd.kind == "move"


def moves(lines: list[str]) -> list[str]:
    """The job's moves: what a scenario's share counts (the unit's moves that ran)."""
    return [x for x in lines if is_move(x)]


def steps(action: Action, _variant: Any) -> list[tuple[float, str]]:
    """A scenario action as the unit's control request (unit/control.py): ``lose`` the next
    ``hold`` ok lines, ``busy`` for ``hold`` s, ``unplug`` the cable for ``hold`` s, ``reset``."""
    request = {"reset": "reset", "unplug": f"fault unplug {action.hold:g}",
               "busy": f"fault busy {action.hold:g}",
               "lose": f"fault lose {int(action.hold)}"}.get(action.kind)
    if request is None:
        raise ValueError(f"action {action.kind!r}: not a Marlin scenario action "
                         "(lose, busy, unplug, reset)")
    return [(0.0, request)]
