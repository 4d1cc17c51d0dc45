"""The unit's 256-byte EEPROM (GVE64 §11-12, §13.5.10; GVE124 §11, §12.5.9).

Byte, float and uint32 access; multi-byte cells are little-endian (specs/gve/eeprom.toml). The
EEPROM is non-volatile: it survives ``J`` and lives as long as the emulated unit.
"""

from __future__ import annotations

import struct

_F = struct.Struct("<f")
_U = struct.Struct("<I")


class Eeprom:
    """256 bytes with typed access; addresses are checked by the command parser."""

    __slots__ = ("data",)

    def __init__(self, image: bytes) -> None:
        if len(image) != 256:
            raise ValueError(f"an EEPROM image has 256 bytes, not {len(image)}")
        self.data = bytearray(image)

    def read_byte(self, address: int) -> int:
        return self.data[address]

    def write_byte(self, address: int, value: int) -> None:
        self.data[address] = value & 0xFF

    def read_raw(self, address: int) -> bytes:
        return bytes(self.data[address : address + 4])

    def write_raw(self, address: int, raw: bytes) -> None:
        self.data[address : address + 4] = raw[:4]

    def read_float(self, address: int) -> float:
        return _F.unpack_from(self.data, address)[0]

    def write_float(self, address: int, value: float) -> None:
        _F.pack_into(self.data, address, value)

    def read_uint(self, address: int) -> int:
        return _U.unpack_from(self.data, address)[0]

    def write_uint(self, address: int, value: int) -> None:
        _U.pack_into(self.data, address, value & 0xFFFFFFFF)


def format_float(value: float) -> str:
    """EFR's answer text (A9 default): ``%g`` of the stored float32 (``300``, ``0.5``)."""
    return "%g" % value
