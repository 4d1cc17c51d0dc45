"""What every family's ``conform emulate serve`` does around its unit: the option checks, the
pty or TCP endpoint, the control socket, line faults, the announcement scripts read, and
serving until SIGINT or SIGTERM. The family's ``serve`` builds the unit and the
:class:`conform.emulator.serve.Emulator`; this module keeps the rest in one place."""

from __future__ import annotations

import signal
import sys
from typing import Any

import click

from conform.errors import UserError
from conform.stops import STOP_SIGNALS


def check_pacing(baud: int | None, answer_delay: float) -> None:
    """The serve options every family's emulator takes: one line for a value out of range."""
    if baud is not None and baud <= 0:
        raise UserError(f"--baud {baud}: must be positive")
    if not 0 <= answer_delay <= 60:  # nan fails this too
        raise UserError(f"--answer-delay {answer_delay}: expected 0..60 seconds")


def control_server(control_path: str | None, endpoint: Any) -> Any:
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


def fault_injector(faults: str | None, seed: int | None, t0: float) -> Any:
    """The line faults asked for with --faults, or None when there are none."""
    from conform.link.faults import FaultConfig, FaultInjector

    if not faults:
        return None
    config = FaultConfig.parse(faults)
    return FaultInjector(config, seed, t0=t0) if config.active else None


def report(msg: str) -> None:
    click.echo(f"conform emulate: {msg}", err=True)


def announce(endpoint: Any, what: str) -> None:
    """The device path alone on stdout's first line (what scripts read), then what is served."""
    click.echo(endpoint.name)
    sys.stdout.flush()
    report(what)


def run_until_signal(emulator: Any) -> None:
    """Serve until SIGINT, SIGTERM or SIGHUP, then put the previous handlers back."""
    def on_signal(signum: int, _frame: Any) -> None:
        emulator.stop()

    old = {s: signal.signal(s, on_signal) for s in STOP_SIGNALS}
    try:
        emulator.run()
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


def open_endpoint(tcp_port: int | None, link_path: str | None) -> tuple[Any, Any]:
    if tcp_port is not None:
        from conform.link.tcp import TcpServerEndpoint

        if not 0 <= tcp_port <= 65535:
            raise UserError(f"--tcp {tcp_port}: not a port number")
        endpoint = TcpServerEndpoint("127.0.0.1", tcp_port)
        port = endpoint.port
        return endpoint, lambda: TcpServerEndpoint("127.0.0.1", port)
    from conform.link.pty import PtyEndpoint

    try:
        endpoint = PtyEndpoint(link=link_path)
    except OSError as exc:
        raise UserError(f"cannot create a pty{' at ' + link_path if link_path else ''}: "
                        f"{exc.strerror or exc}") from None
    return endpoint, lambda: PtyEndpoint(link=link_path)
