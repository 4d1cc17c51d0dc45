"""Walk an MCAP file record by record, trusting nothing in it.

A killed recorder leaves a file that stops mid-record; a hostile or foreign file may claim
lengths it does not have, chunks that decompress to gigabytes, or strings that are not
UTF-8. ``iter_records`` bounds every length by what the file really holds, verifies chunk
CRCs, skips a damaged chunk and stops at the first damaged top-level record, and reports
what it saw in a ``ScanStatus`` instead of raising. Only "this is not an MCAP file at all"
is an error (``UserError``), because there is nothing to salvage.
"""

from __future__ import annotations

import io
import json
import os
import struct
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Protocol

import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Footer, Header, Message, Metadata, Schema

from conform.errors import UserError

MAGIC = b"\x89MCAP0\r\n"
MAX_RECORD = 256 * 1024 * 1024  # larger records are treated as damage, not allocated
MAX_CHUNK_UNCOMPRESSED = 256 * 1024 * 1024
PROGRESS_BYTES = 4 * 1024 * 1024  # data_records tells its progress this often

Item = Header | Schema | Channel | Message | Metadata


@dataclass
class ScanStatus:
    """What a pass over the file found; filled in while ``iter_records`` runs."""

    path: Path
    size: int = 0
    complete: bool = False  # footer and closing magic reached
    problem: str | None = None  # why the walk stopped early, if it did
    damaged_chunks: int = 0
    damaged_records: int = 0
    valid_bytes: int = 0  # end of the last intact top-level record
    library: str = ""
    profile: str = ""
    notes: list[str] = field(default_factory=list)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)  # by name (iter_messages)
    bad_schemas: int = 0  # JSON schemas that are not JSON (iter_messages)

    @property
    def clean(self) -> bool:
        return self.complete and self.problem is None and not self.damaged_chunks \
            and not self.damaged_records

    def record_damage(self, note: str) -> None:
        """A top-level record skipped (``data_records``)."""
        self.damaged_records += 1
        self.notes.append(note)

    @property
    def truncated(self) -> bool:
        return not self.complete


class _Strict(io.BytesIO):
    """A body that refuses to hand out fewer bytes than a field claims."""

    def read(self, n: int | None = -1) -> bytes:
        data = super().read(n)
        if n is not None and n >= 0 and len(data) < n:
            raise EndOfFile()
        return data


def _parse(opcode: int, body: bytes) -> object | None:
    stream = ReadDataStream(_Strict(body))
    if opcode == Opcode.HEADER:
        return Header.read(stream)
    if opcode == Opcode.SCHEMA:
        return Schema.read(stream)
    if opcode == Opcode.CHANNEL:
        return Channel.read(stream)
    if opcode == Opcode.MESSAGE:
        return Message.read(stream, len(body))
    if opcode == Opcode.METADATA:
        return Metadata.read(stream)
    if opcode == Opcode.CHUNK:
        return Chunk.read(stream)
    if opcode == Opcode.FOOTER:
        return Footer.read(stream)
    if opcode == Opcode.DATA_END:
        return _DATA_END
    return None  # indexes, statistics, summary offsets, attachments: not needed here


_DATA_END = object()
_PARSE_ERRORS = (EndOfFile, struct.error, UnicodeDecodeError, ValueError, OverflowError)


def check_magic(path: str | os.PathLike[str]) -> Path:
    """The path, if it names a readable file that starts like an MCAP; else ``UserError``."""
    p = Path(path)
    try:
        with open(p, "rb") as f:
            head = f.read(len(MAGIC))
    except IsADirectoryError:
        raise UserError(f"{p}: is a directory, not an MCAP file") from None
    except FileNotFoundError:
        raise UserError(f"{p}: no such file") from None
    except OSError as exc:
        raise UserError(f"{p}: cannot read: {exc.strerror}") from None
    if head != MAGIC:
        what = "empty" if not head else "not an MCAP file (bad magic at offset 0)"
        raise UserError(f"{p}: {what}")
    return p


def decompress_chunk(compression: str, raw: bytes, usize: int, crc: int) -> bytes:
    """A chunk's records, decompressed and checked against its declared size and CRC.

    Nothing larger than the chunk claims (nor than ``MAX_CHUNK_UNCOMPRESSED``) is allocated.
    """
    if usize > MAX_CHUNK_UNCOMPRESSED:
        raise ValueError(f"chunk claims {usize} bytes uncompressed")
    if compression == "zstd":
        if zstandard.frame_content_size(raw) > usize:
            raise ValueError("zstd frame is larger than its chunk claims")
        data = zstandard.ZstdDecompressor().decompress(raw, max_output_size=max(usize, 1))
    elif compression == "":
        data = bytes(raw)
    elif compression == "lz4":
        data = _lz4_bounded(raw, usize)
    else:
        raise ValueError(f"unknown chunk compression {compression[:20]!r}")
    if len(data) != usize:
        raise ValueError("chunk size does not match its header")
    if crc and zlib.crc32(data) != crc:
        raise ValueError("chunk CRC mismatch")
    return data


def _lz4_bounded(raw: bytes, usize: int) -> bytes:
    """An lz4 frame decompressed to at most ``usize`` bytes (a bomb stops there)."""
    try:
        import lz4.frame
    except ImportError:
        raise ValueError("lz4 chunk, but the lz4 package is not installed") from None
    try:
        declared = lz4.frame.get_frame_info(raw).get("content_size") or 0
        if declared > usize:
            raise ValueError("lz4 frame is larger than its chunk claims")
        dec = lz4.frame.LZ4FrameDecompressor()
        data = dec.decompress(raw, max_length=usize + 1)
    except RuntimeError as exc:  # what the lz4 binding raises for a damaged frame
        raise ValueError(f"lz4: {exc}") from None
    if len(data) > usize:
        raise ValueError("lz4 frame is larger than its chunk claims")
    return data


# opcodes the MCAP specification defines (0x80..0xFF are left to users); anything else in
# the data section is a damaged record, not something to skip
KNOWN_OPCODES = frozenset(range(0x01, 0x10))


def opcode_damaged(opcode: int) -> bool:
    return opcode not in KNOWN_OPCODES and opcode < 0x80


def _chunk_records(chunk: Chunk) -> list[object]:
    data = decompress_chunk(chunk.compression, chunk.data, chunk.uncompressed_size,
                            chunk.uncompressed_crc)
    out: list[object] = []
    pos = 0
    while pos < len(data):
        if pos + 9 > len(data):
            raise ValueError("chunk ends inside a record header")
        opcode = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        if pos + 9 + length > len(data):
            raise ValueError("chunk record runs past the chunk")
        rec = _parse(opcode, data[pos + 9 : pos + 9 + length])
        if isinstance(rec, (Schema, Channel, Message)):
            out.append(rec)
        pos += 9 + length
    return out


@dataclass
class Walk:
    """How a walk over the top-level records ended (filled in as it goes)."""

    problem: str | None = None  # why it stopped before the footer, if it did
    complete: bool = False  # footer and closing magic reached
    end: int = len(MAGIC)  # end of the last whole record the caller went past
    trailing: int = 0  # bytes after the closing magic
    crc_problems: list[str] = field(default_factory=list)  # data or summary CRC mismatch


def walk_records(f: BinaryIO, size: int, walk: Walk) -> Iterator[tuple[int, int, bytes, bytes, bool]]:
    """The top-level records of an open MCAP file: (position, opcode, header, body, in summary).

    Every length is bounded by what the file holds. The footer comes last, then the closing
    magic is checked. A caller that stops at a record it finds damaged leaves ``walk.end`` at
    the end of the record before it.
    """
    pos = len(MAGIC)
    f.seek(pos)
    in_summary = False  # after DATA_END: the summary repeats schemas and channels
    crc = zlib.crc32(MAGIC)  # of the data section, then of the summary section
    summary_at = -1
    while True:
        if pos == size:
            walk.problem = "file ends without a footer"
            return
        head = f.read(9)
        if len(head) < 9:
            walk.problem = f"file ends inside a record header at byte {pos}"
            return
        opcode = head[0]
        (length,) = struct.unpack("<Q", head[1:])
        if length > MAX_RECORD:
            walk.problem = f"record at byte {pos} claims {length} bytes"
            return
        if pos + 9 + length > size:
            walk.problem = f"file ends inside a record at byte {pos} " \
                f"({size - pos - 9} of {length} bytes present)"
            return
        body = f.read(length)
        if opcode == Opcode.DATA_END and not in_summary:
            if len(body) >= 4 and (want := struct.unpack_from("<I", body)[0]) and want != crc:
                walk.crc_problems.append(f"data section CRC mismatch (DataEnd at byte {pos})")
            crc, summary_at = 0, pos + 9 + length
        elif opcode == Opcode.FOOTER and len(body) >= 20:
            summary_start, _offsets, want = struct.unpack_from("<QQI", body)
            crc = zlib.crc32(body[:16], zlib.crc32(head, crc))
            if want and summary_start == summary_at and want != crc:
                walk.crc_problems.append("summary section CRC mismatch")
        else:
            crc = zlib.crc32(body, zlib.crc32(head, crc))
        in_summary = in_summary or opcode == Opcode.DATA_END
        yield pos, opcode, head, body, in_summary
        pos += 9 + length
        if opcode == Opcode.FOOTER:
            if f.read(len(MAGIC)) != MAGIC:
                walk.problem = "footer is not followed by the closing magic"
                return
            walk.complete = True
            walk.end = pos + len(MAGIC)
            walk.trailing = size - walk.end
            return
        walk.end = pos


class WalkStatus(Protocol):
    """What ``data_records`` fills in (``ScanStatus`` here, the analysis's ``ReadStatus``)."""

    path: Path
    size: int
    complete: bool
    problem: str | None
    valid_bytes: int
    notes: list[str]

    def record_damage(self, note: str) -> None: ...


def data_records(status: WalkStatus, progress: Callable[[int, int], None] | None = None
                 ) -> Iterator[tuple[int, int, bytes, bytes, bool]]:
    """The one way conform reads a capture file: its top-level records in file order as
    (position, opcode, header, body, in summary), records of unknown opcode skipped as
    damage. ``status`` says how the walk ended (complete, why it stopped, how far the file
    was intact, CRC mismatches, bytes after the end) once the caller is done with it, whether
    it went to the end or stopped at a record it found damaged. ``progress(bytes, total)``
    is told every 4 MiB. ``iter_records`` parses them; the analysis's fast reader
    (conform.analysis.rawread) takes the bodies as they are."""
    path = check_magic(status.path)
    walk = Walk()
    with open(path, "rb") as f:
        size = status.size = os.fstat(f.fileno()).st_size
        last_report = 0
        try:
            for pos, opcode, head, body, in_summary in walk_records(f, size, walk):
                if progress is not None and pos - last_report > PROGRESS_BYTES:
                    progress(pos, size)
                    last_report = pos
                if opcode_damaged(opcode):
                    status.record_damage(f"record with unknown opcode 0x{opcode:02x} at byte "
                                         f"{pos} skipped ({len(body)} bytes)")
                    continue
                yield pos, opcode, head, body, in_summary
        finally:
            status.valid_bytes = walk.end
            status.complete = walk.complete
            status.problem = status.problem or walk.problem
            for note in walk.crc_problems:
                status.record_damage(note)
            if walk.trailing:
                status.notes.append(f"{walk.trailing} bytes after the end")
    if progress is not None:
        progress(size, size)


def iter_records(status: ScanStatus) -> Iterator[Item]:
    """Header, schemas, channels, messages and metadata in file order (chunks opened).

    Stops quietly at the first damaged top-level record or at the end of the data;
    ``status`` says which, and how far the file was intact.
    """
    for pos, opcode, _head, body, in_summary in data_records(status):
        try:
            rec = _parse(opcode, body)
        except _PARSE_ERRORS as exc:
            status.damaged_records += 1
            status.problem = f"damaged record (opcode 0x{opcode:02x}) at byte {pos}: " \
                f"{_short(exc)}"
            return
        if in_summary:
            continue
        if isinstance(rec, Header):
            status.library, status.profile = rec.library, rec.profile
            yield rec
        elif isinstance(rec, Chunk):
            try:
                inner = _chunk_records(rec)
            except (*_PARSE_ERRORS, zstandard.ZstdError, MemoryError) as exc:
                status.damaged_chunks += 1
                status.notes.append(f"damaged chunk at byte {pos} skipped: {_short(exc)}")
                continue
            yield from inner  # type: ignore[misc]
        elif isinstance(rec, (Schema, Channel, Message, Metadata)):
            yield rec


def iter_messages(status: ScanStatus) -> Iterator[tuple[Channel | None, Message]]:
    """Every message with its channel, in file order (``iter_records``): the channel the file
    declared for it, else, in a file conform wrote whose first chunk (where they live) was
    lost, the one ``McapSink`` gives that id, else None. The metadata records go to
    ``status.metadata`` and JSON schemas that are not JSON are counted as they pass."""
    from conform.capture.sink import default_layout

    channels: dict[int, Channel] = {}
    fallback: dict[int, Channel] | None = None
    for rec in iter_records(status):
        if isinstance(rec, Message):
            channel = channels.get(rec.channel_id)
            if channel is None and status.library.startswith("conform"):
                if fallback is None:
                    fallback = default_layout()[1]
                channel = fallback.get(rec.channel_id)
            yield channel, rec
        elif isinstance(rec, Channel):
            channels.setdefault(rec.id, rec)
        elif isinstance(rec, Metadata):
            status.metadata[rec.name] = dict(rec.metadata)
        elif isinstance(rec, Schema) and rec.encoding == "jsonschema":
            try:
                json.loads(rec.data)
            except (ValueError, RecursionError):
                status.bad_schemas += 1


def _short(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text[:160]
