"""``conform profile diff`` of two GVE profiles (``[dialect]``): the open questions on which
they differ (the engine's command calls it through ``GveFamily.diff_profiles``)."""

from __future__ import annotations

from typing import Any

from conform.families.gve.conformance.profile import diff_profiles, load_profile, unanswered
from conform.families.gve.spec import load_spec


def diff(a: str, b: str) -> tuple[list[str], list[tuple[str, Any, Any]], str]:
    """(notes on partial profiles, rows (question, a, b) that differ, the line when none does).
    A partial profile names the questions it did not answer; they differ."""
    pa, pb = load_profile(a), load_profile(b)
    notes = []
    for path, p in ((a, pa), (b, pb)):
        missing = unanswered(p)
        if missing:
            notes.append(f"{path}: partial profile ({p.meta.get('interrupted', 'interrupted')}); "
                         f"{len(missing)} question(s) not answered: {', '.join(missing)}")
    rows = diff_profiles(pa, pb, dict(load_spec().dialect().choices))
    return notes, [(q, x or "(absent)", y or "(absent)") for q, x, y in rows], "same dialect"
