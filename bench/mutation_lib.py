"""The mutation benchmark's parts (bench/bench_mutation.py): the mutation points of a family's
reference unit (cosmic-ray's operators), their stable ids, the triage file of equivalent
mutants, and the run of one mutant in its own interpreter.

A mutant is never written into the tree, and it reaches only the unit under test: the child
interpreter (``python bench/mutation_lib.py --child``, the job as JSON on stdin) imports a copy
of the family's ``unit`` package under another name (:class:`Shadow`, one module's source
replaced by the mutant's) and makes the emulator's unit from the copy, while the suite's own
reference units (GVE's expected transcripts, grbl's from-state pairs) stay the original. It
then runs the conformance checks in-process (``conform run --target emu:V --profile full
--no-machine``: an emulator gets every opt-in), stopping at the first FAIL or ERROR. Runs are
therefore safe side by side and beside other work in the same tree.

Mutant ids: ``<file>:<line>:<operator>:<k>:<hash>``, e.g.
``unit/motion.py:123:NumberReplacer:1:3f9a0c12``: the file under the family's package, the
line number (for the reader), cosmic-ray's operator without its ``core/`` prefix, ``k`` the
operator's k-th mutation point on that line, and the first 8 hex digits of the SHA-1 of the
line's text (stripped); ``~N`` after the hash when the same text appears on an earlier line of
the file too (N-th repeat). The triage file matches an id without its line number, so an id
stays the same as long as its own line's text does, whatever changes elsewhere.
"""

from __future__ import annotations

import difflib
import hashlib
import importlib.abc
import importlib.util
import inspect
import json
import resource
import sys
import threading
import time
import tomllib
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FAMILIES = ("gve", "grbl", "marlin")
PROFILE = "full"


def family_dir(family: str) -> Path:
    return ROOT / "conform" / "families" / family


def module_name(path: Path) -> str:
    rel = path.resolve().relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


# -- mutation points and ids --------------------------------------------------------------

@dataclass(frozen=True)
class Point:
    """One mutation: ``operator`` (cosmic-ray's name) at its ``occurrence`` in ``path``."""

    id: str
    path: Path
    operator: str
    occurrence: int
    line: int

    @property
    def key(self) -> str:
        return match_key(self.id)


def line_hash(text: str) -> str:
    return hashlib.sha1(text.strip().encode()).hexdigest()[:8]


def make_id(rel: str, line: int, operator: str, k: int, text: str, repeat: int) -> str:
    op = operator.split("/", 1)[-1]
    return f"{rel}:{line}:{op}:{k}:{line_hash(text)}" + (f"~{repeat}" if repeat else "")


def match_key(mutant_id: str) -> str:
    """The id without its line number: what the triage file is matched on."""
    parts = mutant_id.split(":")
    if len(parts) != 5 or not parts[1].isdigit():
        raise ValueError(f"{mutant_id!r} is not a mutant id (FILE:LINE:OPERATOR:K:HASH)")
    return ":".join(parts[:1] + parts[2:])


def operators() -> list[tuple[str, object]]:
    """cosmic-ray's operators that take no arguments (its two variable operators need a
    configuration and are left out)."""
    import cosmic_ray.plugins

    out = []
    for name in cosmic_ray.plugins.operator_names():
        cls = cosmic_ray.plugins.get_operator(name)
        if not cls.arguments():
            out.append((name, cls()))
    return out


def never_run(node, lazy_annotations: bool) -> str | None:  # noqa: ANN001 - a parso node
    """Why a mutation at ``node`` could not change what the module does, or None: a
    keyword-only marker ``*`` in a parameter list (not an operator: cosmic-ray's mutants of it
    are not Python), and, in a module with ``from __future__ import annotations``, anything in
    an annotation (kept as a string, never evaluated)."""
    parent = node.parent
    if (node.type == "operator" and node.value in ("*", "**") and parent is not None
            and parent.type in ("parameters", "typedargslist", "varargslist")):
        return "keyword-only marker"
    child = node
    while lazy_annotations and parent is not None:
        kids = parent.children
        if ((parent.type == "tfpdef" and len(kids) == 3 and kids[2] is child)
                or (parent.type == "annassign" and kids[1] is child)
                or (parent.type == "funcdef" and any(
                    k.type == "operator" and k.value == "->" and kids[i + 1] is child
                    for i, k in enumerate(kids[:-1])))):
            return "annotation"
        child, parent = parent, parent.parent
    return None


def enumerate_points(paths: list[Path], family: str,
                     left_out: Counter[str] | None = None) -> list[Point]:
    """Every mutation point of ``paths``, in a fixed order (file, operator, tree order), but
    those that cannot change what the module does (:func:`never_run`, counted by reason in
    ``left_out``)."""
    from cosmic_ray.ast import ast_nodes, get_ast

    ops = operators()
    points: list[Point] = []
    base = family_dir(family)
    for path in sorted(paths):
        source = path.read_text()
        lines = source.splitlines()
        repeats: list[int] = []
        seen: Counter[str] = Counter()
        for text in lines:
            repeats.append(seen[text.strip()])
            seen[text.strip()] += 1
        nodes = list(ast_nodes(get_ast(source)))
        lazy = "from __future__ import annotations" in source
        rel = path.relative_to(base).as_posix()
        for name, op in ops:
            occurrence = 0
            per_line: Counter[int] = Counter()
            for node in nodes:
                for (line, _col), _end in op.mutation_positions(node):
                    occurrence += 1   # cosmic-ray counts every point, the left-out ones too
                    why = never_run(node, lazy)
                    if why is not None:
                        if left_out is not None:
                            left_out[why] += 1
                        continue
                    k = per_line[line]
                    per_line[line] += 1
                    text = lines[line - 1] if 0 < line <= len(lines) else ""
                    rep = repeats[line - 1] if 0 < line <= len(lines) else 0
                    points.append(Point(make_id(rel, line, name, k, text, rep), path, name,
                                        occurrence - 1, line))
    return points


def mutated_source(point: Point) -> str | None:
    """The module's source with ``point`` applied (None: cosmic-ray made no change)."""
    import cosmic_ray.plugins
    from cosmic_ray.mutating import mutate_code

    op = cosmic_ray.plugins.get_operator(point.operator)()
    return mutate_code(point.path.read_text(), op, point.occurrence)


def line_diff(before: str, after: str) -> list[str]:
    """The changed lines only, ``-`` before and ``+`` after."""
    return [d for d in difflib.unified_diff(before.splitlines(), after.splitlines(), n=0,
                                            lineterm="")
            if d[:1] in "-+" and not d.startswith(("---", "+++"))]


# -- the triage file ------------------------------------------------------------------------

class TriageError(ValueError):
    """A triage file that cannot be used (one line, naming the file and the entry)."""


def load_equivalent(path: Path) -> dict[str, str]:
    """``match_key(id) -> why`` from a triage file::

        [[equivalent]]
        id = "unit/motion.py:123:NumberReplacer:1:3f9a0c12"
        why = "the factor is applied to 0 on every path the unit reaches"

    An entry without a ``why`` (or an empty one), a malformed id or an id given twice is
    refused."""
    if not path.exists():
        return {}
    try:
        doc = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise TriageError(f"{path}: not TOML ({exc})") from None
    unknown = set(doc) - {"equivalent"}
    if unknown:
        raise TriageError(f"{path}: unknown table(s) {', '.join(sorted(unknown))} "
                          "(only [[equivalent]] entries)")
    out: dict[str, str] = {}
    for n, entry in enumerate(doc.get("equivalent", []), 1):
        mid = entry.get("id") if isinstance(entry, dict) else None
        if not isinstance(mid, str):
            raise TriageError(f"{path}: equivalent entry {n} has no id")
        why = entry.get("why")
        if not isinstance(why, str) or not why.strip():
            raise TriageError(f"{path}: equivalent entry {n} ({mid}) has no why: say why the "
                              "mutant cannot be told from the unit")
        extra = set(entry) - {"id", "why"}
        if extra:
            raise TriageError(f"{path}: equivalent entry {n} ({mid}): unknown key(s) "
                              f"{', '.join(sorted(extra))}")
        try:
            key = match_key(mid)
        except ValueError as exc:
            raise TriageError(f"{path}: equivalent entry {n}: {exc}") from None
        if key in out:
            raise TriageError(f"{path}: equivalent entry {n} ({mid}) is listed twice")
        out[key] = why.strip()
    return out


# -- one run of the checks (the child interpreter) -----------------------------------------

class _FirstFailure(BaseException):
    """Stops a run at its first FAIL or ERROR (a BaseException: the runner records ordinary
    exceptions as a harness error and goes on to finish the run)."""


SHADOW = "conform_mutant_unit"


class Shadow(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """A second copy of a family's ``unit`` package, importable as ``conform_mutant_unit[.X]``
    (its own imports of ``conform.families.<f>.unit`` turned into that name), with one module's
    source replaced by ``code``: the unit under test. The original package stays what the
    suite's own reference copies of the unit (the expected transcripts) are made of."""

    def __init__(self, family: str, module: str | None = None, code: str | None = None) -> None:
        self.prefix = f"conform.families.{family}.unit"
        self.dir = family_dir(family) / "unit"
        self.module, self.code = module, code
        self.loaded = False

    def shadow_name(self, name: str) -> str:
        return SHADOW + name[len(self.prefix):]

    def _path(self, fullname: str) -> Path | None:
        rest = fullname[len(SHADOW):].lstrip(".")
        path = self.dir / "__init__.py" if not rest else self.dir / f"{rest}.py"
        return path if path.exists() else None

    def find_spec(self, fullname, path, target=None):  # noqa: ANN001, ANN201
        if fullname != SHADOW and not fullname.startswith(SHADOW + "."):
            return None
        file = self._path(fullname)
        if file is None:
            return None
        package = file.name == "__init__.py"
        return importlib.util.spec_from_file_location(
            fullname, file, loader=self, submodule_search_locations=[str(self.dir)] if package else None)

    def create_module(self, spec):  # noqa: ANN001, ANN201
        return None

    def exec_module(self, module) -> None:  # noqa: ANN001
        path = module.__spec__.origin
        original = self.prefix + module.__name__[len(SHADOW):]
        if original == self.module:
            self.loaded = True
            source = self.code
        else:
            source = Path(path).read_text()
        source = source.replace(self.prefix, SHADOW)
        exec(compile(source, path, "exec", dont_inherit=True), module.__dict__)  # noqa: S102

    def install(self, originals: list[str]) -> dict[str, object]:
        """Put the finder first and import the copy of each of ``originals``; name -> copy."""
        import importlib

        sys.meta_path.insert(0, self)
        return {name: importlib.import_module(self.shadow_name(name)) for name in originals}

    def wrap(self, factory, copies: dict[str, object]):  # noqa: ANN001, ANN201
        """``factory`` (a target's unit factory) made to build the copy: while it runs, the
        unit package's names in ``sys.modules``, and the unit's classes and functions bound in
        the family's other modules or in the factory's closure, are the copy's."""
        def copy_of(value):  # noqa: ANN001, ANN202
            owner = getattr(value, "__module__", None)
            if callable(value) and isinstance(owner, str) and owner in copies:
                return getattr(copies[owner], getattr(value, "__name__", ""), None)
            return None

        def build():  # noqa: ANN202
            saved = {name: sys.modules[name] for name in copies if name in sys.modules}
            rebound: list[tuple[object, str, object]] = []
            family_pkg = self.prefix.rsplit(".", 1)[0] + "."
            for modname, mod in list(sys.modules.items()):
                if not modname.startswith(family_pkg) or modname.startswith(self.prefix) or mod is None:
                    continue
                for attr, value in list(vars(mod).items()):
                    other = copy_of(value)
                    if other is not None:
                        rebound.append((mod, attr, value))
                        setattr(mod, attr, other)
            cells = []
            for cell in getattr(factory, "__closure__", None) or ():
                other = copy_of(cell.cell_contents)
                if other is not None:
                    cells.append((cell, cell.cell_contents))
                    cell.cell_contents = other
            sys.modules.update(copies)
            try:
                return factory()
            finally:
                sys.modules.update(saved)
                for name in copies:   # a module the suite had not imported yet: the suite's
                    if name not in saved:   # own later import must load the original, not
                        sys.modules.pop(name, None)   # keep the copy (the mutant)
                for mod, attr, value in rebound:
                    setattr(mod, attr, value)
                for cell, value in cells:
                    cell.cell_contents = value
        return build


def run_checks(family: str, stop_at_failure: bool = True, shadow: Shadow | None = None,
               modules: list[str] = (), every_variant: bool = False,
               every_alternative: bool = False) -> dict[str, object]:
    """The family's checks on its emulator (default variant, full profile, no state
    machine, every opt-in as an emulator gets): the first failure's check, or the counts.
    ``shadow``: the emulator's unit is built from that copy of the unit package (``modules``:
    the unit modules to copy), the suite's own reference units from the original.
    ``every_variant``: each variant's checks on its own emulator in turn (code that only a
    build with some option runs is reached by that variant's run), up to the first failure.
    ``every_alternative``: each variant's checks also under the dialects of
    :func:`covering_dialects`, reference and emulator alike."""
    import tempfile

    from conform.families import family as family_named

    fam = family_named(family)
    vids = [v.id for v in fam.variants()] if every_variant else [fam.default_variant]
    out: dict[str, object] = {}
    checks, not_pass = 0, {}
    with tempfile.TemporaryDirectory(prefix="conform-mutation-") as tmp:
        dialects: list[tuple[str, str | None]] = [("", None)]
        for n, choices in enumerate(covering_dialects(fam) if every_alternative else (), 1):
            path = Path(tmp) / f"dialect-{n}.toml"
            path.write_text("[dialect]\n" + "".join(f'{q} = "{a}"\n' for q, a in choices.items()))
            dialects.append((f"dialect {n} ({', '.join(f'{q}={a}' for q, a in choices.items())})",
                             str(path)))
        for vid in vids:
            for name, dialect_file in dialects:
                out = _run_variant(fam, vid, stop_at_failure, shadow, modules, dialect_file)
                checks += int(out["checks"])  # type: ignore[call-overload]
                not_pass |= {f"{name}: {k}" if name else k: v
                             for k, v in (out.get("not_pass") or {}).items()}  # type: ignore[union-attr]
                if out["failed"]:
                    if name:
                        out["failed"] = f"[{name}] {out['failed']}"
                    return out | {"checks": checks, "not_pass": not_pass}
    return out | {"checks": checks, "not_pass": not_pass}


def covering_dialects(fam) -> list[dict[str, str]]:  # noqa: ANN001
    """Dialects that together hold every non-default alternative of the family's open
    questions: the k-th holds each question's k-th other alternative (where it has one), so a
    question with n alternatives is covered in n - 1 dialects. A family without open questions:
    none."""
    questions = getattr(fam.load_tables(), "questions", None) or {}
    others = {q.id: [a for a in q.alternatives if a != q.default] for q in questions.values()}
    depth = max((len(a) for a in others.values()), default=0)
    return [{q: alts[k] for q, alts in others.items() if k < len(alts)} for k in range(depth)]


def _run_variant(fam, vid: str, stop_at_failure: bool, shadow: Shadow | None,  # noqa: ANN001
                 modules: list[str], dialect_file: str | None = None) -> dict[str, object]:
    from conform.conformance.plan import Permissions
    from conform.conformance.results import Grade
    from conform.conformance.runner import RunOptions

    perms = Permissions.of(True, False, None, False)
    in_dialect = {"dialect_file": dialect_file} if dialect_file else {}
    target, _ = fam.open_target(f"emu:{vid}", baud=115200, permissions=perms,
                                inputs_control=None, **in_dialect)
    unit_of = None
    if shadow is not None:
        copies = shadow.install(list(modules))
        target.factory = shadow.wrap(target.factory, copies)
        target.unit, target.t = target.factory(), 0.0
        unit_of = type(target.unit).__module__
        if not unit_of.startswith(SHADOW):
            raise RuntimeError(f"the emulator's unit is {unit_of}'s, not the copy's")
    first: list[str] = []

    def progress(result) -> None:  # noqa: ANN001
        if result.grade in (Grade.FAIL, Grade.ERROR):
            detail = (result.detail or "").splitlines()[0][:200] if result.detail else ""
            first.append(f"{result.grade} {result.id}: {detail or result.actual}")
            if stop_at_failure:
                raise _FirstFailure

    try:
        checks = fam.plan_checks(vid, permissions=perms, profile=PROFILE, patterns=(),
                                 machine=False)
        runner = fam.runner(target, vid, options=RunOptions(profile=PROFILE, seed=0),
                            permissions=perms, **in_dialect)
        try:
            run = runner.run(checks, progress)
        except _FirstFailure:
            return {"failed": first[0], "checks": len(checks), "unit_of": unit_of}
    finally:
        target.close()
    if run.aborted:
        return {"failed": f"aborted: {run.aborted}", "checks": len(checks), "unit_of": unit_of}
    other = {c.id: str(c.grade) for c in run.checks if c.grade is not Grade.PASS}
    return {"failed": first[0] if first else None, "checks": len(checks),
            "not_pass": other, "unit_of": unit_of}


def _trace_copy(ran: set[str]) -> None:
    """Record in ``ran`` each module of the unit's copy (the emulator's unit) that has any of
    its functions called, its import aside: a module the suite imports from ``unit/`` for its
    own use (a helper of the reference side) is copied too, but none of its code runs in the
    unit under test, so no check could ever see its mutants."""
    def profile(frame, event, _arg):  # noqa: ANN001, ANN202
        if event == "call" and frame.f_code.co_flags & inspect.CO_OPTIMIZED:   # a function's
            # body, not a module's or a class's (run by the import itself)
            name = frame.f_globals.get("__name__") or ""   # code of the module's own file:
            # not what a decorator made for it (a dataclass's generated methods)
            if name.startswith(SHADOW) and frame.f_code.co_filename == frame.f_globals.get("__file__"):
                ran.add(name)
    sys.setprofile(profile)
    threading.setprofile(profile)


def child_main() -> int:
    """``--child``: one job as JSON on stdin (``family``; ``shadow``: the emulator runs a copy
    of the unit, ``modules`` the unit modules copied (default: all), ``module``/``code`` the one whose source
    is replaced; ``cpu_limit``; ``stop``), one JSON line on stdout."""
    job = json.loads(sys.stdin.read())
    if job.get("cpu_limit"):
        lim = int(job["cpu_limit"])
        resource.setrlimit(resource.RLIMIT_CPU, (lim, lim + 5))
    shadow = Shadow(job["family"], job.get("module"), job.get("code")) if job.get("shadow") else None
    t0 = time.process_time()
    every = [module_name(p) for p in sorted((family_dir(job["family"]) / "unit").glob("*.py"))]
    ran: set[str] = set()
    if job.get("trace"):
        _trace_copy(ran)
    result = run_checks(job["family"], stop_at_failure=job.get("stop", True), shadow=shadow,
                        modules=job.get("modules") or every,
                        every_variant=bool(job.get("every_variant")),
                        every_alternative=bool(job.get("every_alternative")))
    if job.get("trace"):
        sys.setprofile(None)
        threading.setprofile(None)
        result["unit_ran"] = sorted(f"conform.families.{job['family']}.unit" + name[len(SHADOW):]
                                    for name in ran)
    prefix = f"conform.families.{job['family']}.unit"
    result |= {"loaded": shadow.loaded if shadow and job.get("module") else None,
               "cpu_s": round(time.process_time() - t0, 3),
               "unit_modules": sorted(m for m in sys.modules
                                      if m == prefix or m.startswith(prefix + "."))}
    print(json.dumps(result))
    return 0


if __name__ == "__main__" and sys.argv[1:] == ["--child"]:
    sys.path.insert(0, str(ROOT))
    sys.exit(child_main())
