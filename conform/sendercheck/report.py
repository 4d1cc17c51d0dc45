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

import jinja2

from conform.report.render import write_files
from conform.sendercheck.family import ERROR, FAIL, GRADES, NA, WARN, Verdict
from conform.sendercheck.grade import CheckResults

_HTML = """<!doctype html><html><head><meta charset="utf-8"><title>check-sender {{ verdict }}: {{ command }}</title>
<style>body{font-family:sans-serif;margin:2em}table{border-collapse:collapse}
td,th{border:1px solid #ccc;padding:3px 6px;font-size:90%;vertical-align:top}
.FAIL{background:#f8c8c8}.DEVIATION{background:#fbe7b0}.PASS{background:#d4f0d4}
.ERROR{background:#e0c0f0}.NOT-APPLICABLE{color:#999}.INCOMPLETE{background:#ffe5e5}
.badge{padding:0 .4em;border-radius:3px}</style></head><body>
<h1>check-sender <span class="{{ verdict }} badge">{{ verdict }}</span></h1>
<p><code>{{ command }}</code></p>
<p>variant {{ r.variant }} ({{ r.family }}), {{ "%.1f"|format(r.duration) }} s, exit status
{{ r.exit_code }}; {% for g, n in counts.items() %}{{ g }} {{ n }}{% if not loop.last %}, {% endif %}{% endfor %}</p>
{% if r.interrupted %}<p class="abort"><b>INCOMPLETE:</b> {{ r.interrupted }}</p>{% endif %}
{% if to_fix %}<h2>What to fix</h2><ul>{% for v in to_fix %}<li class="{{ v.grade }}"><b>{{ v.rule }}</b>
({{ v.level }}, {{ v.clause }}) in <a href="#{{ v.scenario }}">{{ v.scenario }}</a>: {{ v.detail|plain }}</li>
{% endfor %}</ul>{% endif %}
<h2>Rules × scenarios</h2><table><tr><th>rule</th><th>level</th><th>clause</th>
{% for s in r.scenarios %}<th>{{ s.name }}</th>{% endfor %}</tr>
{% for rule, cells in matrix %}<tr><td>{{ rule.rule }}<br><small>{{ rule.title }}</small></td>
<td>{{ rule.level }}</td><td>{{ rule.clause }}</td>
{% for v in cells %}<td class="{{ v.grade }}" title="{{ v.detail|plain }}">{{ v.grade }}</td>{% endfor %}</tr>
{% endfor %}</table>
<h2>Scenarios</h2>{% for s in r.scenarios %}<h3 id="{{ s.name }}">{{ s.name }}: {{ s.title }}</h3>
<p>{{ "%.2f"|format(s.session.duration) }} s, exit status {{ s.session.exit_code }}{% if s.session.hung %}
(stopped at the {{ s.session.timeout }} s timeout){% endif %};
{% if s.session.comparison %}{{ s.session.comparison.summary() }}; {% endif %}
capture <code>{{ s.session.capture }}</code></p>
<ul>{% for v in s.verdicts if v.grade in shown %}<li class="{{ v.grade }}"><b>{{ v.grade }}</b>
{{ v.rule }} ({{ v.clause }}): {{ v.detail|plain }}
{% for e in v.evidence %}<br><small>{{ e|plain }}</small>{% endfor %}</li>{% endfor %}</ul>
{% endfor %}
<h2>Findings</h2><table><tr><th>scenario</th><th>kind</th><th>severity</th><th>clause</th><th>message</th></tr>
{% for f in r.findings[:2000] %}<tr><td>{{ f.scenario }}</td><td>{{ f.kind }}</td><td>{{ f.severity }}</td>
<td>{{ f.clause }}</td><td>{{ f.message|plain }}</td></tr>{% endfor %}</table></body></html>
"""


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
    env = jinja2.Environment(autoescape=True)
    env.filters["plain"] = plain
    counts = {g.value: r.counts().get(g.value, 0) for g in GRADES}
    to_fix = [v for v in r.verdicts if v.grade in (FAIL, ERROR) and v.level == "MUST"] or \
        [v for v in r.verdicts if v.grade in (FAIL, ERROR)]
    return env.from_string(_HTML).render(r=r, counts=counts, matrix=_matrix(r), to_fix=to_fix,
                                         shown=(FAIL, ERROR, WARN, "PASS"), verdict=verdict(r),
                                         command=shlex.join(r.command))


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
