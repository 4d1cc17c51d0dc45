"""What the diagnosis's confidence means: a measured precision, not a rule's own score.

For each way a diagnosis can lead (the leading stop cause's kind and the rule that named it,
``unit-silent/stall-no-answer``; or, with no stop cause, the outcome, ``outcome/completed``),
the table holds how many sessions of the labelled corpus (tests/diag_corpus.py) it led and in
how many of them the label agreed (the cause was the injected one; the outcome was the
session's own, or the session completed despite the fault its first hazard names). The
confidence said is ``agreed / sessions`` with ``n=sessions``: the precision of that lead on
the corpus. A lead the corpus never produced says its rule's score instead, and that it was
not measured; the causes after the first and the hazards are not calibrated (the corpus
labels what ended a session, and only the lead was measured).

``python bench/bench_diagnosis.py --calibrate`` writes the table (calibration.toml, beside this
file) from the corpus; tests/test_diagnosis_corpus.py checks that it matches the corpus.
"""

from __future__ import annotations

import tomllib
from collections.abc import Iterable
from functools import lru_cache
from pathlib import Path
from typing import Any

TABLE = Path(__file__).with_name("calibration.toml")


@lru_cache(maxsize=1)
def table() -> dict[str, tuple[int, int]]:
    """key -> (agreed, sessions); empty when the table is missing."""
    try:
        doc = tomllib.loads(TABLE.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError):
        return {}
    return {k: (int(v["agreed"]), int(v["sessions"])) for k, v in doc.get("lead", {}).items()
            if int(v.get("sessions", 0)) > 0}


def apply(d: Any) -> None:
    """The leading stop cause and the outcome of diagnosis ``d`` given their measured
    precision (the causes after the first did not lead: what was measured is not theirs)."""
    t = table()
    for c in d.causes[:1]:
        c.measured = t.get(c.key)
    if d.outcome is not None:
        d.outcome.measured = t.get(d.outcome.key)


def count(rows: Iterable[tuple[str, bool]]) -> dict[str, tuple[int, int]]:
    """(lead key, label agreed) per session -> key -> (agreed, sessions)."""
    out: dict[str, list[int]] = {}
    for key, agreed in rows:
        cell = out.setdefault(key, [0, 0])
        cell[0] += bool(agreed)
        cell[1] += 1
    return {k: (v[0], v[1]) for k, v in sorted(out.items())}


def write(counts: dict[str, tuple[int, int]], corpus: str, path: Path = TABLE) -> None:
    lines = ["# The diagnosis's confidence, measured on its labelled corpus (see",
             "# conform/diagnosis/calibration.py): per lead, the sessions it led and how many",
             "# of them agreed with their label. Written by",
             "#   python bench/bench_diagnosis.py --calibrate",
             f'corpus = "{corpus}"', f"sessions = {sum(n for _k, n in counts.values())}", ""]
    for key, (k, n) in counts.items():
        lines += [f'[lead."{key}"]', f"agreed = {k}", f"sessions = {n}", ""]
    path.write_text("\n".join(lines), encoding="utf-8")
    table.cache_clear()
