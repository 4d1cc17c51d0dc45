"""``conform ports``: the serial ports of this machine, and which of them a GVE unit answers on."""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from typing import Any

import click

from conform.cli.params import BAUD, POSITIVE, echo_json, json_option
from conform.errors import UserError


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


def probe(port: Port, spec: Any, baud: int, timeout: float) -> Port:
    """Ask ``?`` (harmless: it only reads the firmware string, GVE64 §13.5.1), plain and, if
    the unit wants them, with a checksum; map the firmware string to a variant."""
    from conform.conformance.target import HarnessError
    from conform.families.gve.conformance.safety import Guard
    from conform.families.gve.conformance.target import open_target, variant_for_firmware

    try:
        target, _ = open_target(port.device, spec, baud=baud, guard=Guard(False, None, False))
    except UserError as exc:
        port.how = str(exc)
        return port
    try:
        for checksum in (False, True):
            try:
                reply = target.exchange(target.frame("!0?", checksum=checksum), timeout=timeout)
            except HarnessError as exc:
                port.how = f"no answer to ? ({exc})"
                continue
            text = reply.lines[0].decode("latin-1").strip() if reply.lines else ""
            if not text.startswith("0,"):
                port.answer = text or None
                port.how = f"answered {text!r}, not a firmware string" if text else "no answer"
                continue
            firmware = text.split(",", 1)[1]
            if checksum:
                firmware = re.sub(r",[0-9A-Fa-f]{2}$", "", firmware)
            port.answer = text
            port.variant, port.how = variant_for_firmware(spec, firmware)
            break
    finally:
        target.close()
    return port


@click.command(name="ports")
@click.argument("paths", nargs=-1, metavar="[PATH]...")
@click.option("--probe", "do_probe", is_flag=True,
              help="Ask each port '?' and say which unit answered (sends nothing that moves).")
@click.option("--baud", type=BAUD, default=115200, show_default=True, help="For --probe.")
@click.option("--timeout", type=POSITIVE, default=1.0, show_default=True,
              help="Seconds to wait for each answer (--probe).")
@json_option()
def cli(paths: tuple[str, ...], do_probe: bool, baud: int, timeout: float, as_json: bool) -> None:
    """List serial ports with description and hardware id; with --probe, which answer as a GVE.

    With PATHs (ports, ptys, pyserial URLs), only those: ptys are not in the system's listing.

    \b
    Examples:
      conform ports
      conform ports --probe
      conform ports --probe /dev/pts/4 socket://localhost:5024
    """
    listed = {p.device: p for p in listed_ports()}
    ports = [listed.get(p, Port(p, "given on the command line")) for p in paths] if paths \
        else list(listed.values())
    if do_probe:
        from conform.cli.progress import progress
        from conform.families.gve.spec import load_spec

        spec = load_spec()
        with progress("conform ports", transient=True) as bar:
            task = bar.task("probing", len(ports))
            for p in ports:
                task.update(step=p.device)
                probe(p, spec, baud, timeout)
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
                f"\n{'':<{width}}  -> no GVE unit: {p.how}"
        click.echo(line)
