"""Protocol families: what is specific to one firmware family, behind one small interface.

The engine (spec tooling, emulator adapter, conformance results and reports, capture,
analysis, CLI) is shared; a family contributes its tables, a reference unit, its conformance
checks graded in the engine's runner, its emulator and control commands, a live decoder for
captures, check-sender's scenarios, a detector for its traffic and its analysis. Each family is
one package, conform.families.gve and conform.families.grbl, with its tables in gve/spec/tables/ and
grbl/spec/tables/. The engine reaches a family only through this registry
(tests/test_family_boundary.py). See docs/architecture.md.

    family_for_variant("grbl-1.1f").make_unit("grbl-1.1f", t0=0.0)
    detect_family(host_bytes, unit_bytes, metadata)   # -> ("grbl", "why") or ("unknown", ...)
"""

from __future__ import annotations

import functools
import os
from collections.abc import Sequence
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from importlib.resources import files
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

from conform.errors import UserError


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


@runtime_checkable
class Family(Protocol):
    """What a protocol family provides to the engine (docs/architecture.md).

    The default family (``DEFAULT_FAMILY``) also gives ``variant_table(pretty)``: its own
    columns for the first table of ``conform spec list`` (title, columns, rows)."""

    name: str

    def variants(self) -> Sequence[VariantInfo]:
        """The variants this family serves."""

    def load_tables(self, root: str | None = None) -> Any:
        """Its tables, validated (one-line ``UserError`` on a bad row)."""

    def make_unit(self, variant: str, *, t0: float = 0.0, **options: Any) -> Any:
        """A sans-I/O reference unit: ``receive(bytes, t)``, ``poll(t)``, ``next_deadline()``,
        ``now``."""

    def run_conformance(self, target: Any, variant: str, **options: Any) -> Any:
        """Run its checks on an open target; a ``conform.conformance.results.TargetRun``."""

    def run_targets(self, targets: list[str], variant: str | None, **options: Any
                    ) -> tuple[list[Any], list[dict[str, Any]]] | None:
        """``conform run``: open each target (``emu:VARIANT`` or a port), run its checks in
        the engine's runner; (TargetRuns, mutant report), or None after ``list_only`` printed
        the checks. Options are the command's (``baud``, ``profile``, ``patterns``,
        ``allow_motion``, ``echo``, ``announce``...); a family ignores those it has no use for.
        The command writes the reports, the summary and the exit code."""

    def detect(self, host: bytes, unit: bytes, metadata: dict[str, Any]) -> Detection:
        """Does this traffic look like this family's?"""

    def analyze(self, path: str, **options: Any) -> Any:
        """Analyse a capture of this family's traffic. A family other than the default one
        returns a result with ``summary_lines()``, ``write_report(dir)``, ``write_tables(dir)``
        and ``fleet_row()``: what ``conform analyze`` prints and writes, and its row in a fleet
        summary (conform.families.capture_hook, conform.analysis.fleet)."""

    def serve(self, variant: str, **options: Any) -> None:
        """Serve the reference unit on a pty or TCP until stopped (``conform emulate``)."""

    def runner(self, target: Any, variant: str, **options: Any) -> Any:
        """A ``conform.conformance.runner.Runner`` for this family's checks on ``target``: the
        engine's loop (ETA, link-loss abort, Ctrl-C, results) calls back for what is the
        family's — grading a check, keeping the unit in a check's starting state, halting the
        unit (retried until acknowledged) and estimating a check's duration."""

    def live_decoder(self, variant: str, *, baud: int | None = None) -> Any:
        """A frame decoder for the capture recorder (``conform.capture.session.Decoder``) that
        turns this family's traffic into frames while it is recorded, or None: the capture
        then holds the raw bytes only (they are decoded when analysed)."""

    pytest_plugin: str | None
    """The module of this family's pytest plugin (``pytest --conform-target``), or None; the
    engine's ``pytest11`` entry point loads it by name, so pytest needs no family import."""

    check_sender: Any
    """check-sender's scenarios, rules and hooks for this family
    (``conform.sendercheck.family.Family``), or None when it judges senders its own way: then
    ``check_sender_cli(command, variant, scenarios, report_dir, timeout, job_file, as_json,
    echo=...)`` runs ``conform check-sender`` and returns the exit code."""

    def characterize(self, target: str, output: str, variant: str | None, **options: Any
                     ) -> None:
        """``conform characterize``: probe what the unit does where the source leaves a choice
        and write the profile (options: ``baud``, ``allow_motion``, ``max_steps``,
        ``allow_eeprom``, ``echo``)."""

    def show_spec(self, variant: str, command: str | None, *, console: Any,
                  as_json: bool = False) -> None:
        """``conform spec show``: a variant's commands (or one) from its tables."""

    def tables_summary(self, root: str | None = None) -> str:
        """``conform spec check``: the one ``ok: ...`` line of its validated tables."""

    def mutants(self) -> Sequence[str]:
        """Names of its deviant units (``emu:VARIANT:MUTANT``); empty when it has none."""

    # -- the diagnosis (conform.diagnosis): optional; a family without them is diagnosed as
    # -- "not available" (the defaults below), the engine reaching them through getattr

    def diagnosis_facts(self, raw: Any, path: str, *, variant: str | None = None,
                        analysis: Any = None) -> Any:
        """``conform diagnose``: a capture already read (``conform.analysis.rawread``) as
        neutral ``conform.diagnosis.facts.Facts`` — lines sent and answered, bytes in flight
        against the receive buffer, the unit's alarms, errors, noise, starvation, holds —
        or None when this family has no diagnosis (the default). ``analysis``: this family's
        own analysis of the capture when the caller has it already (``conform analyze``)."""
        return None

    def reception(self, raw: Any, *, variant: str | None = None) -> Any:
        """The host's lines as the unit would have read them (its receive buffer, line
        assembly, length limits, checksums): a list of ``conform.diagnosis.facts.ParsedLine``
        for every line not read intact, or None when it has no model (the default)."""
        return None

    def live_monitor(self, variant: str | None) -> Any:
        """``conform proxy --live``: an object with ``feed(direction, data, t)`` and a
        ``state`` (``conform.diagnosis.live.LiveState``) kept current from the traffic, cheap
        enough for the recording's pace; None (the default): the view shows the bytes only."""
        return None

    def resume_state(self, raw: Any, facts: Any, *, variant: str | None = None) -> Any:
        """Where a stopped job can resume: a ``conform.diagnosis.facts.ResumePoint`` (last line
        executed, last acknowledged, the uncertain ones, the modal preamble), or None (the
        default)."""
        return None


SPECS_ENV = "CONFORM_SPECS"


def table_folder(name: str, package: str) -> Path:
    """The folder of family ``name``'s tables: ``$CONFORM_SPECS/<name>/`` when that exists (a
    modified copy to try), else the tables shipped inside ``package`` (its ``tables/`` data
    folder, found through importlib.resources so a wheel install finds them too)."""
    env = os.environ.get(SPECS_ENV)
    if env:
        override = Path(env) / name
        if override.is_dir():
            return override
    return Path(str(files(package).joinpath("tables")))


ENTRY_POINT_GROUP = "conform.families"
"""Families are found through this entry point group (``name = "package.module:FAMILY"``);
the built-in ones are registered the same way as a third party's (pyproject.toml)."""

DEFAULT_FAMILY = "gve"   # serves a variant nobody claims; its table comes first in `spec list`
_loaded: dict[str, Family] = {}


@functools.cache
def _entry_points() -> dict[str, EntryPoint]:
    found: dict[str, EntryPoint] = {}
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        found.setdefault(ep.name, ep)
    # the default family first: its table leads `spec list` and it serves an unclaimed variant
    return dict(sorted(found.items(), key=lambda kv: kv[0] != DEFAULT_FAMILY))


def family_names() -> list[str]:
    """The registered families: the default one first, then by name."""
    return list(_entry_points())


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
    return [family(n) for n in family_names()]


def family_for_variant(variant: str) -> Family:
    """The family serving ``variant`` (GVE when nobody claims it, so GVE errors stay as they
    were)."""
    for f in families():
        if f.name != DEFAULT_FAMILY and any(v.id == variant for v in f.variants()):
            return f
    return family(DEFAULT_FAMILY)


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


def detect_family(host: bytes, unit: bytes, metadata: dict[str, Any] | None = None
                  ) -> Detection:
    """The family whose traffic this is: the capture's declared variant first, then the bytes.

    Returns family ``unknown`` when no family scores at least 0.5.
    """
    meta = metadata or {}
    declared = str(meta.get("variant", "") or "")
    if declared:
        f = family_for_variant(declared)
        if f.name != "gve" or any(v.id == declared for v in f.variants()):
            return Detection(f.name, 1.0, f"the capture names variant {declared}")
    best = Detection("unknown", 0.0, "no family recognises the traffic")
    for f in families():
        d = f.detect(host, unit, meta)
        if d.score > best.score:
            best = d
    if best.score < 0.5:
        return Detection("unknown", best.score, best.why if best.score else
                         "no family recognises the traffic")
    return best


UNKNOWN_MIN_BYTES = 256   # less traffic than this stays with the GVE analyser, as before


def divert(host: bytes, unit: bytes, metadata: dict[str, Any], variant: str | None
           ) -> Detection | None:
    """Which non-GVE family should analyse this traffic (None: the GVE analyser, as always).

    An explicit ``--variant`` or the capture's own variant decides; otherwise the bytes do.
    Traffic no family recognises is diverted as ``unknown`` only when there is enough of it
    and it holds no GVE command line at all, so damaged or tiny GVE captures keep their
    GVE findings.
    """
    named = variant or str(metadata.get("variant", "") or "")
    if named:
        fam = family_for_variant(named)
        return None if fam.name == "gve" else Detection(fam.name, 1.0, f"variant {named}")
    d = detect_family(host, unit, metadata)
    if d.family == "gve":
        return None
    if d.family != "unknown":
        return d
    if len(host) + len(unit) >= UNKNOWN_MIN_BYTES and family("gve").detect(host, unit, metadata).score == 0:
        return d
    return None
