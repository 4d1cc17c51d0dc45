"""``conform analyze`` for captures of another protocol family: look at the start of the file
(metadata and the first 64 KiB each way), decide the family (conform.families.divert), and
run that family's analysis. GVE captures return ``False`` untouched, for the GVE analyser."""

from __future__ import annotations

import base64
import binascii
import json
from typing import Any

import click

from conform.families import Detection, divert, family, family_names

PEEK_BYTES = 65536


def peek_capture(path: str, limit: int = PEEK_BYTES) -> tuple[bytes, bytes, dict[str, Any]]:
    """The first ``limit`` bytes of each direction and the session metadata of a capture."""
    from mcap.records import Channel, Message, Metadata

    from conform.capture.scan import ScanStatus, iter_records
    from conform.capture.schemas import DIRECTION_TOPIC

    topic_dir = {t: d for d, t in DIRECTION_TOPIC.items()}
    channels: dict[int, str] = {}
    data = {"host": bytearray(), "unit": bytearray()}
    meta: dict[str, Any] = {}
    seen = 0
    for rec in iter_records(ScanStatus(path)):
        if isinstance(rec, Channel):
            channels.setdefault(rec.id, rec.topic)
        elif isinstance(rec, Metadata) and rec.name == "conform.session":
            meta = dict(rec.metadata)
            if meta.get("variant"):
                break          # the capture says what it is: no need to look at the bytes
        elif isinstance(rec, Message):
            seen += 1
            if seen > 4 * limit // 16:
                break          # enough messages looked at; one direction is simply quiet
            d = topic_dir.get(channels.get(rec.channel_id, ""))
            if d is None or len(data[d]) >= limit:
                if all(len(b) >= limit for b in data.values()):
                    break
                continue
            try:
                payload = json.loads(rec.data)
                data[d] += base64.b64decode(payload.get("data", ""), validate=True)
            except (ValueError, TypeError, AttributeError, binascii.Error, RecursionError):
                continue
    return bytes(data["host"][:limit]), bytes(data["unit"][:limit]), meta


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
                         parquet_dir: str | None = None) -> bool:
    """Analyse ``path`` with its family if it is not GVE traffic; False leaves it to GVE."""
    d = detect_capture(path, variant)
    if d is None:
        return False
    if d.family == "unknown":
        click.echo(f"{path}: protocol unknown ({d.why}); not analysed as traffic of "
                   f"{' or '.join(family_names())}")
        return True
    fam = family(d.family)
    click.echo(f"{path}: protocol family {d.family} ({d.why})")
    a = fam.analyze(path, variant=variant if variant and d.family == fam.name else None,
                    detected=d.why)
    from conform.diagnosis import headline_for

    headline_for(path, a, fam.name, click.echo)
    for line in a.summary_lines():
        click.echo(line)
    if report_dir:
        paths = a.write_report(report_dir)
        click.echo(f"report: {paths['html']}")
    if parquet_dir:
        a.write_tables(parquet_dir)
        click.echo(f"tables: {parquet_dir}")
    return True
