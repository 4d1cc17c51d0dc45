"""The GVE wire protocol, sans-I/O: checksums, lines, commands, answers, packets."""

from conform.families.gve.protocol.answers import INTA_BIT, Answer, Garbled, encode_answer, parse_answer
from conform.families.gve.protocol.checksum import append_checksum, checksum, split_checksum, verify
from conform.families.gve.protocol.commands import (
    NOTHING_TO_GO,
    OK,
    QUEUE_FULL,
    RANGE,
    RUNNING,
    SYNTAX,
    UNKNOWN,
    WATCHDOG,
    Command,
    CommandParser,
    Rejection,
    encode_command,
)
from conform.families.gve.protocol.lines import LineSplitter
from conform.families.gve.protocol.packets import build_packet

__all__ = [
    "INTA_BIT", "NOTHING_TO_GO", "OK", "QUEUE_FULL", "RANGE", "RUNNING", "SYNTAX", "UNKNOWN",
    "WATCHDOG", "Answer", "Command", "CommandParser", "Garbled", "LineSplitter", "Rejection",
    "append_checksum", "build_packet", "checksum", "encode_answer", "encode_command",
    "parse_answer", "split_checksum", "verify",
]
