"""``conform send JOB --target T``: stream a job file to a unit with its family's reference
sender (``Family.send_job``).

The engine picks the family — from ``--variant``, from an ``emu:VARIANT`` target, else by
asking the port each family's harmless question (``conform ports --probe``'s) — checks the
options every family shares, and hands over; a family's own options
(``Family.command_options("send")``) reach only its sender and are refused in one line when
the unit is another family's.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import click

from conform.cli.family_options import family_options, split
from conform.cli.outputs import force_option, fresh_output
from conform.cli.params import BAUD, INPUT_FILE, OUTPUT_FILE, TARGET, VARIANT
from conform.conformance.target import parse_target
from conform.errors import UserError

if TYPE_CHECKING:
    from conform.families import Family

PROBE_TIMEOUT = 0.5   # seconds for each family's question when the port's unit is not named
MAX_TIMEOUT = 600.0


@family_options("send")
@click.command(name="send")
@click.argument("job", type=INPUT_FILE)
@click.option("--target", required=True, type=TARGET,
              help="emu:VARIANT (in-process), a pyserial URL (socket://, rfc2217://...) or a "
                   "port / pty path.")
@click.option("--variant", type=VARIANT, default=None,
              help="The unit's variant (default: emu's, else the unit that answers the probe).")
@click.option("--baud", type=BAUD, default=115200, show_default=True)
@click.option("--timeout", type=float, default=None, metavar="SECONDS",
              help="Answer timeout in seconds (default: the family's sender's).")
@click.option("--record", type=OUTPUT_FILE, default=None,
              help="Record the session as an MCAP capture (FILE.mcap).")
@force_option("the --record file")
@click.option("--allow-motion", is_flag=True,
              help="Required to send motion to anything but an emulator.")
@click.option("-q", "--quiet", is_flag=True, help="No progress lines.")
def cli(job: str, target: str, variant: str | None, baud: int, timeout: float | None,
        record: str | None, force: bool, allow_motion: bool, quiet: bool,
        **family_values: object) -> None:
    """Stream JOB to the unit on TARGET with its family's reference sender and report what
    happened; exit 0 when every job line was acknowledged, 1 for a failed or incomplete send.

    \b
    Examples:
      conform send captures/jobs/part.nc --target emu:gve64-v19 --checksums --packet 20
      conform send job.nc --target emu:grbl-1.1f --method send-response
      conform send job.nc --target /dev/ttyUSB0 --allow-motion --record session.mcap
    """
    fresh_output(record, force, "--record")
    if timeout is not None and (not math.isfinite(timeout) or not 0 < timeout <= MAX_TIMEOUT):
        raise UserError(f"--timeout {timeout:g}: seconds, more than 0 and at most "
                        f"{MAX_TIMEOUT:g}")
    from conform.link.ports import held_open

    with held_open(target, baud):       # the probe and the stream share one open of the port
        fam, variant = _family_of(target, variant, baud)
        _job_of(fam, job)
        mine = split("send", fam.name, family_values)
        fam.send_job(job, target, variant=variant, baud=baud, allow_motion=allow_motion,
                     record=record, timeout=timeout, quiet=quiet, **mine)


def _job_of(fam: Family, job: str) -> None:
    """A job in which the family finds no move its unit executes is another family's (a
    vector file for a g-code unit, or the reverse): refused before anything is sent, as
    check-sender's ``--job`` is (the family's ``check_sender.moves``, where it has one),
    naming the families whose moves it holds."""
    from conform.families import families
    from conform.sendercheck.options import read_job

    moves = getattr(fam.check_sender, "moves", None)
    lines = read_job(job) or []
    if moves is None or moves(lines):
        return
    others = [f.name for f in families() if f.name != fam.name and _job_moves(f, lines)]
    looks = f" it looks like a {' or '.join(others)} job:" if others else ""
    raise UserError(f"{job}:{looks} no line of it is a move a {fam.name} unit executes; is it "
                    "a job of another family? Nothing was sent")


def _job_moves(fam: Family, lines: list[str]) -> int:
    """How many of ``lines`` are moves ``fam``'s unit executes (0 when it cannot tell)."""
    try:
        shapes = fam.check_sender
        if shapes is None:
            return 0
        return shapes.moves(lines) if shapes.moves else len(shapes.units(lines))
    except Exception:  # noqa: BLE001 - a family without check-sender, or a job it cannot read
        return 0


def _family_of(target: str, variant: str | None, baud: int) -> tuple[Family, str | None]:
    """The family whose unit is on ``target``, and its variant when known."""
    from conform.families import default_family, family_for_variant, identify_port

    kind, named, mutant = parse_target(target)
    if kind == "emu":
        if mutant is not None:
            raise UserError(f"--target {target}: send streams to the reference unit; deviant "
                            "units are for `conform run --mutants`")
        if variant and named and variant != named:
            raise UserError(f"--variant {variant} contradicts --target {target}")
        named = named or variant
        return (family_for_variant(named) if named else default_family()), named
    if variant:
        return family_for_variant(variant), variant
    found, answer, _ = identify_port(target, baud=baud, timeout=PROBE_TIMEOUT)
    if found is None:   # nobody answered: the default family's sender says why, in its words
        return default_family(), None
    return found, answer.variant
