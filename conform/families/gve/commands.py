"""What the GVE family adds to the command line: its own subcommands (``send``, the reference
sender; ``profile``, the dialect profiles of ``characterize``) and its options on the engine's
commands (``--dialect`` on ``run``; the A-register, reference switches and ground truth on
``emulate serve``). The engine attaches them (conform.cli.family_options)."""

from __future__ import annotations

from collections.abc import Sequence

import click

from conform.cli.params import INPUT_FILE


def commands() -> Sequence[click.Command]:
    from conform.families.gve.conformance.profile_command import cli as profile
    from conform.families.gve.sender.command import cli as send

    return (send, profile)


def command_options(command: str) -> Sequence[click.Option]:
    if command == "run":
        return (click.Option(["--dialect", "dialect_file"], type=INPUT_FILE, default=None,
                             help="GVE: expect this characterised profile's dialect instead of "
                                  "the defaults."),)
    if command == "emulate serve":
        return (
            click.Option(["--dialect", "dialect_pairs"], multiple=True, metavar="A<n>=ALT",
                         help="GVE: choose an open-question alternative (repeatable)."),
            click.Option(["--profile"], type=INPUT_FILE, default=None,
                         help="GVE: a TOML file whose [dialect] table chooses alternatives."),
            click.Option(["--switch", "switch_pairs"], multiple=True, metavar="AXIS=PULSES",
                         help="GVE: distance from a W's start to that axis's reference switch "
                              "(default 3000)."),
            click.Option(["--truth", "truth_path"], default=None, metavar="FILE.json",
                         help="GVE: on exit, write what the unit accepted and executed (every "
                              "vector, D/K/R/H/G/J, final position) as JSON: the ground truth "
                              "beside a recording."),
        )
    return ()
