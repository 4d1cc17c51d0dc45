"""The GVE family as a :class:`conform.families.Family`: tables (spec/), codec (protocol/),
reference unit (unit/), checks, grading and targets (conformance/, driven by the engine's
runner in conform.conformance),
reference sender (sender/), check-sender scenarios and rules (sendercheck/), the capture
analyser (analysis/, on the engine's capture reading, summaries, tables and reports in
conform.analysis)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

from conform.families import Detection, VariantInfo

# a GVE command line: '!', an address digit, a mnemonic (GVE64 §13.5); answers: a hex status
# code, maybe with comma-separated fields, ended by CR (GVE64 §13.7)
_HOST_LINE = re.compile(rb"![0-7][A-Z?$@>%*]")
_ANSWER = re.compile(rb"(?:^|\r)[0-9A-F](?:,[^\r]*)?\r")


class GveFamily:
    name = "gve"

    def load_tables(self, root: str | None = None) -> Any:
        from conform.families.gve.spec import load_spec

        return load_spec(root)

    def variants(self) -> Sequence[VariantInfo]:
        spec = self.load_tables()
        return [VariantInfo(v.id, self.name, v.title, v.firmware, "".join(v.axes),
                            f"queue {v.queue}", v.base or "") for v in spec.variants.values()]

    def make_unit(self, variant: str, *, t0: float = 0.0, **options: Any) -> Any:
        from conform.families.gve.unit.model import Unit

        spec = self.load_tables()
        dialect = options.pop("dialect", None) or spec.dialect()
        return Unit(spec.variant(variant), dialect, t0=t0, **options)

    def run_conformance(self, target: Any, variant: str, **options: Any) -> Any:
        from conform.conformance.runner import RunOptions
        from conform.families.gve.conformance.suite import run_one, suite

        spec = self.load_tables()
        checks = suite(spec, variant, patterns=options.get("patterns", ()),
                       profile=options.get("profile", "quick"))
        return run_one(spec, target, variant, checks,
                       options=RunOptions(profile=options.get("profile", "quick")))

    def runner(self, target: Any, variant: str, **options: Any) -> Any:
        """Grading against the reference unit, the state keeper, H, D, O0,FF
        (conformance/runner.py); options: ``options`` (RunOptions), ``dialect``, ``unit_cls``."""
        from conform.families.gve.conformance.runner import Runner

        return Runner(self.load_tables(), target, variant, **options)

    def run_targets(self, targets: list[str], variant: str | None, **options: Any) -> Any:
        from conform.families.gve.conformance.run import run_targets

        return run_targets(targets, variant, **options)

    def live_decoder(self, variant: str, *, baud: int | None = None) -> Any:
        from conform.families.gve.decode import make_decoder

        return make_decoder(variant, baud=baud)

    pytest_plugin = "conform.families.gve.conformance.pytest_plugin"

    def characterize(self, target: str, output: str, variant: str | None, **options: Any
                     ) -> None:
        from conform.families.gve.cli import characterize

        characterize(target, output, variant, **options)

    def show_spec(self, variant: str, command: str | None, *, console: Any,
                  as_json: bool = False) -> None:
        from conform.families.gve.cli import show_spec

        show_spec(variant, command, console=console, as_json=as_json)

    def variant_table(self, pretty: bool = False) -> Any:
        from conform.families.gve.cli import variant_table

        return variant_table(pretty)

    def tables_summary(self, root: str | None = None) -> str:
        from conform.families.gve.cli import tables_summary

        return tables_summary(root)

    def mutants(self) -> Sequence[str]:
        from conform.families.gve.conformance.mutants import MUTANTS

        return list(MUTANTS)

    @property
    def check_sender(self) -> Any:
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

    def analyze(self, path: str, **options: Any) -> Any:
        from conform.families.gve.analysis import analyze

        return analyze(path, **options)

    def diagnosis_facts(self, raw: Any, path: str, *, variant: str | None = None,
                        analysis: Any = None) -> Any:
        from conform.families.gve.diagnosis.facts import analysis_facts, facts

        if analysis is not None:
            return analysis_facts(analysis, path)
        return facts(raw, path, variant=variant)

    def reception(self, raw: Any, *, variant: str | None = None) -> Any:
        """Line assembly, the A13 watchdog, checksum mode and the `>` echoes
        (diagnosis/reception.py)."""
        from conform.families.gve.diagnosis.reception import reception

        return reception(raw, variant=variant)

    def live_monitor(self, variant: str | None) -> Any:
        from conform.families.gve.diagnosis.live import live_monitor

        return live_monitor(variant)

    def resume_state(self, raw: Any, facts: Any, *, variant: str | None = None) -> Any:
        """From the queue replay and position read-backs (diagnosis/resume.py)."""
        from conform.families.gve.diagnosis.resume import resume_state

        return resume_state(facts.family_data, facts)


FAMILY = GveFamily()
