"""pytest's assertion rewriting, done once for the workers instead of once in each.

pytest rewrites the asserts of every test module it imports, and of every module of a package
that registers a pytest plugin (conform itself, Hypothesis). It keeps the result in
``__pycache__`` only where it may write bytecode, and every xdist worker collects every module:
on a fresh clone, or with PYTHONDONTWRITEBYTECODE set, eight workers each rewrote the same
hundred test modules and 300 library modules before the first test ran (a minute of the
suite's wall time on two cores). So:

- the packages that are only plugins to the suite (not its tests) are imported as they are:
  their asserts are their own invariants, and their failures read the same either way;
- the controller rewrites the test modules once, before it starts the workers, and writes the
  result where every worker reads it.

Both use helpers of pytest's that are not its public API; where they are missing (another pytest)
nothing is done and the suite runs as before, only slower.
"""

from __future__ import annotations

import sys
from pathlib import Path

# packages registered as pytest plugins whose asserts are not the suite's
NOT_REWRITTEN = ("conform", "hypothesis", "_hypothesis_pytestplugin", "_hypothesis_globals",
                 "_hypothesis_ftz_detector", "pytest_benchmark", "xdist")


def _hook():
    try:
        from _pytest.assertion.rewrite import AssertionRewritingHook
    except ImportError:
        return None
    return next((h for h in sys.meta_path if isinstance(h, AssertionRewritingHook)), None)


def leave_plugins_alone() -> None:
    """Import the plugin packages' modules not yet imported without rewriting them."""
    hook = _hook()
    marked = getattr(hook, "_must_rewrite", None)
    cache = getattr(hook, "_marked_for_rewrite_cache", None)
    if isinstance(marked, set):
        marked.difference_update(NOT_REWRITTEN)
    if isinstance(cache, dict):
        cache.clear()


def rewrite_for_workers(config, folder: Path) -> int:
    """Rewrite each test module and conftest under ``folder`` whose cached rewrite is missing or
    stale, and write it to its ``__pycache__``; return how many were rewritten."""
    try:
        from _pytest.assertion.rewrite import (
            PYC_TAIL,
            _read_pyc,
            _rewrite_test,
            _write_pyc,
            assertstate_key,
            get_cache_dir,
            try_makedirs,
        )
        state = config.stash[assertstate_key]
    except (ImportError, KeyError):
        return 0
    patterns = config.getini("python_files") + ["conftest.py"]
    done = 0
    for fn in sorted({p for pat in patterns for p in folder.rglob(pat)}):
        cache_dir = get_cache_dir(fn)
        pyc = cache_dir / (fn.name[:-3] + PYC_TAIL)
        if _read_pyc(fn, pyc) is not None or not try_makedirs(cache_dir):
            continue
        try:
            source_stat, co = _rewrite_test(fn, config)
        except SyntaxError:
            continue                  # the worker that imports it reports it
        _write_pyc(state, co, source_stat, pyc)
        done += 1
    return done
