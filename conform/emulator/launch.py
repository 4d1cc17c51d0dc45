"""What every family's ``conform emulate serve`` does around its unit: the option checks, the
pty or TCP endpoint, the control socket, line faults, the announcement scripts read, and
serving until SIGINT or SIGTERM, the recording and its metadata. A family's ``serve`` builds
its unit (a :class:`ServedUnit`) and calls :func:`serve_unit`; the rest is here, once."""

from __future__ import annotations

import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from types import FrameType
from typing import TYPE_CHECKING

import click

from conform.errors import UserError
from conform.link.endpoint import Endpoint
from conform.stops import STOP_SIGNALS

if TYPE_CHECKING:
    from conform.emulator.control import ControlHandler
    from conform.emulator.serve import ControlServer, Emulator, SansIOUnit
    from conform.link.faults import FaultInjector


def check_pacing(baud: int | None, answer_delay: float) -> None:
    """The serve options every family's emulator takes: one line for a value out of range."""
    if baud is not None and baud <= 0:
        raise UserError(f"--baud {baud}: must be positive")
    if not 0 <= answer_delay <= 60:  # nan fails this too
        raise UserError(f"--answer-delay {answer_delay}: expected 0..60 seconds")


def control_server(control_path: str | None, endpoint: Endpoint) -> ControlServer:
    """The control socket (``--control PATH`` or a fresh private path); the endpoint is
    closed and a one-line error raised when it cannot listen."""
    from conform.emulator.serve import ControlServer

    try:
        return ControlServer(control_path)
    except (OSError, UserError) as exc:
        endpoint.close()
        if isinstance(exc, UserError):
            raise
        where = control_path or "a private directory"
        raise UserError(f"--control {where}: cannot listen: {exc.strerror or exc}") from None


def fault_injector(faults: str | None, seed: int | None, t0: float) -> FaultInjector | None:
    """The line faults asked for with --faults, or None when there are none."""
    from conform.link.faults import FaultConfig, FaultInjector

    if not faults:
        return None
    config = FaultConfig.parse(faults)
    return FaultInjector(config, seed, t0=t0) if config.active else None


def report(msg: str) -> None:
    click.echo(f"conform emulate: {msg}", err=True)


def announce(endpoint: Endpoint, what: str) -> None:
    """The device path alone on stdout's first line (what scripts read), then what is served."""
    click.echo(endpoint.name)
    sys.stdout.flush()
    report(what)


def run_until_signal(emulator: Emulator, quiet: bool = False) -> None:
    """Serve until SIGINT, SIGTERM or SIGHUP, then put the previous handlers back; meanwhile
    the bytes each way are the progress display (none when ``quiet``)."""
    from conform.cli.progress import progress

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        emulator.stop()

    old = {s: signal.signal(s, on_signal) for s in STOP_SIGNALS}
    try:
        with progress("conform emulate", quiet=quiet) as bar:
            bar.task("serving", None, poll=lambda: f"{emulator.bytes_in} bytes in, "
                                                   f"{emulator.bytes_out} out")
            emulator.run()
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


def open_endpoint(tcp_port: int | None, link_path: str | None
                  ) -> tuple[Endpoint, Callable[[], Endpoint]]:
    if tcp_port is not None:
        from conform.link.tcp import TcpServerEndpoint

        if not 0 <= tcp_port <= 65535:
            raise UserError(f"--tcp {tcp_port}: not a port number")
        endpoint = TcpServerEndpoint("127.0.0.1", tcp_port)
        port = endpoint.port
        return endpoint, lambda: TcpServerEndpoint("127.0.0.1", port)
    from conform.link.pty import PtyEndpoint

    try:
        pty = PtyEndpoint(link=link_path)
    except OSError as exc:
        raise UserError(f"cannot create a pty{' at ' + link_path if link_path else ''}: "
                        f"{exc.strerror or exc}") from None
    current = [pty]

    def reopen() -> Endpoint:
        # the unplugged pty held its number while the line was down (PtyEndpoint.unplug):
        # let it go now, so that the new pty most likely takes that number again
        current[0].close()
        current[0] = PtyEndpoint(link=link_path)
        return current[0]

    return pty, reopen


@dataclass
class ServedUnit:
    """What a family hands :func:`serve_unit`: its unit and what is particular about serving
    it (a fault injector of its own, control requests, what a reconnect does to the unit,
    extra session metadata, what it reports and writes when stopped)."""

    unit: SansIOUnit
    describe: str = ""                       # after "<variant> on <port>" in the announcement
    injector: FaultInjector | None = None    # None: the engine's, from --faults
    control_handler: ControlHandler | None = None   # the family's control requests (None: refused)
    wrap_reopen: Callable[[Callable[[], Endpoint]], Callable[[], Endpoint]] | None = None
    metadata: dict[str, object] = field(default_factory=dict)
    decode: bool = True                      # decode frames while recording (a live decoder)
    backdate: bool = True                    # recorder dates a chunk's first byte a wire time early
    end_counts: Callable[[], dict[str, object]] | None = None   # extra counts at the capture's end
    finish: Callable[[Callable[[str], None]], None] | None = None   # after stopping
    stopped_note: Callable[[], str] | None = None   # added to the "stopped (...)" line


def serve_unit(family: str, variant: str, build: Callable[[float], ServedUnit], *,
               baud: int | None = None, tcp_port: int | None = None, faults: str | None = None,
               seed: int | None = None, control_path: str | None = None,
               link_path: str | None = None, record_path: str | None = None,
               answer_delay: float = 0.0, quiet: bool = False) -> None:
    """``conform emulate serve`` for any family: ``build(t_start)`` makes the unit on the
    monotonic wall clock; this serves it until SIGINT/SIGTERM. The first line of stdout is the
    device path; a recording's session metadata is the same vocabulary for every family. While
    it serves, the bytes each way are the progress display (none with ``quiet``)."""
    from conform.emulator.serve import Emulator

    check_pacing(baud, answer_delay)
    t_start = time.monotonic()
    served = build(t_start)
    injector = served.injector if served.injector is not None else \
        fault_injector(faults, seed, t_start)
    endpoint, reopen = open_endpoint(tcp_port, link_path)
    control = control_server(control_path, endpoint)
    recorder = None
    if record_path:
        from conform.capture import Recorder

        meta = {"capture_method": "emulator", "family": family, "variant": variant,
                "baud": baud or "", "unit_port": endpoint.name, "faults": faults or "",
                "seed": "" if seed is None else seed, **served.metadata}
        try:
            recorder = Recorder(record_path, meta, decode=served.decode,
                                backdate=served.backdate)
        except UserError:
            endpoint.close()
            control.close()
            raise
    emulator = Emulator(served.unit, endpoint, baud=baud, injector=injector, recorder=recorder,
                        control=control, report=report, control_handler=served.control_handler,
                        reopen=served.wrap_reopen(reopen) if served.wrap_reopen else reopen)
    announce(endpoint, f"{variant} on {endpoint.name}"
             + (f" ({served.describe})" if served.describe else "") + f"; control: {control.path}")
    try:
        run_until_signal(emulator, quiet)
    finally:
        control.close()
        if recorder is not None:
            recorder.close({"bytes_in": emulator.bytes_in, "bytes_out": emulator.bytes_out,
                            **(served.end_counts() if served.end_counts else {})})
        if served.finish is not None:
            served.finish(report)
        note = served.stopped_note() if served.stopped_note else ""
        report(f"stopped ({emulator.bytes_in} bytes in, {emulator.bytes_out} out{note})")
