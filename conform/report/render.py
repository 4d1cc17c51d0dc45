"""Conformance reports from :class:`RunResults`: one self-contained ``index.html`` (jinja2
template, inline CSS, no network), ``summary.md``, ``junit.xml`` and ``results.json``."""

from __future__ import annotations

import json
import os
import re
import xml.etree.ElementTree as ET
from collections import OrderedDict
from collections.abc import Callable, Mapping
from datetime import UTC, datetime
from pathlib import Path

import jinja2

from conform.conformance.results import GRADE_ORDER, INFO, MUST, CheckResult, Grade, RunResults
from conform.errors import UserError
from conform.report import view
from conform.report.view import column_name

TEMPLATES = Path(__file__).resolve().parent / "templates"


def default_dir(root: str | Path = "reports", prefix: str = "") -> Path:
    """``reports/<prefix><UTC timestamp>``, numbered (``-2``, ``-3`` …) when a run of the same
    second already has it: one run's report never replaces another's."""
    base = Path(root) / (prefix + datetime.now(UTC).strftime("%Y%m%d-%H%M%S"))
    out, n = base, 1
    while out.exists():
        n += 1
        out = base.with_name(f"{base.name}-{n}")
    return out


def link_latest(directory: str | Path, name: str = "latest") -> Path | None:
    """Point ``<parent>/latest`` at ``directory`` (a relative symlink), so that
    ``reports/latest/index.html`` is always the last run's; None where links are not possible."""
    d = Path(directory)
    link = d.parent / name
    tmp = d.parent / f".{name}.{os.getpid()}"
    try:
        if link.exists() and not link.is_symlink():
            return None  # a real folder of that name belongs to the user
        tmp.unlink(missing_ok=True)
        tmp.symlink_to(d.name, target_is_directory=True)
        os.replace(tmp, link)
    except OSError:
        tmp.unlink(missing_ok=True)
        return None
    return link


def matrix(results: RunResults) -> tuple[list[str], list[tuple[str, list[CheckResult | None]]]]:
    """Columns (one per target run) and rows (check key → the result in each column)."""
    columns = [column_name(r) for r in results.runs]
    return columns, _rows(results, results.checks)


def _rows(results: RunResults, checks: list[CheckResult]
          ) -> list[tuple[str, list[CheckResult | None]]]:
    index = {(r.target, r.variant): i for i, r in enumerate(results.runs)}
    rows: OrderedDict[str, list[CheckResult | None]] = OrderedDict()
    for c in checks:
        i = index.get((c.target, c.variant))
        if i is not None:
            rows.setdefault(c.key, [None] * len(results.runs))[i] = c
    return list(rows.items())


def anchor(check: CheckResult) -> str:
    raw = f"{check.target}|{check.id}"
    return "c-" + re.sub(r"[^A-Za-z0-9]+", "-", raw).strip("-")


def render_html(results: RunResults) -> str:
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)),
                             autoescape=jinja2.select_autoescape(["html", "j2"]),
                             trim_blocks=True, lstrip_blocks=True)

    def rows_of(row: view.Row) -> list[tuple[str, str, list[CheckResult | None]]]:
        return [(key, next(c.level for c in cells if c), cells)
                for key, cells in _rows(results, row.checks)]

    env.globals.update(anchor=anchor, log_lines=view.log_lines, differing=view.differing,
                       replay=lambda c: view.replay_command(c, results.command),
                       rows_of=rows_of)
    columns, subject_rows = view.subject_matrix(results)
    problems = view.problems(results)
    deviations = view.deviations(results)
    return env.get_template("report.html.j2").render(
        results=results, runs=results.runs, head=view.headline(results),
        skipped=view.not_verified(results), levels=view.levels(results), grade_help=view.GRADES,
        not_applicable=sum(1 for c in results.checks if c.grade is Grade.NOT_APPLICABLE),
        problems=problems, n_problems=sum(len(s.checks) for s in problems),
        deviations=deviations, n_deviations=sum(len(s.checks) for s in deviations),
        columns=columns, subject_rows=subject_rows, n_checks=len(results.checks),
        cites=view.citations(subject_rows),
        causes=view.causes(results),
        grades=[g.value for g in GRADE_ORDER], mutants=results.mutants,
    )


def not_verified_lines(results: RunResults) -> list[str]:
    """What a run did not verify and how to include it: for the terminal and the Markdown."""
    out = []
    for g in view.not_verified(results):
        line = f"not verified: {g.sentence()}"
        out.append(line + (f" (enable with {g.how})" if g.how else ""))
    return out


def _md_check(c: CheckResult, log_limit: int = 24, command: str = "") -> list[str]:
    out = [f"- **{c.grade.value}** `{c.id}` ({c.level}"
           + (f"; open question {c.question}" if c.question else "") + f") — {c.title}"]
    if c.expected or c.actual:
        out += [f"  - expected: `{c.expected}`", f"  - actual: `{c.actual}`"]
    if c.detail:
        out.append(f"  - {c.detail}")
    out.append(f"  - replay: `{view.replay_command(c, command)}`")
    if c.log:
        lines = view.log_lines(c, log_limit)
        cut = len(c.log) - len(lines)
        out += ["", "  ```", *(f"  {t} {d:<4} {x}" for t, d, x in lines), "  ```"]
        if cut:
            out.insert(-3, f"  ({cut} earlier chunks in results.json)")
    return out


def render_markdown(results: RunResults) -> str:
    head = view.headline(results)
    out = [f"# Conformance summary: {head.verdict}", ""]
    if results.command:
        out += [f"`{results.command}`", ""]
    out += [f"**{head.text}**", ""]
    if head.scope:
        out += [head.scope, ""]
    out += [f"> **Incomplete run.** {why}" for why in head.incomplete]
    if head.incomplete:
        out.append("")
    out += ["| target | variant | profile | " + " | ".join(g.value for g in GRADE_ORDER)
            + " | time (s) |", "|---" * (len(GRADE_ORDER) + 4) + "|"]
    for r in results.runs:
        counts = r.counts()
        out.append(f"| {r.target} | {r.variant} | {r.profile} | "
                   + " | ".join(str(counts[g.value]) for g in GRADE_ORDER)
                   + f" | {r.duration:.1f} |")
    out.append("")
    out += [f"- {r.target}: {'; '.join(r.notes)}" for r in results.runs if r.notes]
    skipped = view.not_verified(results)
    out += ["", "## Not verified", ""]
    if skipped:
        for g in skipped:
            out.append(f"- {g.sentence()}" + (f" (on {', '.join(g.only)})" if g.only else "")
                       + (f" — enable with `{g.how}`" if g.how else ""))
    else:
        out.append("Nothing skipped: every check this profile holds was run.")
    levels = view.levels(results)
    out += ["", f"MUST: {levels[MUST]}. INFO: {levels[INFO]}.", ""]
    problems = view.problems(results)
    out += [f"## Failures ({sum(len(s.checks) for s in problems)})", ""]
    if not problems:
        out.append("No FAIL and no ERROR.")
    for cause in view.causes(results):
        out.append(f"- **Likely one cause:** {cause.sentence()}")
    if problems:
        out.append("")
    for s in problems:
        out += [f"### {s.clause} ({', '.join(s.commands)})", ""]
        for c in s.checks:
            out += _md_check(c, command=results.command)
        out.append("")
    deviations = view.deviations(results)
    if deviations:
        out += ["", f"## Deviations on open questions ({sum(len(s.checks) for s in deviations)})",
                ""]
        for s in deviations:
            out += [f"### {s.clause}", ""]
            for c in s.checks:
                out += _md_check(c, log_limit=0 if not c.log else 24, command=results.command)
            out.append("")
    columns, rows = view.subject_matrix(results)
    out += ["", "## Commands × variants", "",
            "Each cell: the variant's own clause (a long one: its number in the list under "
            "the table) and the grades of its checks.", "",
            "| command | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
    cites = view.citations(rows)
    for row in rows:
        out.append(f"| {_md_cell(row.subject)} | "
                   + " | ".join(_md_cell(f"{c.cited}: {c.text()}" if c.cited else c.text()
                                         + (f" [{cites[c.clause]}]" if c.clause in cites else ""))
                                for c in row.cells) + " |")
    if cites:
        out += ["", *(f"{n}. {_md_cell(clause)}" for clause, n in cites.items())]
    if results.mutants:
        killed = sum(1 for m in results.mutants if m.get("killed"))
        out += ["", f"## Mutants: {killed}/{len(results.mutants)} killed", "",
                "| mutant | variant | fault | caught by | killed |", "|---|---|---|---|---|"]
        for m in results.mutants:
            out.append(f"| {m['name']} | {m['variant']} | {m['fault']} | "
                       f"{', '.join(m.get('caught_by', [])[:3]) or '—'} | "
                       f"{'yes' if m.get('killed') else 'NO'} |")
    return "\n".join(out) + "\n"


def _md_cell(text: str) -> str:
    """A table cell's text with Markdown's table and inline characters escaped."""
    return re.sub(r"([|<>*_`\\])", r"\\\1", text)


def render_junit(results: RunResults) -> str:
    suites = ET.Element("testsuites", name="conform")
    for r in results.runs:
        counts = r.counts()
        suite = ET.SubElement(
            suites, "testsuite", name=f"{r.target} ({r.variant})", tests=str(len(r.checks)),
            failures=str(counts["FAIL"]), errors=str(counts["ERROR"]),
            skipped=str(counts["SKIPPED"] + counts["NOT-APPLICABLE"]), time=f"{r.duration:.3f}")
        for c in r.checks:
            case = ET.SubElement(suite, "testcase", classname=view.junit_classname(c),
                                 name=c.id, time=f"{c.duration:.4f}")
            message = f"{c.clause}: expected {c.expected!s}; actual {c.actual!s}. {c.detail}"
            body = "\n".join([f"replay: {view.replay_command(c, results.command)}", *c.sequence,
                              *(f"{t} {d} {x}" for t, d, x in view.log_lines(c))])
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


def write_files(directory: str | Path, files: Mapping[str, Callable[[], str]]) -> Path:
    """Create ``directory`` and write each named file from its renderer, in order; a folder that
    cannot be written is the project's one-line error. Returns the directory."""
    d = Path(directory)
    try:
        d.mkdir(parents=True, exist_ok=True)
        for name, render in files.items():
            (d / name).write_text(render(), encoding="utf-8")
    except OSError as exc:
        raise UserError(f"{d}: cannot write the report: {exc.strerror or exc}") from None
    return d


def write_reports(results: RunResults, directory: str | Path) -> Path:
    """Write all four files into ``directory`` (created); returns the directory."""
    return write_files(directory, {
        "results.json": lambda: json.dumps(results.to_json(), indent=1),
        "index.html": lambda: render_html(results),
        "summary.md": lambda: render_markdown(results),
        "junit.xml": lambda: render_junit(results),
    })
