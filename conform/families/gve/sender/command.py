"""GVE's reference sender behind ``conform send JOB --target URL`` (the engine's command,
conform/cli/send_cmd.py): stream a vector file or G-code to a unit; its own options
(checksums, packets, policy, the emulated link's latency and noise, G-code conversion)."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import click

from conform.cli.params import (
    NON_NEGATIVE,
    NON_NEGATIVE_INT,
    POSITIVE,
    POSITIVE_INT,
    PROBABILITY,
)
from conform.errors import LinkError, UserError
from conform.families.gve.sender.core import POLICIES


def _ints(text: str, option: str) -> set[int]:
    """0-based write or answer numbers: ``3,7,12``."""
    parts = [x.strip() for x in text.split(",")] if text.strip() else []
    if any(not x.isdigit() for x in parts):
        bad = next(x for x in parts if not x.isdigit())
        raise UserError(f"{option}: expected comma-separated numbers from 0 (e.g. 3,7,12), "
                        f"not {bad!r} in {text!r}")
    return {int(x) for x in parts}


def _floats(text: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise UserError(f"--steps-per-mm: expected numbers, not {text!r}") from None
    if not vals or any(not math.isfinite(v) or v <= 0 for v in vals):
        raise UserError(f"--steps-per-mm: expected positive numbers, not {text!r}")
    if len(vals) not in (1, 3):
        raise UserError(f"--steps-per-mm: one number for every axis or three (X,Y,Z), not "
                        f"{text!r}")
    return vals


def _check_number(name: str, value: float, lo: float, hi: float = math.inf,
                  lo_open: bool = False) -> None:
    """One line naming the option when a number is not finite or outside its range."""
    bad = not math.isfinite(value) or value < lo or value > hi or (lo_open and value == lo)
    if bad:
        where = f"{'above' if lo_open else 'from'} {lo:g}" + ("" if hi == math.inf else
                                                              f" to {hi:g}")
        raise UserError(f"{name} {value:g}: must be a number {where}")


class Progress:
    """A line on stderr at most every ``every`` seconds of wall time while streaming: 1 s on
    a terminal, else the interval every command's progress keeps off one (5 s,
    ``CONFORM_PROGRESS_SECONDS``)."""

    def __init__(self, sender: object, every: float | None = None) -> None:
        import sys

        from conform.cli.progress import _interval

        self.sender = sender
        self.every = every if every is not None else 1.0 if sys.stderr.isatty() else _interval()
        self.next = time.monotonic()  # a first line at once, then one per ``every`` s
        self.shown = False
        self.said: object = None   # what the last line said: the same is not said again

    def __call__(self, _t: float) -> None:
        now = time.monotonic()
        if now < self.next:
            return
        self.next = now + self.every
        st = self.sender.stats  # type: ignore[attr-defined]
        now_said = (self.sender.progress, st.timeouts, st.garbled, st.queue_full)  # type: ignore[attr-defined]
        if now_said != self.said:   # motion ending after the last line: no repeated lines
            self.said = now_said
            self.show()

    def show(self) -> None:
        done, total = self.sender.progress  # type: ignore[attr-defined]
        st = self.sender.stats  # type: ignore[attr-defined]
        click.echo(f"conform send: {done}/{total} job lines ({100 * done // max(total, 1)} %), "
                   f"{st.timeouts} timeouts, {st.garbled} garbled, {st.queue_full} queue full",
                   err=True)
        self.shown = True


def _finish(sender: object) -> None:
    """Exit 1 unless every job line was acknowledged."""
    s = sender  # type: ignore[assignment]
    if s.failed:  # type: ignore[attr-defined]
        raise UserError(f"send failed: {s.failed}", exit_code=1)  # type: ignore[attr-defined]
    st = s.stats  # type: ignore[attr-defined]
    if st.unacknowledged:
        raise UserError(f"send incomplete: {st.unacknowledged} job line(s) were never "
                        "acknowledged with 0 (the policy moved on without an answer)",
                        exit_code=1)


def send_options() -> tuple[click.Option, ...]:
    """GVE's own options of ``conform send`` (``Family.command_options("send")``)."""
    return (
        click.Option(["--checksums/--no-checksums"], default=False, show_default=True,
                     help="GVE: checksummed lines."),
        click.Option(["--packet"], type=POSITIVE_INT, default=1, show_default=True,
                     help="GVE: C/B lines per *S…*E packet (1: no packets)."),
        click.Option(["--policy"], type=click.Choice(POLICIES), default="careful",
                     show_default=True,
                     help="GVE: what to do after a garbled answer or none (careless ones are "
                          "for demos)."),
        click.Option(["--latency"], type=NON_NEGATIVE, default=0.0, show_default=True,
                     help="GVE: simulated converter latency per direction, ms."),
        click.Option(["--noise"], type=PROBABILITY, default=0.0,
                     help="GVE, emu: probability a byte is damaged."),
        click.Option(["--seed"], type=NON_NEGATIVE_INT, default=1,
                     help="GVE, emu: seed of the noise."),
        click.Option(["--corrupt-command"], default="",
                     help="GVE, emu: damage these host writes (0-based)."),
        click.Option(["--corrupt-answer"], default="",
                     help="GVE, emu: damage these answer lines (0-based)."),
        click.Option(["--steps-per-mm"], default="100", show_default=True,
                     help="GVE, G-code: per axis, X,Y,Z."),
        click.Option(["--feed"], type=POSITIVE, default=600.0, show_default=True,
                     help="GVE, G-code: mm/min before the first F."),
        click.Option(["--accel"], type=POSITIVE, default=500.0, show_default=True,
                     help="GVE, G-code: mm/s²."),
        click.Option(["--lenient"], is_flag=True,
                     help="GVE, G-code: skip words outside the subset and what cannot be read."),
    )


DEFAULT_TIMEOUT = 0.25   # seconds to wait for an answer


def send_job(job: str, target: str, *, variant: str | None, baud: int, allow_motion: bool,
             record: str | None, timeout: float | None, quiet: bool = False,
             checksums: bool = False, packet: int = 1, policy: str = "careful",
             latency: float = 0.0, noise: float = 0.0, seed: int = 1,
             corrupt_command: str = "", corrupt_answer: str = "", steps_per_mm: str = "100",
             feed: float = 600.0, accel: float = 500.0, lenient: bool = False,
             **_: object) -> None:
    """Stream JOB (one command per line, or .nc/.gcode) and report what happened
    (``conform send`` for a GVE unit; the engine checked ``--record`` and ``--timeout``)."""
    from conform.families.gve.sender.job import load_job
    from conform.families.gve.spec import load_spec

    spec = load_spec()
    timeout_ms = 1000.0 * (DEFAULT_TIMEOUT if timeout is None else timeout)
    emu = target == "emu" or target.startswith("emu:")
    var = spec.variant(variant or "gve64-v19")
    dialect = spec.dialect()
    if packet < 1:
        raise UserError(f"--packet {packet}: must be 1 or more")
    if baud <= 0:
        raise UserError(f"--baud {baud}: must be positive")
    _check_number("--noise", noise, 0.0, 1.0)
    _check_number("--latency", latency, 0.0, 10_000.0)
    _check_number("--feed", feed, 0.0, lo_open=True)
    _check_number("--accel", accel, 0.0, lo_open=True)
    spm = _floats(steps_per_mm)
    gopts = {"steps_per_mm": spm if len(spm) > 1 else spm * 3, "feed": feed, "accel": accel,
             "lenient": lenient}
    if not emu and (noise or corrupt_command or corrupt_answer):
        raise UserError("--noise and --corrupt-* simulate a bad line to an emu: target; a "
                        "real port's line is what it is")
    if not emu:
        _send_port(job, gopts, spec, variant, target, baud, checksums, packet, policy,
                   latency, timeout_ms, allow_motion, quiet, record)
        return
    items = load_job(job, var, dialect, **gopts)
    from conform.families.gve.sender.links import LinkModel
    from conform.families.gve.sender.session import send_emulated

    link = LinkModel(baud=baud, latency=latency / 1000.0, noise=noise, seed=seed,
                     corrupt_commands=_ints(corrupt_command, "--corrupt-command"),
                     corrupt_answers=_ints(corrupt_answer, "--corrupt-answer"))
    res = send_emulated(items, var, dialect, policy=policy, checksums=checksums,
                        packet=packet, link=link, record=record, timeout=timeout_ms / 1000.0,
                        progress=None if quiet else Progress)
    s = res.sender
    click.echo(f"sent {len(items)} job lines to {target}: {s.stats.sent} writes, "
               f"{s.stats.answers} answers, {s.stats.garbled} garbled, "
               f"{s.stats.timeouts} timeouts, {s.stats.queue_full} queue full, "
               f"{s.stats.resent} resent")
    click.echo(f"final position: {res.position}")
    if record:
        click.echo(f"capture: {record}")
    _finish(s)
    expected = [0] * len(res.position)
    for it in items:
        for k, x in enumerate(it.vector or ()):
            expected[k] += x
    if tuple(expected) != tuple(res.position):
        raise UserError(f"send incomplete: the unit ended at {res.position}, the job's vectors "
                        f"add up to {tuple(expected)}: a damaged line was executed as received "
                        "(--checksums guards against that)", exit_code=1)


def _send_port(job: str, gopts: dict, spec: object, variant: str | None, target: str,
               baud: int, checksums: bool, packet: int, policy: str, latency: float,
               timeout: float, allow_motion: bool, quiet: bool, record: str | None = None
               ) -> None:
    """A real port (or any pyserial URL): ``?`` first (variant, checksum mode), then stream;
    ``record``: the stream's bytes also go to this capture, as the host end of the cable."""
    import serial

    from conform.families.gve.conformance.target import variant_for_firmware
    from conform.families.gve.sender.job import load_job
    from conform.families.gve.sender.probe import probe_unit
    from conform.link.ports import OPEN_ERRORS

    # the job is read before the port is touched: a bad file or a motion job without
    # --allow-motion never reaches the unit; it is read again for the variant `?` finds
    first = load_job(job, spec.variant(variant or "gve64-v19"), spec.dialect(), **gopts)  # type: ignore[attr-defined]
    if any(i.motion for i in first) and not allow_motion:
        raise UserError(f"{job}: the job moves the machine; sending it to {target} needs "
                        "--allow-motion")
    try:
        port = serial.serial_for_url(target, baudrate=baud, timeout=0.05, write_timeout=2.0)
    except OPEN_ERRORS as exc:
        raise LinkError(f"{target}: cannot open: {exc}") from None
    try:
        try:
            found = probe_unit(port, target)
        except (serial.SerialException, OSError) as exc:
            raise LinkError(f"{target}: {exc}") from None
        vid, how = variant_for_firmware(spec, found.firmware)
        if variant and variant != vid:
            raise UserError(f"--variant {variant}: the unit on {target} answers `?` with "
                            f"{found.firmware!r} ({how})")
        click.echo(f"conform send: {how}" + ("; checksums were left on: cleared with %-"
                                             if found.checksum_was_on else ""), err=True)
        var = spec.variant(vid)  # type: ignore[attr-defined]
        items = load_job(job, var, spec.dialect(), **gopts)  # type: ignore[attr-defined]
        if record:
            port = TapedPort.open(port, record, {"variant": vid, "baud": baud, "target": target,
                                                 "job": Path(job).name})
        _stream(items, var, port, target, checksums, packet, policy, latency, timeout, quiet)
    finally:
        port.close()
        if record:
            click.echo(f"capture: {record}")


class TapedPort:
    """A pyserial port whose bytes also go to a capture (``send --record`` to a real port):
    host bytes when written, unit bytes when read, on the wall clock."""

    def __init__(self, port: Any, recorder: Any) -> None:
        self.port, self.recorder = port, recorder

    @classmethod
    def open(cls, port: Any, path: str, metadata: dict[str, Any]) -> TapedPort:
        from conform.capture.recorder import Recorder
        from conform.conformance.recorded import TAP

        # dated as written and read (a real unit's answer may come faster than the baud
        # rate would suggest from a converter's buffer: nothing is backdated)
        return cls(port, Recorder(path, {"tap": TAP, "capture_method": "conform send",
                                         **metadata}, backdate=False))

    @property
    def timeout(self) -> Any:
        return self.port.timeout

    @timeout.setter
    def timeout(self, value: Any) -> None:
        self.port.timeout = value

    @property
    def in_waiting(self) -> int:
        return self.port.in_waiting

    def write(self, data: bytes) -> Any:
        t0 = self.recorder.clock()
        n = self.port.write(data)
        self.recorder.chunk("host", bytes(data), self.recorder.clock(), t0)
        return n

    def _read(self, data: bytes) -> bytes:
        if data:
            self.recorder.chunk("unit", data)
        return data

    def read(self, size: int = 1) -> bytes:
        return self._read(self.port.read(size))

    def read_until(self, expected: bytes = b"\n", size: int | None = None) -> bytes:
        return self._read(self.port.read_until(expected, size))

    def close(self) -> None:
        from conform.stops import shield

        with shield():   # the capture is finished however the send ended
            try:
                self.recorder.close()
            finally:
                self.port.close()


def _stream(items: list, var: object, port: object, target: str, checksums: bool, packet: int,
            policy: str, latency: float, timeout: float, quiet: bool) -> None:
    import serial

    from conform.families.gve.sender.core import Sender
    from conform.families.gve.sender.links import halt_and_delete, run_serial
    from conform.stops import interrupted_by

    sender = Sender(items, var, policy=policy, checksums=checksums, packet=packet,  # type: ignore[arg-type]
                    timeout=timeout / 1000.0)
    progress = Progress(sender)
    try:
        run_serial(sender, port, latency=latency / 1000.0,
                   on_progress=None if quiet else progress)
    except KeyboardInterrupt as exc:   # Ctrl-C, SIGTERM, SIGHUP (conform.stops)
        answers = halt_and_delete(sender, port)
        port.close()
        shown = ", ".join(a.decode("ascii", "replace").strip() or "(none)" for a in answers)
        raise UserError(f"interrupted ({interrupted_by(exc)}): sent H and D to leave the unit "
                        f"halted (answers: {shown})", exit_code=130) from None
    except (serial.SerialException, OSError):
        done, total = sender.progress
        raise LinkError(f"{target}: link lost after {done} of {total} job lines acknowledged "
                        "(the port went away: cable, power, or another program on the port); "
                        "the unit may still run what it took", exit_code=1) from None
    if progress.shown:
        progress.show()
    s = sender.stats
    click.echo(f"sent {len(items)} job lines to {target}: {s.sent} writes, {s.answers} answers, "
               f"{s.garbled} garbled, {s.timeouts} timeouts, {s.queue_full} queue full")
    if sender.last_position is not None:
        click.echo(f"final position: {sender.last_position}")
    _finish(sender)
