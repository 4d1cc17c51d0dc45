"""Every way a user or a supervisor ends a command — Ctrl-C, ``kill``/``timeout`` (SIGTERM), a
closed terminal or a cancelled CI job (SIGHUP) — arrives as one exception, :class:`Stopped`.

It is a ``KeyboardInterrupt``, so the places that already make Ctrl-C safe (the conformance
runner's halt, the reference sender's H and D) make the other two safe as well, with no
per-command copy. ``conform`` installs the handlers once (:func:`stop_signals`, in
``conform.cli.main``) whatever the signals' inherited state: a shell starts a background job
(``conform run … &``) with SIGINT ignored, and such a run must still halt the unit when
interrupted. Only the first signal raises; the later ones are counted, so the halt and the
partial report that follow are never cut short. The exit status is 128 + the signal's number
(130, 143, 129), the shell's convention.

Commands that run until stopped (``proxy``, ``sniff``, ``emulate serve``) replace the handlers
while they run with their own clean stop (:data:`STOP_SIGNALS` names what they must catch).
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from types import FrameType

from conform.errors import UserError

STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
_NAMES = {signal.SIGINT: "Ctrl-C", signal.SIGTERM: "SIGTERM", signal.SIGHUP: "SIGHUP"}


def signal_name(signum: int) -> str:
    """How a report names the signal: Ctrl-C for SIGINT, else SIGTERM/SIGHUP."""
    try:
        return _NAMES.get(signal.Signals(signum), signal.Signals(signum).name)
    except ValueError:
        return f"signal {signum}"


class Stopped(KeyboardInterrupt):
    """The command was asked to stop by a signal (a ``KeyboardInterrupt`` for every handler
    written for Ctrl-C)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal_name(signum))
        self.signum = signum

    @property
    def name(self) -> str:
        return signal_name(self.signum)

    @property
    def exit_code(self) -> int:
        return 128 + self.signum


@dataclass
class StopState:
    """What arrived while the handlers were installed."""

    signum: int | None = None   # the first stop signal
    later: int = 0              # signals after the first (ignored: the halt must finish)
    shielded: int = 0           # >0: a signal is recorded, not raised (see :func:`shield`)

    @property
    def exit_code(self) -> int | None:
        """128 + the first signal's number, or None when none arrived."""
        return None if self.signum is None else 128 + self.signum

    @property
    def name(self) -> str | None:
        return None if self.signum is None else signal_name(self.signum)


_state: StopState | None = None


def current() -> StopState | None:
    """The state of the installed handlers (None outside :func:`stop_signals`)."""
    return _state


def interrupted_by(exc: BaseException | None = None) -> str:
    """How an interruption is named in a report: the signal that arrived, else Ctrl-C (a bare
    ``KeyboardInterrupt`` raised some other way)."""
    if isinstance(exc, Stopped):
        return exc.name
    if _state is not None and _state.name is not None:
        return _state.name
    return "Ctrl-C"


@contextmanager
def stop_signals() -> Iterator[StopState]:
    """Turn SIGINT, SIGTERM and SIGHUP into :class:`Stopped` while the block runs (the first
    one only), then put the previous handlers back. Outside the main thread (where Python
    cannot set handlers) nothing is installed."""
    global _state
    state = StopState()
    if threading.current_thread() is not threading.main_thread():
        yield state
        return

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        if state.signum is not None:
            state.later += 1
            return
        state.signum = signum
        if not state.shielded:
            raise Stopped(signum)

    outer = _state
    previous = {}
    for sig in STOP_SIGNALS:   # installed whatever was inherited, SIG_IGN included
        previous[sig] = signal.signal(sig, on_signal)
    _state = state
    try:
        yield state
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        _state = outer


@contextmanager
def shield() -> Iterator[None]:
    """Finish this block (a report being written) even when a stop signal arrives in it; the
    signal is recorded and the command exits with its status afterwards."""
    state = _state
    if state is None:
        yield
        return
    state.shielded += 1
    try:
        yield
    finally:
        state.shielded -= 1


def exit_status(code: int) -> int:
    """The status to exit with: a stop signal's (128 + N) when one arrived, else ``code``."""
    state = _state
    return code if state is None or state.exit_code is None else state.exit_code


@contextmanager
def halting(halt: Callable[[], str] | None,
            then: Callable[[str], str] | None = None) -> Iterator[None]:
    """An interruption inside the block halts the unit (``halt``: the family's stop, retried
    until acknowledged; None for an emulated one) and ends the command with one line saying
    what was sent — for commands that talk to a unit outside the conformance runner. ``then``
    (given how the command was stopped) saves what was done so far, shielded from further
    signals, and says where."""
    try:
        yield
    except KeyboardInterrupt as exc:
        how = interrupted_by(exc)
        what = halt() if halt is not None else "nothing to stop (an emulated unit)"
        if then is not None:
            with shield():
                what += f"; {then(how)}"
        raise UserError(f"interrupted ({how}): {what}", exit_code=130) from None
