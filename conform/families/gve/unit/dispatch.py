"""Dispatch of the reference unit: from a command id of the tables to its handler.

Each command family's module declares the handlers it holds (``HANDLERS``: command id ->
method name); :data:`HANDLER_NAMES` is their union. A unit binds a handler for every command
of ``specs/commands.toml`` (a command without one answers 3, unknown), so a deviant unit is a
subclass overriding one method. Before the handler run the checks every command shares: not
while running (``while_running = false`` in the table, A27) and A7's rate limit.
"""

from __future__ import annotations

from collections.abc import Mapping

from conform.families.gve.protocol.commands import Command
from conform.families.gve.unit import (
    packets,
    parameters,
    readback,
    reception,
    reset,
    signals,
    vectors,
)
from conform.families.gve.unit.replies import RANGE, RUNNING, UNKNOWN, Reply
from conform.families.gve.unit.state import UnitState


def _union(*tables: Mapping[str, str]) -> dict[str, str]:
    out: dict[str, str] = {}
    for table in tables:
        for cid, name in table.items():
            if cid in out:
                raise ValueError(f"command {cid!r} has two handlers: {out[cid]}, {name}")
            out[cid] = name
    return out


HANDLER_NAMES: Mapping[str, str] = _union(
    readback.HANDLERS, vectors.HANDLERS, parameters.HANDLERS, signals.HANDLERS,
    reception.HANDLERS, packets.HANDLERS, reset.HANDLERS)
"""Command id (``specs/commands.toml``) -> the unit's handler method."""


class CommandDispatch(UnitState):
    """Binding handlers and running a parsed command through the shared checks."""

    def _bind_handlers(self) -> None:
        self.handlers = {}
        for cid in self.spec.commands:
            name = HANDLER_NAMES.get(cid)
            fn = getattr(self, name, None) if name else None
            self.handlers[cid] = fn if fn is not None else self._cmd_unimplemented

    def _cmd_unimplemented(self, args: tuple, t: float) -> Reply:
        return UNKNOWN

    def _execute(self, cmd: Command, t: float) -> Reply:
        name = cmd.name
        if not self._specs[name].while_running and self._busy_for(name):
            return RUNNING
        if self._velocity_args:
            for i in self._velocity_args.get(name, ()):
                if cmd.args[i] > self.variant.max_rate:
                    return RANGE
        return self.handlers[name](cmd.args, t)

    def _busy_for(self, name: str) -> bool:
        if name in self._always_allowed:
            return False
        if name == "Y":
            return self._exec.running
        return self._exec.running or self._mpg_run

    def _velocity_arg_indexes(self) -> dict[str, tuple[int, ...]]:
        """A7 rate-limited: the argument positions of each command that are velocities."""
        out = {}
        for cid, spec in self._specs.items():
            idx: list[int] = []
            i = 0
            for p in spec.params:
                width = self._naxes if p.per_axis else 1
                if p.range_name == "velocity":
                    idx.extend(range(i, i + width))
                i += width
            if idx:
                out[cid] = tuple(idx)
        return out
