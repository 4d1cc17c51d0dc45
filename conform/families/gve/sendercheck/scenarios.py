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


def _scenario(name: str, title: str, *, vectors: int = 60, pulses: int = 100,
              over_queue: int | None = None, head: int = 0, speed: int = 20000,
              **common: Any) -> Scenario:
    """A scenario with its job's shape in ``params``: ``vectors`` (job length; with
    ``over_queue`` the queue size plus that many), ``pulses`` per vector, ``head`` (pulses of
    one long first vector: the queue fills while it runs) and ``speed`` (V)."""
    return Scenario(name, title, params={"vectors": vectors, "pulses": pulses,
                                         "over_queue": over_queue, "head": head,
                                         "speed": speed}, **common)


SCENARIOS: dict[str, Scenario] = {s.name: s for s in (
    _scenario("clean", "clean line", vectors=60, pulses=300, tags=frozenset({"fed"})),
    _scenario("noisy", "noisy line: bit errors both ways, garbled answers",
              faults="corrupt=0.002,garble=0.03", vectors=80, tags=frozenset({"noise"})),
    _scenario("lost-answers", "lost answers: 5 % of the answers never arrive", lose=0.05,
              vectors=80),
    _scenario("slow-unit", "slow unit: a job longer than the queue (queue full, code 1)",
              over_queue=40, head=120000, pulses=100, speed=20000,
              tags=frozenset({"full", "fed"})),
    _scenario("usb-latency", "USB-converter latency 1-16 ms each way", faults="latency=1-16",
              vectors=80, tags=frozenset({"fed"})),
    _scenario("stop", "stop input pressed mid-job, released 0.3 s later", vectors=120,
              pulses=200, speed=10000, actions=(Action("stop", 0.3, 0.3),),
              tags=frozenset({"stop"})),
    _scenario("link-loss", "link lost for 1 s mid-job, then back (disconnect and reconnect)",
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


def steps(action: Action, variant: Any) -> list[tuple[float, str]]:
    """A scenario action as timed emulator control requests: ``stop`` presses the stop input
    and releases it ``hold`` s later; ``link`` is the engine's dead line."""
    if action.kind == "stop":
        port, bit = stop_input(variant)
        return [(0.0, f"press {port}.{bit}"), (action.hold, f"release {port}.{bit}")]
    if action.kind == "link":
        return [(0.0, f"link dead {action.hold:g}"), (action.hold, "link back")]
    raise ValueError(f"action {action.kind!r}: not a GVE scenario action (stop, link)")


def job_length(scn: Scenario, variant: Any) -> int:
    over = scn.params["over_queue"]
    return variant.queue + over if over is not None else scn.params["vectors"]


def make_job(scn: Scenario, variant: Any, given: list[str] | None = None) -> list[str]:
    """The vector file the program streams for ``scn`` on ``variant`` (``given``: the user's
    own, used as it is)."""
    if given is not None:
        return list(given)
    n = job_length(scn, variant)
    naxes = len(variant.axes)
    p = scn.params
    lines = ["A200", f"V{p['speed']}"]
    if p["head"]:
        lines.append("C" + ",".join(str(x) for x in ((p["head"],) + (0,) * naxes)[:naxes]))
        n -= 1
    for k in range(n):
        d = tuple(x * p["pulses"] for x in _PATTERN[k % len(_PATTERN)]) + (0,) * naxes
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


def make_unit(variant: Any, dialect: Any, t0: float, _scn: Scenario | None = None) -> Any:
    """The GVE reference unit (sans-I/O, on the emulator's wall clock)."""
    from conform.families.gve.unit.model import Unit

    return Unit(variant, dialect, t0=t0)
