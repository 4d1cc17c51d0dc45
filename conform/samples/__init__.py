"""The files the README's tour uses, shipped with conform so that the tour runs from a wheel:
the sample captures (every protocol family's), the jobs, the reference sender scripts for
``conform check-sender``, the recorded transcripts for ``conform emulate judge`` and the
documents the README links (``docs/``).

``write_samples(DIR)`` lays them out as in a clone of the repository (``captures/``,
``captures/jobs/``, ``tests/senders/``, ``tests/data/``, ``docs/``), so every command of the tour
reads the same paths in ``DIR`` as in a clone. In a clone, this package's folders are links
to those folders; a wheel carries the files themselves (pyproject.toml, package data).
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from importlib.resources import files
from importlib.resources.abc import Traversable
from pathlib import Path

from conform.errors import UserError, writable_folder

# (folder in this package, file names it ships, where they go in DIR, its subfolders too)
LAYOUT: tuple[tuple[str, tuple[str, ...], str, bool], ...] = (
    ("captures", ("*.mcap", "README.md"), "captures", False),
    ("captures/jobs", ("*",), "captures/jobs", False),
    ("senders", ("*.py",), "tests/senders", False),
    ("data", ("*.transcript",), "tests/data", True),
    ("docs", ("*.md",), "docs", False),
)


def _matching(folder: Traversable, patterns: tuple[str, ...], deep: bool, at: str = ""
              ) -> Iterator[tuple[Traversable, str]]:
    """The files of ``folder`` named like ``patterns`` (``deep``: in its subfolders too), each
    with its path below ``folder``."""
    from fnmatch import fnmatch

    for item in sorted(folder.iterdir(), key=lambda t: t.name):
        if item.is_file() and any(fnmatch(item.name, p) for p in patterns):
            yield item, f"{at}{item.name}"
        elif deep and item.is_dir():
            yield from _matching(item, patterns, deep, f"{at}{item.name}/")


def sample_files() -> list[tuple[Traversable, str]]:
    """Every sample: (the packaged file, its path relative to DIR)."""
    root = files(__name__)
    out = []
    for folder, patterns, dest, deep in LAYOUT:
        where = root.joinpath(folder)
        if not where.is_dir():
            raise UserError(f"the samples' {folder}/ is missing from this install of conform "
                            "(reinstall it)")
        out += [(item, f"{dest}/{rel}") for item, rel in _matching(where, patterns, deep)]
    return out


def write_samples(directory: str | Path, *, force: bool = False) -> list[Path]:
    """Write every sample under ``directory``; an existing sample file is refused without
    ``force`` (one line naming it) before anything is written."""
    out = writable_folder(directory, "DIR")
    todo = [(item, out / rel) for item, rel in sample_files()]
    there = [str(dest) for _, dest in todo if dest.exists()]
    if there and not force:
        raise UserError(f"{there[0]}: exists ({len(there)} sample file(s) already there); "
                        "choose another folder or add --force to replace them")
    written = []
    for item, dest in todo:
        dest.parent.mkdir(parents=True, exist_ok=True)
        with item.open("rb") as src, open(dest, "wb") as dst:
            shutil.copyfileobj(src, dst)
        written.append(dest)
    return written
