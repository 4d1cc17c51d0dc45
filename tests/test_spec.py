"""The tables load, validate, and say what the manuals say."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conform.families.gve.spec import SpecError, load_spec
from conform.families.gve.spec.diff import diff_variants

VARIANTS = ("gve64-v10", "gve64-v19", "gve64-phantom", "gve124")
CLAUSE = re.compile(r"^(GVE64|GVE124) §\d+(\.\d+)*$")
DIGEST_COMMANDS = {
    "?", "Q", "L", "C", "T", "$", "A", "V", "VL", "B", "VK", "VN", "XA", "XU", "XD", "XM", "P", "PF",
    "P4", "N", "N<axis>", "W", "Y", "K", "R", "H", "D", "G", "ER", "EW", "EFR", "EUR", "EFW", "EUW",
    "O", "I1", "I2", "SR", "SW", "F", "@", ">", "J", "%", "*S", "*E", "7V",
}


def test_every_variant_loads(spec):
    assert set(spec.variants) == set(VARIANTS)
    for vid in VARIANTS:
        v = spec.variant(vid)
        assert v.commands and v.axes and v.queue > 0


def test_every_command_of_both_manuals_is_a_row(spec):
    assert set(spec.commands) == DIGEST_COMMANDS


def test_every_command_row_cites_a_clause(spec):
    for cmd in spec.commands.values():
        assert cmd.clauses, cmd.id
        assert all(CLAUSE.match(c) for c in cmd.clauses), (cmd.id, cmd.clauses)
        for v in spec.variants.values():
            if v.has(cmd.id):
                assert v.command(cmd.id).clause_for(v.manual).startswith(v.manual), (v.id, cmd.id)


def test_every_error_code_is_used_somewhere(spec):
    """Each code names the rows that raise it, and those rows agree with it."""
    assert set(spec.errors) == set(range(8))
    for code, err in spec.errors.items():
        assert err.raised_by, code
        assert all(c == "*" or c in spec.commands for c in err.raised_by)
    busy = {c.id for c in spec.commands.values() if not c.while_running}
    manual_busy = set(spec.errors[7].raised_by)
    assert manual_busy <= busy  # N, K, R, D are 'not while running' by the manual
    assert spec.errors[6].raised_by == ("G",)
    examples = {int(line[0], 16) & 7 for ex in spec.examples for line in ex.expect}
    assert {0, 1, 5} <= examples  # the §13.7 table shows OK, queue full and out of range


def test_queue_axes_and_rates(spec):
    assert spec.variant("gve64-v19").queue == 420
    assert spec.variant("gve124").queue == 128
    assert spec.variant("gve124").axes == ("X", "Y", "Z")
    assert spec.variant("gve64-phantom").range("V") == (10, 200000)
    assert spec.variant("gve64-v10").range("V") == (10, 125000)
    assert spec.variant("gve124").range("V") == (10, 100000)
    assert spec.variant("gve124").range("$") == (1, 2147483647)


def test_version_differences(spec):
    v10, v19, g124 = (spec.variant(x) for x in ("gve64-v10", "gve64-v19", "gve124"))
    added = {d.what for d in diff_variants(v10, v19) if d.kind == "command-added"}
    assert added == {"VL", "VK", "VN", "XM", "N<axis>"}
    diffs = diff_variants(v19, g124)
    removed = {d.what for d in diffs if d.kind == "command-removed"}
    assert {"P4", "I2", "Y", "EFR", "EUR", "EFW", "EUW"} <= removed
    fields = {d.what: d for d in diffs if d.kind == "field"}
    assert (fields["queue"].a, fields["queue"].b) == ("420", "128")
    assert "status_words" in fields
    assert all(d.clause for d in diffs)


def test_reset_state(spec):
    r = spec.variant("gve64-v19").reset
    assert (r["A"], r["V"], r["$"], r["B"], r["outputs"], r["checksum"]) == (20, 1000, 512, 35000, 0xFF, False)
    assert spec.variant("gve124").reset["B"] == 50000


def test_eeprom_maps(spec):
    img = spec.variant("gve64-v19").eeprom.image()
    assert len(img) == 256 and img[0x05] == 0xFF and img[0x04] == 0xFF
    assert 0x30 in spec.variant("gve64-v19").eeprom.cells
    assert set(spec.variant("gve124").eeprom.cells) == {0x01, 0x05, 0xFD}


def test_open_questions(spec):
    assert [f"A{i}" for i in range(1, 25)] == list(spec.questions)[:24]
    for q in spec.questions.values():
        assert q.default in q.alternatives
    settled = {q.id for q in spec.questions.values() if q.settled}
    assert {"A2", "A3", "A5", "A22"} <= settled


def test_dialect_overrides_and_rejects(spec):
    d = spec.dialect({"A6": "1-65535"})
    assert d["A6"] == "1-65535" and d.ranges["accel"] == (1, 65535) and not d.is_default("A6")
    from conform.errors import UserError

    with pytest.raises(UserError, match="A6='nope'"):
        spec.dialect({"A6": "nope"})
    with pytest.raises(UserError, match="unknown open question"):
        spec.dialect({"A99": "x"})


# --- malformed tables: one line naming file, row and field -------------------------------------

def test_answer_times_come_from_the_tables(spec):
    """H and W answer when their action ends (their rows say so); everything else at once."""
    from conform.families.gve.conformance.checks import generate

    v = spec.variant("gve64-v19")
    late = {cid: c.answer_within for cid, c in v.commands.items() if c.answer_within != 0.5}
    assert late == {"H": 5.0, "W": 60.0, "G": 1.0}
    steps = [st for ch in generate(spec, "gve64-v19") for st in ch.script
             if st.line is not None and (st.line == b"!0H\r" or st.line.startswith(b"!0H,"))]
    assert steps and {st.timeout for st in steps} == {5.0}


def _broken(tmp_path: Path, file: str, old: str, new: str) -> Path:
    root = tmp_path / "specs"
    shutil.copytree(load_spec().root, root)
    path = root / file
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))
    return root


@pytest.mark.parametrize(
    ("file", "old", "new", "pattern"),
    [
        ("commands.toml", 'family = "vector"', 'family = "vectr"',
         r"commands\.toml:\d+: command 'L' \(row 3\): field 'family': 'vectr' is not one of"),
        ("commands.toml", 'clause = ["GVE64 §13.5.3", "GVE124 §12.5.3"]', 'clause = ["page 12"]',
         r"commands\.toml:\d+: command 'A' .*field 'clause': 'page 12' is not a clause"),
        ("commands.toml", 'range = "velocity" }', 'range = "velo" }',
         r"variants\.toml:\d+: variant 'gve64-v10': field 'ranges': command 'V' needs range 'velo'"),
        ("variants.toml", 'queue = 128', 'queue = "many"', r"variant 'gve124'"),
        ("variants.toml", 'remove_commands = ["P4"', 'remove_commands = ["P5"',
         r"variant 'gve124': field 'remove_commands': 'P5' is not in the base"),
        ("errors.toml", "code = 7", "code = 9", r"errors\.toml:\d+: error 9 \(row 8\): field 'code'"),
        ("questions.toml", 'default = "silent"', 'default = "loud"',
         r"questions\.toml:\d+: question 'A23' .*field 'default'"),
        ("eeprom.toml", "address = 0xFD", "address = 0x1FD", r"eeprom\.toml:\d+: cell .*field 'address'"),
        ("commands.toml", "[[command]]\nid = \"Q\"", "[[command]]\nid = \"Q\"\nbogus = 1",
         r"command 'Q' \(row 2\): field 'bogus': unknown field"),
        ("status.toml", "queue_full_bit = 5", "queue_full_bit = [", r"status\.toml: "),
        ("commands.toml", "answer_within = 5.0", "answer_within = nan",
         r"command 'H' .*field 'answer_within': expected seconds"),
        ("commands.toml", "answer_within = 60.0", "answer_within = 0",
         r"command 'W' .*field 'answer_within': expected seconds"),
    ],
)
def test_malformed_table_gives_one_line(tmp_path, file, old, new, pattern):
    root = _broken(tmp_path, file, old, new)
    with pytest.raises(SpecError) as info:
        load_spec(root)
    message = str(info.value)
    assert "\n" not in message
    assert re.search(pattern, message), message


def test_malformed_table_cli_exit(tmp_path):
    root = _broken(tmp_path, "commands.toml", 'family = "vector"', 'family = "vectr"')
    proc = subprocess.run([sys.executable, "-m", "conform", "spec", "check", "--specs", str(root)],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "commands.toml" in lines[0] and "family" in lines[0]


def test_spec_cli_commands():
    run = lambda *a: subprocess.run([sys.executable, "-m", "conform", "spec", *a],  # noqa: E731
                                    capture_output=True, text=True)
    out = run("list")
    assert out.returncode == 0 and all(v in out.stdout for v in VARIANTS)
    out = run("diff", "gve64-v10", "gve64-v19")
    assert out.returncode == 0
    for name in ("VL", "VK", "VN", "XM", "N<axis>", "GVE64 §14.1") [:5]:
        assert name in out.stdout
    out = run("diff", "gve64-v19", "gve124")
    for name in ("P4", "I2", "EFR", "EUR", "EFW", "EUW", "status_words", "420", "128"):
        assert name in out.stdout, name
    assert re.search(r"│ Y\s", out.stdout)
    out = run("show", "gve124", "V")
    assert "GVE124 §12.5.3" in out.stdout and "10..100000" in out.stdout
    out = run("show", "gve64-v10", "VL")
    assert out.returncode != 0 and "absent" in out.stderr
