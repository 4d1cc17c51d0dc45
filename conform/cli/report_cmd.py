"""``conform report results.json``: re-render the reports of a conformance run."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import click

from conform.cli.params import INPUT_FILE, OUTPUT_DIR
from conform.conformance.results import Grade, RunResults
from conform.errors import UserError, load_user_file, writable_folder
from conform.report.render import write_reports

MAX_RESULTS_BYTES = 256 << 20
"""A results file past this is refused before it is read (a run's results are a few MB)."""

_TEXT = (str,)
_OPT_TEXT = (str, type(None))
_CHECK_FIELDS: dict[str, tuple[type, ...]] = {  # the fields of CheckResult the reports use
    "id": _TEXT, "clause": _TEXT, "level": _TEXT, "title": _TEXT, "expected": _TEXT,
    "actual": _TEXT, "detail": _TEXT, "question": _OPT_TEXT, "alternative": _OPT_TEXT,
    "replay": _TEXT, "variant": _TEXT, "target": _TEXT, "seed": (int, type(None)),
    "sequence": (list,), "log": (list,), "duration": (int, float),
}
_RUN_FIELDS: dict[str, tuple[type, ...]] = {
    "target": _TEXT, "variant": _TEXT, "profile": _TEXT, "started": _TEXT,
    "aborted": _OPT_TEXT, "notes": (list,), "duration": (int, float), "emulated": (bool, int),
}
_MUTANT_FIELDS: dict[str, tuple[type, ...]] = {
    "name": _TEXT, "variant": _TEXT, "fault": _TEXT, "killed": (bool, int), "caught_by": (list,),
}


def _fields(where: str, item: Any, types: dict[str, tuple[type, ...]], required: tuple[str, ...]
            ) -> None:
    if not isinstance(item, dict):
        raise UserError(f"{where}: expected an object, got {type(item).__name__}")
    for key in required:
        if key not in item:
            raise UserError(f"{where}: field {key!r} missing")
    for key, allowed in types.items():
        if key not in item:
            continue
        value = item[key]
        if not isinstance(value, allowed) or (isinstance(value, bool) and bool not in allowed):
            names = " or ".join("null" if t is type(None) else t.__name__ for t in allowed)
            raise UserError(f"{where}: field {key!r}: expected {names}, got {value!r:.40}")
        if isinstance(value, float) and not math.isfinite(value):
            raise UserError(f"{where}: field {key!r}: {value!r} is not a finite number")
        if isinstance(value, list) and key in ("sequence", "notes", "caught_by"):
            for i, x in enumerate(value):
                if not isinstance(x, str):
                    raise UserError(f"{where}: {key}[{i}]: expected text, got {x!r:.40}")


def check_results(data: Any, name: str) -> None:
    """Every field the reports use has the type they need; one line naming the first that
    does not (``from_json`` itself takes what it is given)."""
    if not isinstance(data, dict):
        raise UserError(f"{name}: not a conform results file (expected an object)")
    for key in ("command", "created"):
        if not isinstance(data.get(key, ""), str):
            raise UserError(f"{name}: field {key!r}: expected text")
    for i, c in enumerate(data.get("checks", [])):
        where = f"{name}: checks[{i}]"
        _fields(where, c, _CHECK_FIELDS, ("id", "grade", "clause"))
        if c["grade"] not in {g.value for g in Grade}:
            raise UserError(f"{where}: grade {c['grade']!r:.40} is not one of "
                            f"{', '.join(g.value for g in Grade)}")
        for j, e in enumerate(c.get("log", [])):
            _fields(f"{where}.log[{j}]", e, {"t": (int, float), "dir": _TEXT, "data": _TEXT},
                    ("t", "dir", "data"))
    for key in ("runs", "mutants"):
        if not isinstance(data.get(key, []), list):
            raise UserError(f"{name}: field {key!r}: expected a list")
    for i, r in enumerate(data.get("runs", [])):
        _fields(f"{name}: runs[{i}]", r, _RUN_FIELDS, ("target", "variant"))
    for i, m in enumerate(data.get("mutants", [])):
        _fields(f"{name}: mutants[{i}]", m, _MUTANT_FIELDS, ("name", "variant", "fault"))


def _json_error(exc: ValueError) -> str:
    if isinstance(exc, json.JSONDecodeError):
        return (f"not a conform results file (JSON, line {exc.lineno} column {exc.colno}: "
                f"{exc.msg}); `conform report` re-renders the results.json of a run")
    return str(exc).split("; use sys")[0]


def load_results(path: str) -> RunResults:
    """``RunResults.load`` with every hostile file turned into one UserError line."""
    p = Path(path)
    if p.suffix in (".mcap", ".part", ".zip"):   # a capture or a bundle: another command's
        raise UserError(f"{p}: a capture, not a conform results file: `conform analyze {p}` "
                        "reads it; `conform report` re-renders the results.json of a run")
    data = load_user_file(p, json.loads, max_bytes=MAX_RESULTS_BYTES, what="results file",
                          describe=_json_error)
    if not isinstance(data, dict) or not isinstance(data.get("checks"), list):
        raise UserError(f"{p}: not a conform results file (no 'checks' list)")
    check_results(data, str(p))
    try:
        return RunResults.from_json(data)
    except (KeyError, TypeError, ValueError) as exc:
        raise UserError(f"{p}: malformed results: {exc}") from None


@click.command(name="report")
@click.argument("results", type=INPUT_FILE)
@click.option("-o", "--output", type=OUTPUT_DIR, default=None,
              help="Folder to write into (default: the folder of RESULTS).")
def cli(results: str, output: str | None) -> None:
    """Write index.html, summary.md and junit.xml (and results.json) from RESULTS.

    \b
    Example:
      conform report reports/latest/results.json -o shared/
    """
    data = load_results(results)
    out = writable_folder(output, "-o") if output else Path(results).resolve().parent
    write_reports(data, out)
    click.echo(f"report: {out / 'index.html'}")
