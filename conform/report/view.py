"""What a conformance report shows, in the order a reader needs it, independent of the format.

The HTML, Markdown and terminal renderings all take their content from here: the headline (and
why a run is incomplete), what was not verified and how to enable it, the failures grouped by
manual section with a replay command each, and the subjects × variants matrix (one row per
command, whatever clause each variant's manual gives it).
"""

from __future__ import annotations

import re
import shlex
from collections import Counter, OrderedDict
from dataclasses import dataclass, field

from conform.conformance.results import GRADE_ORDER, INFO, MUST, CheckResult, Grade, RunResults

#: what a reader must look at, worst first
PROBLEMS = (Grade.FAIL, Grade.ERROR)

LEVELS = {
    MUST: "follows from what the manual states: a FAIL is a defect of the unit",
    INFO: "probes an open question (A1–A29) or random sequences: a FAIL counts (exit 1), but "
          "read the question before calling it a defect",
}
def levels(results: RunResults) -> dict[str, str]:
    """What MUST and INFO mean in this run's report: INFO names the open questions (their
    first and last id) of the families whose units were judged, where they have any
    (``Family.open_questions``); a family without any is not given another's."""
    from conform.families import family_for_variant

    named = []
    for fam in {family_for_variant(r.variant).name: family_for_variant(r.variant)
                for r in results.runs}.values():
        table = fam.open_questions()
        if table and table[2]:
            named.append(f"{table[2][0][0]}–{table[2][-1][0]}")
    if not named:
        return {MUST: LEVELS[MUST], INFO: LEVELS[INFO].replace(" (A1–A29)", "")}
    return {MUST: LEVELS[MUST], INFO: LEVELS[INFO].replace("A1–A29", ", ".join(named))}


GRADES = {
    "PASS": "as the tables and the reference model say",
    "FAIL": "differs from what the manual states",
    "ERROR": "the harness or the link failed",
    "DEVIATION": "differs on an open question (recorded, not a failure)",
    "SKIPPED": "not run (see Not verified)",
    "NOT-APPLICABLE": "the variant lacks it",
}


@dataclass
class SkipGroup:
    """SKIPPED checks that share one reason, and how a run would include them."""

    reason: str
    how: str
    checks: list[CheckResult] = field(default_factory=list)
    only: list[str] = field(default_factory=list)  # the targets, when not all of the run's

    @property
    def targets(self) -> list[str]:
        return sorted({c.target for c in self.checks})

    def sentence(self) -> str:
        """``"3 checks need EEPROM writes"``."""
        n = len(self.checks)
        return f"{n} check needs {self.reason}" if n == 1 else f"{n} checks need {self.reason}"


@dataclass
class Section:
    """The checks of one manual section (``GVE64 §13.5.3``)."""

    clause: str
    checks: list[CheckResult] = field(default_factory=list)

    @property
    def anchor(self) -> str:
        return "s-" + re.sub(r"[^A-Za-z0-9]+", "-", self.clause).strip("-")

    @property
    def commands(self) -> list[str]:
        """The commands its checks are about (the third part of the id), in first-seen order."""
        out: OrderedDict[str, None] = OrderedDict()
        for c in self.checks:
            parts = c.id.split("/")
            if len(parts) > 2:
                out.setdefault(parts[2], None)
        return list(out)

    def counts(self) -> Counter[str]:
        return Counter(c.grade.value for c in self.checks)


def section_of(clause: str) -> str:
    """The first clause a check cites: ``"GVE64 §13.5.2, GVE64 §14.1"`` → ``"GVE64 §13.5.2"``."""
    return clause.split(",", 1)[0].strip() or "(no clause)"


def junit_classname(c: CheckResult) -> str:
    """``gve64-v19.13.5.3``: the variant and the manual section, as JUnit's dotted class."""
    number = section_of(c.clause).split("§", 1)[-1].strip().replace(" ", "-")
    return f"{c.variant}.{number}" if c.variant else number


def _clause_key(clause: str) -> tuple:
    manual, _, number = clause.partition("§")
    nums = tuple(int(x) if x.isdigit() else 10**6 for x in re.split(r"[.\s]", number.strip())
                 if x)
    return (manual.strip(), nums, clause)


def by_section(checks: list[CheckResult]) -> list[Section]:
    """Checks grouped by manual section: manuals in the order the checks first cite them,
    sections in each manual's numeric order (§13.5.3 before §13.5.13)."""
    groups: dict[str, Section] = {}
    manuals: dict[str, int] = {}
    for c in checks:
        key = section_of(c.clause)
        groups.setdefault(key, Section(key)).checks.append(c)
        manuals.setdefault(_clause_key(key)[0], len(manuals))
    return sorted(groups.values(),
                  key=lambda s: (manuals[_clause_key(s.clause)[0]], _clause_key(s.clause)))


# the options of the run a replay must keep, or on a real unit the check only SKIPs (no
# --allow-motion), runs at another speed (--baud) or cannot drive the inputs it needs
REPLAY_FLAGS = ("--allow-motion", "--allow-eeprom")
REPLAY_VALUES = ("--max-steps", "--inputs-control", "--baud", "--dialect")


def replay_command(c: CheckResult, command: str = "") -> str:
    """The command that re-runs one check on the same target (with its seed if it has one),
    with the options of the run (``command``, as typed) that the check depends on."""
    token = c.replay or c.id
    if c.seed is not None and "@" not in token:
        token = f"{token}@{c.seed}"
    target = c.target or f"emu:{c.variant}"
    return (f"conform run --target {shlex.quote(target)} --variant {shlex.quote(c.variant)} "
            f"--replay {shlex.quote(token)}" + "".join(f" {shlex.quote(a)}"
                                                       for a in _kept_options(command)))


def _kept_options(command: str) -> list[str]:
    """The :data:`REPLAY_FLAGS` and :data:`REPLAY_VALUES` given in ``command``."""
    try:
        argv = shlex.split(command)
    except ValueError:
        return []
    kept: list[str] = []
    for i, arg in enumerate(argv):
        name, eq, _ = arg.partition("=")
        if arg in REPLAY_FLAGS:
            kept.append(arg)
        elif name in REPLAY_VALUES and eq:
            kept.append(arg)
        elif arg in REPLAY_VALUES and i + 1 < len(argv):
            kept += [arg, argv[i + 1]]
    return kept


_HOW = (
    # (words in the reason, what the checks need, how to include them when the reason does not
    # say it; the runner's reasons end in "enable with OPTIONS)")
    (("inputs",), "driven inputs (only an emulator can drive them)",
     "--target emu:VARIANT, or --inputs-control with `conform emulate serve` behind the link"),
    (("max-steps", "envelope"), "moves longer than --max-steps allows", "a larger --max-steps"),
    (("eeprom",), "EEPROM writes", "--allow-eeprom"),
    (("motion", "actuator"), "motion (axes, outputs, spindle)", "--allow-motion --max-steps N"),
)
_ENABLE = re.compile(r"enable with (.+?)\)?$")


def _skip_group(detail: str) -> tuple[str, str]:
    """(what the checks need, how to include them) for one SKIPPED check's detail."""
    said = _ENABLE.search(detail)
    reason = detail.split(" (", 1)[0]
    found = [(name, how) for words, name, how in _HOW if any(w in reason.lower() for w in words)]
    if found:
        names = " and ".join(dict.fromkeys(name for name, _ in found))
        return names, said.group(1) if said else " ".join(dict.fromkeys(h for _, h in found))
    reason = re.sub(r"b'[^']*'|\d+", "…", reason).strip()
    return (reason or "(no reason given)"), said.group(1) if said else ""


def _largest_steps(hows: list[str]) -> str:
    """``--max-steps 4000`` of several: the largest, which enables them all."""
    numbers = [int(m.group(1)) for h in hows if (m := re.search(r"--max-steps (\d+)", h))]
    return f"--max-steps {max(numbers)}" if numbers else hows[0]


def not_verified(results: RunResults) -> list[SkipGroup]:
    """SKIPPED checks grouped by reason, the largest group first; a group names its targets
    when it does not hold for all of them."""
    groups: dict[str, SkipGroup] = {}
    hows: dict[str, list[str]] = {}
    for c in results.checks:
        if c.grade is Grade.SKIPPED:
            reason, how = _skip_group(c.detail)
            groups.setdefault(reason, SkipGroup(reason, how)).checks.append(c)
            hows.setdefault(reason, []).append(how)
    every = {r.target for r in results.runs}
    for g in groups.values():
        g.only = [] if set(g.targets) >= every else g.targets
        g.how = _largest_steps(hows[g.reason]) if "--max-steps " in g.how and \
            "--allow" not in g.how else g.how
    return sorted(groups.values(), key=lambda g: -len(g.checks))


@dataclass
class Headline:
    """The verdict of the whole run in one line, and whether (and why) it is incomplete."""

    verdict: str  # FAIL | ERROR | PASS | INCOMPLETE
    text: str
    incomplete: list[str]
    scope: str = ""   # what the verdict proves, when that is less than it seems


EMULATED_SCOPE = (
    "Every target was an emulator (emu:): this run checks the reference model against the "
    "tables it was built from — the checks and the model agree. It says nothing about a real "
    "unit; for that, run the same checks with --target on its serial port.")


def _emulated_scope(results: RunResults, failing: int) -> str:
    """What a run on emulators proves: with nothing failing, that the checks and the model
    agree; with FAILs, where an emulator was judged as another variant (its differences) or
    where the model and its tables disagree (a defect of conform) — never "they agree"."""
    if not failing:
        return EMULATED_SCOPE
    other = sorted({f"{r.target} judged as {r.variant}" for r in results.runs
                    if r.target != f"emu:{r.variant}"})
    why = (f"{', '.join(other)}: the FAILs are where the emulated variant differs from the one "
           "asked for (--variant), i.e. the variants' differences" if other else
           "the FAILs and ERRORs are where the reference model disagrees with the tables it "
           "was built from: a defect of conform itself, worth reporting")
    return (f"Every target was an emulator (emu:): {why}. It says nothing about a real unit; "
            "for that, run the same checks with --target on its serial port.")


def headline(results: RunResults) -> Headline:
    counts = Counter(c.grade.value for c in results.checks)
    total = sum(counts.values())
    shown = ", ".join(f"{counts[g.value]} {g.value}" for g in GRADE_ORDER if counts[g.value])
    targets = len(results.runs)
    where = f"{total} checks on {targets} target{'s' if targets != 1 else ''}"
    incomplete = [f"{r.target}: {r.aborted}" for r in results.runs if r.aborted]
    if incomplete:
        verdict = "INCOMPLETE"
    elif counts["FAIL"]:
        verdict = "FAIL"
    elif counts["ERROR"]:
        verdict = "ERROR"
    else:
        verdict = "PASS"
    scope = _emulated_scope(results, counts["FAIL"] + counts["ERROR"]) \
        if results.runs and all(r.emulated for r in results.runs) else ""
    if any(r.target.count(":") > 1 for r in results.runs):
        scope = ""   # emu:VARIANT:MUTANT, a deviant unit: the run is about the checks' power
    return Headline(verdict, f"{shown or 'no check run'} — {where}", incomplete, scope)


@dataclass
class Cell:
    """One subject on one target: grade counts, the worst grade (its colour) and the clause the
    target's variant gives it."""

    counts: Counter[str]
    worst: str | None
    clause: str = ""

    @property
    def cited(self) -> str:
        """The clause as the cell shows it: a manual's section (``GVE64 §13.5.2``) is short
        enough; a longer citation (source files and functions) is left to the row's
        footnote (``citations``), so the grades stay on the page."""
        return self.clause if len(self.clause) <= SHORT_CLAUSE else ""

    def text(self) -> str:
        if not self.counts:
            return "—"
        return " ".join(f"{n} {g}" for g in (x.value for x in GRADE_ORDER)
                        if (n := self.counts.get(g)))


SHORT_CLAUSE = 24
"""The longest clause a matrix cell shows beside its grades (characters)."""


def citations(rows: list[Row]) -> dict[str, int]:
    """The clauses too long for a matrix cell (``Cell.cited``), numbered from 1 in the order
    the rows first cite them: the cell carries the number, the list under the table the
    citation."""
    out: dict[str, int] = {}
    for row in rows:
        for cell in row.cells:
            if cell.clause and not cell.cited:
                out.setdefault(cell.clause, len(out) + 1)
    return out


def _worst(counts: Counter[str]) -> str | None:
    for g in GRADE_ORDER:
        if counts.get(g.value):
            return g.value
    return None


def column_name(run) -> str:  # noqa: ANN001 - a TargetRun
    return run.variant if run.target == f"emu:{run.variant}" else f"{run.target} ({run.variant})"


@dataclass
class Row:
    """One subject (a command, a setting: ``CheckResult.row``): its checks on every target and
    one cell per target."""

    subject: str
    checks: list[CheckResult] = field(default_factory=list)
    cells: list[Cell] = field(default_factory=list)

    @property
    def anchor(self) -> str:
        """``r-N_003caxis_003e``: unique per subject, whatever characters it holds."""
        return "r-" + "".join(ch if ch.isascii() and ch.isalnum() else f"_{ord(ch):04x}"
                              for ch in self.subject)


def subject_matrix(results: RunResults) -> tuple[list[str], list[Row]]:
    """Columns (one per target run) and one row per subject, so that one command lines up
    across variants whose manuals number it differently; rows in the order of the first
    manual's sections. Each cell holds the grades and that variant's own clause."""
    rows: dict[str, Row] = {}
    for section in by_section(results.checks):
        for c in section.checks:
            rows.setdefault(c.row, Row(c.row)).checks.append(c)
    for row in rows.values():
        for run in results.runs:
            mine = [c for c in row.checks if c.target == run.target and c.variant == run.variant]
            counts = Counter(c.grade.value for c in mine)
            clauses = dict.fromkeys(section_of(c.clause) for c in mine)
            row.cells.append(Cell(counts, _worst(counts), ", ".join(clauses)))
    return [column_name(r) for r in results.runs], list(rows.values())


def _run_index(results: RunResults) -> dict[tuple[str, str], int]:
    return {(r.target, r.variant): i for i, r in enumerate(results.runs)}


def problems(results: RunResults) -> list[Section]:
    """FAIL and ERROR checks by manual section: FAIL before ERROR, MUST before INFO, then in the
    order of the run's targets."""
    order = _run_index(results)
    chosen = [c for c in results.checks if c.grade in PROBLEMS]
    chosen.sort(key=lambda c: (PROBLEMS.index(c.grade), c.level != MUST,
                               order.get((c.target, c.variant), 0), c.id))
    return by_section(chosen)


@dataclass
class Cause:
    """FAILs with one root cause: the unit gave the same wrong answer code to many checks
    (``VL, VK, VN, XM answered 3 where 0 was expected``: commands this unit does not know, not
    thirty separate faults)."""

    actual: str
    expected: list[str] = field(default_factory=list)
    checks: list[CheckResult] = field(default_factory=list)

    @property
    def commands(self) -> list[str]:
        return Section("", self.checks).commands

    def shown(self, limit: int = 12) -> list[CheckResult]:
        """The checks the cause links to: the first of each command first, then the rest, at
        most ``limit`` (the others are listed with their sections below)."""
        firsts: dict[str, CheckResult] = {}
        for c in self.checks:
            parts = c.id.split("/")
            firsts.setdefault(parts[2] if len(parts) > 2 else c.id, c)
        rest = [c for c in self.checks if all(c is not f for f in firsts.values())]
        return [*firsts.values(), *rest][:limit]

    def sentence(self) -> str:
        n = len(self.checks)
        wanted = " or ".join(self.expected)
        shown = ", ".join(self.commands[:CAUSE_NAMES])
        if len(self.commands) > CAUSE_NAMES:
            shown += f" and {len(self.commands) - CAUSE_NAMES} more commands"
        return (f"{shown} answered {self.actual} where {wanted} was "
                f"expected: one cause, {n} checks")


CAUSE_NAMES = 8  # commands a cause names before "and N more" (the first screen stays readable)
CAUSE_MIN = 3   # this many FAILs with the same wrong answer code are shown as one cause


def answer_code(text: str) -> str:
    """The code of an exchange's answer: ``!0VL1000 → 3,5F`` → ``3``."""
    answer = str(text).rsplit("→", 1)[-1].strip()
    return answer.split(",", 1)[0].strip()


def causes(results: RunResults) -> list[Cause]:
    """FAILs grouped by the answer code the unit gave where another was expected, per target,
    largest first; only groups of :data:`CAUSE_MIN` or more."""
    groups: dict[tuple[str, str], Cause] = {}
    for c in results.checks:
        if c.grade is not Grade.FAIL or not c.actual:
            continue
        exp, act = answer_code(c.expected), answer_code(c.actual)
        if exp and act and exp != act:
            g = groups.setdefault((c.target, act), Cause(act))
            g.checks.append(c)
            if exp not in g.expected:
                g.expected.append(exp)
    return sorted((g for g in groups.values() if len(g.checks) >= CAUSE_MIN),
                  key=lambda g: -len(g.checks))


def differing(expected: str, actual: str) -> tuple[str, str, str, str]:
    """(common start, expected's middle, actual's middle, common end): what to highlight."""
    a, b = str(expected), str(actual)
    i = 0
    while i < min(len(a), len(b)) and a[i] == b[i]:
        i += 1
    j = 0
    while j < min(len(a), len(b)) - i and a[len(a) - 1 - j] == b[len(b) - 1 - j]:
        j += 1
    return a[:i], a[i:len(a) - j], b[i:len(b) - j], a[len(a) - j:]


def deviations(results: RunResults) -> list[Section]:
    return by_section([c for c in results.checks if c.grade is Grade.DEVIATION])


def log_lines(c: CheckResult, limit: int | None = None) -> list[tuple[str, str, str]]:
    """(time, direction, bytes as text) per chunk on the wire; the last ``limit`` if given."""
    entries = c.log if limit is None else c.log[-limit:]
    return [(f"{e.t:10.6f}", e.dir, repr(e.data)[2:-1]) for e in entries]
