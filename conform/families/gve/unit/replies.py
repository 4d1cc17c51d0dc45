"""What a command handler of the reference unit replies: the answer codes and the sentinels.

The codes are the low three bits of the answer digit (GVE64 §13.7, GVE124 §12.6); bit 3 is
INTA, added when the answer is encoded.
"""

from __future__ import annotations

from collections.abc import Sequence

OK, QUEUE_FULL, WATCHDOG, UNKNOWN, SYNTAX, RANGE, NOTHING_TO_GO, RUNNING = range(8)

INF = float("inf")
"""No deadline."""


class _Defer:
    """A handler's reply meaning "the answer comes later" (HALT, W); the handler arranged it."""

    __repr__ = lambda self: "DEFER"  # noqa: E731


DEFER = _Defer()
"""Reply sentinel: the handler scheduled its answer itself."""

Reply = int | tuple[int, Sequence[object]] | bytes | None | _Defer
"""What a handler returns: an error code; (code, answer fields); raw bytes to send verbatim
(``>``, ``J``); None for no answer (``*S``, a silent ``J``); or :data:`DEFER`."""
