"""``conform ports``: the serial ports of this machine, and which unit answers on which."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import click

from conform.cli.params import BAUD, POSITIVE, echo_json, json_option, quiet_option


@dataclass
class Port:
    device: str
    description: str = ""
    hwid: str = ""
    answer: str | None = None  # the `?` answer (probe only)
    variant: str | None = None
    how: str = ""  # how the variant was decided, or why the probe failed


def listed_ports() -> list[Port]:
    """pyserial's listing (USB converters, on-board UARTs); ptys are not in it."""
    from serial.tools import list_ports

    return [Port(p.device, p.description or "", p.hwid or "")
            for p in sorted(list_ports.comports(), key=lambda p: p.device)]


def probe(port: Port, baud: int, timeout: float) -> Port:
    """Ask the port each family's harmless question, in the families' probe order, until one
    family's unit answers (conform.families: ``Family.probe``)."""
    from conform.families import identify_port

    _, got, _ = identify_port(port.device, baud=baud, timeout=timeout)
    port.answer, port.variant, port.how = got.answer, got.variant, got.how
    return port


@click.command(name="ports")
@click.argument("paths", nargs=-1, metavar="[PATH]...")
@click.option("--probe", "do_probe", is_flag=True,
              help="Ask each port each family's harmless question and say which unit answered "
                   "(sends nothing that moves or holds a unit).")
@click.option("--baud", type=BAUD, default=115200, show_default=True, help="For --probe.")
@click.option("--timeout", type=POSITIVE, default=1.0, show_default=True, metavar="SECONDS",
              help="Seconds to wait for each answer (--probe).")
@json_option()
@quiet_option()
def cli(paths: tuple[str, ...], do_probe: bool, baud: int, timeout: float, as_json: bool,
        quiet: bool) -> None:
    """List serial ports with description and hardware id; with --probe, which unit answers.

    With PATHs (ports, ptys, pyserial URLs), only those: ptys are not in the system's listing.

    \b
    Examples:
      conform ports
      conform ports --probe
      conform ports --probe /dev/pts/4 socket://localhost:5024
    """
    # a listing names what it was given; a path that is no port is refused (--probe says of
    # each port why nothing answered). A URL (socket://, rfc2217://) is pyserial's to open.
    for path in [] if do_probe else paths:
        if "://" not in path and not Path(path).is_char_device():
            from conform.errors import UserError

            what = "not a serial port (a device or pty)" if Path(path).exists() else \
                "no such port"
            raise UserError(f"{path}: {what}: `conform ports` lists them")
    listed = {p.device: p for p in listed_ports()}
    ports = [listed.get(p, Port(p, "given on the command line")) for p in paths] if paths \
        else list(listed.values())
    if do_probe:
        from conform.cli.progress import progress

        with progress("conform ports", quiet=quiet, transient=True) as bar:
            task = bar.task("probing", len(ports))
            for p in ports:
                task.update(step=p.device)
                probe(p, baud, timeout)
                task.update(advance=1)
    if as_json:
        echo_json({"ports": [asdict(p) for p in ports]})
        return
    if not ports:
        click.echo("no serial ports found (a pty or URL can be given: conform ports --probe PATH)")
        return
    width = max(len(p.device) for p in ports)
    for p in ports:
        line = f"{p.device:<{width}}  {p.description or '-'}  [{p.hwid or 'no hardware id'}]"
        if do_probe:
            line += f"\n{'':<{width}}  -> {p.variant}: {p.how}" if p.variant else \
                f"\n{'':<{width}}  -> no unit recognised: {p.how}"
        click.echo(line)
