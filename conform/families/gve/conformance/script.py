"""A check's script: the steps sent to a target, and running them.

A script is data (frozen, hashable), so the reference unit's transcript of it can be cached and
the same script replayed on any target: a step sends one line (or waits, or drives an input, or
returns the unit to its power-up state).
"""

from __future__ import annotations

from dataclasses import dataclass

from conform.conformance.target import Reply
from conform.families.gve.conformance.safety import (
    INPUTS_SKIP,
    Guard,
    axis_moves,
    blocked_reason,
    envelope_reason,
    hazards,
)
from conform.families.gve.conformance.target import GveTarget as Target

# answer kinds whose fields are compared loosely on a real unit
POSITION = "position"  # changes while moving: compared within a tolerance
ENVIRONMENT = "environment"  # depends on the unit at hand (firmware text, EEPROM, inputs)


@dataclass(frozen=True)
class Step:
    line: bytes = b""
    answer: bool = True  # wait for an answer (False: lines inside a packet, a cut line)
    lines: int = 1  # answer lines expected (`>` may give two)
    timeout: float = 0.5
    wait: float = 0.0  # seconds to let pass before sending
    input: tuple[int, int, bool] | None = None  # (port, bit, active), emulator only
    reset: bool = False  # return to the power-up state first
    subject: bool = False  # the step the check is about
    kind: str = ""  # POSITION | ENVIRONMENT | ""
    shape: tuple[tuple[str, int | None], ...] = ()  # (radix, width) of each answer field: how
    #                      an ENVIRONMENT answer is compared on a real unit
    tolerance: float | None = None  # the answer's delay must be the reference's within ± this
    #                      (the manual's timing words: at once, the watchdog)
    ready: bool = False  # the wait lets the unit come back after J (a link waits at least the
    #                      readiness it measured, plus a margin)

    def describe(self) -> str:
        if self.reset:
            return "(reset)"
        if self.input is not None:
            port, bit, active = self.input
            return f"(input I{port}.{bit} {'active' if active else 'inactive'})"
        text = self.line.decode("latin-1").replace("\r", "")
        if self.wait and not self.line:
            return f"(wait {self.wait:g} s)"
        return (f"(wait {self.wait:g} s) " if self.wait else "") + text


Script = tuple[Step, ...]


def script_needs(script: Script) -> set[str]:
    """What a script asks of the machine: motion, actuator, eeprom, reset, inputs."""
    out: set[str] = set()
    idle = True  # the runner starts every script with the queue empty (read back)
    for step in script:
        if step.line:
            risks = hazards(step.line, idle)
            out |= risks
            idle = idle and "motion" not in hazards(step.line)
        if step.input is not None:
            out.add("inputs")
    return out


def skip_reason(script: Script, guard: Guard, drives_inputs: bool) -> str | None:
    """Why a script may not run on this target, or None (see :func:`safety.not_verified`)."""
    needs = script_needs(script)
    if "inputs" in needs and not drives_inputs:
        return INPUTS_SKIP
    blocked = guard.blocked(needs - {"inputs"})
    if blocked:
        return blocked_reason(blocked)
    if guard.max_steps is not None:
        worst = max((abs(n) for step in script if step.line for n in axis_moves(step.line)),
                    default=0)
        if worst > guard.max_steps:
            return envelope_reason(worst, guard.max_steps)
    return None


def run_script(target: Target, script: Script) -> list[Reply | None]:
    """Run every step; a reply per step (None for steps that send nothing or expect nothing).

    A reset step brings the target to the state the script starts from (the emulator: a new
    unit; a link: see :mod:`conform.families.gve.conformance.state`)."""
    target.begin_log()
    out: list[Reply | None] = []
    for step in script:
        if step.reset:
            target.prepare(script)
            target.begin_log(keep=not target.emulated)
        out.append(run_step(target, step))
    return out


def run_steps(target: Target, steps: Script) -> list[Reply | None]:
    """Run steps on the target as it is (reset steps included)."""
    out: list[Reply | None] = []
    for step in steps:
        if step.reset:
            target.reset()
        out.append(run_step(target, step))
    return out


def run_step(target: Target, step: Step) -> Reply | None:
    if step.wait:
        target.wait(target.ready_wait(step.wait) if step.ready else step.wait)
    if step.input is not None:
        target.set_input(*step.input)
    if not step.line:
        return None
    if step.answer:
        return target.exchange(step.line, step.timeout, step.lines)
    t, stray = target.send(step.line)
    return Reply(step.line, t - target.t_log0, stray=stray)
