"""What Marlin's rules read of one check-sender session (:class:`SenderRun`), made from the
engine's session (conform.sendercheck.session: the program run on a pty against the Marlin
unit, the recording, the scenario's actions) and the unit's own ground truth: every command
it ran (when, with which line number), when it restarted."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from conform.sendercheck.family import Scenario

OUTPUT_TAIL = 3000  # bytes of the program's output kept


@dataclass
class MarlinTruth:
    """The unit (its ``truth`` is the ground truth) and how many of the commands it ran are
    moves, counted as the log grows (what a scenario's share is measured in)."""

    unit: Any
    t0: float
    _seen: int = 0
    _moves: int = 0

    def moves_run(self) -> int:
        from conform.families.marlin.sendercheck.scenarios import is_move

        log = self.unit.truth.log
        for _t, _n, text in log[self._seen:]:
            self._moves += is_move(text)
        self._seen = len(log)
        return self._moves


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
    events: list[dict[str, Any]] = field(default_factory=list)   # with t_unit: when asked
    faults: dict[str, int] = field(default_factory=dict)
    directory: Path | None = None
    t0: float = 0.0


def sender_run(s: Any) -> SenderRun:
    """The rules' view of an engine session whose ground truth ``settle`` wrote. The unit's
    clock is the supervisor's (monotonic), so a request's unit time is the program's start
    plus its ``t_run``."""
    if s.analysis is None:
        raise RuntimeError(f"the capture could not be analysed: {s.analysis_error or 'none'}")
    out = s.directory / "program.out"
    output = out.read_bytes()[-OUTPUT_TAIL:].decode(errors="replace") if out.exists() else ""
    events = [{**e, "t_unit": s.started + e["t_run"]} for e in s.events]
    return SenderRun(s.scenario, s.job_lines, s.analysis, list(s.truth["log"]),
                     list(s.truth["resets"]), s.exit_code, s.hung, output, events, s.faults,
                     s.directory, s.truth["t0"])
