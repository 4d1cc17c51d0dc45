"""grbl 1.1f as a protocol family: tables in specs/grbl/, a sans-I/O reference unit, the
conformance checks generated from the tables, traffic detection and capture analysis.

Subpackages, as GVE's: ``spec`` (load and validate specs/grbl), ``protocol`` (split a byte
stream into lines and realtime bytes, classify what grbl sends; the g-code parser and its modal
state), ``unit`` (the reference unit: model, planner, ``$`` commands, the text it sends, input
pins, faults, control requests), ``conformance`` (checks, characterisation), ``analysis``
(captures, reference streaming senders, the HTML report), ``sendercheck`` (check-sender's
scenarios, sessions and rules); ``serve`` (the emulator on a pty/TCP), ``cli`` (spec show).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from conform.families import Detection, Family, FleetColumn, VariantInfo

if TYPE_CHECKING:
    import click
    from rich.console import Console

    from conform.analysis.rawread import RawCapture
    from conform.capture.merge import HostLines
    from conform.capture.session import Decoder
    from conform.conformance.observed import ProbeHooks
    from conform.conformance.plan import Permissions
    from conform.conformance.runner import Check, Runner, RunOptions
    from conform.conformance.target import Target
    from conform.diagnosis.facts import Facts, ParsedLine, ResumePoint
    from conform.diagnosis.live import LiveMonitor
    from conform.emulator.serve import SansIOUnit
    from conform.families import AnalysisResult, ProbeAnswer
    from conform.sendercheck.family import Family as SenderShapes


class GrblFamily(Family):
    name = "grbl"
    title = "grbl 1.1f"
    table_files = ("variants", "codes", "settings", "protocol", "status", "examples")
    characterize_about = (
        "the build's compile-time choices: version and build date, the $I options, receive "
        "buffer and planner sizes, whether CR LF ends one line or two, the line-length limit. "
        "Nothing moves, nothing is written to the EEPROM.")

    def load_tables(self, root: str | None = None) -> Any:
        from conform.families.grbl.spec.load import load_grbl

        return load_grbl(root)

    def variants(self) -> Sequence[VariantInfo]:
        spec = self.load_tables()
        return [VariantInfo(v.id, self.name, v.title, f"Grbl {v.version} ({v.build})",
                            "".join(v.axes), f"rx {v.rx_buffer} B, planner {v.planner_blocks}",
                            f"line {v.line_max} chars") for v in spec.variants.values()]

    line_ending = "\r\n"   # report.c: every line the unit prints ends CR LF

    def judge_answers(self, variant: str) -> Callable[[str], bool]:
        """``ok`` and ``error:N`` close the answer to one line (protocol.c, report.c
        report_status_message); a streaming sender counts them."""
        from conform.families.grbl.emulate_judge import is_answer

        return is_answer

    def judge_unit(self, variant: str) -> Any:
        """The recordings (shared/recordings/grbl-1.1f) come from grbl-sim, whose input pins
        read high: no limit switch ever closes, so its ``$H`` seeks on and fails. The unit
        judged is given the same setting (``switches=False``)."""
        return self.make_unit(variant, switches=False)

    def judge_follow(self, variant: str) -> Callable[[Any, str], None] | None:
        from conform.families.grbl.emulate_judge import Follow

        return Follow()

    def judge_near(self, variant: str) -> Callable[[str, str], bool] | None:
        from conform.families.grbl.emulate_judge import near

        return near

    def make_unit(self, variant: str, *, t0: float = 0.0, mutant: str | None = None,
                  **options: Any) -> SansIOUnit:
        """The reference unit, or the deviant unit ``mutant`` (conformance/mutants.py)."""
        from conform.families.grbl.unit.model import GrblUnit

        spec = self.load_tables()
        if mutant is not None:
            from conform.families.grbl.conformance.mutants import mutant as named

            return named(mutant).make(spec, variant, t0=t0, **options)
        return GrblUnit(spec.variant(variant), spec, t0=t0, **options)

    def mutant_fault(self, name: str) -> str:
        from conform.families.grbl.conformance.mutants import mutant

        return mutant(name).fault

    def runner(self, target: Target, variant: str, *, options: RunOptions | None = None,
               permissions: Permissions | None = None,
               allow_motion: bool = False, allow_eeprom: bool = False, **_: Any) -> Runner[Any]:
        """grbl's checks in the engine's runner (checks.GrblRunner): fresh unit by soft reset,
        halt by feed hold then soft reset."""
        from conform.families.grbl.conformance.checks import GrblRunner

        max_steps = None
        if permissions is not None:
            allow_motion, allow_eeprom = permissions.allow_motion, permissions.allow_eeprom
            max_steps = permissions.max_steps
        return GrblRunner(target, variant, allow_motion=allow_motion, allow_eeprom=allow_eeprom,
                          options=options, max_steps=max_steps)

    def plan_checks(self, variant: str, *, permissions: Permissions, profile: str = "quick",
                    patterns: Sequence[str] = (), machine: bool = True, **_: Any) -> Sequence[Check]:
        """The checks of the tables; ``machine=False`` leaves the random sequences out."""
        from conform.families.grbl.conformance.checks import SEQUENCES, generate, select

        spec = self.load_tables()
        checks = [c for c in generate(spec, variant) if machine or not c.id.endswith(SEQUENCES)]
        return select(checks, patterns)

    def run_mutants(self, variants: Sequence[str], *, profile: str = "quick", seed: int = 0,
                    progress: Callable[[str], None] | None = None) -> list[dict[str, object]]:
        """Every deviant unit through the checks, and whether a check meant for it caught it
        (conformance/mutants.py)."""
        from conform.families.grbl.conformance.checks import run_checks
        from conform.families.grbl.conformance.mutants import run_mutants

        spec = self.load_tables()
        report: list[dict[str, Any]] = []
        for vid in variants:
            part, _ = run_mutants(spec, vid, lambda target, vid: run_checks(
                target, vid, profile=profile, spec=spec, sequences=False))
            for m in part:
                if progress is not None:
                    progress(f"mutant {m['name']} on {vid}: "
                             + (f"killed by {len(m['caught_by'])} checks" if m["killed"] else "SURVIVED"))
            report += part
        return report

    def live_decoder(self, variant: str, *, baud: int | None = None) -> Decoder | None:
        return None   # recorded raw; lines are paired when the capture is analysed

    def host_lines(self) -> HostLines | None:
        return None  # every line gets exactly one ok or error: the engine's default count

    pytest_plugin = None
    # a fleet summary's grbl columns (GrblAnalysis.fleet_row): motion lines answered ok,
    # hazards and planner starvations
    latency_measure = "line to ok/error"   # fleet_row()'s latency percentiles
    fleet_columns = (
        FleetColumn("vectors_accepted", "motion lines", total=True, rate="vectors_per_s",
                    rate_label="motion lines/s", machines=False, sessions=False),
        FleetColumn("hazards", "hazards", total=True, flag=True, summary=True),
        FleetColumn("starvations", "starvations", total=True, summary=True),
    )

    @property
    def check_sender(self) -> SenderShapes[Any, Any, Any]:
        """check-sender's grbl scenarios, rules and hooks (sendercheck/family.py)."""
        from conform.families.grbl.sendercheck.family import GRBL

        return GRBL

    def characterize_probes(self) -> ProbeHooks:
        from conform.families.grbl.conformance.characterize import ITEMS, characterize
        from conform.families.grbl.conformance.checks import stop_unit

        return characterize, stop_unit, ITEMS

    def show_spec(self, variant: str, command: str | None, *, console: Console,
                  as_json: bool = False) -> None:
        from conform.families.grbl.cli import show

        show(variant, command, console)

    def tables_summary(self, root: str | None = None) -> str:
        g = self.load_tables(root)
        return (f"ok: grbl: {len(g.variants)} variant, {len(g.errors)} error codes, "
                f"{len(g.alarms)} alarm codes, {len(g.settings)} settings, "
                f"{len(g.commands)} $ commands, {len(g.examples)} examples")

    def probe(self, device: str, *, baud: int, timeout: float) -> ProbeAnswer:
        from conform.families.grbl.conformance.portprobe import probe

        return probe(device, baud=baud, timeout=timeout)

    def mutants(self) -> Sequence[str]:
        from conform.families.grbl.conformance.mutants import MUTANTS

        return tuple(MUTANTS)

    def detect(self, host: bytes, unit: bytes, metadata: dict[str, Any]) -> Detection:
        from conform.families.grbl.protocol.codec import detect

        return detect(host, unit)

    def analyze(self, path: str, **options: Any) -> AnalysisResult:
        from conform.families.grbl.analysis.analyze import analyze_capture

        return analyze_capture(path, **options)

    def diagnosis_facts(self, raw: RawCapture, path: str, *, variant: str | None = None,
                        analysis: AnalysisResult | None = None) -> Facts | None:
        from conform.families.grbl.diagnosis.facts import facts

        return facts(raw, path, variant=variant, analysis=analysis)

    def reception(self, raw: RawCapture, *, variant: str | None = None) -> list[ParsedLine] | None:
        """The receive ring (128 bytes, silent drops) and line reader replayed on the host's
        bytes, the answers as the clock (diagnosis.py)."""
        from conform.families.grbl.diagnosis.facts import reception

        return reception(raw, variant=variant)

    def live_monitor(self, variant: str | None) -> LiveMonitor | None:
        from conform.families.grbl.diagnosis.live import live_monitor

        return live_monitor(variant)

    def resume_state(self, raw: RawCapture, facts: Facts, *, variant: str | None = None
                     ) -> ResumePoint | None:
        from conform.families.grbl.diagnosis.facts import resume_state

        return resume_state(raw, facts, variant=variant)

    def send_job(self, job: str, target: str, **options: Any) -> None:
        """``conform send``: the reference streamer (sender/command.py)."""
        from conform.families.grbl.sender.command import send_job

        send_job(job, target, **options)

    def command_options(self, command: str) -> Sequence[click.Option]:
        if command == "send":
            from conform.families.grbl.sender.command import send_options

            return send_options()
        return ()

    def serve(self, variant: str, **options: Any) -> None:
        from conform.families.grbl.serve import serve

        serve(variant, **options)


FAMILY = GrblFamily()
