"""The engine's typed seam holds: ``mypy`` (configured in pyproject.toml: the engine, i.e.
conform/ outside the families' own packages) finds no error, and the engine names ``Any``
only where a value really is anything (a bound, so it does not creep back)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
ANY_BOUND = 150


def _engine_files() -> list[Path]:
    return [p for p in sorted((REPO / "conform").rglob("*.py"))
            if not re.match(r"families/[a-z0-9_]+/", p.relative_to(REPO / "conform").as_posix())]


@pytest.mark.slow   # 15 s of CPU cold (no .mypy_cache), over a minute on a loaded 2-core machine
def test_mypy_is_clean_over_the_engine():
    done = subprocess.run([sys.executable, "-m", "mypy"], cwd=REPO, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    assert "Success" in done.stdout


def test_the_engine_names_any_sparingly():
    counts = {p: len(re.findall(r"\bAny\b", p.read_text(encoding="utf-8"))) for p in _engine_files()}
    assert len(counts) > 50 and (REPO / "conform" / "families" / "__init__.py") in counts
    total = sum(counts.values())
    worst = sorted(counts.items(), key=lambda kv: -kv[1])[:5]
    assert total <= ANY_BOUND, f"{total} > {ANY_BOUND}: " + ", ".join(
        f"{p.relative_to(REPO)} {n}" for p, n in worst)
