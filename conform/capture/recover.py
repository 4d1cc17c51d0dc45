"""``capture info`` and ``capture recover``: summarise a capture, salvage a killed one.

Recovery is a rewrite: every intact schema, channel, message and metadata record of the
damaged file goes, in order, into a fresh MCAP written by the normal writer (so it has a
summary, indexes and a footer), plus a ``conform.recovery`` metadata record saying what was
lost. The damaged file is left untouched.
"""

from __future__ import annotations

import binascii
import json
import os
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

from mcap.records import Channel, Header, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer

from conform import __version__
from conform.capture.batch import BATCH_KEYS, is_batch, is_raw_batch, payload_bytes, rows, unbatch_raw
from conform.capture.recorder import PART_SUFFIX
from conform.capture.scan import ScanStatus, iter_messages, iter_records
from conform.capture.schemas import DIRECTION_TOPIC, TOPIC_EXCHANGES, TOPIC_FRAMES, TOPIC_LINK
from conform.capture.sink import default_layout
from conform.errors import UserError

_RAW_TOPICS = {topic: d for d, topic in DIRECTION_TOPIC.items()}
_CHECKED = {TOPIC_FRAMES, TOPIC_EXCHANGES, TOPIC_LINK}


@dataclass
class CaptureInfo:
    path: Path
    status: ScanStatus
    first_ns: int | None = None
    last_ns: int | None = None
    messages: Counter[str] = field(default_factory=Counter)
    bytes: dict[str, int] = field(default_factory=lambda: dict.fromkeys(DIRECTION_TOPIC, 0))
    gaps: dict[str, int] = field(default_factory=lambda: dict.fromkeys(DIRECTION_TOPIC, 0))
    reads: dict[str, int] = field(default_factory=lambda: dict.fromkeys(DIRECTION_TOPIC, 0))
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    bad_messages: int = 0
    bad_schemas: int = 0

    @property
    def duration(self) -> float:
        if self.first_ns is None or self.last_ns is None:
            return 0.0
        return (self.last_ns - self.first_ns) / 1e9

    @property
    def state(self) -> str:
        if self.status.clean and (self.bad_messages or self.bad_schemas):
            return "damaged"  # whole, but some raw messages cannot be read
        if self.status.clean:
            return "recovered" if "conform.recovery" in self.metadata else "clean"
        if self.status.complete:
            return "damaged"
        return "truncated"


def resolve_source(path: str | os.PathLike[str]) -> Path:
    """``FILE.mcap`` falls back to ``FILE.mcap.part`` when only the unfinished one exists."""
    p = Path(path)
    if not p.exists():
        part = p.with_name(p.name + PART_SUFFIX)
        if part.exists():
            return part
    return p


def capture_info(path: str | os.PathLike[str]) -> CaptureInfo:
    """One pass over the file: duration, bytes each way, messages per channel, state."""
    src = resolve_source(path)
    info = CaptureInfo(src, ScanStatus(src))
    expected = dict.fromkeys(DIRECTION_TOPIC, 0)
    for channel, rec in iter_messages(info.status):
        topic = channel.topic if channel is not None else f"<channel {rec.channel_id}>"
        info.messages[topic] += 1
        t = rec.log_time
        info.first_ns = t if info.first_ns is None else min(info.first_ns, t)
        info.last_ns = t if info.last_ns is None else max(info.last_ns, t)
        direction = _RAW_TOPICS.get(topic)
        if direction is not None:
            span = _raw_span(rec.data)
            if span is None:
                info.bad_messages += 1
                continue
            offset, length, reads = span
            info.bytes[direction] += length
            info.reads[direction] += reads
            if offset != expected[direction]:
                info.gaps[direction] += 1
            expected[direction] = offset + length
        elif topic in _CHECKED and not _derived_ok(topic, rec.data):
            info.bad_messages += 1
    info.metadata = info.status.metadata
    info.bad_schemas = info.status.bad_schemas
    return info


def _raw_span(data: bytes) -> tuple[int, int, int] | None:
    """(stream offset, bytes, reads) of a raw message, format 1 or 2; None if unreadable."""
    try:
        payload = json.loads(data)
        if not isinstance(payload, dict):
            return None
        if is_raw_batch(payload):
            reads = unbatch_raw(payload, 0)
            return int(payload["offset"]), sum(r["length"] for r in reads), len(reads)
        offset, length = int(payload["offset"]), int(payload["length"])
        if len(payload_bytes(payload)) != length:
            return None
    except (ValueError, KeyError, TypeError, RecursionError, OverflowError, binascii.Error):
        return None
    if offset < 0 or length < 0:
        return None
    return offset, length, 1


def _derived_ok(topic: str, data: bytes) -> bool:
    """A ``/frames``, ``/exchanges`` or ``/link`` message that can be read (JSON objects;
    format 2 batches whose columns hold together)."""
    try:
        payload = json.loads(data)
    except (ValueError, RecursionError):
        return False
    if not isinstance(payload, dict):
        return False
    if topic in BATCH_KEYS and is_batch(payload):
        try:
            rows(payload, BATCH_KEYS[topic])
        except ValueError:
            return False
    return True


def format_info(info: CaptureInfo) -> str:
    s = info.status
    pad = " " * 16
    lines = [f"{'file:':<16}{info.path}", f"{'state:':<16}{info.state}"]
    if s.problem and not s.complete:
        lines.append(f"{pad}{s.problem}; intact up to byte {s.valid_bytes} of {s.size}")
    for note in s.notes[:5]:
        lines.append(f"{pad}{note}")
    session = info.metadata.get("conform.session", {})
    for key in ("capture_method", "variant", "baud", "host_port", "unit_port", "started"):
        if session.get(key):
            lines.append(f"{key + ':':<16}{session[key]}")
    lines.append(f"{'duration:':<16}{info.duration:.3f} s")
    for d in DIRECTION_TOPIC:
        gap = f"  ({info.gaps[d]} gaps in offsets)" if info.gaps[d] else ""
        lines.append(f"{'bytes ' + d + ':':<16}{info.bytes[d]} in {info.reads[d]} reads{gap}")
    lines.append("messages:")
    for topic, n in sorted(info.messages.items()):
        lines.append(f"  {topic:<14}{n}")
    if info.bad_messages:
        lines.append(f"unreadable messages: {info.bad_messages}")
    if info.bad_schemas:
        lines.append(f"unreadable schemas: {info.bad_schemas}")
    return "\n".join(lines)


@dataclass
class RecoverResult:
    source: Path
    output: Path
    status: ScanStatus
    messages: int
    last_ns: int | None


def default_output(src: Path) -> Path:
    if src.name.endswith(PART_SUFFIX):
        return src.with_name(src.name[: -len(PART_SUFFIX)])
    stem = src.name[:-5] if src.name.endswith(".mcap") else src.name
    return src.with_name(stem + ".recovered.mcap")


def recover(
    path: str | os.PathLike[str], output: str | os.PathLike[str] | None = None, *,
    force: bool = False,
) -> RecoverResult:
    """Rewrite what is intact in ``path`` as a complete MCAP at ``output``."""
    src = resolve_source(path)
    status = ScanStatus(src)
    records = iter_records(status)  # raises UserError now if src is not an MCAP at all
    first = next(records, None)
    dst = Path(output) if output is not None else default_output(src)
    if dst.resolve() == src.resolve():
        raise UserError(f"{dst}: output would overwrite the file being recovered")
    if dst.exists() and not force:
        raise UserError(f"{dst}: already exists (use --force to replace it)")
    tmp = dst.with_name(dst.name + ".tmp")
    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    metadata: list[Metadata] = []
    count = 0
    last_ns: int | None = None
    fallback_schemas, fallback_channels = default_layout()
    try:
        with open(tmp, "wb") as f:
            writer = Writer(f, chunk_size=1024 * 1024, compression=CompressionType.ZSTD)
            library = first.library if isinstance(first, Header) else ""
            profile = first.profile if isinstance(first, Header) else ""
            writer.start(profile=profile, library=library or f"conform {__version__}")
            pending: list[object] = [first] if first is not None and not isinstance(first, Header) else []
            for rec in _chain(pending, records):
                if isinstance(rec, Schema) and rec.id not in schemas:
                    schemas[rec.id] = writer.register_schema(rec.name, rec.encoding, rec.data)
                elif isinstance(rec, Channel) and rec.id not in channels:
                    channels[rec.id] = writer.register_channel(
                        rec.topic, rec.message_encoding, schemas.get(rec.schema_id, 0),
                        dict(rec.metadata),
                    )
                elif isinstance(rec, Message) and rec.channel_id not in channels \
                        and status.library.startswith("conform") \
                        and rec.channel_id in fallback_channels:
                    # the chunk holding this conform file's channels was lost: use the
                    # layout every conform recorder writes
                    for sid, schema in fallback_schemas.items():
                        if sid not in schemas:
                            schemas[sid] = writer.register_schema(schema.name, schema.encoding,
                                                                  schema.data)
                    ch = fallback_channels[rec.channel_id]
                    channels[rec.channel_id] = writer.register_channel(
                        ch.topic, ch.message_encoding, schemas[ch.schema_id])
                    writer.add_message(channels[rec.channel_id], rec.log_time, rec.data,
                                       rec.publish_time, rec.sequence)
                    count += 1
                    last_ns = rec.log_time if last_ns is None else max(last_ns, rec.log_time)
                elif isinstance(rec, Message) and rec.channel_id in channels:
                    writer.add_message(channels[rec.channel_id], rec.log_time, rec.data,
                                       rec.publish_time, rec.sequence)
                    count += 1
                    last_ns = rec.log_time if last_ns is None else max(last_ns, rec.log_time)
                elif isinstance(rec, Metadata):
                    metadata.append(rec)
            for m in metadata:
                writer.add_metadata(m.name, m.metadata)
            writer.add_metadata("conform.recovery", {
                "source": str(src),
                "tool_version": __version__,
                "source_complete": "true" if status.complete else "false",
                "problem": status.problem or "",
                "intact_bytes": str(status.valid_bytes),
                "source_bytes": str(status.size),
                "damaged_chunks": str(status.damaged_chunks),
                "messages": str(count),
            })
            writer.finish()
        os.replace(tmp, dst)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise UserError(f"{dst}: cannot write: {exc.strerror}") from None
    return RecoverResult(src, dst, status, count, last_ns)


_T = TypeVar("_T")


def _chain(first: Iterable[_T], rest: Iterable[_T]) -> Iterator[_T]:
    yield from first
    yield from rest
