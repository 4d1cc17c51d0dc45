"""Characterisation: probe every open question (A1–A29) and find which alternative the unit
follows.

Each question has a probe script. The target runs it once; the reference unit runs it under each
alternative of that question (the other questions as found so far). The alternatives whose
transcript equals the target's are the candidates: one is a finding, several mean the probe
cannot tell them apart on this variant, none means the unit does something the register does
not list. Two passes settle questions whose probes depend on each other.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from conform.conformance.suite import now_iso
from conform.conformance.target import HarnessError
from conform.families.gve.conformance.expect import Reference, first_mismatch, show
from conform.families.gve.conformance.motion_free import queue_edge_steps
from conform.families.gve.conformance.profile import Profile
from conform.families.gve.conformance.script import ENVIRONMENT, Script, Step, run_script, skip_reason
from conform.families.gve.conformance.target import GveTarget as Target
from conform.families.gve.conformance.target import leave_checksums
from conform.families.gve.protocol.checksum import append_checksum

RESET = Step(reset=True)


def _s(text: str, cs: bool = False, **kw: Any) -> Step:
    body = text.encode("ascii")
    return Step(line=(append_checksum(body) if cs else body) + b"\r", **kw)


def _raw(data: bytes, **kw: Any) -> Step:
    return Step(line=data, **kw)


def _running(v: Any) -> list[Step]:
    return [_s("!0V10"), _s("!0C1000,0,0")]


def probe(q: str, v: Any) -> Script | None:
    """The probe script for question ``q`` on variant ``v`` (None: nothing to send). Where a
    zero-pulse vector tells the alternatives apart (A4, A14) the probe moves nothing (GVE64
    §13.5.2: L0,0,0 is a normal vector without motion effect); A5 needs a vector running and
    reads the position back once the queue has run, so that the vector beyond the capacity is
    seen executed before ``excludes-running`` can be found."""
    hi_v = v.ranges["velocity"][1]
    p: list[Step]
    if q == "A1":
        p = [_raw(b"!0V1000\n", timeout=0.2), _raw(b"!0V1001\r\n", timeout=0.2), _s("!0@")]
    elif q == "A2":
        p = [_s("!0S100")]
    elif q == "A3":
        p = [_s("!000,FF")]
    elif q == "A4":  # behind H the first L0,0,0 waits in the queue: may a second follow?
        p = [_s("!0H", timeout=v.commands["H"].answer_within), _s("!0L0,0,0"),
             _s("!0L0,0,0"), _s("!0D")]
    elif q == "A5":
        fill, drain = queue_edge_steps(v, "!0C0,1,0")
        p = [*fill, _s("!0F"), Step(wait=drain), _s("!0PF")]
    elif q == "A6":
        p = [_s("!0A1000"), _s("!0A1001"), _s("!0A65535"), _s("!0A65536")]
    elif q == "A7":
        p = [_s(f"!0V{v.max_rate}"), _s(f"!0V{v.max_rate + 1}"), _s(f"!0V{hi_v}")]
    elif q == "A8":
        if "XM" not in v.commands:
            return None
        p = [_s("!0XM0"), _s("!0XM255"), _s("!0XM256"), _s("!0XM1001")]
    elif q == "A9":
        p = [_s(f"!0T{n}") for n in range(1, 12)] + [_s("!0@"), _s("!0V9"), _s("!0>", lines=2)]
        if "EFR" in v.commands:
            p.append(_s("!0EFR30", kind=ENVIRONMENT))
    elif q == "A10":
        p = [_s("!0@"), _s("!0V1000"), _s("!0@"), _s("!0ZZ"), _s("!0V9"), _s("!0>", lines=2),
             _s("!0@")]
    elif q == "A11":
        p = [_s("!0%+"), _raw(b"!0V1000,00\r"), _s("!0V1000"), _s("!0@", cs=True)]
    elif q == "A12":
        p = [_s("!0*S", answer=False), _s("!0B1000", answer=False), _s("!0V100", answer=False),
             _s("!0B2000", answer=False), _s("!0*E3")]
    elif q == "A13":
        p = []
        for gap in (0.05, 0.5, 1.5):
            p += [_raw(b"!0V10", answer=False), Step(wait=gap), _raw(b"00\r", timeout=0.2)]
    elif q == "A14":
        p = [_s("!0L0,0,0")]
    elif q == "A15":
        p = [_s("!0G")]
    elif q == "A16":
        halt = _s("!0H", answer=False, timeout=v.commands["H"].answer_within)
        p = [_s("!0V1000"), _s("!0C3000,0,0"), Step(wait=0.5), halt,
             _s("!0V500", answer=False), Step(wait=2.0), _s("!0@")]
    elif q == "A17":
        p = [_s("!0J", timeout=0.3), _s("!0@", wait=0.5, timeout=0.3),
             _s("!0@", wait=2.0)]
    elif q == "A18":
        if "EFW" not in v.commands:
            return None
        p = [_s("!0EFW40,1.5"), _s("!0EFR40"), _s("!0EFW40,0000C03F"), _s("!0EFR40")]
    elif q == "A19":
        p = [_s(f"!{v.spindle_address}?", kind=ENVIRONMENT), _s(f"!{v.spindle_address}V0")]
    elif q == "A20":
        p = [_s("!0SR1"), _s("!0SW3,01"), _s("!0SR5")]
    elif q == "A21":
        p = [_s("!0v1000"), _s("!0pf")]
    elif q == "A22":
        p = [_s("!0V+1000"), _s("!0T 5"), _s("!0V1000,")]
    elif q == "A23":
        other = next(a for a in range(8) if a not in v.addresses.values())
        p = [_s(f"!{other}V100", timeout=0.2)]
    elif q == "A24":
        p = [_s("!0SW6,80"), _s("!0V9"), _s("!0ZZ"), _s("!0V1000")]
    elif q == "A25":
        # the pause after a vector that ends at rest delays the next one (timing-sensitive)
        p = [_s("!0V20000"), _s("!0A1000"), _s("!0L100,0,0"), Step(wait=0.02),
             _s("!0L100,0,0"), Step(wait=0.01), _s("!0PF", kind="position")]
    elif q == "A26":
        p = [_s("!0V1000"), _s("!0A1000"), _s("!0L1000,1000,0"), Step(wait=1.2), _s("!0PF")]
    elif q == "A27":
        busy = "!0Y-" if "Y" in v.commands else "!0WX,100,1000,10,1000"
        p = [*_running(v), _s(busy, timeout=0.5)]
    elif q == "A28":
        cell = next((c for c in v.eeprom.cells.values()
                     if c.type == "byte" and int(c.default) != 0xFF), None)
        if cell is None:
            return None
        p = [_s("!0ER%02X" % cell.address)]
    elif q == "A29":
        # checksums on; a valid V; a V with a wrong sum; what does `>` repeat?
        p = [_s("!0%+"), _s("!0V1000", cs=True), _raw(b"!0V1001,00\r"), _s("!0>", cs=True, lines=2)]
    else:
        return None
    return (RESET, *p)


@dataclass
class Finding:
    question: str
    status: str  # determined | ambiguous | no-match | not-probed
    choice: str
    matches: list[str]
    probe: list[str]
    answers: list[str]
    note: str = ""


def characterize(spec: Any, target: Target, variant_id: str, *,
                 progress: Callable[[Finding], None] | None = None,
                 passes: int = 2, findings: dict[str, Finding] | None = None,
                 probing: Callable[[str], None] | None = None
                 ) -> tuple[Any, dict[str, Finding]]:
    """Probe every open question; (the dialect found, the finding per question).

    ``findings`` (given by the caller) fills as questions are answered, so that an interrupted
    characterisation still has what was found; ``probing`` is told each question of the first
    pass before its probe runs (the passes after it only re-read the same answers)."""
    checksums_before = target.checksum_on
    try:
        return _characterize(spec, target, variant_id, progress, passes,
                             {} if findings is None else findings, probing)
    finally:
        leave_checksums(target, checksums_before)


def _characterize(spec: Any, target: Target, variant_id: str,
                  progress: Callable[[Finding], None] | None, passes: int,
                  findings: dict[str, Finding], probing: Callable[[str], None] | None
                  ) -> tuple[Any, dict[str, Finding]]:
    variant = spec.variant(variant_id)
    belief = dict(spec.dialect().choices)
    observed: dict[str, list[Any]] = {}
    for n in range(passes):
        for q in spec.questions:
            if probing is not None and n == 0:
                probing(q)
            script = probe(q, variant)
            if script is None:
                findings[q] = Finding(q, "not-probed", belief[q], [], [], [],
                                      f"{variant_id} has nothing to probe {q} with")
                continue
            why = skip_reason(script, target.guard, target.drives_inputs)
            if why is not None:
                findings[q] = Finding(q, "not-probed", belief[q], [], [], [], why)
                continue
            if q not in observed:
                try:
                    observed[q] = run_script(target, script)
                except HarnessError as exc:
                    findings[q] = Finding(q, "not-probed", belief[q], [], [], [], str(exc))
                    continue
            actual = observed[q]
            matches = []
            for alt in spec.questions[q].alternatives:
                d = spec.dialect(belief | {q: alt})
                ref = Reference(spec, variant_id, d)
                expected = ref.transcript(script)
                if first_mismatch(script, expected, actual, not target.emulated,
                                  lambda e, a: 0.0) is None:
                    matches.append(alt)
            if len(matches) == 1:
                status, choice = "determined", matches[0]
            elif matches:
                status = "ambiguous"
                choice = belief[q] if belief[q] in matches else matches[0]
            else:
                status, choice = "no-match", belief[q]
            belief[q] = choice
            findings[q] = Finding(
                q, status, choice, matches, [s.describe() for s in script if s.line or s.wait],
                [show(s, r) for s, r in zip(script, actual, strict=True) if s.line],
                "" if status != "ambiguous" else "the probe cannot tell these apart here")
            if progress is not None and n == passes - 1:
                progress(findings[q])
    return spec.dialect(belief), findings


def to_profile(spec: Any, dialect: Any, findings: dict[str, Finding], *, target: str,
               variant: str, interrupted: str | None = None) -> Profile:
    """The profile of a characterisation; an ``interrupted`` one holds the questions answered
    before the stop, marked ``partial`` with the unanswered questions listed."""
    counts: dict[str, int] = {}
    for f in findings.values():
        counts[f.status] = counts.get(f.status, 0) + 1
    meta: dict[str, Any] = {"target": target, "variant": variant, "created": now_iso(),
                            "summary": ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))}
    if interrupted is not None:
        meta |= {"partial": True, "interrupted": interrupted,
                 "unanswered": [q for q in spec.questions if q not in findings]}
        return Profile({q: f.choice for q, f in findings.items()}, meta,
                       _evidence(findings))
    return Profile(dict(dialect.choices), meta, _evidence(findings))


def _evidence(findings: dict[str, Finding]) -> dict[str, dict[str, Any]]:
    evidence = {}
    for q, f in findings.items():
        ev: dict[str, Any] = {"status": f.status, "matches": f.matches}
        if f.note:
            ev["note"] = f.note
        if f.probe:
            ev["probe"] = f.probe
            ev["answers"] = f.answers
        evidence[q] = ev
    return evidence
