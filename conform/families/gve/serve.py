"""``conform emulate serve VARIANT`` for GVE units: the reference unit (with a dialect, reference
switch distances and an answer delay) behind a pty or TCP through the engine's serving adapter
(conform.emulator.serve.Emulator), with the GVE control commands on its control socket
(unit/control.py) and, on request, the ground truth written on exit."""

from __future__ import annotations

import time
from typing import Any

from conform.errors import UserError
from conform.families.gve.conformance.profile import load_profile
from conform.families.gve.spec import load_spec


def serve(variant: str, *, baud: int | None = None, tcp_port: int | None = None,
          dialect_pairs: tuple[str, ...] = (), profile: str | None = None,
          faults: str | None = None, seed: int | None = None, control_path: str | None = None,
          link_path: str | None = None, record_path: str | None = None,
          switch_pairs: tuple[str, ...] = (), answer_delay: float = 0.0,
          truth_path: str | None = None, mutant: str | None = None, **_ignored: Any) -> None:
    """Serve until SIGINT/SIGTERM; the first line of stdout is the device path. ``mutant``
    serves a deviant unit (conform.families.gve.conformance.mutants) instead of the reference,
    so that the suite can be run against it over a real pty as against a real unit."""
    from conform.emulator.launch import (
        announce,
        check_pacing,
        control_server,
        fault_injector,
        open_endpoint,
        report,
        run_until_signal,
    )
    from conform.emulator.serve import Emulator
    from conform.families.gve.unit.control import run_control
    from conform.families.gve.unit.model import Unit

    spec = load_spec()
    v = spec.variant(variant)
    dialect = spec.dialect(_dialect_choices(dialect_pairs, profile))
    check_pacing(baud, answer_delay)
    t_start = time.monotonic()  # the unit runs on the monotonic wall clock
    cls: Any = Unit
    if mutant is not None:
        from conform.families.gve.conformance.mutants import MUTANTS

        if mutant not in MUTANTS:
            raise UserError(f"unknown mutant {mutant!r} (known: {', '.join(MUTANTS)})")
        cls = MUTANTS[mutant].cls
    try:
        unit = cls(v, dialect, t0=t_start, switches=_switches(switch_pairs),
                    answer_delay=answer_delay)
    except ValueError as exc:
        raise UserError(f"--switch: {exc}") from None
    truth = None
    if truth_path:
        from conform.families.gve.unit.truth import GroundTruth

        truth = GroundTruth(unit, t0=t_start)
    injector = fault_injector(faults, seed, t_start)
    endpoint, reopen = open_endpoint(tcp_port, link_path)

    control = control_server(control_path, endpoint)
    control_path = control.path
    recorder = None
    if record_path:
        from conform.capture import Recorder

        try:
            recorder = Recorder(record_path, {
                "capture_method": "emulator", "variant": v.id, "baud": baud or "",
                "unit_port": endpoint.name, "dialect": ",".join(
                    f"{k}={x}" for k, x in dialect.changed().items()),
                "faults": faults or "", "seed": "" if seed is None else seed})
        except UserError:
            endpoint.close()
            control.close()
            raise

    emulator = Emulator(unit, endpoint, baud=baud, injector=injector, recorder=recorder,
                        control=control, reopen=reopen, report=report,
                        control_handler=run_control)
    announce(endpoint, f"{v.id} on {endpoint.name}; control: {control_path}"
             + (f"; dialect {dialect.changed()}" if dialect.changed() else ""))
    try:
        run_until_signal(emulator)
    finally:
        control.close()
        if recorder is not None:
            recorder.close({"bytes_in": emulator.bytes_in, "bytes_out": emulator.bytes_out})
        if truth is not None and truth_path:
            try:
                truth.write(truth_path)
            except OSError as exc:
                report(f"--truth {truth_path}: cannot write: {exc.strerror or exc}")
        report(f"stopped ({emulator.bytes_in} bytes in, {emulator.bytes_out} out)")


def _dialect_choices(pairs: tuple[str, ...], profile: str | None) -> dict[str, str]:
    choices: dict[str, str] = dict(load_profile(profile).dialect) if profile else {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key or not value:
            raise UserError(f"--dialect {pair!r:.40}: expected A<n>=<alternative>")
        choices[key.strip().upper()] = value.strip()
    return choices


def _switches(pairs: tuple[str, ...]) -> dict[str, int]:
    out = {}
    for pair in pairs:
        axis, sep, value = pair.partition("=")
        value = value.strip()
        if not sep or not value.lstrip("-").isdigit() or len(value) > 11:
            raise UserError(f"--switch {pair!r:.40}: expected AXIS=PULSES (e.g. X=3000)")
        out[axis.strip().upper()] = int(value)
    return out
