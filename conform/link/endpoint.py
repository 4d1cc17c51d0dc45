"""The one interface every byte mover in ``conform.link`` offers.

A pty, a TCP server and a pyserial port all look alike to the proxy, the sniffer and the
emulator: ``read(max_bytes, timeout)`` returns what arrived (``b""`` on timeout),
``write(data)`` sends all of it, ``close()`` is idempotent. A port that vanishes (adapter
unplugged, peer killed, socket closed) raises :class:`PortGone`, so callers can turn it into a
link event and carry on with the other direction.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from conform.errors import LinkError


class PortGone(LinkError):
    """The port or its peer disappeared while in use (EIO, EOF, unplugged adapter)."""


class WriteTimeout(LinkError):
    """Nobody drained the other side of the link in time."""


@runtime_checkable
class Endpoint(Protocol):
    """What the forwarding loop, the sniffer and the emulator need from a link end."""

    @property
    def name(self) -> str:
        """A human-readable name: device path or URL."""
        ...

    def read(self, max_bytes: int = 4096, timeout: float | None = 0.1) -> bytes:
        """Return up to ``max_bytes`` as soon as any arrive; ``b""`` after ``timeout`` s."""
        ...

    def write(self, data: bytes) -> None:
        """Send every byte of ``data`` (blocking)."""
        ...

    def close(self) -> None:
        """Release the port; calling it twice is harmless."""
        ...
