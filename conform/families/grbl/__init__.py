"""grbl 1.1f as a protocol family: tables in grbl/spec/tables/, a sans-I/O reference unit, the
conformance checks generated from the tables, traffic detection and capture analysis.

Modules: ``tables`` (load and validate grbl/spec/tables), ``codec`` (split a byte stream into lines
and realtime bytes, classify what grbl sends), ``gcode`` (the parser and its modal state),
``planner`` (motion in virtual time), ``unit`` + ``system`` + ``report`` (the reference unit),
``serve`` (the emulator on a pty/TCP), ``checks`` (conformance), ``analysis`` (captures).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from conform.families import Detection, VariantInfo


class GrblFamily:
    name = "grbl"

    def load_tables(self, root: str | None = None) -> Any:
        from conform.families.grbl.tables import load_grbl

        return load_grbl(root)

    def variants(self) -> Sequence[VariantInfo]:
        spec = self.load_tables()
        return [VariantInfo(v.id, self.name, v.title, f"Grbl {v.version} ({v.build})",
                            "".join(v.axes), f"rx {v.rx_buffer} B, planner {v.planner_blocks}",
                            f"line {v.line_max} chars") for v in spec.variants.values()]

    def make_unit(self, variant: str, *, t0: float = 0.0, **options: Any) -> Any:
        from conform.families.grbl.unit import GrblUnit

        spec = self.load_tables()
        return GrblUnit(spec.variant(variant), spec, t0=t0, **options)

    def run_conformance(self, target: Any, variant: str, **options: Any) -> Any:
        from conform.families.grbl.checks import run_checks

        return run_checks(target, variant, **options)

    def runner(self, target: Any, variant: str, **options: Any) -> Any:
        """grbl's checks in the engine's runner (checks.GrblRunner): fresh unit by soft reset,
        halt by feed hold then soft reset."""
        from conform.families.grbl.checks import GrblRunner

        return GrblRunner(target, variant, **options)

    def run_targets(self, targets: list[str], variant: str | None, *, baud: int = 115200,
                    patterns: Any = (), profile: str = "quick", allow_motion: bool = False,
                    allow_eeprom: bool = False, list_only: bool = False, echo: Any = print,
                    announce: Any = None, **_options: Any) -> Any:
        from conform.families.grbl.checks import run_targets

        runs = run_targets(targets or [f"emu:{variant}"], variant, baud=baud,
                           patterns=patterns, profile=profile, allow_motion=allow_motion,
                           allow_eeprom=allow_eeprom, list_only=list_only, echo=echo,
                           announce=announce)
        return None if list_only else (runs, [])

    def live_decoder(self, variant: str, *, baud: int | None = None) -> Any:
        return None   # recorded raw; lines are paired when the capture is analysed

    pytest_plugin = None
    check_sender = None   # its senders are judged by sendercheck.run_cli (conform check-sender)

    def check_sender_cli(self, *args: Any, **kw: Any) -> int:
        """``conform check-sender --variant grbl-…``: this family's scenarios and rules."""
        from conform.families.grbl.sendercheck import run_cli

        return run_cli(*args, **kw)

    def characterize(self, target: str, output: str, variant: str | None, *, baud: int = 115200,
                     echo: Any = print, **_options: Any) -> None:
        from conform.families.grbl.characterize import run

        run(target, output, variant, baud, echo=echo)

    def show_spec(self, variant: str, command: str | None, *, console: Any,
                  as_json: bool = False) -> None:
        from conform.families.grbl.show import show

        show(variant, command, console)

    def tables_summary(self, root: str | None = None) -> str:
        g = self.load_tables(root)
        return (f"ok: grbl: {len(g.variants)} variant, {len(g.errors)} error codes, "
                f"{len(g.alarms)} alarm codes, {len(g.settings)} settings, "
                f"{len(g.commands)} $ commands, {len(g.examples)} examples")

    def mutants(self) -> Sequence[str]:
        return ()

    def detect(self, host: bytes, unit: bytes, metadata: dict[str, Any]) -> Detection:
        from conform.families.grbl.codec import detect

        return detect(host, unit)

    def analyze(self, path: str, **options: Any) -> Any:
        from conform.families.grbl.analysis import analyze_capture

        return analyze_capture(path, **options)

    def diagnosis_facts(self, raw: Any, path: str, *, variant: str | None = None,
                        analysis: Any = None) -> Any:
        from conform.families.grbl.diagnosis import facts

        return facts(raw, path, variant=variant, analysis=analysis)

    def reception(self, raw: Any, *, variant: str | None = None) -> Any:
        """The receive ring (128 bytes, silent drops) and line reader replayed on the host's
        bytes, the answers as the clock (diagnosis.py)."""
        from conform.families.grbl.diagnosis import reception

        return reception(raw, variant=variant)

    def live_monitor(self, variant: str | None) -> Any:
        from conform.families.grbl.live import live_monitor

        return live_monitor(variant)

    def resume_state(self, raw: Any, facts: Any, *, variant: str | None = None) -> Any:
        from conform.families.grbl.diagnosis import resume_state

        return resume_state(raw, facts, variant=variant)

    def serve(self, variant: str, **options: Any) -> None:
        from conform.families.grbl.serve import serve

        serve(variant, **options)


FAMILY = GrblFamily()
