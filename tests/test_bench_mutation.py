"""bench/bench_mutation.py's parts: a mutant's source really reaches the conformance run (a
hand-made mutant of grbl's reference unit is killed, the same module substituted unmutated
passes), the triage file refuses an entry without a why, and a mutant's id does not move when
lines are added elsewhere in its file, and annotations are not mutated."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import mutation_lib  # noqa: E402

REPLIES = ROOT / "conform" / "families" / "grbl" / "unit" / "replies.py"
VERSION_LINE = 'f"[VER:{v.version}.{v.build}:{info}]"'


def child(code: str) -> dict:
    job = {"family": "grbl", "module": mutation_lib.module_name(REPLIES), "path": str(REPLIES),
           "code": code, "cpu_limit": 60}
    r = subprocess.run([sys.executable, str(ROOT / "bench" / "mutation_lib.py"), "--child"],
                       input=json.dumps(job), capture_output=True, text=True, timeout=300,
                       cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_substituted_source_reaches_the_run():
    source = REPLIES.read_text()
    assert source.count(VERSION_LINE) == 1
    broken = source.replace(VERSION_LINE, VERSION_LINE.replace("{v.build}", "{v.build}x"))
    killed = child(broken)
    assert killed["loaded"] is True
    assert killed["failed"] and killed["failed"].startswith(("FAIL", "ERROR")), killed
    same = child(source)
    assert same["loaded"] is True and same["failed"] is None, same
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
