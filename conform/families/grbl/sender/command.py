"""``conform send JOB --target T`` for a grbl unit (``Family.send_job``; the command is the
engine's, conform/cli/send_cmd.py): read the job, open the target (``emu:grbl-…`` in-process
on a virtual clock, or a port, pty or URL), stream with :mod:`.stream`, record the session
when asked, and print what happened.

Every way it ends leaves the unit halted: an ``error:N`` with lines of ours still in grbl's
buffers, Ctrl-C, SIGTERM and SIGHUP send feed hold then a soft reset (the conformance runner's
stop, ``checks.stop_unit``); an ALARM has stopped the unit already; a lost link cannot be told.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from conform.conformance.target import HarnessError
from conform.errors import LinkError, UserError
from conform.families.grbl.sender.stream import METHODS, ReadyError, Stats, Streamer

DEFAULT_TIMEOUT = 5.0     # seconds of silence (with '?' asked every second) before the link is lost
EPOCH = 1_750_000_000.0   # an emulated session's virtual clock starts at this date (as GVE's)


def send_options() -> tuple[click.Option, ...]:
    """grbl's own options of ``conform send``."""
    return (click.Option(["--method"], type=click.Choice(METHODS), default="counting",
                         show_default=True,
                         help="grbl: character counting (keep unanswered lines within the "
                              "receive buffer) or send-response (one line per ok/error)."),)


class Taped:
    """A target whose traffic also goes to a capture ``Recorder`` (host bytes when written,
    unit bytes when read: the host end of the cable), with the bytes ``Target.send`` drains
    before it writes kept for the next read."""

    def __init__(self, target: Any, recorder: Any = None, base: float = 0.0) -> None:
        self.target = target
        self.recorder = recorder
        self.base = base
        self.emulated = target.emulated
        self._held = b""

    def now(self) -> float:
        return self.target.now()

    def _tape(self, direction: str, data: bytes, t: float, t_first: float | None = None) -> None:
        if self.recorder is not None and data:
            self.recorder.chunk(direction, data, self.base + t,
                                None if t_first is None else self.base + t_first)

    def send(self, data: bytes) -> tuple[float, bytes]:
        t, stray = self.target.send(data)
        self._tape("unit", stray, t)
        self._held += stray
        self._tape("host", data, self.target.now(), t)
        return t, b""

    def receive(self, deadline: float) -> bytes:
        if self._held:
            data, self._held = self._held, b""
            return data
        data = self.target.receive(deadline)
        self._tape("unit", data, self.target.now())
        return data

    def drain(self) -> bytes:
        data = self._held + self.target.drain()
        self._held = b""
        return data


def send_job(job: str, target: str, *, variant: str | None, baud: int, allow_motion: bool,
             record: str | None, timeout: float | None, quiet: bool = False,
             method: str = "counting", **_: Any) -> None:
    """Stream ``job`` to the grbl unit on ``target`` (see the module docstring)."""
    from conform.conformance.target import parse_target
    from conform.families import family
    from conform.families.grbl.sender.job import load_job
    from conform.families.grbl.spec.load import load_grbl

    spec = load_grbl()
    fam = family("grbl")
    v = spec.variant(variant or fam.default_variant)
    lines = load_job(job, line_max=v.line_max, realtime=set(spec.realtime))
    emulated = parse_target(target)[0] == "emu"
    if not emulated and not allow_motion:
        raise UserError(f"sending {job} to {target} moves the machine: add --allow-motion "
                        "(nothing was sent)")
    tgt, _ = fam.open_target(target if not emulated else f"emu:{v.id}", baud=baud,
                             permissions=None)
    recorder = None
    try:
        from conform.capture.recorder import Recorder, WallClock

        base = EPOCH if emulated else WallClock()() - tgt.now()
        if record is not None:
            recorder = Recorder(record, {
                "capture_method": "conform send (grbl reference streamer)"
                                  + (", in-process emulator (virtual clock)" if emulated else ""),
                "variant": v.id, "baud": baud, "sender_method": method, "target": target,
                "job": Path(job).name,
                "tap": "host end of the serial cable (host bytes as sent, unit bytes as read)"},
                clock=lambda: base + tgt.now(), overwrite_part=False)
        taped = Taped(tgt, recorder, base)
        stats = _stream(taped, lines, spec, v, method=method, job=job, quiet=quiet,
                        timeout=DEFAULT_TIMEOUT if timeout is None else timeout, target=target)
    finally:
        from conform.stops import shield

        with shield():   # the capture is finished even when a second signal comes
            if recorder is not None:
                recorder.close({"job_lines": len(lines)})
            tgt.close()
    _summary(stats, lines, target, v.id, method, v.rx_buffer, record)


def _stream(taped: Taped, lines: list, spec: Any, v: Any, *, method: str, job: str,
            quiet: bool, timeout: float, target: str) -> Stats:
    """Run the streamer; every way it ends that leaves lines of ours in grbl halts the unit."""
    from conform.cli.progress import progress
    from conform.families.grbl.conformance.checks import stop_unit
    from conform.stops import interrupted_by

    with progress("conform send", quiet=quiet) as bar:
        task = bar.task("job lines", len(lines))

        def shown(s: Streamer) -> None:
            task.update(completed=s.stats.sent,
                        step=f"{s.stats.ok} ok, {s.in_flight} bytes in flight")

        streamer = Streamer(taped, lines, spec, rx_buffer=v.rx_buffer, method=method,
                            timeout=timeout, job=job, progress=shown)
        try:
            stats = streamer.run()
        except ReadyError as exc:
            raise UserError(f"{target}: {exc}", exit_code=1) from None
        except HarnessError as exc:   # a lost link: nothing can be told to the unit
            raise LinkError(f"{target}: link lost after {streamer.stats.sent} of {len(lines)} "
                            f"job lines ({exc}); the unit could not be told to stop",
                            exit_code=1) from None
        except KeyboardInterrupt as exc:   # Ctrl-C, SIGTERM, SIGHUP (conform.stops)
            what = stop_unit(taped)
            raise UserError(f"interrupted ({interrupted_by(exc)}) after {streamer.stats.sent} "
                            f"of {len(lines)} job lines: {what}", exit_code=130) from None
        except Exception:
            stop_unit(taped)   # a bug must not leave the machine running the rest of its buffer
            raise
    stop = stats.stopped
    if stop is not None and stop.flush:
        stop.message += (f"; {len(streamer.pending)} job lines sent after it were in grbl's "
                         f"buffers: {stop_unit(taped)}")
    return stats


def _summary(st: Stats, lines: list, target: str, vid: str, method: str, rx_buffer: int,
             record: str | None) -> None:
    click.echo(f"sent {st.sent} of {len(lines)} job lines to {target} ({vid}, {method}): "
               f"{st.ok} ok, {st.errors} errors in {st.seconds:.2f} s; at most "
               f"{st.max_in_flight} bytes in flight (receive buffer {rx_buffer})")
    if st.position and st.stopped is None:   # the job ended and the motion with it
        click.echo(f"final position: {st.position} ({st.state})")
    if record:
        click.echo(f"capture: {record}")
    if st.stopped is not None:
        raise UserError(f"send stopped: {st.stopped.message}", exit_code=1)
