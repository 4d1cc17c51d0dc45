"""Whose traffic a capture holds, from a look at its start: the session metadata and the
first bytes each way (what ``conform analyze``, fleets, the diagnosis and bundles ask before
they read a capture whole)."""

from __future__ import annotations

import json
from pathlib import Path

from conform.families import Detection, divert
from conform.jsondoc import JsonObject

PEEK_BYTES = 65536


def peek_capture(path: str, limit: int = PEEK_BYTES, *, bytes_too: bool = False
                 ) -> tuple[bytes, bytes, JsonObject]:
    """The first ``limit`` bytes of each direction and the session metadata of a capture
    (only the metadata when it names a variant, unless ``bytes_too``)."""
    from conform.capture.batch import payload_bytes
    from conform.capture.scan import ScanStatus, iter_messages
    from conform.capture.schemas import DIRECTION_TOPIC

    topic_dir = {t: d for d, t in DIRECTION_TOPIC.items()}
    data = {"host": bytearray(), "unit": bytearray()}
    status = ScanStatus(Path(path))
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


def detect_capture(path: str, variant: str | None) -> Detection | None:
    """The non-GVE family of a capture, or None (GVE, or a file the GVE path should judge)."""
    return peek_family(path, variant)[0]


def peek_family(path: str, variant: str | None) -> tuple[Detection | None, JsonObject]:
    """:func:`detect_capture` and the session metadata it saw (empty when it had none)."""
    if variant:
        return divert(b"", b"", {}, variant), {}
    try:
        host, unit, meta = peek_capture(path)
    except Exception:  # noqa: BLE001 - not ours to report: the GVE path says what is wrong
        return None, {}
    return divert(host, unit, meta, variant), meta


def detect_or_empty(path: str, variant: str | None) -> tuple[Detection | None, bool]:
    """The family of a capture other than the default one (None: the default family's), and
    whether it holds no traffic at all (and is intact: a damaged file with no traffic goes to
    the default path, which says what is damaged)."""
    if variant:
        return divert(b"", b"", {}, variant), False
    try:
        host, unit, meta = peek_capture(path)
    except Exception:  # noqa: BLE001 - not ours to report: the default path says what is wrong
        return None, False
    if not host and not unit and not meta.get("variant"):
        return None, _intact(path)
    return divert(host, unit, meta, variant), False


def _intact(path: str) -> bool:
    from conform.capture.scan import ScanStatus, iter_messages

    status = ScanStatus(Path(path))
    for _ in iter_messages(status):
        pass
    return status.clean
