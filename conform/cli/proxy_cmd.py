"""``conform proxy``: sit between a sender program and the unit, recording both ways."""

from __future__ import annotations

import gc
import signal
import sys

import click

from conform.capture.live import ProxyCapture, run_until_signal
from conform.cli.outputs import force_option, free_link, fresh_output
from conform.cli.params import BAUD, OUTPUT_FILE, VARIANT, quiet_option
from conform.cli.progress import progress, recording
from conform.errors import LinkError
from conform.stops import STOP_SIGNALS


@click.command(name="proxy")
@click.option("--unit", "unit_url", required=True,
              help="The unit: a device path, an emulator's pty, or any pyserial URL "
                   "(socket://host:port, rfc2217://...).")
@click.option("-o", "--output", required=True, type=OUTPUT_FILE,
              help="The MCAP file to write (FILE.part until finished).")
@click.option("--baud", default=115200, show_default=True, type=BAUD,
              help="Baud rate of the unit's port (also used for wire-time estimates).")
@click.option("--variant", type=VARIANT, default=None,
              help="Decode frames with this variant's tables (`conform spec list` names them).")
@click.option("--no-decode", is_flag=True, help="Record raw bytes only.")
@click.option("--reconnect", is_flag=True,
              help="If the unit's port vanishes, wait for it to come back and go on.")
@click.option("--link", default=None, type=OUTPUT_FILE,
              help="Also make this symlink to the sender's pty (a stable name).")
@quiet_option()
@force_option("the -o file")
@click.option("--live", is_flag=True,
              help="A terminal view on stderr that updates while it records: bytes in flight "
                   "against the receive buffer, answer latency, errors and events, and the "
                   "diagnosis so far.")
def cli(unit_url: str, output: str, baud: int, variant: str | None, no_decode: bool,
        reconnect: bool, link: str | None, quiet: bool, force: bool, live: bool) -> None:
    """Create a pty for the sender, forward it to the unit and record until SIGINT/SIGTERM.

    The first line on stdout is the pty's device path; stderr shows the bytes recorded.

    \b
    Example:
      conform proxy --unit /dev/ttyUSB0 --baud 115200 -o session.mcap
    """
    fresh_output(output, force, "-o")
    free_link(link)
    # the recorder's writer thread must not hold the GIL for long while a pump thread waits
    # to forward bytes: a short switch interval bounds that wait (latency added at p99)
    sys.setswitchinterval(0.0002)
    # the writer thread keeps a quarter second of decoded rows (thousands of small tuples) and
    # drops them at each flush: no cycles to find, so the cyclic collector need not rescan
    # them hundreds of times a second (about a tenth of the recorder's CPU at 921 600 Bd)
    gc.freeze()
    gc.set_threshold(10_000, 10, 10)
    # from here a signal only asks for the stop: raised while the forwarding threads start, it
    # would end the command with them still running and the capture never finished
    asked: list[int] = []
    for sig in STOP_SIGNALS:
        signal.signal(sig, lambda signum, _frame: asked.append(signum))
    proxy = ProxyCapture(unit_url, output, baud=baud, variant=variant, decode=not no_decode,
                         reconnect=reconnect, link=link)
    # a sender may start on the pty and stop us before run_until_signal is reached: from the
    # moment the path is out, SIGINT/SIGTERM end the recording cleanly
    for sig in STOP_SIGNALS:
        signal.signal(sig, lambda _signum, _frame: proxy.ask_stop())
    if asked:
        proxy.ask_stop()
    if live:
        from conform.diagnosis.live import LiveView, watching

        # the view taps the recorder before the sender learns the pty: it sees every line
        view = LiveView(proxy.recorder, variant, title=f"proxy {proxy.host_path} ⇄ {unit_url}")
        sys.stdout.write(proxy.host_path + "\n")
        sys.stdout.flush()
        failure = watching(proxy, view)
    else:
        with progress("conform proxy", quiet=quiet) as bar:
            recording(bar, proxy.recorder, f"{proxy.host_path} ⇄ {unit_url}")
            sys.stdout.write(proxy.host_path + "\n")
            sys.stdout.flush()
            failure = run_until_signal(proxy)
    click.echo(f"conform proxy: recorded {proxy.recorder.path}", err=True)
    if failure:
        raise LinkError(f"{failure} (recording finished cleanly in {proxy.recorder.path})",
                        exit_code=1)
