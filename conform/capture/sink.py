"""Write session records into an MCAP file: schemas, channels, metadata, zstd chunks.

A thin layer over ``mcap.writer.Writer``; the only policy here is the layout (one JSON
schema per channel, registered up front) and small chunks, so that ``flush()`` every fraction
of a second leaves a file whose every complete chunk is readable after a crash.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from typing import IO, Any

import orjson
from mcap.records import Channel, Schema
from mcap.writer import CompressionType, Writer

from conform import __version__
from conform.capture.schemas import CHANNELS, PROFILE, schema_bytes
from conform.capture.session import Record

LIBRARY = f"conform {__version__}"
CHUNK_SIZE = 64 * 1024


def encode_payload(payload: Mapping[str, Any]) -> bytes:
    """Compact JSON (orjson: a batch of thousands of frames encodes ten times faster).

    JSON has no NaN or infinity: orjson writes a non-finite time as ``null``. What orjson
    refuses (an integer beyond 64 bits, a non-string key) goes through the standard library.
    """
    try:
        return orjson.dumps(payload)
    except TypeError:  # orjson.JSONEncodeError
        return json.dumps(payload, separators=(",", ":"), ensure_ascii=True).encode("ascii")


class McapSink:
    """An open MCAP file with every conform channel registered."""

    def __init__(
        self,
        stream: IO[bytes],
        *,
        chunk_size: int = CHUNK_SIZE,
        compression: CompressionType = CompressionType.ZSTD,
        library: str = LIBRARY,
        topics: Mapping[str, tuple[str, dict[str, object]]] = CHANNELS,
    ) -> None:
        self._stream = stream
        self._writer = Writer(stream, chunk_size=chunk_size, compression=compression,
                              enable_data_crcs=True)
        self._writer.start(profile=PROFILE, library=library)
        self._channels: dict[str, int] = {}
        schema_ids: dict[str, int] = {}
        for topic, (schema_name, schema) in topics.items():
            if schema_name not in schema_ids:
                schema_ids[schema_name] = self._writer.register_schema(
                    schema_name, "jsonschema", schema_bytes(schema)
                )
            self._channels[topic] = self._writer.register_channel(
                topic, "json", schema_ids[schema_name]
            )
        self._sequence = dict.fromkeys(self._channels, 0)
        self.count = 0

    def metadata(self, name: str, data: Mapping[str, object]) -> None:
        """An MCAP Metadata record; values become strings as the format requires."""
        self._writer.add_metadata(name, {str(k): _text(v) for k, v in data.items()})

    def write(self, record: Record, data: bytes | None = None) -> None:
        channel = self._channels[record.topic]
        self._sequence[record.topic] += 1
        self._writer.add_message(
            channel_id=channel,
            log_time=record.log_time,
            publish_time=record.log_time,
            sequence=self._sequence[record.topic],
            data=data if data is not None else encode_payload(record.payload),
        )
        self.count += 1

    def flush(self, fsync: bool = False) -> None:
        """Close the open chunk and hand everything to the OS (and the disk with ``fsync``)."""
        self._writer.flush()
        if fsync:
            os.fsync(self._stream.fileno())

    def finish(self) -> None:
        """Summary, footer, closing magic; the stream is left open for the caller."""
        self._writer.finish()
        self._stream.flush()


def default_layout() -> tuple[dict[int, Schema], dict[int, Channel]]:
    """The schema and channel records ``McapSink`` writes, with the ids it gives them.

    A conform file whose first chunk (where these live) is damaged can still be read and
    recovered with them: the ids are assigned the same way every time.
    """
    schemas: dict[int, Schema] = {}
    by_name: dict[str, int] = {}
    channels: dict[int, Channel] = {}
    for topic, (schema_name, schema) in CHANNELS.items():
        if schema_name not in by_name:
            by_name[schema_name] = len(by_name) + 1
            schemas[by_name[schema_name]] = Schema(by_name[schema_name], schema_bytes(schema),
                                                   "jsonschema", schema_name)
        cid = len(channels) + 1
        channels[cid] = Channel(cid, topic, "json", {}, by_name[schema_name])
    return schemas, channels


def _text(value: object) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)
