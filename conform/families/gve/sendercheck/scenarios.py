"""The GVE scenarios: what check-sender does to the link and the unit, and the job it gives.

Every scenario hands the program the same kind of job (a vector file: ``A``, ``V``, then
``C`` vectors, with identical vectors back to back, the case where a resend and the next
vector look alike) and changes one thing:

| scenario | what happens | what it shows |
|---|---|---|
| clean | nothing | the baseline: simplex, checksums, queue kept fed |
| noisy | bits flipped both ways, answers garbled | checksums, `>`/`@` recovery |
| lost-answers | 5 % of the answers never arrive | recovery after silence, no blind resend |
| slow-unit | a 6 s first vector, then 40 more vectors than the queue holds | queue full (code 1) handled, paced |
| usb-latency | 1–16 ms converter latency each way | whether the queue still stays fed |
| stop | the stop input pressed a third into the job, released 0.3 s later | INTA, K/R/G/D |
| link-loss | the line dead for 1 s a third into the job | recovery after a dead line |
"""

from __future__ import annotations

from typing import Any

from conform.sendercheck.family import Action, Scenario

SCENARIOS: dict[str, Scenario] = {s.name: s for s in (
    Scenario("clean", "clean line", vectors=60, pulses=300, tags=frozenset({"fed"})),
    Scenario("noisy", "noisy line: bit errors both ways, garbled answers",
             faults="corrupt=0.002,garble=0.03", vectors=80, tags=frozenset({"noise"})),
    Scenario("lost-answers", "lost answers: 5 % of the answers never arrive", lose=0.05,
             vectors=80),
    Scenario("slow-unit", "slow unit: a job longer than the queue (queue full, code 1)",
             over_queue=40, head=120000, pulses=100, speed=20000,
             tags=frozenset({"full", "fed"})),
    Scenario("usb-latency", "USB-converter latency 1-16 ms each way", faults="latency=1-16",
             vectors=80, tags=frozenset({"fed"})),
    Scenario("stop", "stop input pressed mid-job, released 0.3 s later", vectors=120,
             pulses=200, speed=10000, actions=(Action("stop", 0.3, 0.3),),
             tags=frozenset({"stop"})),
    Scenario("link-loss", "link lost for 1 s mid-job, then back (disconnect and reconnect)",
             vectors=80, pulses=200, speed=10000, actions=(Action("link", 0.3, 1.0),),
             tags=frozenset({"link"})),
)}

FAST = ("clean", "lost-answers")

# identical vectors back to back on purpose: a resend and the next vector look alike
_PATTERN = ((1, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (0, 1, 0), (0, 1, 0), (-1, 0, 0),
            (-1, -1, 0), (0, -1, 0), (0, -1, 0))

STOP_INPUT = (1, 7)  # IN7: the stop button of GVE64 §13.5.12


def stop_input(variant: Any) -> tuple[int, int]:
    """IN7 where the variant has it; else its highest input on port 1 (GVE124 has only
    IN0..IN2, GVE124 §12.5.11: any Intr may serve as a stop)."""
    bits = variant.input_bits.get("port1", ())
    return STOP_INPUT if STOP_INPUT[1] in bits else (1, max(bits))


def control_line(kind: str, on: bool, variant: Any) -> str:
    """The emulator control request for a scenario action (``stop`` only)."""
    port, bit = stop_input(variant)
    return f"{'press' if on else 'release'} {port}.{bit}"


def job_length(scn: Scenario, variant: Any) -> int:
    return variant.queue + scn.over_queue if scn.over_queue is not None else scn.vectors


def make_job(scn: Scenario, variant: Any) -> list[str]:
    """The vector file the program streams for ``scn`` on ``variant``."""
    n = job_length(scn, variant)
    naxes = len(variant.axes)
    lines = ["A200", f"V{scn.speed}"]
    if scn.head:
        lines.append("C" + ",".join(str(x) for x in ((scn.head,) + (0,) * naxes)[:naxes]))
        n -= 1
    for k in range(n):
        d = tuple(x * scn.pulses for x in _PATTERN[k % len(_PATTERN)]) + (0,) * naxes
        lines.append("C" + ",".join(str(x) for x in d[:naxes]))
    return lines


def job_vectors(lines: list[str]) -> list[tuple[str, tuple[int, ...]]]:
    """The C/L vectors of a vector file, in order (other commands left out)."""
    out = []
    for raw in lines:
        line = raw.split("#", 1)[0].split(";", 1)[0].strip()
        if line.startswith("!"):
            line = line[2:] if len(line) > 1 and line[1].isdigit() else line[1:]
        if line[:1] in ("C", "L") and line[1:2] in "-0123456789" and line[1:2]:
            try:
                out.append((line[0], tuple(int(x) for x in line[1:].split(","))))
            except ValueError:
                continue
    return out


def prepare_unit(unit: Any, scn: Scenario, t: float) -> None:
    """The machine's own setup before the program starts: with a stop scenario the stop
    input is enabled as an interrupt (ST0, GVE64 §13.5.12), as a Gravos machine's setup
    leaves it; a program that writes ST0 itself overrides this."""
    if "stop" in scn.tags:
        unit.handlers["SW"]((0, 1 << stop_input(unit.variant)[1]), t)


def make_unit(variant: Any, dialect: Any, t0: float) -> Any:
    """The GVE reference unit (sans-I/O, on the emulator's wall clock)."""
    from conform.families.gve.unit.model import Unit

    return Unit(variant, dialect, t0=t0)
