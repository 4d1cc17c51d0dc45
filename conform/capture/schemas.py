"""Topics and JSON schemas of a conform capture (see docs/capture-format.md).

Every channel is ``message_encoding="json"`` with a ``jsonschema`` schema, so Foxglove and
the ``mcap`` CLI show each one without plugins. ``/log`` uses Foxglove's published
``foxglove.Log`` JSON schema so the Log panel picks it up.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from conform.jsondoc import JsonObject

FORMAT_VERSION = "2"  # 1: one message per read and per line; 2: batches
PROFILE = ""  # plain MCAP, JSON messages (no ROS profile)

TOPIC_HOST = "/serial/host"
TOPIC_UNIT = "/serial/unit"
TOPIC_FRAMES = "/frames"
TOPIC_EXCHANGES = "/exchanges"
TOPIC_LINK = "/link"
TOPIC_LOG = "/log"

DIRECTION_TOPIC = {"host": TOPIC_HOST, "unit": TOPIC_UNIT}
DIRECTIONS = ("host", "unit")

LOG_LEVELS = {"unknown": 0, "debug": 1, "info": 2, "warning": 3, "error": 4, "fatal": 5}
LINK_KINDS = ("open", "close", "error", "disconnect", "reconnect", "baud")

_TIME = {"type": "number", "description": "seconds since the Unix epoch (clock in metadata)"}
_NULLABLE_TIME = {"type": ["number", "null"], "description": _TIME["description"]}

RAW_CHUNK: JsonObject = {
    "title": "conform.RawChunk",
    "description": "Bytes as one read returned them, in one direction",
    "type": "object",
    "properties": {
        "direction": {"type": "string", "enum": list(DIRECTIONS)},
        "data": {"type": "string", "contentEncoding": "base64", "description": "the bytes"},
        "hex": {"type": "string", "description": "the bytes as space-separated hex pairs"},
        "text": {"type": "string", "description": "printable ASCII, others escaped (\\r, \\xNN)"},
        "length": {"type": "integer", "minimum": 0},
        "offset": {"type": "integer", "minimum": 0, "description": "index of the first byte "
                   "in this direction's stream"},
        "t_read": _TIME | {"description": "when the read returned"},
        "t_first": _TIME | {"description": "estimated arrival of the first byte "
                            "(t_read - length*10/baud when estimated)"},
        "seq": {"type": "integer", "description": "chunk number in this direction"},
    },
    "required": ["direction", "data", "hex", "text", "length", "offset", "t_read", "t_first"],
}

FRAME: JsonObject = {
    "title": "conform.Frame",
    "description": "One decoded line: a command from the host or an answer from the unit",
    "type": "object",
    "properties": {
        "direction": {"type": "string", "enum": list(DIRECTIONS)},
        "kind": {"type": "string", "enum": ["command", "rejection", "answer", "echo", "garbled"]},
        "text": {"type": "string", "description": "the line, escaped, without its terminator"},
        "offset": {"type": "integer", "description": "byte offset of the line's first byte"},
        "length": {"type": "integer", "description": "bytes including the terminator"},
        "t_first": _TIME | {"description": "estimated time of the line's first byte"},
        "t_last": _TIME | {"description": "time the read holding its terminator returned"},
    },
    "required": ["direction", "kind", "text", "offset", "length", "t_first", "t_last"],
}

EXCHANGE: JsonObject = {
    "title": "conform.Exchange",
    "description": "A command paired with its answer (or its lack of one)",
    "type": "object",
    "properties": {
        "status": {"type": "string",
                   "enum": ["answered", "unanswered", "unsolicited"]},
        "command": {"type": ["string", "null"], "description": "command line, escaped"},
        "answer": {"type": ["string", "null"], "description": "answer line, escaped"},
        "t_command": _NULLABLE_TIME | {"description": "when the command's terminator arrived"},
        "t_answer": _NULLABLE_TIME | {"description": "estimated first byte of the answer"},
        "latency": {"type": ["number", "null"], "description": "t_answer - t_command, s"},
        "command_offset": {"type": ["integer", "null"]},
        "answer_offset": {"type": ["integer", "null"]},
    },
    "required": ["status", "command", "answer", "latency"],
}


@dataclass(frozen=True)
class CaptureFields:
    """The decoded fields a family adds to every frame and exchange it records.

    The engine records the bytes and the neutral part of a frame (``FRAME``: where a line is,
    when, which way, what kind) and of an exchange (``EXCHANGE``: a command, its answer and
    their times); what a line means in one protocol is the family's, declared here as JSON
    schema properties in row order (a family's live decoder gives ``fields``; its rows hold
    the neutral fields, then these). A capture's frame and exchange batches carry a column
    per field, so reading one needs no family (``batch.rows``).
    """

    frame: tuple[tuple[str, JsonObject], ...] = ()
    exchange: tuple[tuple[str, JsonObject], ...] = ()

    @property
    def frame_keys(self) -> tuple[str, ...]:
        return tuple(FRAME["properties"]) + tuple(k for k, _ in self.frame)

    @property
    def exchange_keys(self) -> tuple[str, ...]:
        return tuple(EXCHANGE["properties"]) + tuple(k for k, _ in self.exchange)

    def frame_schema(self) -> JsonObject:
        return _with(FRAME, self.frame)

    def exchange_schema(self) -> JsonObject:
        return _with(EXCHANGE, self.exchange)

    def channels(self) -> dict[str, tuple[str, JsonObject]]:
        """topic -> (schema name, schema) of a format 2 capture with these fields."""
        if not (self.frame or self.exchange):
            return CHANNELS
        return _layout(("conform.RawBatch", RAW_BATCH),
                       ("conform.FrameBatch", _batch_of("conform.FrameBatch", self.frame_schema())),
                       ("conform.ExchangeBatch",
                        _batch_of("conform.ExchangeBatch", self.exchange_schema())))


def _with(item: JsonObject, extra: tuple[tuple[str, JsonObject], ...]) -> JsonObject:
    clash = [k for k, _ in extra if k in item["properties"]]
    if clash:
        raise ValueError(f"{item['title']}: a family field may not replace {clash[0]!r}")
    return item | {"properties": item["properties"] | dict(extra)}


NEUTRAL = CaptureFields()  # a capture recorded without a family's decoder

LINK_EVENT: JsonObject = {
    "title": "conform.LinkEvent",
    "description": "Something that happened to a port, not to the bytes on it",
    "type": "object",
    "properties": {
        "kind": {"type": "string", "enum": list(LINK_KINDS)},
        "side": {"type": "string", "description": "host, unit or session"},
        "detail": {"type": "string"},
        "t": _TIME,
    },
    "required": ["kind", "side", "detail", "t"],
}

# Foxglove's published foxglove.Log JSON schema (the fields every Log panel reads).
FOXGLOVE_LOG: JsonObject = {
    "title": "foxglove.Log",
    "description": "A log message",
    "type": "object",
    "properties": {
        "timestamp": {
            "type": "object",
            "title": "time",
            "properties": {
                "sec": {"type": "integer", "minimum": 0},
                "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
            },
            "description": "Timestamp of log message",
        },
        "level": {
            "title": "foxglove.LogLevel",
            "description": "Log level",
            "oneOf": [
                {"title": title.upper(), "const": value}
                for title, value in LOG_LEVELS.items()
            ],
        },
        "message": {"type": "string", "description": "Log message"},
        "name": {"type": "string", "description": "Process or node name"},
        "file": {"type": "string", "description": "Filename"},
        "line": {"type": "integer", "minimum": 0, "description": "Line number in the file"},
    },
    "required": ["timestamp", "level", "message", "name", "file", "line"],
}

def _batch_of(title: str, item: JsonObject) -> JsonObject:
    props: JsonObject = {"count": {"type": "integer", "minimum": 0,
                                       "description": "items in this batch"}}
    for key, prop in item["properties"].items():
        props[key] = {"type": "array", "items": prop, "description": prop.get("description", key)}
    return {
        "title": title,
        "description": f"{item['description']}: everything decoded in one moment of the "
                       "recording, one list per field (item i is the i-th of every list)",
        "type": "object",
        "properties": props,
        "required": ["count"],
    }


RAW_BATCH: JsonObject = {
    "title": "conform.RawBatch",
    "description": "Consecutive reads in one direction, their bytes stored once",
    "type": "object",
    "properties": {
        "direction": {"type": "string", "enum": list(DIRECTIONS)},
        "offset": {"type": "integer", "minimum": 0, "description": "index of the first byte "
                   "in this direction's stream"},
        "count": {"type": "integer", "minimum": 1, "description": "reads in this batch"},
        "t_start": _TIME | {"description": "when the first read returned"},
        "t_end": _TIME | {"description": "when the last read returned"},
        "bytes": {"type": "integer", "minimum": 0, "description": "bytes in this batch"},
        "reads": {"type": "string", "contentEncoding": "base64",
                  "description": "per read, 28 bytes little-endian: u32 bytes the read "
                                 "returned, u64 call order (one count for both directions), "
                                 "f64 when it returned, f64 estimated arrival of its first "
                                 "byte (seconds since the epoch)"},
        "data": {"type": "string", "contentEncoding": "base64",
                 "description": "the bytes of all the reads, concatenated"},
    },
    "required": ["direction", "offset", "reads", "data"],
}
FRAME_BATCH = _batch_of("conform.FrameBatch", FRAME)
EXCHANGE_BATCH = _batch_of("conform.ExchangeBatch", EXCHANGE)

def _layout(raw: tuple[str, JsonObject], frames: tuple[str, JsonObject],
            exchanges: tuple[str, JsonObject]) -> dict[str, tuple[str, JsonObject]]:
    return {TOPIC_HOST: raw, TOPIC_UNIT: raw, TOPIC_FRAMES: frames, TOPIC_EXCHANGES: exchanges,
            TOPIC_LINK: ("conform.LinkEvent", LINK_EVENT),
            TOPIC_LOG: ("foxglove.Log", FOXGLOVE_LOG)}


# topic -> (schema name, schema) of the neutral fields (a family's: ``CaptureFields.channels``).
# Format 1 (one message per read and per line) is still read, no longer written; its frames
# and exchanges carry the fields of the family that recorded them besides these. Format 2
# batches (the same topics and the same channel ids).
CHANNELS_V1 = _layout(("conform.RawChunk", RAW_CHUNK), ("conform.Frame", FRAME),
                      ("conform.Exchange", EXCHANGE))
CHANNELS = _layout(("conform.RawBatch", RAW_BATCH), ("conform.FrameBatch", FRAME_BATCH),
                   ("conform.ExchangeBatch", EXCHANGE_BATCH))


def schema_bytes(schema: JsonObject) -> bytes:
    return json.dumps(schema, separators=(",", ":"), sort_keys=True).encode()
