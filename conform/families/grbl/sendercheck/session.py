"""What grbl's rules read of one check-sender session (:class:`SenderRun`), made from the
engine's session (conform.sendercheck.session: the program run on a pty against the grbl unit,
the recording, the scenario's actions) and the unit's own ground truth: the lines its parser
took and their answers, the bytes its receive ring dropped, when it restarted."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from conform.families.grbl.analysis.analyze import GrblAnalysis
from conform.sendercheck.family import Scenario

OUTPUT_TAIL = 2000  # bytes of the program's output kept


@dataclass
class GrblTruth:
    """The unit (its ``taken`` and ``lost`` are the ground truth) and the restarts the
    emulator's reopen hook saw (``len(taken)`` at each)."""

    unit: Any
    restarts: list[int] = field(default_factory=list)


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


def sender_run(s: Any) -> SenderRun:
    """The rules' view of an engine session whose ground truth ``settle`` wrote."""
    if s.analysis is None:
        raise RuntimeError(f"the capture could not be analysed: {s.analysis_error or 'none'}")
    out = s.directory / "program.out"
    output = out.read_bytes()[-OUTPUT_TAIL:].decode(errors="replace") if out.exists() else ""
    return SenderRun(s.scenario, s.job_lines, s.analysis, s.truth["bytes_lost"], s.exit_code,
                     s.hung, output, s.truth["taken"], s.truth["restarts_after_line"],
                     s.events, s.faults, s.directory, s.timeout)
