"""``conform analyze`` for captures of another protocol family: look at the start of the file
(metadata and the first 64 KiB each way), decide the family (conform.families.divert), and
run that family's analysis. GVE captures return ``False`` untouched, for the GVE analyser."""

from __future__ import annotations

import base64
import binascii
import json
from typing import Any

import click

from conform.families import Detection, divert

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
    if variant:
        return divert(b"", b"", {}, variant)
    try:
        host, unit, meta = peek_capture(path)
    except Exception:  # noqa: BLE001 - not ours to report: the GVE path says what is wrong
        return None
    return divert(host, unit, meta, variant)


def analyze_other_family(path: str, variant: str | None, report_dir: str | None,
                         parquet_dir: str | None = None) -> bool:
    """Analyse ``path`` with its family if it is not GVE traffic; False leaves it to GVE."""
    d = detect_capture(path, variant)
    if d is None:
        return False
    if d.family == "unknown":
        click.echo(f"{path}: protocol unknown ({d.why}); not analysed as GVE or grbl traffic")
        return True
    from conform.families.grbl.analysis import analyze_capture, write_parquet, write_report

    click.echo(f"{path}: protocol family {d.family} ({d.why})")
    a = analyze_capture(path, variant=variant if variant and d.family == "grbl" else None,
                        detected=d.why)
    m = a.metrics
    click.echo(f"{m['lines']} lines, {m['answered']} answered ({m['ok']} ok, {m['errors']} "
               f"error) in {m['duration_s']:.3f} s; streaming {m['streaming_method']}, at most "
               f"{m['max_bytes_in_flight']} bytes in flight (receive buffer {m['rx_buffer']}); "
               f"{m['status_polls']} status polls ({m['poll_rate_hz']:.1f}/s)")
    counts = m.get("finding_counts", {})
    click.echo("findings: " + (", ".join(f"{k} {n}" for k, n in counts.items()) or "none"))
    for f in a.findings:
        if f.severity in ("hazard", "error"):
            click.echo(f"  {f.t:10.4f}s {f.severity:7} {f.kind}: {f.message}")
    for note in a.notes:
        click.echo(f"note: {note}")
    if report_dir:
        paths = write_report(a, report_dir)
        click.echo(f"report: {paths['html']}")
    if parquet_dir:
        write_parquet(a, parquet_dir)
        click.echo(f"tables: {parquet_dir}")
    return True
