"""``conform send JOB --target URL``: stream a vector file or G-code to a unit."""

from __future__ import annotations

import click

from conform.errors import LinkError, UserError
from conform.sender.core import POLICIES


def _ints(text: str) -> set[int]:
    try:
        return {int(x) for x in text.split(",") if x.strip()}
    except ValueError:
        raise UserError(f"expected comma-separated numbers, not {text!r}") from None


def _floats(text: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise UserError(f"--steps-per-mm: expected numbers, not {text!r}") from None
    if not vals or any(v <= 0 for v in vals):
        raise UserError(f"--steps-per-mm: expected positive numbers, not {text!r}")
    return vals


@click.command(name="send")
@click.argument("job", type=click.Path(dir_okay=False, path_type=str))
@click.option("--target", required=True,
              help="emu:VARIANT (in-process), a pyserial URL (socket://, rfc2217://...) or a "
                   "port / pty path.")
@click.option("--variant", default=None, help="The unit's variant (default: emu's, or gve64-v19).")
@click.option("--baud", type=int, default=115200, show_default=True)
@click.option("--checksums/--no-checksums", default=False, show_default=True)
@click.option("--packet", type=int, default=1, show_default=True,
              help="C/B lines per *S…*E packet (1: no packets).")
@click.option("--policy", type=click.Choice(POLICIES), default="careful", show_default=True,
              help="What to do after a garbled answer or none (careless ones are for demos).")
@click.option("--latency", type=float, default=0.0, show_default=True,
              help="Simulated converter latency per direction, ms.")
@click.option("--timeout", type=float, default=250.0, show_default=True,
              help="Answer timeout, ms.")
@click.option("--noise", type=float, default=0.0, help="emu: probability a byte is damaged.")
@click.option("--seed", type=int, default=1, help="emu: seed of the noise.")
@click.option("--corrupt-command", default="", help="emu: damage these host writes (0-based).")
@click.option("--corrupt-answer", default="", help="emu: damage these answer lines (0-based).")
@click.option("--record", type=click.Path(dir_okay=False, path_type=str), default=None,
              help="emu: record the session as an MCAP capture.")
@click.option("--steps-per-mm", default="100", show_default=True, help="G-code: per axis, X,Y,Z.")
@click.option("--feed", type=float, default=600.0, show_default=True,
              help="G-code: mm/min before the first F.")
@click.option("--accel", type=float, default=500.0, show_default=True, help="G-code: mm/s².")
@click.option("--allow-motion", is_flag=True,
              help="Required to send motion to anything but an emulator.")
def cli(job: str, target: str, variant: str | None, baud: int, checksums: bool, packet: int,
        policy: str, latency: float, timeout: float, noise: float, seed: int,
        corrupt_command: str, corrupt_answer: str, record: str | None, steps_per_mm: str,
        feed: float, accel: float, allow_motion: bool) -> None:
    """Stream JOB (one command per line, or .nc/.gcode) and report what happened."""
    from conform.sender.job import load_job
    from conform.spec import load_spec

    spec = load_spec()
    emu = target.startswith("emu:")
    vid = (target[4:] if emu else None) or variant or "gve64-v19"
    if variant and emu and target[4:] and variant != target[4:]:
        raise UserError(f"--variant {variant} contradicts --target {target}")
    var = spec.variant(vid)
    dialect = spec.dialect()
    if packet < 1:
        raise UserError(f"--packet {packet}: must be 1 or more")
    if baud <= 0:
        raise UserError(f"--baud {baud}: must be positive")
    spm = _floats(steps_per_mm)
    items = load_job(job, var, dialect, steps_per_mm=spm if len(spm) > 1 else spm * 3,
                     feed=feed, accel=accel)
    motion = any(i.motion for i in items)
    if not emu and motion and not allow_motion:
        raise UserError(f"{job}: the job moves the machine; sending it to {target} needs "
                        "--allow-motion")
    if not emu and (record or noise or corrupt_command or corrupt_answer):
        raise UserError("--record, --noise and --corrupt-* work with emu: targets only "
                        "(record a real port with `conform proxy`)")
    if emu:
        from conform.sender.links import LinkModel
        from conform.sender.session import send_emulated

        link = LinkModel(baud=baud, latency=latency / 1000.0, noise=noise, seed=seed,
                         corrupt_commands=_ints(corrupt_command),
                         corrupt_answers=_ints(corrupt_answer))
        res = send_emulated(items, var, dialect, policy=policy, checksums=checksums,
                            packet=packet, link=link, record=record, timeout=timeout / 1000.0)
        s = res.sender
        click.echo(f"sent {len(items)} job lines to {target}: {s.stats.sent} writes, "
                   f"{s.stats.answers} answers, {s.stats.garbled} garbled, "
                   f"{s.stats.timeouts} timeouts, {s.stats.queue_full} queue full, "
                   f"{s.stats.resent} resent")
        click.echo(f"final position: {res.position}")
        if record:
            click.echo(f"capture: {record}")
        if s.failed:
            raise UserError(f"send failed: {s.failed}", exit_code=1)
        return
    _send_port(items, var, target, baud, checksums, packet, policy, latency, timeout)


def _send_port(items: list, var: object, target: str, baud: int, checksums: bool, packet: int,
               policy: str, latency: float, timeout: float) -> None:
    import serial

    from conform.sender.core import Sender
    from conform.sender.links import halt_and_delete, run_serial

    try:
        port = serial.serial_for_url(target, baudrate=baud, timeout=0.05)
    except (serial.SerialException, ValueError, OSError) as exc:
        raise LinkError(f"{target}: cannot open: {exc}") from None
    sender = Sender(items, var, policy=policy, checksums=checksums, packet=packet,  # type: ignore[arg-type]
                    timeout=timeout / 1000.0)
    try:
        run_serial(sender, port, latency=latency / 1000.0)
    except KeyboardInterrupt:
        answers = halt_and_delete(sender, port)
        port.close()
        shown = ", ".join(a.decode("ascii", "replace").strip() or "(none)" for a in answers)
        raise UserError(f"interrupted: sent H and D to leave the unit halted (answers: {shown})",
                        exit_code=130) from None
    except (serial.SerialException, OSError) as exc:
        raise LinkError(f"{target}: {exc}") from None
    port.close()
    s = sender.stats
    click.echo(f"sent {len(items)} job lines to {target}: {s.sent} writes, {s.answers} answers, "
               f"{s.garbled} garbled, {s.timeouts} timeouts, {s.queue_full} queue full")
    if sender.last_position is not None:
        click.echo(f"final position: {sender.last_position}")
    if sender.failed:
        raise UserError(f"send failed: {sender.failed}", exit_code=1)
