"""GVE's check-sender family (conform.sendercheck.family.Family): its scenarios and rules, the
reference unit with its control commands, the ground truth of every vector the unit accepted,
the job compared with it (relative vectors: compare.py) and the capture analysed by the GVE
analyser."""

from __future__ import annotations

from typing import Any

from conform.families.gve.sendercheck import rules, scenarios
from conform.families.gve.sendercheck.compare import compare
from conform.families.gve.unit.control import run_control
from conform.sendercheck.family import Family


def _variant(variant_id: str) -> tuple[Any, Any]:
    from conform.families.gve.spec import load_spec

    spec = load_spec()
    return spec.variant(variant_id), spec.dialect()


def _observe(unit: Any, t0: float) -> Any:
    from conform.families.gve.unit.truth import GroundTruth

    return GroundTruth(unit, t0=t0)


def _settle(s: Any, unit: Any, truth: Any) -> None:
    """The queue runs out in virtual time; the truth is written; the job is compared."""
    from conform.families.gve.unit.model import run_until_idle
    from conform.families.gve.unit.truth import dumps

    if not unit.inta:
        run_until_idle(unit, unit.now, unit.now + 3600.0)
    s.truth = truth.to_dict()
    (s.directory / "truth.json").write_text(dumps(s.truth), "utf-8")
    accepted = [(a["kind"], tuple(a["vector"])) for a in s.truth["accepted"]]
    deleted = any(e["command"] == "D" and e["code"] == 0 for e in s.truth["events"])
    s.comparison = compare(s.job, accepted,
                           tail_may_be_missing="stop" in s.scenario.tags and deleted)


def _analyze(capture: Any, variant_id: str) -> Any:
    from conform.families.gve.analysis.analyze import analyze

    return analyze(capture, variant=variant_id, whatif_replays=False)


def _truth_findings(s: Any) -> list[dict[str, Any]]:
    """The comparison's facts as findings, each with the clause that makes it a hazard."""
    out: list[dict[str, Any]] = []
    c = s.comparison
    if c is None:
        return out
    for kind, items, clause in (
            ("double-move", c.doubles, "GVE64 §13.5.2 (relative vectors: executed twice "
                                       "moves twice)"),
            ("extra-vector", c.extras, "GVE64 §13.5.2"),
            ("lost-vector", c.lost, "GVE64 §13.5.2, §13.7 (a vector not accepted is not "
                                    "executed)"),
            ("altered-vector", c.altered, "GVE64 §13.3.2 (a damaged line is executed "
                                          "unless checksums are on)")):
        for it in items:
            out.append({"kind": kind, "severity": "hazard", "clause": clause,
                        "scenario": s.scenario.name, "source": "ground-truth",
                        "confirmed": True, "message": f"{kind}: {it}", **it})
    return out


def _taken(truth: Any) -> int:
    return len(truth.accepted)


GVE = Family(
    name="gve", default_variant="gve64-v19", scenarios=scenarios.SCENARIOS, rules=rules.RULES,
    job=scenarios.make_job, units=scenarios.job_vectors, prepare=scenarios.prepare_unit,
    make_unit=scenarios.make_unit, steps=scenarios.steps, control=lambda _faults: run_control,
    variant=_variant, observe=_observe, taken=_taken, settle=_settle, analyze=_analyze,
    truth_findings=_truth_findings, fast=scenarios.FAST,
)
