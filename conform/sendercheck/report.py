"""check-sender's reports, as for ``conform run``: ``index.html`` (self-contained),
``summary.md``, ``junit.xml`` and ``results.json`` (every verdict and every finding, each
with its kind, severity, clause and scenario)."""

from __future__ import annotations

import ast
import json
import re
import shlex
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from conform.report.render import write_files
from conform.sendercheck.family import ERROR, FAIL, GRADES, NA, WARN, Verdict
from conform.sendercheck.grade import CheckResults


def _matrix(r: CheckResults) -> list:
    rules: dict[str, list[Verdict]] = {}
    for s in r.scenarios:
        for v in s.verdicts:
            rules.setdefault(v.rule, []).append(v)
    return [(cells[0], cells) for cells in rules.values()]


def plain(value: object) -> str:
    """A value as a reader wants it on the page: a mapping as "key value" pairs, a list
    joined, never Python's ``{'key': ...}``."""
    if isinstance(value, dict):
        return ", ".join(f"{str(k).replace('_', ' ')} {plain(v)}" for k, v in value.items())
    if isinstance(value, list | tuple):
        return ", ".join(plain(v) for v in value)
    return _MAPPING.sub(_words, str(value))   # a mapping already made text, in words


_MAPPING = re.compile(r"\{'[^{}]*\}")


def _words(m: re.Match[str]) -> str:
    try:
        return f"({plain(ast.literal_eval(m.group(0)))})"
    except (ValueError, SyntaxError):
        return m.group(0)


def render_html(r: CheckResults) -> str:
    """The page, on the engine's template environment and page head (the analysis reports'
    look, whatever the family)."""
    from conform.analysis.report import template_env

    env = template_env()
    env.filters["plain"] = plain
    counts = {g.value: r.counts().get(g.value, 0) for g in GRADES}
    to_fix = [v for v in r.verdicts if v.grade in (FAIL, ERROR) and v.level == "MUST"] or \
        [v for v in r.verdicts if v.grade in (FAIL, ERROR)]
    run_line = (f"variant {r.variant} ({r.family}), {r.duration:.1f} s, exit status "
                f"{r.exit_code}; " + ", ".join(f"{g} {n}" for g, n in counts.items()))
    return env.get_template("check_sender.html.j2").render(
        r=r, run_line=run_line, matrix=_matrix(r), to_fix=to_fix, scenario_line=scenario_line,
        shown=(FAIL, ERROR, WARN, "PASS"), verdict=verdict(r), command=shlex.join(r.command))


def scenario_line(s: Any) -> str:
    """A scenario's line: its time, exit status (and timeout), the job against the ground
    truth where the family compares one, and its capture; no empty part."""
    ss = s.session
    parts = [f"{ss.duration:.2f} s, exit status {ss.exit_code}"
             + (f" (stopped at the {ss.timeout:g} s timeout)" if ss.hung else ""),
             ss.comparison.summary() if ss.comparison else "", f"capture {ss.capture}"]
    return "; ".join(p for p in parts if p and p.strip())


def verdict(r: CheckResults) -> str:
    """The run in one word: INCOMPLETE (interrupted), FAIL (a MUST rule), ERROR, else PASS."""
    if r.interrupted:
        return "INCOMPLETE"
    return {1: FAIL, 2: ERROR}.get(r.exit_code, "PASS")


def render_markdown(r: CheckResults) -> str:
    out = [f"# check-sender summary: {verdict(r)}", "", f"`{shlex.join(r.command)}`", "",
           f"variant {r.variant}, {r.duration:.1f} s, exit status {r.exit_code}", "",
           *([f"**INCOMPLETE**: {r.interrupted}", ""] if r.interrupted else []),
           "| rule | level | clause | " + " | ".join(s.name for s in r.scenarios) + " |",
           "|---|---|---|" + "---|" * len(r.scenarios)]
    for _v, cells in _matrix(r):
        c = cells[0]
        out.append(f"| {c.rule} | {c.level} | {c.clause} | "
                   + " | ".join("—" if v.grade == NA else v.grade.value for v in cells) + " |")
    out += ["", "| scenario | time (s) | exit | job against the ground truth |",
            "|---|---|---|---|"]
    for s in r.scenarios:
        ss = s.session
        out.append(f"| {s.name} | {ss.duration:.2f} | {ss.exit_code}"
                   f"{' (timeout)' if ss.hung else ''} | "
                   f"{ss.comparison.summary() if ss.comparison else ''} |")
    bad = [v for v in r.verdicts if v.grade in (FAIL, ERROR, WARN)]
    if bad:
        out += ["", "## Not passed", ""]
        for v in bad:
            out.append(f"- **{v.grade.value}** {v.scenario} / {v.rule} ({v.level}, {v.clause}): "
                       f"{v.detail}")
    return "\n".join(out) + "\n"


def render_junit(r: CheckResults) -> str:
    suites = ET.Element("testsuites", name="conform check-sender")
    for s in r.scenarios:
        vs = s.verdicts
        suite = ET.SubElement(suites, "testsuite", name=s.name, tests=str(len(vs)),
                              failures=str(sum(v.grade == FAIL for v in vs)),
                              errors=str(sum(v.grade == ERROR for v in vs)),
                              skipped=str(sum(v.grade == NA for v in vs)),
                              time=f"{s.session.duration:.3f}")
        for v in vs:
            case = ET.SubElement(suite, "testcase", classname=f"{r.variant}.{s.name}",
                                 name=f"{v.rule} ({v.clause})")
            text = "\n".join([v.detail, *v.evidence])
            if v.grade == FAIL:
                ET.SubElement(case, "failure", message=v.detail, type=v.level).text = text
            elif v.grade == ERROR:
                ET.SubElement(case, "error", message=v.detail).text = text
            elif v.grade == NA:
                ET.SubElement(case, "skipped", message=v.detail)
            elif v.grade == WARN:
                ET.SubElement(case, "system-out").text = f"{WARN.value} {text}"
    ET.indent(suites)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(suites, encoding="unicode")


def write_reports(r: CheckResults, directory: str | Path) -> Path:
    return write_files(directory, {
        "results.json": lambda: json.dumps(r.to_json(), indent=1, default=str) + "\n",
        "index.html": lambda: render_html(r),
        "summary.md": lambda: render_markdown(r),
        "junit.xml": lambda: render_junit(r),
    })
