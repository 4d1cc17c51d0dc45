"""The engine reaches a protocol family only through the registry (conform.families): no
module under conform/ outside a family's own package imports a family package, and none names
a family or its protocol words in an identifier or a string constant (docs/architecture.md)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent / "conform"


FAMILY_PACKAGES = ("conform.families.gve", "conform.families.grbl")

def _family_imports(path: Path) -> set[str]:
    """Every family module ``path`` imports, at the top or inside a function."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names
                                     if node.module == "conform.families"]
        else:
            continue
        found |= {n for n in names if n.startswith(FAMILY_PACKAGES)
                  and (n in FAMILY_PACKAGES or n.startswith(tuple(p + "." for p in FAMILY_PACKAGES)))}
    return found


def _engine_modules() -> list[Path]:
    """Every module outside a family's own folder (families/<name>/...); the seam itself,
    families/*.py, is engine."""
    return [p for p in sorted(ROOT.rglob("*.py"))
            if not (p.relative_to(ROOT).parts[0] == "families" and len(p.relative_to(ROOT).parts) > 2)]


def test_the_engine_imports_families_only_through_the_registry():
    offences = []
    for path in _engine_modules():
        rel = path.relative_to(ROOT).as_posix()
        for name in sorted(_family_imports(path)):
            offences.append(f"conform/{rel} imports {name}")
    assert not offences, "\n".join(offences)


def test_the_check_sees_lazy_and_from_imports(tmp_path):
    probe = tmp_path / "probe.py"
    probe.write_text("def f():\n    from conform.families.grbl.conformance.checks import run_checks\n"
                     "import conform.families.gve.spec\nfrom conform.families import gve\n"
                     "from conform.families import family_for_variant\n")
    assert _family_imports(probe) == {"conform.families.grbl.conformance.checks", "conform.families.gve.spec",
                                      "conform.families.gve"}


def test_every_registered_family_is_a_family():
    from conform.families import Family, default_family, families

    for fam in families():
        assert isinstance(fam, Family), fam.name
        assert fam.name and fam.variants()
    assert default_family() is families()[0]


# what the engine may not say: a family's name or its protocol words
VOCABULARY = re.compile(r"gve|grbl|marlin|(?<![a-z])inta(?![a-z])|packet_role|vectors_accepted|!0|resend",
                        re.I)
def _vocabulary(path: Path, rel: str) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    docs = {id(n.body[0].value) for n in ast.walk(tree)
            if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
            and n.body and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
    hits = []
    for node in ast.walk(tree):
        text = None
        if isinstance(node, ast.Name):
            text = node.id
        elif isinstance(node, ast.Attribute | ast.arg):
            text = node.attr if isinstance(node, ast.Attribute) else node.arg
        elif isinstance(node, ast.FunctionDef | ast.ClassDef):
            text = node.name
        elif isinstance(node, ast.alias):
            text = node.name
        elif isinstance(node, ast.ImportFrom):
            text = node.module or ""
        elif isinstance(node, ast.Constant) and isinstance(node.value, str | bytes) and id(node) not in docs:
            text = node.value.decode("latin-1") if isinstance(node.value, bytes) else node.value
        if text and VOCABULARY.search(text):
            hits.append(f"{rel}:{getattr(node, 'lineno', '?')}: {text[:40]!r}")
    return hits


def test_the_engine_names_no_family():
    rels = {p: p.relative_to(ROOT).as_posix() for p in _engine_modules()}
    hits = [h for p, rel in rels.items() for h in _vocabulary(p, rel)]
    assert not hits, "\n".join(hits)


def test_the_vocabulary_check_can_fail(tmp_path):
    probe = tmp_path / "probe.py"
    probe.write_text('"""Talks of GVE in a docstring, which is allowed."""\nX = "!0?"\ngrbl_port = 1\n')
    assert len(_vocabulary(probe, "probe.py")) == 2


def test_a_plugin_bug_is_one_line_not_a_traceback(tmp_path):
    """A family plugin that raises where the engine calls it: one line naming the error and
    where, exit 70; CONFORM_DEBUG=1 gives the traceback."""
    import os
    import subprocess
    import sys

    pkg = tmp_path / "brokenfam"
    pkg.mkdir()
    (pkg / "__init__.py").write_text(
        "from conform.families import Family, VariantInfo\n"
        "class Broken(Family):\n"
        "    name = 'broken'\n"
        "    def variants(self):\n"
        "        return [VariantInfo('broken-1', 'broken', 't', 'f', '-', '-')]\n"
        "    def plan_checks(self, variant, **kw):\n"
        "        raise ZeroDivisionError('a plugin bug')\n"
        "FAMILY = Broken()\n")
    info = tmp_path / "brokenfam-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: brokenfam\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[conform.families]\nbroken = brokenfam:FAMILY\n")
    env = {k: v for k, v in os.environ.items() if k != "CONFORM_DEBUG"}
    env["PYTHONPATH"] = str(tmp_path)
    args = [sys.executable, "-m", "conform", "run", "--target", "emu:broken-1", "--list"]
    p = subprocess.run(args, capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert p.returncode == 70, p.stderr
    assert "Traceback" not in p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "ZeroDivisionError: a plugin bug" in lines[0]
    assert "brokenfam/__init__.py:" in lines[0]
    p = subprocess.run(args, capture_output=True, text=True, env=env | {"CONFORM_DEBUG": "1"},
                       cwd=tmp_path, timeout=120)
    assert "Traceback" in p.stderr


def test_a_plugin_that_does_not_load_is_left_out_in_one_line(tmp_path):
    import os
    import subprocess
    import sys

    info = tmp_path / "ghost-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: ghost\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[conform.families]\nghost = ghostpkg:FAMILY\n")
    env = dict(os.environ, PYTHONPATH=str(tmp_path))
    p = subprocess.run([sys.executable, "-m", "conform", "spec", "list", "--json"],
                       capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert p.returncode == 0 and "Traceback" not in p.stderr
    assert p.stderr.strip().splitlines() == [
        "conform: protocol family 'ghost' (ghostpkg:FAMILY) does not load: "
        "ModuleNotFoundError: No module named 'ghostpkg'; left out"]
    assert "gve64-v19" in p.stdout
    p = subprocess.run([sys.executable, "-m", "conform", "run", "--target", "emu:gve64-v19",
                        "--list"], capture_output=True, text=True, env=env, cwd=tmp_path,
                       timeout=120)
    assert p.returncode == 0 and p.stderr.count("does not load") == 1


def _imports_of(path: Path, modules: set[str]) -> set[str]:
    """The project modules ``path`` imports at run time (at the top or inside a function; not
    under ``if TYPE_CHECKING:``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    typing_only = {id(n) for node in ast.walk(tree)
                   if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
                   for b in node.body for n in ast.walk(b)}
    found = set()
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for a in node.names:
                full = f"{node.module}.{a.name}"
                found.add(full if full in modules else node.module)
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
    return found & modules


def test_no_run_time_import_cycle():
    """The house drawn from the imports has no cycle (docs/architecture.md)."""
    import sys

    paths = {}
    for f in ROOT.rglob("*.py"):
        name = ".".join(f.relative_to(ROOT.parent).with_suffix("").parts)
        paths[name.removesuffix(".__init__")] = f
    graph = {m: _imports_of(f, set(paths)) - {m} for m, f in paths.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))

    def visit(v: str) -> None:   # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    assert not cycles, cycles
