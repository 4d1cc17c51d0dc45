"""The engine reaches a protocol family only through the registry (conform.families): no
module under conform/ outside conform/families/ imports a family package directly, except the
GVE-only entries listed here, each with its reason (docs/architecture.md names them too)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent / "conform"
FAMILY_PACKAGES = ("conform.families.gve", "conform.families.grbl")

# module (relative to conform/) -> the family modules it may import, and why
ALLOWED = {
    "cli/spec_cmd.py": ({"conform.families.gve.spec", "conform.families.gve.spec.diff"},
                        "`spec diff` and `spec questions` are GVE-only subcommands (the GVE "
                        "command tables' diff, the A-register)"),
    "cli/profile_cmd.py": ({"conform.families.gve.conformance.profile",
                            "conform.families.gve.spec"},
                           "`conform profile` compares GVE dialect profiles (A-register)"),
    "cli/ports_cmd.py": ({"conform.families.gve.conformance.safety",
                          "conform.families.gve.conformance.target", "conform.families.gve.spec"},
                         "`conform ports --probe` identifies GVE units with '?'"),
    "cli/send_cmd.py": ({"conform.families.gve.sender.core", "conform.families.gve.sender.job",
                         "conform.families.gve.spec", "conform.families.gve.sender.links",
                         "conform.families.gve.sender.session",
                         "conform.families.gve.conformance.target",
                         "conform.families.gve.sender.probe"},
                        "`conform send` is the GVE reference sender"),
}


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
    return [p for p in sorted(ROOT.rglob("*.py"))
            if p.relative_to(ROOT).parts[0] not in ("families",)]


def test_the_engine_imports_families_only_through_the_registry():
    offences = []
    for path in _engine_modules():
        rel = path.relative_to(ROOT).as_posix()
        allowed = ALLOWED.get(rel, (set(), ""))[0]
        for name in sorted(_family_imports(path) - allowed):
            offences.append(f"conform/{rel} imports {name}")
    assert not offences, "\n".join(offences)


def test_the_whitelist_is_not_stale():
    """Every exception is still needed (an entry whose import went away is removed)."""
    for rel, (allowed, why) in ALLOWED.items():
        assert why
        used = _family_imports(ROOT / rel)
        assert allowed <= used, f"conform/{rel}: no longer imports {sorted(allowed - used)}"


def test_the_check_sees_lazy_and_from_imports(tmp_path):
    probe = tmp_path / "probe.py"
    probe.write_text("def f():\n    from conform.families.grbl.conformance.checks import run_checks\n"
                     "import conform.families.gve.spec\nfrom conform.families import gve\n"
                     "from conform.families import family_for_variant\n")
    assert _family_imports(probe) == {"conform.families.grbl.conformance.checks", "conform.families.gve.spec",
                                      "conform.families.gve"}


def test_every_registered_family_is_a_family():
    from conform.families import DEFAULT_FAMILY, Family, families, family

    for fam in families():
        assert isinstance(fam, Family), fam.name
    assert callable(family(DEFAULT_FAMILY).variant_table)
