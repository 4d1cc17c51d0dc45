"""``conform send JOB --target T`` for a grbl unit (``Family.send_job``; the command is the
engine's, conform/cli/send_cmd.py): read the job, open the target (``emu:grbl-…`` in-process
on a virtual clock, or a port, pty or URL), stream with :mod:`.stream`, record the session
when asked, and print what happened.

Every way it ends leaves the unit halted: an ``error:N`` with lines of ours still in grbl's
buffers, Ctrl-C, SIGTERM and SIGHUP send feed hold then a soft reset (the conformance runner's
stop, ``checks.stop_unit``); an ALARM has stopped the unit already; a lost link cannot be told.
"""

from __future__ import annotations

from typing import Any

import click

from conform.conformance.recorded import RecordedTarget, sending_to
from conform.conformance.target import HarnessError
from conform.errors import LinkError, UserError
from conform.families.grbl.sender.stream import METHODS, ReadyError, Stats, Streamer

DEFAULT_TIMEOUT = 5.0     # seconds of silence (with '?' asked every second) before the link is lost


def send_options() -> tuple[click.Option, ...]:
    """grbl's own options of ``conform send``."""
    return (click.Option(["--method"], type=click.Choice(METHODS), default="counting",
                         show_default=True,
                         help="grbl: character counting (keep unanswered lines within the "
                              "receive buffer) or send-response (one line per ok/error)."),)


def send_job(job: str, target: str, *, variant: str | None, baud: int, allow_motion: bool,
             record: str | None, timeout: float | None, quiet: bool = False,
             method: str = "counting", **_: Any) -> None:
    """Stream ``job`` to the grbl unit on ``target`` (see the module docstring)."""
    from conform.families import family
    from conform.families.grbl.sender.job import load_job
    from conform.families.grbl.spec.load import load_grbl

    spec = load_grbl()
    fam = family("grbl")
    v = spec.variant(variant or fam.default_variant)
    lines = load_job(job, line_max=v.line_max, realtime=set(spec.realtime))
    with sending_to(fam, target, v.id, job=job, job_lines=len(lines), baud=baud, record=record,
                    allow_motion=allow_motion, metadata={
                        "capture_method": "conform send (grbl reference streamer)",
                        "sender_method": method}) as taped:
        stats = _stream(taped, lines, spec, v, method=method, job=job, quiet=quiet,
                        timeout=DEFAULT_TIMEOUT if timeout is None else timeout, target=target)
    _summary(stats, lines, target, v.id, method, v.rx_buffer, record)


def _stream(taped: RecordedTarget, lines: list, spec: Any, v: Any, *, method: str, job: str,
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
