"""``conform analyze`` for captures of another protocol family: look at the start of the file
(metadata and the first 64 KiB each way), decide the family (conform.families.divert), and
run that family's analysis. GVE captures return ``False`` untouched, for the GVE analyser."""

from __future__ import annotations

from typing import Any

import click

from conform.families import family, family_names
from conform.families.peek import detect_or_empty, peek_capture


def not_this_family(path: str, variant: str) -> str | None:
    """Why ``--variant`` cannot be right for this capture (it names, or its bytes are, another
    family's traffic), or None. An analysis of one family's traffic as another's would
    report bogus findings (overflows, unanswered lines) instead of saying so."""
    from conform.families import detect_family, family_for_variant

    wanted = family_for_variant(variant).name
    try:
        host, unit, meta = peek_capture(path, bytes_too=True)
    except Exception:  # noqa: BLE001 - not ours to report: the analyser says what is wrong
        return None
    seen = detect_family(host, unit, {})   # the bytes first: a capture may name a wrong one
    if seen.family not in ("unknown", wanted):
        return (f"this is not {wanted} traffic: {seen.why} ({seen.family}); leave out "
                f"--variant or give one of {seen.family}'s")
    declared = str(meta.get("variant", "") or "")
    if seen.family == "unknown" and declared and declared != variant:
        named = family_for_variant(declared).name
        if named != wanted:
            return (f"this is not {wanted} traffic: the capture names variant {declared} "
                    f"({named}); leave out --variant or give one of {named}'s")
    return None


def analyze_other_family(path: str, variant: str | None, report_dir: str | None,
                         parquet_dir: str | None = None, as_json: bool = False) -> Any:
    """Analyse ``path`` with its family if it is not the default family's traffic: that
    family's analysis (True for traffic of no family, or none at all); False leaves it to the
    default family's analyser.

    A capture with no byte either way (a program that died at once) is reported as empty,
    whatever family the bytes would have been. ``as_json``: the text goes to stderr and the
    analysis's findings document (the shape GVE's ``--json`` prints) to stdout."""
    def echo(text: str) -> None:
        click.echo(text, err=as_json)

    d, empty = detect_or_empty(path, variant)
    if empty:
        echo(f"{path}: empty capture: no byte either way (the program sent nothing and "
             "nothing came back); nothing to analyse")
        if as_json:
            _echo_json({"capture": path, "variant": None, "findings": [],
                        "metrics": {"bytes_host": 0, "bytes_unit": 0, "streaming_method": "none"},
                        "notes": ["empty capture"], "empty": True})
        return True
    if d is None:
        return False
    if d.family == "unknown":
        echo(f"{path}: protocol unknown ({d.why}); not analysed as traffic of "
             f"{' or '.join(family_names())}")
        if as_json:
            _echo_json({"capture": path, "variant": None, "findings": [], "metrics": {},
                        "notes": [f"protocol unknown: {d.why}"]})
        return True
    fam = family(d.family)
    echo(f"{path}: protocol family {d.family} ({d.why})")
    a = fam.analyze(path, variant=variant if variant and d.family == fam.name else None,
                    detected=d.why, parquet=parquet_dir)   # a family may stream its tables
    from conform.diagnosis import headline_for

    headline_for(path, a, fam.name, echo)
    for line in a.summary_lines():
        echo(line)
    paths = {}
    if report_dir:
        paths["report"] = str(a.write_report(report_dir)["html"])
        echo(f"report: {paths['report']}")
    if parquet_dir:
        a.write_tables(parquet_dir)
        paths["parquet"] = parquet_dir
        echo(f"tables: {parquet_dir}")
    if as_json:
        document = getattr(a, "findings_document", None)
        _echo_json((document() if document else {"capture": path, "family": d.family,
                                                 "summary": a.summary_lines()}) | paths)
    return a


def _echo_json(doc: dict[str, object]) -> None:
    from conform.cli.params import echo_json

    echo_json(doc)
