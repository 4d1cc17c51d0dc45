"""The GVE family as a :class:`conform.families.Family`: tables (spec/), codec (protocol/),
reference unit (unit/), checks, grading and targets (conformance/, driven by the engine's
runner in conform.conformance),
reference sender (sender/), check-sender scenarios and rules (sendercheck/), the capture
analyser (analysis/, on the engine's capture reading, summaries, tables and reports in
conform.analysis)."""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from conform.families import Detection, Family, FleetColumn, VariantInfo

if TYPE_CHECKING:
    import click
    from rich.console import Console

    from conform.analysis.rawread import RawCapture
    from conform.capture.merge import HostLines
    from conform.capture.session import Decoder
    from conform.conformance.plan import Permissions
    from conform.conformance.runner import Check, Runner, RunOptions
    from conform.conformance.target import Target
    from conform.diagnosis.facts import Facts, ParsedLine, ResumePoint
    from conform.diagnosis.live import LiveMonitor
    from conform.emulator.serve import SansIOUnit
    from conform.families import AnalysisResult, ProbeAnswer
    from conform.sendercheck.family import Family as SenderShapes
# a GVE command line: '!', an address digit, a mnemonic (GVE64 §13.5); answers: a hex status
# code, maybe with comma-separated fields, ended by CR (GVE64 §13.7)
_HOST_LINE = re.compile(rb"![0-7][A-Z?$@>%*]")
_ANSWER = re.compile(rb"(?:^|\r)[0-9A-F](?:,[^\r]*)?\r")


class GveFamily(Family):
    name = "gve"
    title = "Gravos GVE64/GVE124 interpolators"
    needs_travel_bound = True   # checks size their moves within --max-steps pulses
    default_rank = 0   # the units conform was first written for: commands without a variant
    table_files = ("commands", "errors", "status", "eeprom", "variants", "questions", "examples")
    characterize_about = (
        "the open questions A1-A29 of the manuals (the protocol digest's register): which "
        "alternative the unit follows on each, written as a [dialect] profile. Probes that "
        "move need --allow-motion --max-steps N, the EEPROM probe (A18) --allow-eeprom.")

    def load_tables(self, root: str | None = None) -> Any:
        from conform.families.gve.spec import load_spec

        return load_spec(root)

    def variants(self) -> Sequence[VariantInfo]:
        spec = self.load_tables()
        return [VariantInfo(v.id, self.name, v.title, v.firmware, "".join(v.axes),
                            f"queue {v.queue}", v.base or "") for v in spec.variants.values()]

    def make_unit(self, variant: str, *, t0: float = 0.0, **options: Any) -> SansIOUnit:
        from conform.families.gve.unit.model import Unit

        spec = self.load_tables()
        dialect = options.pop("dialect", None) or spec.dialect()
        return Unit(spec.variant(variant), dialect, t0=t0, **options)

    def runner(self, target: Target, variant: str, *, options: RunOptions | None = None,
               permissions: Permissions | None = None,
               dialect_file: str | None = None, **kw: Any) -> Runner[Any]:
        """Grading against the reference unit, the state keeper, H, D, O0,FF
        (conformance/runner.py); ``dialect_file``: a characterised profile's dialect expected
        instead of the defaults; ``dialect``, ``unit_cls`` as the Runner takes them."""
        from conform.families.gve.conformance.runner import Runner

        if dialect_file:
            kw["dialect"] = self._dialect(dialect_file)
        return Runner(self.load_tables(), target, variant, options=options, **kw)

    def _dialect(self, dialect_file: str | None) -> Any:
        from conform.families.gve.conformance.profile import load_profile_dialect

        return load_profile_dialect(self.load_tables(), dialect_file) if dialect_file else None

    def open_target(self, text: str, *, baud: int, permissions: Permissions | None,
                    inputs_control: str | None = None, dialect_file: str | None = None,
                    **_: Any) -> tuple[Target, str | None]:
        from conform.families.gve.conformance.safety import Guard
        from conform.families.gve.conformance.target import open_target

        guard = Guard(permissions.allow_motion, permissions.max_steps, permissions.allow_eeprom)
        target, implied = open_target(text, self.load_tables(), baud=baud, guard=guard,
                                      dialect=self._dialect(dialect_file))
        if inputs_control and not target.emulated:
            target.inputs = inputs_control  # type: ignore[attr-defined]
        return target, implied

    def identify(self, target: Target) -> tuple[str, str]:
        from conform.families.gve.conformance.target import identify

        return identify(target, self.load_tables())

    def plan_checks(self, variant: str, *, permissions: Permissions, profile: str = "quick",
                    patterns: Sequence[str] = (), machine: bool = True, **_: Any) -> Sequence[Check]:
        from conform.families.gve.conformance.safety import Guard
        from conform.families.gve.conformance.suite import suite

        guard = Guard(permissions.allow_motion, permissions.max_steps, permissions.allow_eeprom)
        return suite(self.load_tables(), variant, patterns=patterns, guard=guard,
                     machine=machine, profile=profile)

    def permission_notes(self, permissions: Permissions) -> list[str]:
        # EEPROM checks say their own reason when SKIPPED (conformance/safety.py)
        return [] if permissions.allow_motion else ["motion-bearing checks SKIPPED (no --allow-motion)"]

    def mutant_count(self, variants: Sequence[str]) -> int:
        from conform.families.gve.conformance.mutants import mutant_targets

        return len(list(mutant_targets(variants)))

    def run_mutants(self, variants: Sequence[str], *, profile: str = "quick", seed: int = 0,
                    progress: Callable[[str], None] | None = None) -> list[dict[str, object]]:
        from conform.families.gve.conformance.suite import run_mutants

        report, _ = run_mutants(self.load_tables(), variants, profile=profile, seed=seed,
                                progress=progress)
        return report

    def live_decoder(self, variant: str, *, baud: int | None = None) -> Decoder | None:
        from conform.families.gve.decode import make_decoder

        return make_decoder(variant, baud=baud)

    def host_lines(self) -> HostLines | None:
        from conform.families.gve.decode import PacketLines

        return PacketLines()

    pytest_plugin = "conform.families.gve.conformance.pytest_plugin"

    # a fleet summary's GVE columns: vectors the unit accepted, hazards (findings of that
    # severity) and the replayed queue's starvations and standstill (analysis/output.py)
    latency_measure = "round trip"   # fleet_row()'s latency percentiles
    fleet_columns = (
        FleetColumn("vectors_accepted", "vectors accepted", total=True, rate="vectors_per_s",
                    rate_label="vectors/s", machines=False, sessions=False),
        FleetColumn("hazards", "hazards", total=True, flag=True, summary=True),
        FleetColumn("starvations", "starvations", total=True, summary=True),
        FleetColumn("starved_s", "starved s", ".3f", total=True,
                    note="starved s: time the replayed queue stood empty while the job had "
                         "vectors still to come (a session report's starvations, summed per "
                         "machine)"),
        FleetColumn("standstill_s", "standstill s", ".3f", total=True,
                    note="standstill s: from the queue running empty to the next vector's "
                         "start (the starved time plus the braking to rest and the restart)"),
    )

    def characterize(self, target: str, output: str, variant: str | None, **options: Any
                     ) -> None:
        from conform.families.gve.cli import characterize

        characterize(target, output, variant, **options)

    def show_spec(self, variant: str, command: str | None, *, console: Console,
                  as_json: bool = False) -> None:
        from conform.families.gve.cli import show_spec

        show_spec(variant, command, console=console, as_json=as_json)

    @property
    def default_variant(self) -> str:
        return "gve64-v19"

    def variant_table(self, pretty: bool = False
                      ) -> tuple[str, Sequence[str], Sequence[Sequence[object]]]:
        from conform.families.gve.cli import variant_table

        return variant_table(pretty)

    def diff_variants(self, a: str, b: str) -> tuple[str, Sequence[str], Sequence[Sequence[object]]]:
        from conform.families.gve.cli import diff_table

        return diff_table(a, b)

    def open_questions(self) -> tuple[str, Sequence[str], Sequence[Sequence[object]]] | None:
        from conform.families.gve.cli import questions_table

        return questions_table()

    def tables_summary(self, root: str | None = None) -> str:
        from conform.families.gve.cli import tables_summary

        return tables_summary(root)

    def commands(self) -> Sequence[click.Command]:
        from conform.families.gve.cli import commands

        return commands()

    def diff_profiles(self, a: str, b: str) -> tuple[list[str], list[tuple[str, object, object]], str]:
        from conform.families.gve.conformance.profile_command import diff

        return diff(a, b)

    def send_job(self, job: str, target: str, **options: Any) -> None:
        """``conform send``: the reference sender (sender/command.py)."""
        from conform.families.gve.sender.command import send_job

        send_job(job, target, **options)

    def command_options(self, command: str) -> Sequence[click.Option]:
        from conform.families.gve.cli import command_options

        return command_options(command)

    probe_rank = 200   # '!' opens every GVE line; other protocols may act on it at once
    probe_disturbs_others = True

    def probe(self, device: str, *, baud: int, timeout: float) -> ProbeAnswer:
        from conform.families.gve.conformance.portprobe import probe

        return probe(device, baud=baud, timeout=timeout)

    def mutants(self) -> Sequence[str]:
        from conform.families.gve.conformance.mutants import MUTANTS

        return list(MUTANTS)

    @property
    def check_sender(self) -> SenderShapes[Any, Any, Any]:
        """check-sender's GVE scenarios, rules and hooks (sendercheck/family.py)."""
        from conform.families.gve.sendercheck.family import GVE

        return GVE

    def detect(self, host: bytes, unit: bytes, metadata: dict[str, Any]) -> Detection:
        lines = host.count(b"\r") or 1
        hits = len(_HOST_LINE.findall(host[:65536]))
        answers = len(_ANSWER.findall(unit[:65536]))
        if hits == 0:
            if answers >= 3 and not host.strip():
                return Detection(self.name, 0.5, f"{answers} GVE-shaped answers, no host bytes")
            return Detection(self.name, 0.0, "no '!<address><command>' lines from the host")
        score = min(1.0, hits / min(lines, 200) * 0.8 + (0.2 if answers else 0.0))
        return Detection(self.name, score, f"{hits} GVE command lines from the host")

    def serve(self, variant: str, **options: Any) -> None:
        from conform.families.gve.serve import serve

        serve(variant, **options)

    def analyze(self, path: str, **options: Any) -> AnalysisResult:
        from conform.families.gve.analysis import analyze

        return analyze(path, **options)

    def diagnosis_facts(self, raw: RawCapture, path: str, *, variant: str | None = None,
                        analysis: AnalysisResult | None = None) -> Facts | None:
        from conform.families.gve.diagnosis.facts import analysis_facts, facts

        if analysis is not None:
            return analysis_facts(analysis, path)
        return facts(raw, path, variant=variant)

    def reception(self, raw: RawCapture, *, variant: str | None = None) -> list[ParsedLine] | None:
        """Line assembly, the A13 watchdog, checksum mode and the `>` echoes
        (diagnosis/reception.py)."""
        from conform.families.gve.diagnosis.reception import reception

        return reception(raw, variant=variant)

    def live_monitor(self, variant: str | None) -> LiveMonitor | None:
        from conform.families.gve.diagnosis.live import live_monitor

        return live_monitor(variant)

    def resume_state(self, raw: RawCapture, facts: Facts, *, variant: str | None = None
                     ) -> ResumePoint | None:
        """From the queue replay and position read-backs (diagnosis/resume.py)."""
        from conform.families.gve.diagnosis.resume import resume_state

        return resume_state(facts.family_data, facts)


FAMILY = GveFamily()
