"""Protocol families: what is specific to one firmware family, behind one small interface.

The engine (spec tooling, emulator adapter, conformance results and reports, capture,
analysis, CLI) is shared; a family contributes its tables, a reference unit, its conformance
checks graded in the engine's runner, its emulator and control commands, a live decoder for
captures, check-sender's scenarios, a detector for its traffic and its analysis. Each family is
one package (``conform.families.<name>``, its tables in the top-level ``specs/<name>/``) registered in
the ``conform.families`` entry point group. The engine reaches a family only through this
registry (tests/test_family_boundary.py). See docs/architecture.md and
docs/writing-a-family.md.

    family_for_variant(variant).make_unit(variant, t0=0.0)
    detect_family(host_bytes, unit_bytes, metadata)   # -> Detection(name, score, why)
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from importlib.resources import files
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from conform.errors import UserError

if TYPE_CHECKING:  # the shapes of the hooks below; imported where they are used
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
    from conform.jsondoc import JsonObject
    from conform.sendercheck.family import Family as SenderShapes


@dataclass(frozen=True)
class VariantInfo:
    """One row of ``conform spec list`` for any family."""

    id: str
    family: str
    title: str
    firmware: str
    axes: str
    buffer: str
    notes: str = ""


@dataclass(frozen=True)
class Detection:
    """How much a family recognises a stretch of traffic (0: not at all, 1: certainly)."""

    family: str
    score: float
    why: str


@dataclass(frozen=True)
class FleetColumn:
    """A column a family adds to a fleet summary (``conform analyze`` of many captures): its
    analyses' ``fleet_row()`` give the value under ``key``. ``total``: summed per machine and
    over the fleet; ``rate``: a per-second column, this total over the duration, under that
    key; ``machines`` / ``sessions``: shown in that table; ``flag``: a session or machine
    with a non-zero value is marked; ``summary``: its total is said in the command's lines;
    ``spec``: number format; ``note``: what it means, said under the report's tables."""

    key: str
    label: str
    spec: str = ""
    total: bool = False
    rate: str | None = None
    rate_label: str = ""
    machines: bool = True
    sessions: bool = True
    flag: bool = False
    summary: bool = False
    note: str = ""


class AnalysisResult(Protocol):
    """What ``conform analyze`` asks of any family's analysis (``Family.analyze``)."""

    def summary_lines(self) -> list[str]:
        """What ``conform analyze`` prints: the session in a line, findings and notes."""

    def write_report(self, directory: str) -> dict[str, Path]:
        """``index.html``, ``summary.md`` and ``findings.json`` in ``directory`` (built on
        ``conform.analysis.report``'s shared pieces); returns their paths (``html`` ...)."""

    def write_tables(self, directory: str) -> dict[str, Path]:
        """Its tables as Parquet files in ``directory``; returns their paths."""

    def fleet_row(self) -> dict[str, object]:
        """Its row of a fleet summary: the engine's columns (``duration_s``, ``exchanges``,
        ``exchanges_per_s``, ``findings``, ``rtt_p50_ms``...) and the family's
        (``Family.fleet_columns``)."""


def _whole_line(line: str) -> str:
    return line


def _every_line(line: str) -> bool:
    return True


class Family:
    """What a protocol family provides to the engine, with a default for every optional ability
    (docs/architecture.md, docs/writing-a-family.md).

    A family subclasses this, sets ``name`` and implements at least ``load_tables``,
    ``variants``, ``make_unit``, ``detect`` and the abilities it has (a run, an emulator, an
    analyser, check-sender); what it leaves at the default answers with a one-line
    ``UserError`` naming the family and the missing ability, or with "nothing" where nothing is
    a fine answer (no mutants, no live decoder, no extra options). The engine never branches
    on a family's name: what differs between families is asked of them here.
    """

    name: str = ""
    title: str = ""
    """What the family covers, for the top-level help (``conform --help``)."""

    default_rank: int = 100
    """The family with the lowest rank serves commands given no variant (its
    ``default_variant``); ``$CONFORM_VARIANT`` overrides (see :func:`default_variant`)."""

    pytest_plugin: str | None = None
    """The module of this family's pytest plugin (``pytest --conform-target``), or None; the
    engine's ``pytest11`` entry point loads it by name, so pytest needs no family import."""

    needs_travel_bound: bool = False
    """``--allow-motion`` on a real unit needs ``--max-steps`` (the family's checks size
    their moves by it)."""

    table_files: tuple[str, ...] = ()
    """The names of its table files (without ``.toml``): how ``spec check --specs DIR`` tells
    whose tables a folder holds."""

    characterize_about: str = ""
    """What ``conform characterize`` asks of this family's units, in a sentence or two for its
    help (what is probed, and whether it moves or writes anything); empty: not listed."""

    @property
    def check_sender(self) -> SenderShapes[Any, Any, Any] | None:
        """check-sender's scenarios, rules and hooks (``conform.sendercheck.family.Family``),
        run by the engine's supervisor (conform.sendercheck); None: this family judges no
        senders. A family may override it with a property or a class attribute."""
        return None

    # -- tables ---------------------------------------------------------------------------
    def load_tables(self, root: str | None = None) -> object:
        """Its tables, validated (one-line ``UserError`` on a bad row); their shape is the
        family's own (the engine only asks that they load)."""
        raise self.lacks("tables")

    def variants(self) -> Sequence[VariantInfo]:
        """The variants this family serves."""
        raise self.lacks("variants")

    @property
    def default_variant(self) -> str:
        """The variant a command addresses when none is named: the first in the tables."""
        return self.variants()[0].id

    def variant_table(self, pretty: bool = False
                      ) -> tuple[str, Sequence[str], Sequence[Sequence[object]]]:
        """``conform spec list``'s table of this family: (title, columns, rows)."""
        return (f"{self.name} variants", ["variant", "title", "firmware", "axes", "buffers", "notes"],
                [[v.id, v.title, v.firmware, v.axes, v.buffer, v.notes] for v in self.variants()])

    def show_spec(self, variant: str, command: str | None, *, console: Console,
                  as_json: bool = False) -> None:
        """``conform spec show``: a variant's commands (or one) from its tables."""
        raise self.lacks("`spec show`")

    def diff_variants(self, a: str, b: str) -> tuple[str, Sequence[str], Sequence[Sequence[object]]]:
        """``conform spec diff A B``: (title, columns, rows) of what differs from A to B."""
        raise self.lacks("`spec diff`")

    def open_questions(self) -> tuple[str, Sequence[str], Sequence[Sequence[object]]] | None:
        """``conform spec questions``: (title, columns, rows) of the choices its sources leave
        open and the default assumed, or None when it has none."""
        return None

    def tables_summary(self, root: str | None = None) -> str:
        """``conform spec check``: the one ``ok: ...`` line of its validated tables."""
        self.load_tables(root)
        return f"ok: {self.name}: {len(self.variants())} variants"

    # -- the reference unit ------------------------------------------------------------------
    def make_unit(self, variant: str, *, t0: float = 0.0, **options: Any) -> SansIOUnit:
        """A sans-I/O reference unit: ``receive(bytes, t)``, ``poll(t)``, ``next_deadline()``,
        ``now`` (conform.emulator.serve.SansIOUnit). ``options``: the family's own (a mutant's
        name, a dialect, a profile)."""
        raise self.lacks("a reference unit")

    def judge_mask(self, variant: str) -> Callable[[str], str]:
        """What ``conform emulate judge`` compares of one answer line: the line with what
        differs from run to run of the same firmware (temperatures, build dates) masked.
        The default compares lines whole."""
        return _whole_line

    line_ending: str = "\n"
    """How the unit ends its answer lines. A text transcript cannot hold a CR, so ``conform
    emulate judge`` gives each of its unit lines this ending before comparing."""

    def judge_answers(self, variant: str) -> Callable[[str], bool]:
        """Which unit lines (without their ending) close the answer to one host line: what an
        ok-paced sender waits for before it writes its next line. ``conform emulate judge``
        paces a recording's host writes by them. The default: every line does."""
        return _every_line

    def judge_unit(self, variant: str) -> SansIOUnit:
        """The reference unit ``conform emulate judge`` plays a recording into: by default
        ``make_unit(variant)``; a family whose recordings come from firmware in a stated
        setting (a simulator with no switches wired, say) gives its unit that setting."""
        return self.make_unit(variant)

    def judge_follow(self, variant: str) -> Callable[[Any, str], None] | None:
        """None (the default), or a function the judge calls with the reference unit and each
        recorded answer line (without its ending), in order, before it plays the host write
        the line answered: the family may then put the reference where the recorded unit was
        after an artefact it states (a place reached by a simulator's own timing), so that
        what follows is judged from the same place. Everything else stays judged."""
        return None

    def judge_near(self, variant: str) -> Callable[[str, str], bool] | None:
        """Two answer lines (after ``judge_mask``) that differ but are the same within what
        the family states may differ between two runs (e.g. positions reported while the
        machine moves, within the motion model's tolerance); None (the default): lines are
        the same only when equal."""
        return None

    def mutants(self) -> Sequence[str]:
        """Names of its deviant units (``emu:VARIANT:MUTANT``); empty when it has none."""
        return ()

    def serve(self, variant: str, **options: Any) -> None:
        """Serve the reference unit on a pty or TCP until stopped (``conform emulate``)."""
        raise self.lacks("an emulator")

    # -- conformance: what ``conform run``'s loop (conform.conformance.plan) asks -------------
    def open_target(self, text: str, *, baud: int, permissions: Permissions | None,
                    inputs_control: str | None = None, **family_values: Any
                    ) -> tuple[Target, str | None]:
        """Open ``emu:VARIANT[:MUTANT]`` or a port; (the target, the variant its name implies).
        By default an emulator is this family's unit on the engine's virtual clock
        (``make_unit(variant, mutant=NAME)`` for a mutant) and a port is a plain link."""
        from conform.conformance.target import EmuTarget, open_link, parse_target

        kind, what, mutant = parse_target(text)
        if kind != "emu":
            return open_link(text, baud=baud), None
        vid = what or self.default_variant
        if mutant is not None and mutant not in self.mutants():
            known = ", ".join(self.mutants()) or "none"
            raise UserError(f"target {text!r}: {self.name} has no mutant {mutant!r} (known: {known})")
        return EmuTarget(lambda: self.make_unit(vid, mutant=mutant) if mutant else self.make_unit(vid),
                         text if what else f"emu:{vid}",
                         baud=baud), vid

    def identify(self, target: Target) -> tuple[str, str]:
        """Ask an open unit which variant it is; (variant, how it was decided)."""
        return self.default_variant, f"assumed {self.default_variant} ({self.name} units are not asked)"

    def plan_checks(self, variant: str, *, permissions: Permissions, profile: str = "quick",
                    patterns: Sequence[str] = (), machine: bool = True, **family_values: Any
                    ) -> Sequence[Check]:
        """The checks of ``variant`` for a run (each with ``id``, ``level``, ``clause``,
        ``title``), filtered by the globs ``patterns``; ``machine``: with the random
        sequences, where the family has them."""
        raise self.lacks("conformance checks")

    def runner(self, target: Target, variant: str, *, options: RunOptions | None = None,
               permissions: Permissions | None = None, **family_values: Any) -> Runner[Any]:
        """A ``conform.conformance.runner.Runner`` that grades this family's checks on
        ``target``: the engine's loop (ETA, link-loss abort, Ctrl-C, results) calls back for
        grading a check, keeping the unit in a check's starting state, halting the unit
        (retried until acknowledged) and estimating a check's duration. Its type parameter is
        the family's own check type (``Runner[ItsCheck]``), hence ``Any`` here."""
        raise self.lacks("conformance checks")

    def permission_notes(self, permissions: Permissions) -> list[str]:
        """What a run on a real unit leaves out for want of an opt-in (the report says it)."""
        notes = []
        if not permissions.allow_motion:
            notes.append("motion-bearing checks SKIPPED (no --allow-motion)")
        if not permissions.allow_eeprom:
            notes.append("setting writes SKIPPED (no --allow-eeprom)")
        return notes

    def mutant_count(self, variants: Sequence[str]) -> int:
        return len(variants) * len(self.mutants())

    def run_mutants(self, variants: Sequence[str], *, profile: str = "quick", seed: int = 0,
                    progress: Callable[[str], None] | None = None) -> list[dict[str, object]]:
        """Run the checks against every deviant unit: which checks caught each (FAIL)."""
        import time

        from conform.conformance.plan import Permissions
        from conform.conformance.results import Grade
        from conform.conformance.runner import RunAborted, RunOptions

        report: list[dict[str, object]] = []
        perms = Permissions.of(True, True, None, True)
        for vid in variants:
            for name in self.mutants():
                t0 = time.perf_counter()
                target, _ = self.open_target(f"emu:{vid}:{name}", baud=115200, permissions=perms)
                checks = self.plan_checks(vid, permissions=perms, profile=profile, machine=False)
                runner = self.runner(target, vid, options=RunOptions(profile=profile, seed=seed),
                                     permissions=perms)
                try:
                    run = runner.run(checks)
                except RunAborted as exc:
                    run = exc.run
                caught_by = [c.id for c in run.checks if c.grade is Grade.FAIL]
                report.append({"name": name, "variant": vid, "fault": self.mutant_fault(name),
                               "catches": [], "caught_by": caught_by, "expected_hit": [],
                               "killed": bool(caught_by),
                               "seconds": round(time.perf_counter() - t0, 3)})
                if progress is not None:
                    progress(f"mutant {name} on {vid}: "
                             f"{f'killed by {len(caught_by)} checks' if caught_by else 'SURVIVED'}")
        return report

    def mutant_fault(self, name: str) -> str:
        """What the deviant unit ``name`` does wrong, in a few words."""
        return name

    def characterize_probes(self) -> ProbeHooks | None:
        """For the default ``characterize``: (probe(target, variant, out) appending
        ``conform.conformance.observed.Observation``s to ``out``, stop(target) halting the unit,
        the item names probed in order); None when the family has no probes."""
        return None

    def characterize(self, target: str, output: str, variant: str | None, *, baud: int = 115200,
                     echo: Callable[[str], object] = print, **options: Any) -> None:
        """``conform characterize``: probe what the unit does where builds or the source leave
        a choice and write the profile. The default runs ``characterize_probes``."""
        hooks = self.characterize_probes()
        if hooks is None:
            raise self.lacks("`characterize`")
        from conform.conformance.observed import characterize_target

        probe, stop, items = hooks
        characterize_target(self, target, output, variant, baud=baud, probe=probe, stop=stop,
                            items=items, echo=echo,
                            title=f"what this {self.name} build does, probed by conform "
                                  "characterize")

    def diff_profiles(self, a: str, b: str) -> tuple[list[str], list[tuple[str, object, object]], str]:
        """``conform profile diff`` of two profiles of a shape the engine does not read (the
        engine compares ``[observed]`` profiles itself): (notes, rows (item, a, b) that differ,
        the line when none does)."""
        raise self.lacks("profiles of this shape")

    probe_rank: int = 100
    """``ports --probe`` asks the families in this order: a family whose question could
    disturb another family's unit (a byte another protocol acts on at once) asks late."""

    probe_disturbs_others: bool = False
    """True when this family's question is a byte another protocol acts on at once: it is
    asked only after every other family has been given the longer time to answer."""

    def probe(self, device: str, *, baud: int, timeout: float) -> ProbeAnswer:
        """``conform ports --probe``: ask the port something harmless to every family's units
        (nothing that moves, holds or changes a setting) and say whether this family's unit
        answered. The default: this family has no probe."""
        return ProbeAnswer(None, None, f"{self.name}: no probe")

    # -- the reference sender: ``conform send`` ----------------------------------------------
    def send_job(self, job: str, target: str, *, variant: str | None, baud: int,
                 allow_motion: bool, record: str | None, timeout: float | None, quiet: bool,
                 **family_values: Any) -> None:
        """``conform send JOB --target T``: stream the job file to the unit with this family's
        reference sender and print what happened (``UserError`` with exit 1 for a failed or
        incomplete send). ``variant``: named by the user or found by the probe (None: the
        family decides); ``allow_motion``: nothing that moves goes to a non-emulated unit
        without it; ``record``: an MCAP capture of the session (already checked free, or
        ``--force`` given); ``timeout``: the answer timeout in seconds (None: the family's);
        ``family_values``: this family's own ``command_options("send")``. An interruption
        (Ctrl-C, SIGTERM, SIGHUP: a ``KeyboardInterrupt``) halts the unit before it ends the
        command."""
        raise self.lacks("reference sender (`conform send`)")

    # -- capture and analysis ------------------------------------------------------------------
    def detect(self, host: bytes, unit: bytes, metadata: JsonObject) -> Detection:
        """Does this traffic look like this family's?"""
        return Detection(self.name, 0.0, f"{self.name} does not detect traffic")

    def live_decoder(self, variant: str, *, baud: int | None = None) -> Decoder | None:
        """A frame decoder for the capture recorder (``conform.capture.session.Decoder``), or
        None: the capture then holds the raw bytes only (decoded when analysed). Its ``fields``
        (``conform.capture.schemas.CaptureFields``) declare what its frames and exchanges
        record besides the engine's neutral fields."""
        return None

    def host_lines(self) -> HostLines | None:
        """The sniffer's count of host lines owed an answer (a
        ``conform.capture.merge.HostLines``), or None: every line owes one answer."""
        return None

    def analyze(self, path: str, **options: Any) -> AnalysisResult:
        """Analyse a capture of this family's traffic: what ``conform analyze`` prints and
        writes, and its row in a fleet summary (conform.families.capture_hook,
        conform.analysis.fleet)."""
        raise self.lacks("capture analysis")

    fleet_columns: Sequence[FleetColumn] = ()
    """The columns its analyses add to a fleet summary (``conform.analysis.fleet``)."""

    latency_measure: str = "command to answer"
    """What its ``fleet_row()``'s latency percentiles (``rtt_p50_ms`` ...) measure, in a
    fleet report's words (``round trip``, ``line to ok``): sessions whose families measure
    differently are never put in one latency column (``conform.analysis.fleet``)."""

    # -- the diagnosis (conform.diagnosis): optional; a family without them is diagnosed as
    # -- "not available" (the defaults below), the engine reaching them through getattr

    def diagnosis_facts(self, raw: RawCapture, path: str, *, variant: str | None = None,
                        analysis: AnalysisResult | None = None) -> Facts | None:
        """``conform diagnose``: a capture already read (``conform.analysis.rawread``) as
        neutral ``conform.diagnosis.facts.Facts`` — lines sent and answered, bytes in flight
        against the receive buffer, the unit's alarms, errors, noise, starvation, holds —
        or None when this family has no diagnosis (the default). ``analysis``: this family's
        own analysis of the capture when the caller has it already (``conform analyze``)."""
        return None

    def reception(self, raw: RawCapture, *, variant: str | None = None) -> list[ParsedLine] | None:
        """The host's lines as the unit would have read them (its receive buffer, line
        assembly, length limits, checksums): a list of ``conform.diagnosis.facts.ParsedLine``
        for every line not read intact, or None when it has no model (the default)."""
        return None

    def live_monitor(self, variant: str | None) -> LiveMonitor | None:
        """``conform proxy --live``: an object with ``feed(direction, data, t)`` and a
        ``state`` (``conform.diagnosis.live.LiveState``) kept current from the traffic, cheap
        enough for the recording's pace; None (the default): the view shows the bytes only."""
        return None

    def resume_state(self, raw: RawCapture, facts: Facts, *, variant: str | None = None
                     ) -> ResumePoint | None:
        """Where a stopped job can resume: a ``conform.diagnosis.facts.ResumePoint`` (last line
        executed, last acknowledged, the uncertain ones, the modal preamble), or None (the
        default)."""
        return None

    # -- the command line ------------------------------------------------------------------------
    def commands(self) -> Sequence[click.Command]:
        """Click commands this family adds to ``conform`` (e.g. its reference sender)."""
        return ()

    def command_options(self, command: str) -> Sequence[click.Option]:
        """Click options this family adds to the engine's ``command`` (``run``, ``emulate
        serve``, ...); their values reach this family's hook for that command and are refused
        when the command addresses another family's unit."""
        return ()

    # -- helpers ------------------------------------------------------------------------------
    def lacks(self, what: str) -> UserError:
        """The one-line error for an ability this family does not have."""
        return UserError(f"the {self.name} family has no {what}")


@dataclass(frozen=True)
class ProbeAnswer:
    """What ``ports --probe`` learnt from one port for one family."""

    variant: str | None   # the unit's variant when this family's unit answered
    answer: str | None    # what it answered, as text
    how: str              # how the variant was decided, or why not


SPECS_ENV = "CONFORM_SPECS"


def table_folder(name: str, package: str) -> Path:
    """The folder of family ``name``'s tables: ``$CONFORM_SPECS/<name>/`` when that exists (a
    modified copy to try), else the tables shipped inside ``package`` (its ``tables/`` data
    folder, found through importlib.resources: a wheel carries the top-level ``specs/<name>/``
    there, setup.py), else, in a source checkout or an editable install, ``specs/<name>/`` beside
    the package's top-level folder."""
    env = os.environ.get(SPECS_ENV)
    if env:
        override = Path(env) / name
        if override.is_dir():
            return override
    return _shipped_tables(name, package)


@functools.cache
def _shipped_tables(name: str, package: str) -> Path:
    """Where the installed tables are: found once (a unit reads its tables many times a run)."""
    shipped = Path(str(files(package).joinpath("tables")))
    if shipped.is_dir():
        return shipped
    return Path(str(files(package.partition(".")[0]))).parent / "specs" / name


ENTRY_POINT_GROUP = "conform.families"
"""Families are found through this entry point group (``name = "package.module:FAMILY"``);
the built-in ones are registered the same way as a third party's (pyproject.toml)."""

VARIANT_ENV = "CONFORM_VARIANT"
"""A variant named here is what commands address when given none (else the default family's)."""

_loaded: dict[str, Family] = {}
_broken: set[str] = set()


@functools.cache
def _entry_points() -> dict[str, EntryPoint]:
    found: dict[str, EntryPoint] = {}
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        found.setdefault(ep.name, ep)
    return found


def family_names() -> list[str]:
    """The registered families: by rank (the default one first), then by name."""
    return [f.name for f in families()]


def family(name: str) -> Family:
    """The registered family called ``name``."""
    eps = _entry_points()
    if name not in eps:
        raise UserError(f"unknown protocol family {name!r} (known: {', '.join(eps) or 'none'})")
    if name not in _loaded:
        try:
            loaded = eps[name].load()
        except Exception as exc:  # a broken plugin is named, not a traceback
            raise UserError(f"protocol family {name!r} ({eps[name].value}) does not load: "
                            f"{type(exc).__name__}: {exc}") from None
        _loaded[name] = loaded
    return _loaded[name]


def families() -> list[Family]:
    """Every registered family that loads, the default one (lowest ``default_rank``) first.
    A registered family that does not load is said once on stderr and left out, so one broken
    plugin does not take every command down (asking for it by name gives the error)."""
    found = []
    for n in _entry_points():
        try:
            found.append(family(n))
        except UserError as exc:
            if n not in _broken:
                _broken.add(n)
                print(f"conform: {exc}; left out", file=sys.stderr)
    return sorted(found, key=lambda f: (f.default_rank, f.name))


def default_family() -> Family:
    """The family that serves commands given no variant (``$CONFORM_VARIANT``'s, else the
    lowest ``default_rank``)."""
    named = os.environ.get(VARIANT_ENV)
    if named:
        owner = _owner(named)
        if owner is None:
            raise UserError(f"${VARIANT_ENV}: {unknown_variant(named, '')}")
        return owner
    return families()[0]


def default_variant() -> str:
    """The variant commands address when given none."""
    return os.environ.get(VARIANT_ENV) or default_family().default_variant


def _owner(variant: str) -> Family | None:
    return next((f for f in families() if any(v.id == variant for v in f.variants())), None)


def identify_port(device: str, *, baud: int, timeout: float
                  ) -> tuple[Family | None, ProbeAnswer, list[str]]:
    """Which family's unit answers on ``device``: each family's harmless question in
    ``probe_rank`` order until one names its variant (``conform ports --probe``, ``conform
    send`` given no variant). Returns that family (None when none did), its answer (else the
    first answer heard) and what each family found. The harmless questions are asked first
    with ``timeout``, then every family's with three times as long: a unit on a loaded host (an
    emulator beside other work, a USB adapter's latency) may answer late, and a question that
    disturbs other units (``probe_disturbs_others``) must not reach it before it had that time."""
    tried: list[str] = []
    heard: str | None = None
    for wait, everyone in ((timeout, False), (3 * timeout, True)):
        for fam in sorted(families(), key=lambda f: f.probe_rank):
            if fam.probe_disturbs_others and not everyone:
                continue
            got = fam.probe(device, baud=baud, timeout=wait)
            if got.variant:
                return fam, got, tried
            heard = heard or got.answer
            tried.append(got.how)
    how = "; ".join(dict.fromkeys(tried)) or "no family can probe"
    return None, ProbeAnswer(None, heard, how), tried


def unit_on_port(device: str, *, baud: int, timeout: float = 0.5) -> tuple[Family, str]:
    """The family and variant of the unit on ``device``, found with ``identify_port``'s
    harmless questions (``conform run`` and ``characterize`` given no ``--variant``); a port
    that cannot be opened or where no unit answers is one ``UserError`` line, before any
    check or probe is sent."""
    from conform.link.ports import open_port

    open_port(device, baud).close()   # a port that cannot be opened says so in its own words
    found, answer, _ = identify_port(device, baud=baud, timeout=timeout)
    if found is None or answer.variant is None:
        heard = f" (it sent {answer.answer[:40]!r})" if answer.answer else ""
        raise UserError(f"{device}: no unit answered at {baud} Bd{heard}: is the unit on, "
                        "on this port and at this baud rate (--baud)? "
                        "`conform ports --probe` asks every port; --variant names the unit")
    return found, answer.variant


def family_of_tables(root: str | Path) -> Family:
    """Whose tables the folder ``root`` holds: the family most of whose table files are there
    (the default family when none is)."""
    present = {p.stem for p in Path(root).glob("*.toml")} if Path(root).is_dir() else set()
    ranked = sorted(families(), key=lambda f: -len(present & set(f.table_files)))
    best = ranked[0]
    return best if present & set(best.table_files) else default_family()


def family_for_variant(variant: str) -> Family:
    """The family serving ``variant``; the default family when nobody claims it (its tables
    then say what is wrong with the name)."""
    return _owner(variant) or default_family()


def unknown_variant(variant_id: str, family_name: str) -> str:
    """The one-line error for a variant ``family_name`` does not have: every family's variants,
    and whose it is when another family has it."""
    by_family: dict[str, list[str]] = {}
    for f in families():
        by_family[f.name] = [v.id for v in f.variants()]
    owner = next((n for n, ids in by_family.items() if variant_id in ids), None)
    known = "; ".join(f"{n}: {', '.join(ids)}" for n, ids in by_family.items())
    if owner is not None and owner != family_name:
        return (f"{variant_id!r} is a {owner} variant; this needs a {family_name} unit "
                f"(known: {known})")
    return f"unknown variant {variant_id!r} (known: {known})"


def detect_family(host: bytes, unit: bytes, metadata: dict[str, object] | None = None
                  ) -> Detection:
    """The family whose traffic this is: the capture's declared variant first, then the bytes.

    Returns family ``unknown`` when no family scores at least 0.5.
    """
    meta = metadata or {}
    declared = str(meta.get("variant", "") or "")
    if declared:
        owner = _owner(declared)
        if owner is not None:
            return Detection(owner.name, 1.0, f"the capture names variant {declared}")
    best = Detection("unknown", 0.0, "no family recognises the traffic")
    for f in families():
        d = f.detect(host, unit, meta)
        if d.score > best.score:
            best = d
    if best.score < 0.5:
        return Detection("unknown", best.score, best.why if best.score else
                         "no family recognises the traffic")
    return best


UNKNOWN_MIN_BYTES = 256   # less traffic than this stays with the default family's analyser


def divert(host: bytes, unit: bytes, metadata: dict[str, object], variant: str | None
           ) -> Detection | None:
    """Which family other than the default one should analyse this traffic (None: the default
    family's analyser, which also reads damaged or unrecognised captures).

    An explicit ``--variant`` or the capture's own variant decides; otherwise the bytes do.
    Traffic no family recognises is diverted as ``unknown`` only when there is enough of it
    and the default family sees none of its own lines in it, so damaged or tiny captures of
    the default family keep their findings.
    """
    home = default_family()
    named = variant or str(metadata.get("variant", "") or "")
    if named:
        fam = family_for_variant(named)
        return None if fam is home else Detection(fam.name, 1.0, f"variant {named}")
    d = detect_family(host, unit, metadata)
    if d.family == home.name:
        return None
    if d.family != "unknown":
        return d
    if len(host) + len(unit) >= UNKNOWN_MIN_BYTES and home.detect(host, unit, metadata).score == 0:
        return d
    return None
