"""Conformance reports from :class:`RunResults`: one self-contained ``index.html`` (jinja2
template, inline CSS, no network), ``summary.md``, ``junit.xml`` and ``results.json``."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections import OrderedDict
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import jinja2

from conform.conformance.results import GRADE_ORDER, CheckResult, Grade, RunResults
from conform.errors import UserError

TEMPLATES = Path(__file__).resolve().parent / "templates"
NOTEWORTHY = (Grade.FAIL, Grade.ERROR, Grade.DEVIATION)


def default_dir(root: str | Path = "reports") -> Path:
    return Path(root) / datetime.now(UTC).strftime("%Y%m%d-%H%M%S")


def _column(run: Any) -> str:
    return run.variant if run.target == f"emu:{run.variant}" else f"{run.target} ({run.variant})"


def matrix(results: RunResults) -> tuple[list[str], list[tuple[str, list[CheckResult | None]]]]:
    """Columns (one per target run) and rows (check key → the result in each column)."""
    columns = [_column(r) for r in results.runs]
    rows: OrderedDict[str, list[CheckResult | None]] = OrderedDict()
    for i, run in enumerate(results.runs):
        for c in run.checks:
            rows.setdefault(c.key, [None] * len(columns))[i] = c
    return columns, list(rows.items())


def anchor(check_id: str, target: str = "") -> str:
    raw = f"{target}|{check_id}"
    return "c-" + "".join(ch if ch.isalnum() else "-" for ch in raw) + f"-{abs(hash(raw)) % 10**6}"


def _log_text(check: CheckResult) -> list[tuple[str, str, str]]:
    return [(f"{e.t:10.6f}", e.dir, repr(e.data)[2:-1]) for e in check.log]


def render_html(results: RunResults) -> str:
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)),
                             autoescape=jinja2.select_autoescape(["html", "j2"]),
                             trim_blocks=True, lstrip_blocks=True)
    env.globals.update(anchor=anchor, log_text=_log_text)
    columns, rows = matrix(results)
    details = [c for c in results.checks if c.grade in NOTEWORTHY or c.grade is Grade.SKIPPED]
    details.sort(key=lambda c: (GRADE_ORDER.index(c.grade), c.variant, c.id))
    passed = [c for c in results.checks if c.grade is Grade.PASS]
    return env.get_template("report.html.j2").render(
        results=results, runs=results.runs, columns=columns, rows=rows, details=details,
        passed=passed, grades=[g.value for g in GRADE_ORDER], mutants=results.mutants,
    )


def render_markdown(results: RunResults) -> str:
    out = ["# Conformance summary", ""]
    if results.command:
        out += [f"`{results.command}`", ""]
    out += ["| target | variant | profile | " + " | ".join(g.value for g in GRADE_ORDER)
            + " | time (s) |", "|---" * (len(GRADE_ORDER) + 4) + "|"]
    for r in results.runs:
        counts = r.counts()
        out.append(f"| {r.target} | {r.variant} | {r.profile} | "
                   + " | ".join(str(counts[g.value]) for g in GRADE_ORDER)
                   + f" | {r.duration:.1f} |")
    out.append("")
    for r in results.runs:
        if r.aborted:
            out += [f"**{r.target}: {r.aborted}**", ""]
        for note in r.notes:
            out += [f"- {r.target}: {note}"]
    if results.mutants:
        killed = sum(1 for m in results.mutants if m.get("killed"))
        out += ["", f"## Mutants: {killed}/{len(results.mutants)} killed", "",
                "| mutant | variant | fault | caught by | killed |", "|---|---|---|---|---|"]
        for m in results.mutants:
            out.append(f"| {m['name']} | {m['variant']} | {m['fault']} | "
                       f"{', '.join(m.get('caught_by', [])[:3]) or '—'} | "
                       f"{'yes' if m.get('killed') else 'NO'} |")
    for grade in NOTEWORTHY:
        items = [c for c in results.checks if c.grade is grade]
        if not items:
            continue
        out += ["", f"## {grade.value} ({len(items)})", ""]
        for c in items:
            out.append(f"- **{c.id}** ({c.clause}; {c.level}) — {c.title}")
            if c.expected or c.actual:
                out.append(f"  - expected: `{c.expected}`")
                out.append(f"  - actual: `{c.actual}`")
            if c.detail:
                out.append(f"  - {c.detail}")
            if c.seed is not None:
                out.append(f"  - seed {c.seed}; replay: `conform run --replay '{c.replay}'`")
            else:
                out.append(f"  - replay: `conform run --target {c.target} --variant {c.variant} "
                           f"--replay '{c.replay}'`")
    return "\n".join(out) + "\n"


def render_junit(results: RunResults) -> str:
    suites = ET.Element("testsuites", name="conform")
    for r in results.runs:
        counts = r.counts()
        suite = ET.SubElement(
            suites, "testsuite", name=f"{r.target} ({r.variant})", tests=str(len(r.checks)),
            failures=str(counts["FAIL"]), errors=str(counts["ERROR"]),
            skipped=str(counts["SKIPPED"] + counts["NOT-APPLICABLE"]), time=f"{r.duration:.3f}")
        for c in r.checks:
            case = ET.SubElement(suite, "testcase", classname=f"{r.variant}.{c.clause}",
                                 name=c.id, time=f"{c.duration:.4f}")
            message = f"{c.clause}: expected {c.expected!s}; actual {c.actual!s}. {c.detail}"
            body = "\n".join([f"replay: {c.replay}", *c.sequence,
                              *(f"{t} {d} {x}" for t, d, x in _log_text(c))])
            if c.grade is Grade.FAIL:
                ET.SubElement(case, "failure", message=message, type="FAIL").text = body
            elif c.grade is Grade.ERROR:
                ET.SubElement(case, "error", message=c.detail or "harness error").text = body
            elif c.grade in (Grade.SKIPPED, Grade.NOT_APPLICABLE):
                ET.SubElement(case, "skipped", message=f"{c.grade.value}: {c.detail}")
            elif c.grade is Grade.DEVIATION:
                ET.SubElement(case, "system-out").text = f"DEVIATION {message}"
    ET.indent(suites)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(suites, encoding="unicode")


def write_reports(results: RunResults, directory: str | Path) -> Path:
    """Write all four files into ``directory`` (created); returns the directory."""
    d = Path(directory)
    try:
        d.mkdir(parents=True, exist_ok=True)
        results.dump(d / "results.json")
        (d / "index.html").write_text(render_html(results), encoding="utf-8")
        (d / "summary.md").write_text(render_markdown(results), encoding="utf-8")
        (d / "junit.xml").write_text(render_junit(results), encoding="utf-8")
    except OSError as exc:
        raise UserError(f"{d}: cannot write the report: {exc.strerror or exc}") from None
    return d
