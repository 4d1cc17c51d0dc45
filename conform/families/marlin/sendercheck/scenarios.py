"""check-sender's scenarios for Marlin: what is done to the link and the unit while a sender
program streams a job, and the job itself (every line different, so the ground truth can say
which job line ran how often)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Action:
    kind: str      # "reset" | "unplug" | "busy" | "lose"
    at: float      # share of the job's lines run by the unit, 0..1
    hold: float    # seconds the cable is out / the unit is busy; ok lines lost (lose)


@dataclass(frozen=True)
class Scenario:
    name: str
    title: str
    faults: str = ""          # the link's faults (conform.link.faults spec)
    lose: float = 0.0         # probability that an ok line is lost
    actions: tuple[Action, ...] = ()
    tags: frozenset[str] = frozenset()   # noise, lost-ok, busy, restart
    timeout: float = 40.0


SCENARIOS = {s.name: s for s in (
    Scenario("clean", "a clean job of short moves"),
    Scenario("noisy", "noise on the host's line: damaged lines, Error:checksum and Resend:",
             faults="host.corrupt=1e-3", tags=frozenset({"noise"})),
    Scenario("lost-ok", "two ok lines lost in the middle of the job (the unit says nothing more)",
             actions=(Action("lose", 0.5, 2),), tags=frozenset({"lost-ok"})),
    Scenario("busy", "the unit is busy for 6 s a third into the job (busy: processing)",
             actions=(Action("busy", 0.3, 6.0),), tags=frozenset({"busy"})),
    Scenario("reset", "the unit resets a third into the job (start, banner, line number 0)",
             actions=(Action("reset", 0.3, 0.0),), tags=frozenset({"restart"})),
    Scenario("link-lost", "the cable pulled a third into the job for 1 s; the board has "
             "restarted when it is back", actions=(Action("unplug", 0.3, 1.0),),
             tags=frozenset({"restart"})),
)}


def default_job(n: int = 120) -> list[str]:
    """Short moves, every line different (a line's text says which job line it is)."""
    return ["G90", *(f"G1 X{(i % 40) * 0.5 + i / 1000:.3f} Y{(i % 9) * 0.5:.1f} F6000"
                     for i in range(1, n + 1))]
