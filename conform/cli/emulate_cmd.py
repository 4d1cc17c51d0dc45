"""``conform emulate``: the reference unit as a serial device (a pty) or a TCP endpoint.

    conform emulate gve64-v19                   # prints /dev/pts/N, serves until Ctrl-C
    conform emulate gve124 --tcp 5000 --baud 115200 --dialect A10=every-line
    conform emulate gve64-v10 --faults corrupt=1e-3,latency=1-16 --seed 7
    conform emulate control /tmp/conform-emu-XXXX.sock press stop
"""

from __future__ import annotations

import sys

import click

from conform.cli.family_options import family_options, split
from conform.cli.outputs import force_option, fresh_output
from conform.cli.params import (
    BAUD,
    NON_NEGATIVE,
    OUTPUT_FILE,
    PORT_NUMBER,
    VARIANT,
    quiet_option,
    seed_option,
    variant_ids,
)
from conform.errors import UserError


class _EmulateGroup(click.Group):
    """``conform emulate VARIANT ...`` runs ``serve``; ``conform emulate control ...`` talks
    to a running emulator."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        if args and args[0] not in self.commands and args[0] not in ("-h", "--help"):
            args = ["serve", *args]
        return super().parse_args(ctx, args)


@click.group(cls=_EmulateGroup,
             subcommand_metavar="[serve] VARIANT [OPTIONS] | control SOCKET WORDS... | judge RECORDING")
def cli() -> None:
    """Serve the reference unit model on a pty or TCP, or control a running one.

    `conform emulate VARIANT [OPTIONS]` is short for `conform emulate serve VARIANT [OPTIONS]`
    (see `conform emulate serve --help` for the options).

    \b
    Examples:
      conform emulate serve gve64-v19               # prints /dev/pts/N; Ctrl-C stops it
      conform emulate gve64-v19 --baud 115200       # the same, paced at the wire speed
      conform emulate gve124 --tcp 5024             # socket://localhost:5024
      conform emulate control SOCKET press stop     # SOCKET: shown on the emulator's stderr
    """


@family_options("emulate serve")
@cli.command("serve")
@click.argument("variant", type=VARIANT)
@click.option("--baud", type=BAUD, default=None,
              help="Pace both directions at this wire speed (10 bits per byte).")
@click.option("--tcp", "tcp_port", type=PORT_NUMBER, default=None,
              help="Serve socket://127.0.0.1:PORT instead of a pty (0: any free port).")
@click.option("--faults", default=None, metavar="SPEC",
              help="Noise, drops, latency, garbled answers, disconnects "
                   "(e.g. corrupt=1e-3,drop=1e-4,latency=1-16,garble=0.01,disconnect=0.02).")
@seed_option()
@quiet_option()
@click.option("--control", "control_path", default=None, metavar="PATH",
              help="Unix socket for control commands (default: a fresh path, shown on stderr).")
@click.option("--link", "link_path", default=None, metavar="PATH",
              help="Also create a symlink PATH to the pty (stable across injected disconnects).")
@click.option("--record", "record_path", default=None, metavar="FILE.mcap", type=OUTPUT_FILE,
              help="Record the session as an MCAP capture.")
@click.option("--answer-delay", type=NON_NEGATIVE, default=0.0, show_default=True,
              help="Processing time of the unit before each answer, seconds.")
@force_option("the --record file")
def serve_cmd(variant: str, baud: int | None, tcp_port: int | None, faults: str | None,
              seed: int, quiet: bool, control_path: str | None, link_path: str | None,
              record_path: str | None, answer_delay: float, force: bool,
              **family_values: object) -> None:
    """Serve VARIANT until SIGINT/SIGTERM; the first line of stdout is the device path.

    \b
    Examples:
      conform emulate serve gve64-v19 --baud 115200
      conform emulate serve gve64-v19 --faults "corrupt=1e-3,latency=1-16" --seed 1
    """
    from conform.families import family_for_variant

    fresh_output(record_path, force, "--record")
    fam = family_for_variant(variant)
    fam.serve(variant, baud=baud, tcp_port=tcp_port, faults=faults, seed=seed,
              link_path=link_path, record_path=record_path, answer_delay=answer_delay,
              control_path=control_path, quiet=quiet,
              **split("emulate serve", fam.name, family_values))


@cli.command("control", context_settings={"ignore_unknown_options": True})
@click.argument("socket_path", metavar="SOCKET")
@click.argument("words", nargs=-1, required=True)
def control_cmd(socket_path: str, words: tuple[str, ...]) -> None:
    """Send a control command to a running emulator, e.g. `press stop`, `input 1 7 off`,
    `release sensor`, `state`, `help` (GVE); `press door`, `press probe`, `press limit-x`,
    `fault lose 2`, `fault unplug 1`, `state`, `help` (grbl).

    \b
    Examples:
      conform emulate gve64-v19 --control /tmp/emu.sock &
      conform emulate control /tmp/emu.sock press stop
      conform emulate grbl-1.1f --control /tmp/grbl.sock &
      conform emulate control /tmp/grbl.sock press door
    """
    import os
    import stat

    from conform.emulator.control import send_control

    try:
        mode = os.stat(socket_path).st_mode
    except OSError:
        mode = None
    if mode is None or not stat.S_ISSOCK(mode):
        what = "no such file" if mode is None else \
            f"a {'folder' if stat.S_ISDIR(mode) else 'file'}, not a control socket"
        raise UserError(f"{socket_path}: cannot reach the emulator ({what}): start it with "
                        f"`conform emulate serve VARIANT --control {socket_path}` and give "
                        "the same path while it runs")
    try:
        reply = send_control(socket_path, " ".join(words))
    except (OSError, TimeoutError) as exc:
        raise UserError(f"{socket_path}: cannot reach the emulator ({exc.strerror or exc}): "
                        "is `conform emulate serve --control` still running?") from None
    click.echo(reply)
    if not reply.startswith("ok"):
        sys.exit(1)


@cli.command("judge")
@click.argument("recording", type=click.Path(dir_okay=False), metavar="RECORDING")
@click.option("--variant", type=VARIANT, default=None,
              help="The reference variant to judge (default: the one the capture names).")
@click.option("--settle", type=NON_NEGATIVE, default=3.0, show_default=True,
              help="Seconds the reference is given after the last host write.")
@click.option("--json", "as_json", is_flag=True, help="Print the verdict as one JSON object.")
def judge_cmd(recording: str, variant: str | None, settle: float, as_json: bool) -> None:
    """Play what a host wrote to a real unit into the reference unit and compare the answers.

    RECORDING is an MCAP capture of a session with real firmware (`conform proxy -o`) or a
    text transcript (`SECONDS > LINE` for the host, `SECONDS < LINE` for the unit; see
    docs/architecture.md). The host's writes are played as the recorded sender paced them
    (after the answers it waited for); a transcript's lines get the family's line ending.
    Exit 0 when every recorded answer line is matched, 1 when they differ: the differences
    are listed with the host line they followed; 2 for a recording of another family.

    \b
    Examples:
      conform emulate judge real-session.mcap
      conform emulate judge tests/data/marlin/facts-2.1.2.4.transcript --variant marlin-2.1
    """
    import json

    from conform.emulator.judge import judge_recording, read_transcript, render
    from conform.families import family_for_variant

    transcript = read_transcript(recording)
    name, named_by = variant, "--variant"
    if not name and transcript.variant:
        name, named_by = transcript.variant, recording
    if not name:
        name, named_by = _folder_variant(recording)
    if not name:
        raise UserError(f"{recording}: the recording names no variant and its folder has no "
                        "VARIANT file: give --variant")
    known = variant_ids()
    if name not in known:
        raise UserError(f"{named_by}: {name!r} is not a variant (known: {', '.join(known)})")
    fam = family_for_variant(name)
    verdict = judge_recording(transcript, fam, name, settle)
    if as_json:
        click.echo(json.dumps(verdict.to_dict()))
    else:
        for line in render(verdict):
            click.echo(line)
    sys.exit(0 if verdict.agrees else 1)


def _folder_variant(recording: str) -> tuple[str | None, str]:
    """The variant a folder of recordings names in its ``VARIANT`` file (its first word), as
    a folder of one firmware's recordings does: then the files in it need no --variant.
    Returns it and the file's path (for an error that names where it came from)."""
    from pathlib import Path

    path = Path(recording).parent / "VARIANT"
    try:
        words = path.read_text(encoding="utf-8", errors="replace").split()
    except OSError:
        return None, str(path)
    return (words[0] if words else None), str(path)
