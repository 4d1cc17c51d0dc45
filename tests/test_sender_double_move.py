"""Regression: a careful sender whose job repeats a vector must not be reported as moving twice.

The careful reference sender sends identical vectors back to back; one answer is garbled,
it asks `>`, the echo shows its own line arrived (answered 0), and it goes on to the next
job vector, which is the same text. That once became a confirmed double move; a blind
resend of the same vector must still be one.
"""

from __future__ import annotations

from pathlib import Path

from conform.families.gve.analysis import analyze
from conform.families.gve.protocol import CommandParser
from conform.families.gve.sender.job import parse_item
from conform.families.gve.sender.links import LinkModel
from conform.families.gve.sender.session import send_emulated


def _items(spec, lines):
    var = spec.variant("gve64-v19")
    parser = CommandParser(var, spec.dialect())
    return var, [parse_item(x, var, parser, f"job:{k}") for k, x in enumerate(lines, 1)]


def _run(spec, tmp_path: Path, policy: str, corrupt: int) -> object:
    var, items = _items(spec, ["C100,0,0", "C100,0,0", "C100,0,0", "C0,50,0"])
    path = tmp_path / f"{policy}-{corrupt}.mcap"
    res = send_emulated(items, var, spec.dialect(), policy=policy, record=path,
                        link=LinkModel(corrupt_answers={corrupt}))
    return res, analyze(path)


def test_careful_identical_vectors_after_repeat_are_not_a_double_move(spec, tmp_path):
    res, a = _run(spec, tmp_path, "careful", 1)  # answer 1: the first C (answer 0 is `@`)
    assert res.position[:2] == (300, 50)  # the unit moved exactly as the job says
    assert a.metrics["finding_counts"].get("repeat-used") == 1
    assert not [f for f in a.findings if f.kind == "double-move"]
    assert not a.hazards()


def test_careful_sender_resolves_identical_vectors_through_the_index(spec, tmp_path):
    # the second C's answer garbled: `>` echoes a line identical to the one before, so the
    # sender needs `@`; it must finish the job (it used to stop) and nothing is a hazard
    res, a = _run(spec, tmp_path, "careful", 2)
    assert res.sender.failed is None
    assert res.position[:2] == (300, 50)
    assert not [f for f in a.findings if f.kind == "double-move" and f.extra.get("confirmed")]


def test_blind_resend_of_a_repeated_vector_is_still_a_double_move(spec, tmp_path):
    res, a = _run(spec, tmp_path, "blind", 1)
    assert res.position[:2] == (400, 50)  # the unit really took it twice
    kinds = a.metrics["finding_counts"]
    assert kinds.get("blind-resend") == 1 and kinds.get("double-move") == 1
