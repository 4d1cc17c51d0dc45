"""How long a run on a link will take: the estimate printed before it starts, and the ETA.

Each check costs what its script takes on the reference unit's virtual clock (waits, moves,
silences waited out), plus a per-line overhead of the link (both directions' wire time at the
run's baud and a turnaround), plus the way to its starting state (the commands the state keeper
would send, or J and the unit's deaf time). The state machine costs its wall-time budget.
While running, the remaining estimate is scaled by how the finished checks compared with theirs.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from conform.conformance.runner import Estimate
from conform.families.gve.conformance.script import run_steps, skip_reason
from conform.families.gve.conformance.state import StateKeeper
from conform.families.gve.conformance.target import GveEmuTarget

TURNAROUND = 0.0025  # s per exchange beyond the wire time (pty/USB converter, host)
ANSWER_BYTES = 6  # a typical answer line


def _line_cost(line: bytes, baud: int) -> float:
    return (len(line) + ANSWER_BYTES) * 10.0 / baud + TURNAROUND


def estimate_run(runner: Any, checks: Sequence[Any]) -> Estimate:
    """The estimate of ``checks`` on the runner's target (see the module doc)."""
    target = runner.target
    baud = int(getattr(target, "baud", 115200) or 115200)
    ready = float(runner.variant.reset.get("ready_after_s", 2.0)) + 0.15
    sim = StateKeeper(runner.ref, target) if not target.emulated else None
    est = Estimate()
    for check in checks:
        cost = 0.0
        if check.na is not None:
            pass
        elif check.kind == "machine":
            cost = runner.machine_budget() or 0.0
            if sim is not None:
                sim.done(False)
        elif skip_reason(check.script, target.guard, target.drives_inputs) is None:
            ref = runner.ref
            t = GveEmuTarget(lambda r=ref: r.unit_cls(r.variant, r.dialect), "estimate")
            body = check.script[1:] if check.script and check.script[0].reset else check.script
            run_steps(t, body)
            cost = t.now() + sum(_line_cost(s.line, baud) for s in body if s.line)
            if sim is not None:
                lines, _ = sim.plan(check.script)
                if lines is None:
                    cost += ready
                else:
                    cost += sum(_line_cost(x, baud) for x in lines) + 2 * _line_cost(b"!0P4", baud)
                sim.done(True)
        est.per_check[check.id] = cost
        est.total += cost
    return est
