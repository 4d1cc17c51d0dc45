"""Shell completion (click's ``_CONFORM_COMPLETE``) offers every family's variants wherever a
variant or an ``emu:`` target is asked for."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from conform.families import families

VARIANTS = [v.id for f in families() for v in f.variants()]


def complete(words: str) -> list[str]:
    env = dict(os.environ, COMP_WORDS=words, COMP_CWORD=str(len(words.split()) - 1
                                                            + words.endswith(" ")),
               _CONFORM_COMPLETE="bash_complete")
    r = subprocess.run([sys.executable, "-m", "conform"], env=env, capture_output=True,
                       text=True, timeout=60)
    return [line.split(",", 1)[1] for line in r.stdout.splitlines() if "," in line]


def test_every_family_is_in_the_tables() -> None:
    names = {f.name for f in families()}
    assert {"gve", "grbl", "marlin"} <= names
    assert any(v.startswith("grbl-") for v in VARIANTS)
    assert any(v.startswith("marlin-") for v in VARIANTS)


@pytest.mark.parametrize("words", ["conform run --variant ", "conform emulate serve ",
                                   "conform check-sender --variant "])
def test_variants_complete_for_every_family(words) -> None:
    assert complete(words) == VARIANTS


def test_emu_targets_complete_for_every_family() -> None:
    assert complete("conform run --target emu:") == [f"emu:{v}" for v in VARIANTS]
    assert complete("conform run --target emu:m") == [f"emu:{v}" for v in VARIANTS
                                                      if v.startswith("m")]
