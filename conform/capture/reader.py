"""Read a conform capture back: raw chunks, frames, exchanges, link events, logs, metadata.

For the analyser and the CLI. Tolerant by design: a truncated or partly damaged file gives
everything that is intact, and ``capture.truncated`` / ``capture.status`` say what was
missing. Only a file that is not an MCAP at all raises ``UserError``::

    cap = open_capture("run.mcap")
    for chunk in cap.raw_chunks("host"):      # dicts as in docs/capture-format.md,
        chunk["bytes"]                        # plus the decoded bytes
    df = cap.table("/exchanges")              # a pandas DataFrame, one row per message
    cap.metadata["conform.session"]["baud"]
    cap.truncated                             # True if the recorder never finished
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from mcap.records import Channel, Message

from conform.capture.batch import BATCH_KEYS, is_batch, is_raw_batch, payload_bytes, rows, unbatch_raw
from conform.capture.scan import ScanStatus, check_magic, iter_messages
from conform.capture.schemas import (
    DIRECTION_TOPIC,
    TOPIC_EXCHANGES,
    TOPIC_FRAMES,
    TOPIC_LINK,
    TOPIC_LOG,
)
from conform.jsondoc import JsonObject

if TYPE_CHECKING:
    import pandas as pd


@dataclass(frozen=True)
class CaptureMessage:
    topic: str
    log_time: int  # ns since the epoch
    sequence: int
    payload: JsonObject


class Capture:
    """One capture file; every iterator makes its own pass over the file."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = check_magic(path)
        self._status: ScanStatus | None = None
        self._metadata: dict[str, dict[str, str]] | None = None
        self.bad_messages = 0

    # -- low level -------------------------------------------------------------------------
    def _pass(self, topics: set[str] | None) -> Iterator[tuple[Channel, Message]]:
        status = ScanStatus(self.path)
        for channel, msg in iter_messages(status):
            if channel is not None and (topics is None or channel.topic in topics):
                yield channel, msg
        self._status = status
        self._metadata = status.metadata

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[CaptureMessage]:
        """JSON messages on ``topics`` (all if ``None``), in file order."""
        wanted = set(topics) if topics is not None else None
        bad = 0
        for channel, msg in self._pass(wanted):
            if channel.message_encoding != "json":
                continue
            try:
                payload = json.loads(msg.data)
            except (ValueError, RecursionError):
                bad += 1
                continue
            if not isinstance(payload, dict):
                bad += 1
                continue
            yield CaptureMessage(channel.topic, msg.log_time, msg.sequence, payload)
        self.bad_messages = bad

    @property
    def status(self) -> ScanStatus:
        """What the last full pass found (makes one if none has run)."""
        if self._status is None:
            for _ in self._pass(set()):
                pass
        assert self._status is not None
        return self._status

    @property
    def truncated(self) -> bool:
        return self.status.truncated

    @property
    def clean(self) -> bool:
        return self.status.clean

    @property
    def metadata(self) -> dict[str, dict[str, str]]:
        """MCAP Metadata records by name (``conform.session``, ``conform.session_end``...)."""
        if self._metadata is None:
            self.status  # noqa: B018 - a pass fills it
        assert self._metadata is not None
        return self._metadata

    # -- typed views -----------------------------------------------------------------------
    def raw_chunks(self, direction: str | None = None) -> Iterator[JsonObject]:
        """Raw chunks (reads), both directions merged in file order, with ``bytes`` added.

        Format 2 batches are unpacked into one dict per read (``direction``, ``bytes``,
        ``length``, ``offset``, ``t_read``, ``t_first``, ``order``, ``log_time``).
        """
        if direction is not None and direction not in DIRECTION_TOPIC:
            raise ValueError(f"direction must be 'host' or 'unit', not {direction!r}")
        topics = [DIRECTION_TOPIC[direction]] if direction else list(DIRECTION_TOPIC.values())
        batched: list[JsonObject] = []  # both directions: put back in call order
        for m in self.messages(topics):
            if is_raw_batch(m.payload):
                try:
                    reads = unbatch_raw(m.payload, m.log_time)
                except ValueError:
                    self.bad_messages += 1
                    continue
                if direction:
                    yield from reads
                else:
                    batched.extend(reads)
                continue
            payload = dict(m.payload)
            try:
                payload["bytes"] = payload_bytes(payload)
            except ValueError:
                self.bad_messages += 1
                continue
            payload["log_time"] = m.log_time
            yield payload
        batched.sort(key=lambda r: r["order"])
        yield from batched

    def _topic(self, topic: str) -> Iterator[JsonObject]:
        for m in self.messages([topic]):
            yield {**m.payload, "log_time": m.log_time}

    def _batched(self, topic: str) -> Iterator[JsonObject]:
        for m in self.messages([topic]):
            if not is_batch(m.payload):  # format 1: one message per item
                yield {**m.payload, "log_time": m.log_time}
                continue
            try:
                items = rows(m.payload, BATCH_KEYS[topic])
            except ValueError:
                self.bad_messages += 1
                continue
            for item in items:
                yield {**item, "log_time": m.log_time}

    def frames(self) -> Iterator[JsonObject]:
        """Decoded lines (``conform.Frame`` dicts with the fields of the family that decoded
        them), unpacked from format 2 batches."""
        return self._batched(TOPIC_FRAMES)

    def exchanges(self) -> Iterator[JsonObject]:
        """Exchanges (``conform.Exchange`` dicts), unpacked from format 2 batches."""
        return self._batched(TOPIC_EXCHANGES)

    def link_events(self) -> Iterator[JsonObject]:
        return self._topic(TOPIC_LINK)

    def logs(self) -> Iterator[JsonObject]:
        return self._topic(TOPIC_LOG)

    def stream(self, direction: str) -> bytes:
        """Every byte of one direction, concatenated (gaps are not filled)."""
        return b"".join(c["bytes"] for c in self.raw_chunks(direction))

    def table(self, topic: str) -> pd.DataFrame:
        """A topic (or ``"host"``/``"unit"``) as a DataFrame; ``log_time`` in ns."""
        import pandas as pd

        by_topic = {t: d for d, t in DIRECTION_TOPIC.items()}
        if topic in DIRECTION_TOPIC or topic in by_topic:
            rows: Iterable[JsonObject] = self.raw_chunks(by_topic.get(topic, topic))
        elif topic == TOPIC_FRAMES:
            rows = self.frames()
        elif topic == TOPIC_EXCHANGES:
            rows = self.exchanges()
        else:
            rows = self._topic(topic)
        return pd.DataFrame.from_records(list(rows))


def open_capture(path: str | os.PathLike[str]) -> Capture:
    """A ``Capture`` for ``path``; ``UserError`` if it is missing or not an MCAP file."""
    return Capture(Path(path))
