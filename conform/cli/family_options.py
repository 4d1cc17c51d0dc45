"""Options and subcommands that families add to the command line.

A family declares click options for an engine command (``Family.command_options("run")``) and
whole subcommands of its own (``Family.commands()``); the engine attaches them here, so the
engine's commands never name a family's options. A family's option given to a command that
addresses another family's unit is a usage error naming both.
"""

from __future__ import annotations

from collections.abc import Callable

import click
from click.core import ParameterSource

from conform.errors import UserError

# (command, option's parameter name) -> the families that declared it
_OWNERS: dict[tuple[str, str], set[str]] = {}


def family_options(command: str) -> Callable[[click.Command], click.Command]:
    """Put above an engine command's ``@click.command``: every family's options for
    ``command`` are appended to it, and its callback takes them as ``**family_values``."""

    def attach(cmd: click.Command) -> click.Command:
        from conform.families import families

        taken = {p.name for p in cmd.params}
        for fam in families():
            for opt in fam.command_options(command):
                _OWNERS.setdefault((command, str(opt.name)), set()).add(fam.name)
                if opt.name not in taken:   # families declaring the same option share it
                    taken.add(opt.name)
                    cmd.params.append(opt)
        return cmd

    return attach


def split(command: str, family_name: str, values: dict[str, object]) -> dict[str, object]:
    """The family options among ``values`` meant for ``family_name``'s hook; an option of
    another family that the user set is refused in one line."""
    ctx = click.get_current_context(silent=True)
    mine: dict[str, object] = {}
    for name, value in values.items():
        owners = _OWNERS.get((command, name), {family_name})
        if family_name in owners:
            mine[name] = value
            continue
        given = ctx is not None and ctx.get_parameter_source(name) in (
            ParameterSource.COMMANDLINE, ParameterSource.ENVIRONMENT)
        if given:
            flag = next((p.opts[0] for p in ctx.command.params if p.name == name), name) \
                if ctx is not None else name
            raise UserError(f"{flag} is an option of {' and '.join(sorted(owners))} units; "
                            f"this {command} addresses "
                            f"a {family_name} unit")
    return mine


def add_family_commands(group: click.Group) -> None:
    """Every family's own subcommands; a name another command has is not replaced (the
    first family by rank keeps it) and the clash is said once on stderr."""
    from conform.families import families

    for fam in families():
        for cmd in fam.commands():
            if cmd.name in group.commands:
                click.echo(f"conform: {fam.name}'s command {cmd.name!r} is already taken; "
                           "not added", err=True)
                continue
            group.add_command(cmd)
