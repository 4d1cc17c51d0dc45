"""One INFO check per open question (A1–A29) in every run, so that each report records the
unit's answer: PASS under the project's default, DEVIATION naming the alternative the unit
follows, FAIL when it follows none the register lists.

The scripts are characterisation's probes (conform.families.gve.conformance.characterize),
motion-free wherever a zero-pulse vector can tell the alternatives apart; a probe that needs
motion or EEPROM writes is SKIPPED without the opt-in like any other check.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from conform.families.gve.conformance.characterize import probe
from conform.families.gve.conformance.script import ENVIRONMENT


def _eeprom_by_shape(q: str, steps: tuple) -> tuple:
    """A28 asks what the EEPROM held at delivery: a unit in use holds its own settings, so the
    answer is compared by its shape on a real unit (exactly on the emulator)."""
    if q != "A28":
        return steps
    return tuple(dataclasses.replace(s, kind=ENVIRONMENT, shape=(("hex", 2),)) if s.line else s
                 for s in steps)


def question_checks(b: Any) -> None:
    """``question/An`` for every open question; its last line is the subject (NOT-APPLICABLE
    where the variant lacks what the probe needs)."""
    for q, question in b.spec.questions.items():
        clause = next((c for c in question.clauses if c.startswith(b.manual + " ")),
                      question.clauses[0])
        script = probe(q, b.v)
        if script is None:
            b.add(None, f"question/{q}", f"{q}: {question.question}", [], clause=clause,
                  questions=(q,), na=f"{b.v.id} has nothing to probe {q} with")
            continue
        last = max(i for i, s in enumerate(script) if s.line)
        steps = tuple(dataclasses.replace(s, subject=True) if i == last else s
                      for i, s in enumerate(_eeprom_by_shape(q, script)))
        b.add(None, f"question/{q}", f"{q}: {question.question}", steps, clause=clause,
              questions=(q,))
