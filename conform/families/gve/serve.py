"""``conform emulate serve VARIANT`` for GVE units: the reference unit (with a dialect, reference
switch distances and an answer delay) behind a pty or TCP through the engine's serving adapter
(conform.emulator.serve.Emulator), with the GVE control commands on its control socket
(unit/control.py) and, on request, the ground truth written on exit."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from conform.errors import UserError, writable_folder
from conform.families.gve.conformance.profile import complete_profile
from conform.families.gve.spec import load_spec


def serve(variant: str, *, dialect_pairs: tuple[str, ...] = (), profile: str | None = None,
          switch_pairs: tuple[str, ...] = (), answer_delay: float = 0.0,
          truth_path: str | None = None, mutant: str | None = None, **served: Any) -> None:
    """Serve until SIGINT/SIGTERM; the first line of stdout is the device path. ``mutant``
    serves a deviant unit (conform.families.gve.conformance.mutants) instead of the reference,
    so that the suite can be run against it over a real pty as against a real unit."""
    from conform.emulator.launch import ServedUnit, serve_unit
    from conform.families.gve.unit.control import run_control
    from conform.families.gve.unit.model import Unit

    if truth_path:   # written on exit: a place it cannot go is said now, not after the session
        if Path(truth_path).is_dir():
            raise UserError(f"--truth {truth_path}: is a folder (expected a FILE.json)")
        writable_folder(Path(truth_path).parent, "--truth")
    spec = load_spec()
    v = spec.variant(variant)
    dialect = spec.dialect(_dialect_choices(dialect_pairs, profile))
    switches = _switches(switch_pairs)
    cls: Any = Unit
    if mutant is not None:
        from conform.families.gve.conformance.mutants import MUTANTS

        if mutant not in MUTANTS:
            raise UserError(f"unknown mutant {mutant!r} (known: {', '.join(MUTANTS)})")
        cls = MUTANTS[mutant].cls

    def build(t_start: float) -> ServedUnit:
        try:
            unit = cls(v, dialect, t0=t_start, switches=switches, answer_delay=answer_delay)
        except ValueError as exc:
            raise UserError(f"--switch: {exc}") from None
        truth = None
        if truth_path:
            from conform.families.gve.unit.truth import GroundTruth

            truth = GroundTruth(unit, t0=t_start)

        def finish(report: Any) -> None:
            if truth is not None and truth_path:
                try:
                    truth.write(truth_path)
                except OSError as exc:
                    report(f"--truth {truth_path}: cannot write: {exc.strerror or exc}")

        changed = dialect.changed()
        return ServedUnit(unit, describe=f"dialect {changed}" if changed else "",
                          control_handler=run_control, finish=finish,
                          metadata={"dialect": ",".join(f"{k}={x}" for k, x in changed.items())})

    serve_unit("gve", v.id, build, answer_delay=answer_delay, **served)


def _dialect_choices(pairs: tuple[str, ...], profile: str | None) -> dict[str, str]:
    choices: dict[str, str] = dict(complete_profile(profile).dialect) if profile else {}
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
