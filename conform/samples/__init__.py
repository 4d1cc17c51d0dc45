"""The files the README's tour uses, shipped with conform so that the tour runs from a wheel:
the sample captures (every protocol family's), the jobs, the reference sender scripts for
``conform check-sender``, a recorded transcript for ``conform emulate judge`` and the
documents the README links (``docs/``).

``write_samples(DIR)`` lays them out as in a clone of the repository (``captures/``,
``captures/jobs/``, ``tests/senders/``, ``tests/data/marlin/``, ``docs/``), so every command of the tour
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

# (folder in this package, file names it ships, where they go in DIR)
LAYOUT: tuple[tuple[str, tuple[str, ...], str], ...] = (
    ("captures", ("*.mcap", "README.md"), "captures"),
    ("captures/jobs", ("*",), "captures/jobs"),
    ("senders", ("careful.py", "grbl_counting.py", "marlin_careful.py"), "tests/senders"),
    ("marlin", ("*.transcript",), "tests/data/marlin"),
    ("docs", ("*.md",), "docs"),
)


def _matching(folder: Traversable, patterns: tuple[str, ...]) -> Iterator[Traversable]:
    from fnmatch import fnmatch

    for item in sorted(folder.iterdir(), key=lambda t: t.name):
        if item.is_file() and any(fnmatch(item.name, p) for p in patterns):
            yield item


def sample_files() -> list[tuple[Traversable, str]]:
    """Every sample: (the packaged file, its path relative to DIR)."""
    root = files(__name__)
    out = []
    for folder, patterns, dest in LAYOUT:
        where = root.joinpath(folder)
        if not where.is_dir():
            raise UserError(f"the samples' {folder}/ is missing from this install of conform "
                            "(reinstall it)")
        out += [(item, f"{dest}/{item.name}") for item in _matching(where, patterns)]
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
