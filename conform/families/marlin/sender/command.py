"""``conform send JOB --target T`` for a Marlin unit (``Family.send_job``; the command is the
engine's): read the job, open the target (``emu:marlin-…`` in-process on a virtual clock, or a
port), stream with :mod:`.stream`, record when asked, print what happened. An interruption
halts the unit the way the conformance runner does (``M108``, ``M410`` quickstop, heaters
off: ``checks.halt``)."""

from __future__ import annotations

from typing import Any

import click

from conform.conformance.recorded import sending_to
from conform.errors import LinkError, UserError

DEFAULT_TIMEOUT = 10.0   # seconds with nothing from the unit (busy: processing counts) before the link is lost


def send_job(job: str, target: str, *, variant: str | None, baud: int, allow_motion: bool,
             record: str | None, timeout: float | None, quiet: bool = False, **_: Any) -> None:
    from conform.cli.progress import progress
    from conform.conformance.target import HarnessError
    from conform.families import family
    from conform.families.marlin.conformance.checks import halt
    from conform.families.marlin.sender.stream import Streamer, load_job
    from conform.stops import halting

    fam = family("marlin")
    v = fam.load_tables().variant(variant or fam.default_variant)
    lines = load_job(job, max_cmd_size=v.max_cmd_size)
    with sending_to(fam, target, v.id, job=job, job_lines=len(lines), baud=baud, record=record,
                    allow_motion=allow_motion, metadata={
                        "capture_method": "conform send (Marlin reference streamer)"}) as taped:
        with progress("conform send", quiet=quiet) as bar:
            task = bar.task("job lines", len(lines))
            streamer = Streamer(taped, lines, job=job,
                                timeout=DEFAULT_TIMEOUT if timeout is None else timeout,
                                progress=lambda s: task.update(completed=s.stats.ok))
            try:
                with halting(lambda: halt(taped)):
                    st = streamer.run()
            except HarnessError as exc:
                raise LinkError(f"{target}: link lost after {streamer.stats.ok} of {len(lines)} "
                                f"job lines ({exc})", exit_code=1) from None
    click.echo(f"sent {st.sent} of {len(lines)} job lines to {target} ({v.id}): {st.ok} ok, "
               f"{st.resends} resent, in {st.seconds:.2f} s")
    if st.position:
        click.echo(f"final position: {st.position}")
    if st.unknown:
        click.echo(f"conform send: {len(st.unknown)} job line(s) unknown to the unit, skipped by "
                   f"it (the first: {st.unknown[0]})", err=True)
    if record:
        click.echo(f"capture: {record}")
    if st.stopped is not None:
        raise UserError(f"send stopped: {st.stopped}", exit_code=1)
