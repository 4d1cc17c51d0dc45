"""``conform analyze`` for captures of another protocol family: look at the start of the file
(metadata and the first 64 KiB each way), decide the family (conform.families.divert), and
run that family's analysis. GVE captures return ``False`` untouched, for the GVE analyser."""

from __future__ import annotations

import json
from typing import Any

import click

from conform.families import Detection, divert, family, family_names

PEEK_BYTES = 65536


def peek_capture(path: str, limit: int = PEEK_BYTES, *, bytes_too: bool = False
                 ) -> tuple[bytes, bytes, dict[str, Any]]:
    """The first ``limit`` bytes of each direction and the session metadata of a capture
    (only the metadata when it names a variant, unless ``bytes_too``)."""
    from conform.capture.batch import payload_bytes
    from conform.capture.scan import ScanStatus, iter_messages
    from conform.capture.schemas import DIRECTION_TOPIC

    topic_dir = {t: d for d, t in DIRECTION_TOPIC.items()}
    data = {"host": bytearray(), "unit": bytearray()}
    status = ScanStatus(path)
    seen = 0
    for channel, rec in iter_messages(status):
        if status.metadata.get("conform.session", {}).get("variant") and not bytes_too:
            break          # the capture says what it is: no need to look at the bytes
        seen += 1
        if seen > 4 * limit // 16:
            break          # enough messages looked at; one direction is simply quiet
        d = topic_dir.get(channel.topic) if channel is not None else None
        if d is None or len(data[d]) >= limit:
            if all(len(b) >= limit for b in data.values()):
                break
            continue
        try:
            data[d] += payload_bytes(json.loads(rec.data))
        except (ValueError, AttributeError, RecursionError):
            continue
    meta = dict(status.metadata.get("conform.session", {}))
    return bytes(data["host"][:limit]), bytes(data["unit"][:limit]), meta


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


def detect_capture(path: str, variant: str | None) -> Detection | None:
    """The non-GVE family of a capture, or None (GVE, or a file the GVE path should judge)."""
    return peek_family(path, variant)[0]


def peek_family(path: str, variant: str | None) -> tuple[Detection | None, dict[str, Any]]:
    """:func:`detect_capture` and the session metadata it saw (empty when it had none)."""
    if variant:
        return divert(b"", b"", {}, variant), {}
    try:
        host, unit, meta = peek_capture(path)
    except Exception:  # noqa: BLE001 - not ours to report: the GVE path says what is wrong
        return None, {}
    return divert(host, unit, meta, variant), meta


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

    d, empty = _detect_or_empty(path, variant)
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
                    detected=d.why)
    from conform.diagnosis import headline_for

    headline_for(path, a, fam.name, click.echo)
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


def _detect_or_empty(path: str, variant: str | None) -> tuple[Detection | None, bool]:
    """The family of a capture other than the default one (None: the default family's), and
    whether it holds no traffic at all."""
    if variant:
        return divert(b"", b"", {}, variant), False
    try:
        host, unit, meta = peek_capture(path)
    except Exception:  # noqa: BLE001 - not ours to report: the default path says what is wrong
        return None, False
    if not host and not unit and not meta.get("variant"):
        return None, True
    return divert(host, unit, meta, variant), False


def _echo_json(doc: dict[str, Any]) -> None:
    from conform.cli.params import echo_json

    echo_json(doc)
