"""What a GVE capture records of each line and exchange beyond the engine's neutral fields
(``conform.capture.schemas.CaptureFields``): the decoded command or answer, checksums and
packets. The live decoder (``decode.FrameDecoder``) fills them, in this order after the
neutral fields; a capture's schema and its batch columns name them."""

from __future__ import annotations

from conform.capture.schemas import CaptureFields

CAPTURE_FIELDS = CaptureFields(
    frame=(
        ("address", {"type": ["integer", "null"]}),
        ("name", {"type": ["string", "null"], "description": "command mnemonic"}),
        ("args", {"type": "array", "description": "command parameters as parsed"}),
        ("code", {"type": ["integer", "null"], "description": "answer error code (bits 2..0)"}),
        ("inta", {"type": ["boolean", "null"], "description": "answer INTA bit (bit 3)"}),
        ("fields", {"type": "array", "items": {"type": "string"}}),
        ("checksum", {"type": ["string", "null"], "description": "checksum as sent, hex"}),
        ("checksum_status", {"type": "string", "enum": ["none", "ok", "bad", "missing"]}),
        ("checksum_mode", {"type": "boolean", "description": "checksums were on for this line"}),
        ("packet", {"type": ["integer", "null"], "description": "packet number (*S..*E)"}),
        ("packet_role", {"type": ["string", "null"],
                         "enum": ["start", "member", "end", "answer", None]}),
        ("error", {"type": ["string", "null"], "description": "why a line was rejected/garbled"}),
    ),
    exchange=(
        ("name", {"type": ["string", "null"]}),
        ("code", {"type": ["integer", "null"]}),
        ("inta", {"type": ["boolean", "null"]}),
        ("packet", {"type": ["integer", "null"]}),
        ("packet_commands", {"type": ["integer", "null"],
                             "description": "commands inside the packet this answer closes"}),
    ),
)
FRAME_KEYS = CAPTURE_FIELDS.frame_keys
EXCHANGE_KEYS = CAPTURE_FIELDS.exchange_keys
