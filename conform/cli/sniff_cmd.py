"""``conform sniff``: passive tap on a Y-cable with two receive-only adapters."""

from __future__ import annotations

import os

import click

from conform.capture.live import SniffCapture, run_until_signal
from conform.cli.outputs import force_option, fresh_output
from conform.cli.params import BAUD, OUTPUT_FILE, VARIANT, quiet_option
from conform.cli.progress import progress, recording
from conform.errors import LinkError, UserError


@click.command(name="sniff")
@click.option("--host-port", required=True,
              help="Adapter that receives what the sender transmits (device or pyserial URL).")
@click.option("--unit-port", required=True,
              help="Adapter that receives what the unit transmits.")
@click.option("-o", "--output", required=True, type=OUTPUT_FILE,
              help="The MCAP file to write (FILE.part until finished).")
@click.option("--baud", default=115200, show_default=True, type=BAUD)
@click.option("--variant", type=VARIANT, default=None,
              help="Decode frames with this variant's tables (`conform spec list` names them).")
@click.option("--no-decode", is_flag=True, help="Record raw bytes only.")
@click.option("--reconnect", is_flag=True,
              help="If an adapter vanishes, wait for it to come back and go on.")
@quiet_option()
@force_option("the -o file")
@click.option("--live", is_flag=True,
              help="A terminal view on stderr that updates while it records (as proxy --live).")
def cli(host_port: str, unit_port: str, output: str, baud: int, variant: str | None,
        no_decode: bool, reconnect: bool, quiet: bool, force: bool, live: bool) -> None:
    """Record both directions of a live link without sending a byte, until SIGINT/SIGTERM.

    \b
    Example:
      conform sniff --host-port /dev/ttyUSB1 --unit-port /dev/ttyUSB2 -o session.mcap
    """
    if os.path.realpath(host_port) == os.path.realpath(unit_port):
        raise UserError(f"--host-port and --unit-port are both {host_port}: the tap needs one "
                        "receive-only adapter per direction")
    fresh_output(output, force, "-o")
    tap = SniffCapture(host_port, unit_port, output, baud=baud, variant=variant,
                       decode=not no_decode, reconnect=reconnect)
    click.echo(f"conform sniff: recording {host_port} + {unit_port} to {output}", err=True)
    if live:
        from conform.diagnosis.live import LiveView, watching

        failure = watching(tap, LiveView(tap.recorder, variant,
                                         title=f"sniff {host_port} + {unit_port}"))
    else:
        with progress("conform sniff", quiet=quiet) as bar:
            recording(bar, tap.recorder, f"{host_port} + {unit_port}")
            failure = run_until_signal(tap)
    click.echo(f"conform sniff: recorded {tap.recorder.path}", err=True)
    if failure:
        raise LinkError(f"{failure} (recording finished cleanly in {tap.recorder.path})",
                        exit_code=1)
