"""bench/bench_mutation.py's parts: a mutant's source really reaches the emulator the
conformance run judges, and only it (a hand-made mutant of GVE's reference unit FAILs, the
same module copied unmutated passes), the triage file refuses an entry without a why, and a
mutant's id does not move when lines are added elsewhere in its file, and annotations are not
mutated."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import mutation_lib  # noqa: E402

ANSWERS = ROOT / "conform" / "families" / "gve" / "unit" / "answers.py"
A10_LINE = "        if a10 == 1:\n"   # A10: which lines advance the @ index


def child(code: str | None) -> dict:
    job = {"family": "gve", "shadow": True, "module": mutation_lib.module_name(ANSWERS),
           "code": code, "cpu_limit": 60}
    r = subprocess.run([sys.executable, str(ROOT / "bench" / "mutation_lib.py"), "--child"],
                       input=json.dumps(job), capture_output=True, text=True, timeout=300,
                       cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_mutant_reaches_the_emulator_and_not_the_reference():
    """GVE's checks grade the emulator's transcript against the reference unit's: a mutant
    that reached both would pass. The hand-made one (A10 the wrong way round: the @ index
    advanced by the lines the default does not count) FAILs its check, so only the emulator
    runs it; the same module copied unchanged passes."""
    source = ANSWERS.read_text()
    assert source.count(A10_LINE) == 1
    killed = child(source.replace(A10_LINE, A10_LINE.replace("a10 == 1", "a10 != 1")))
    assert killed["loaded"] is True and killed["unit_of"].startswith(mutation_lib.SHADOW)
    assert killed["failed"] and killed["failed"].startswith("FAIL"), killed
    same = child(source)
    assert same["loaded"] is True and same["unit_of"].startswith(mutation_lib.SHADOW)
    assert same["failed"] is None, same
    assert same["checks"] > 100 and not same["not_pass"]


def test_triage_entry_without_why_is_refused(tmp_path):
    f = tmp_path / "x-equivalent.toml"
    f.write_text('[[equivalent]]\nid = "unit/a.py:3:AddNot:0:0123abcd"\nwhy = "  "\n')
    with pytest.raises(mutation_lib.TriageError, match="has no why"):
        mutation_lib.load_equivalent(f)
    f.write_text('[[equivalent]]\nid = "unit/a.py:3:AddNot:0:0123abcd"\n'
                 'why = "the flag is read nowhere"\n')
    assert mutation_lib.load_equivalent(f) == {"unit/a.py:AddNot:0:0123abcd":
                                               "the flag is read nowhere"}
    f.write_text('[[equivalent]]\nid = "unit/a.py:AddNot:0"\nwhy = "w"\n')
    with pytest.raises(mutation_lib.TriageError, match="not a mutant id"):
        mutation_lib.load_equivalent(f)


def test_ids_stay_when_lines_are_added_elsewhere(tmp_path, monkeypatch):
    pytest.importorskip("cosmic_ray")
    code = ("from __future__ import annotations\n\n\ndef f(a: int | None, *, b: int = 2) -> int:\n"
            "    if a < b:\n        return a + 1\n    return b - 1\n")
    fam = tmp_path / "fam"
    (fam / "unit").mkdir(parents=True)
    path = fam / "unit" / "m.py"
    path.write_text(code)
    monkeypatch.setattr(mutation_lib, "family_dir", lambda _name: fam)   # ids are relative to it
    before = mutation_lib.enumerate_points([path], "x")
    path.write_text("X = 1\n\n" + code)
    after = [p for p in mutation_lib.enumerate_points([path], "x") if p.line > 2]
    assert len(before) > 20
    assert [p.key for p in before] == [p.key for p in after]
    assert [p.line + 2 for p in before] == [p.line for p in after]
    assert len({p.id for p in before}) == len(before)
    # on the def line only the default's number: its annotations are never evaluated, and
    # its '*' is no product
    assert {p.operator for p in before if p.line == 4} == {"core/NumberReplacer"}


def test_the_covering_dialects_hold_every_alternative_once():
    """--every-alternative: each non-default alternative of every GVE open question is in
    exactly one of the dialects, each a dialect the tables accept; a family without open
    questions has none."""
    from conform.families import family

    gve = family("gve")
    questions = gve.load_tables().questions
    dialects = mutation_lib.covering_dialects(gve)
    assert len(dialects) == max(len(q.alternatives) for q in questions.values()) - 1
    held = sorted((q, a) for d in dialects for q, a in d.items())
    assert held == sorted((q.id, a) for q in questions.values() for a in q.alternatives
                          if a != q.default)
    for d in dialects:
        gve.load_tables().dialect(d)   # a UserError if any choice were not an alternative
    assert mutation_lib.covering_dialects(family("grbl")) == []
