"""Marlin 2.1 as a protocol family: tables in specs/marlin/, a sans-I/O reference unit,
conformance checks graded per clause, traffic detection and capture analysis, check-sender.

Rooms: ``spec`` (tables and their loader), ``protocol`` (checksums, framing, reading lines,
detection), ``unit`` (the reference unit, its faults, control requests and ``serve``),
``conformance`` (checks in the engine's runner, mutants), ``analysis`` (captures),
``sendercheck`` (judging a sender program), ``show`` (``conform spec show``).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from conform.families import Detection, Family, VariantInfo

if TYPE_CHECKING:
    from rich.console import Console

    from conform.capture.session import Decoder
    from conform.conformance.observed import ProbeHooks
    from conform.conformance.plan import Permissions
    from conform.conformance.runner import Check, Runner, RunOptions
    from conform.conformance.target import Target
    from conform.emulator.serve import SansIOUnit
    from conform.families import AnalysisResult, ProbeAnswer
    from conform.sendercheck.family import Family as SenderShapes

REAL_BOARD_NOTES = [
    "settings checks set M92/M201/M203-M206/M301/M304/M220/M221/M111 and put back what "
    "M503, M220, M221 read before each check",
    "EEPROM checks end with M500 of the settings the unit had at their start: what its EEPROM "
    "held before the run is replaced by them",
    "motion checks home (G28) and move a few mm from there; G92 changes the logical "
    "coordinates; M112 checks leave the unit halted until it is reset"]


class MarlinFamily(Family):
    """Marlin's hooks (the Family base class's: ``plan_checks``, ``runner``, ``mutants``,
    ``diff_variants``, ...)."""

    name = "marlin"
    title = "Marlin 2.1 (3D printers, plotters, small CNC and lasers)"
    default_rank = 300
    latency_measure = "line to ok"   # fleet_row()'s latency percentiles (ok_p50_ms ...)
    table_files = ("variants", "messages", "commands", "caps")
    characterize_about = (
        "the build's configuration: firmware and protocol version, the M115 capabilities, "
        "ADVANCED_OK with the planner and command-queue sizes, MAX_CMD_SIZE, the host "
        "keepalive, the emergency parser, how a repeated line number is treated. No motion, "
        "no heat, no EEPROM write.")
    pytest_plugin = None

    @property
    def default_variant(self) -> str:
        return next(iter(self.load_tables().variants))

    def load_tables(self, root: str | None = None) -> Any:
        from conform.families.marlin.spec import load_marlin

        return load_marlin(root)

    def variants(self) -> Sequence[VariantInfo]:
        spec = self.load_tables()
        return [VariantInfo(v.id, self.name, v.title, f"Marlin {v.firmware}", "XYZE",
                            f"queue {v.bufsize}, rx {v.rx_buffer} B, planner {v.planner_blocks}",
                            ", ".join(k for k in ("ADVANCED_OK", "EMERGENCY_PARSER") if v.on(k))
                            or "ok, no emergency parser") for v in spec.variants.values()]

    def make_unit(self, variant: str, *, t0: float = 0.0, **options: Any) -> SansIOUnit:
        from conform.families.marlin.conformance.mutants import make

        spec = self.load_tables()
        return make(spec.variant(variant), spec, t0=t0, **options)

    line_ending = "\n"     # serial.h SERIAL_EOL: a bare LF (a println's lines end CR LF)

    def judge_mask(self, variant: str) -> Callable[[str], str]:
        from conform.families.marlin.protocol.codec import mask_volatile

        return mask_volatile

    def judge_answers(self, variant: str) -> Callable[[str], bool]:
        """``ok`` closes the answer to one line (queue.cpp ok_to_send; M105's ``ok T:``)."""
        from conform.families.marlin.protocol.codec import is_answer

        return is_answer

    def judge_near(self, variant: str) -> Callable[[str, str], bool] | None:
        """M114 answers within POSITION_TOLERANCE (protocol/codec.py): where a quickstop
        leaves the axes depends on the moment it is read."""
        from functools import partial

        from conform.families.marlin.protocol.codec import near_position

        v = self.load_tables().variant(variant)
        return partial(near_position, steps=v.steps_per_mm[:3])

    def runner(self, target: Target, variant: str, *, options: RunOptions | None = None,
               permissions: Permissions | None = None,
               **family_values: Any) -> Runner[Any]:
        from conform.families.marlin.conformance.checks import MarlinRunner

        motion = bool(permissions.allow_motion) if permissions is not None else \
            bool(family_values.pop("allow_motion", False))
        eeprom = bool(permissions.allow_eeprom) if permissions is not None else False
        if options is not None and target.emulated:
            options.notes.append(self.real_board_note(variant, options.profile))
        return MarlinRunner(target, variant, allow_motion=motion, allow_eeprom=eeprom,
                            options=options)

    def real_board_note(self, variant: str, profile: str = "quick") -> str:
        """What the same run on a real board would leave out or change (an emulator run
        does everything)."""
        from conform.families.marlin.conformance.checks import HEATERS_ENV, generate

        checks = generate(self.load_tables(), variant, profile)
        moves = sum(c.motion for c in checks)
        eeprom = sum(c.eeprom for c in checks)
        heats = sum(c.heat for c in checks)
        settings = sum("/settings/" in c.id for c in checks)
        return (f"a real board: {moves} checks that move or halt it SKIPPED without "
                f"--allow-motion (with it, one halt check runs, last, and leaves it halted "
                f"until reset), {eeprom} EEPROM checks without --allow-eeprom, {heats} heating "
                f"checks without {HEATERS_ENV}=1; {settings} settings checks put back what "
                "M503, M220 and M221 read before each")

    def plan_checks(self, variant: str, *, permissions: Permissions | None = None, profile: str = "quick",
                    patterns: Sequence[str] = (), machine: bool = True, **_values: Any
                    ) -> Sequence[Check]:
        from conform.families.marlin.conformance.checks import generate, select

        return select(generate(self.load_tables(), variant, profile), patterns)

    def permission_notes(self, permissions: Permissions) -> list[str]:
        from conform.families.marlin.conformance.checks import HEATERS_ENV

        notes = [] if permissions.allow_motion else [
            "checks that move or halt the unit SKIPPED (no --allow-motion)"]
        notes += [] if permissions.allow_eeprom else [
            "EEPROM checks (M500) SKIPPED (no --allow-eeprom)"]
        heating = os.environ.get(HEATERS_ENV, "") == "1"
        notes += [f"checks that heat run ({HEATERS_ENV}=1) and set the targets back to 0"
                  if heating else f"checks that heat SKIPPED unless {HEATERS_ENV}=1"]
        return notes + REAL_BOARD_NOTES

    def mutant_fault(self, name: str) -> str:
        from conform.families.marlin.conformance.mutants import MUTANTS

        return (MUTANTS[name].__doc__ or name).strip()

    def diff_variants(self, a: str, b: str) -> tuple[str, Sequence[str], Sequence[Sequence[object]]]:
        from conform.families.marlin.spec import diff

        spec = self.load_tables()
        va, vb = spec.variant(a), spec.variant(b)
        rows = diff(va, vb)
        return (f"{a} → {b}: {len(rows)} differences", ["what", a, b, "source"], rows)

    def live_decoder(self, variant: str, *, baud: int | None = None) -> Decoder | None:
        return None   # recorded raw; lines are paired when the capture is analysed

    @property
    def check_sender(self) -> SenderShapes[Any, Any, Any]:
        """check-sender's Marlin scenarios, rules and hooks (sendercheck/family.py)."""
        from conform.families.marlin.sendercheck.family import MARLIN

        return MARLIN

    def characterize_probes(self) -> ProbeHooks:
        from conform.families.marlin.conformance.characterize import ITEMS, characterize
        from conform.families.marlin.conformance.checks import halt

        return characterize, halt, ITEMS

    def show_spec(self, variant: str, command: str | None, *, console: Console,
                  as_json: bool = False) -> None:
        from conform.families.marlin.show import show

        show(variant, command, console, as_json)

    def tables_summary(self, root: str | None = None) -> str:
        s = self.load_tables(root)
        return (f"ok: marlin: {len(s.variants)} variants, {len(s.messages)} message kinds, "
                f"{len(s.commands)} commands, {len(s.caps)} M115 capabilities")

    def mutants(self) -> Sequence[str]:
        from conform.families.marlin.conformance.mutants import MUTANTS

        return tuple(MUTANTS)

    def detect(self, host: bytes, unit: bytes, metadata: dict[str, Any]) -> Detection:
        from conform.families.marlin.protocol.codec import detect

        return detect(host, unit)

    def analyze(self, path: str, **options: Any) -> AnalysisResult:
        from conform.families.marlin.analysis.analyze import analyze_capture

        return analyze_capture(path, **options)

    def diagnosis_facts(self, raw: Any, path: str, *, variant: str | None = None,
                        analysis: Any = None) -> Any:
        """``conform diagnose``: the analysis as neutral facts (diagnosis/facts.py)."""
        from conform.families.marlin.diagnosis.facts import facts

        return facts(raw, path, variant=variant, analysis=analysis)

    def probe(self, device: str, *, baud: int, timeout: float) -> ProbeAnswer:
        """M115, the capability report (conformance/portprobe.py)."""
        from conform.families.marlin.conformance.portprobe import probe

        return probe(device, baud=baud, timeout=timeout)

    def send_job(self, job: str, target: str, **options: Any) -> None:
        """``conform send``: the reference streamer (sender/command.py)."""
        from conform.families.marlin.sender.command import send_job

        send_job(job, target, **options)

    def serve(self, variant: str, **options: Any) -> None:
        from conform.families.marlin.unit.serve import serve

        serve(variant, **options)


FAMILY = MarlinFamily()
