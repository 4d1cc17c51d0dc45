"""Marlin's tables load, every row cites the source, variants are deltas on one base, a bad row
is one line naming file, row and field, and `conform spec list|show|check` show Marlin."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from conform.errors import UserError
from conform.families.marlin.spec import diff, load_marlin

S = load_marlin()


def test_variants_are_a_base_and_a_delta():
    base, adv = S.variant("marlin-2.1"), S.variant("marlin-2.1-adv")
    assert base.base is None and adv.base == "marlin-2.1"
    assert (base.bufsize, base.max_cmd_size, base.block_buffer, base.keepalive) == (4, 96, 16, 2)
    assert [d[0] for d in diff(base, adv)] == ["option ADVANCED_OK", "option EMERGENCY_PARSER"]
    assert adv.bufsize == base.bufsize and adv.cite["bufsize"] == base.cite["bufsize"]


def test_every_row_cites_a_source():
    for m in S.messages.values():
        assert ".cpp" in m.cite or ".h" in m.cite, m.kind
    for c in S.commands.values():
        assert ".cpp" in c.cite, c.code
    for key in ("bufsize", "max_cmd_size", "rx_buffer", "block_buffer", "keepalive", "options"):
        assert S.variant("marlin-2.1").cite[key]


@pytest.mark.parametrize(("edit", "words"), [
    (('bufsize = 4', 'bufsize = "four"'), ["variants.toml", "variant.marlin-2.1", "'bufsize'"]),
    (('base = "marlin-2.1"', 'base = "marlin-9"'), ["variant.marlin-2.1-adv", "no variant"]),
    (('ADVANCED_OK = true', 'ADVANCED_OK = 1'), ["options.ADVANCED_OK"]),
])
def test_a_bad_row_is_one_line(tmp_path, edit, words):
    src = S.root
    shutil.copytree(src, tmp_path / "t")
    p = tmp_path / "t" / "variants.toml"
    text = p.read_text()
    assert edit[0] in text
    p.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(UserError) as e:
        load_marlin(str(tmp_path / "t"))
    assert "\n" not in str(e.value) and all(w in str(e.value) for w in words), str(e.value)


def test_bad_command_kind_and_pattern(tmp_path):
    shutil.copytree(S.root, tmp_path / "t")
    p = tmp_path / "t" / "commands.toml"
    p.write_text(p.read_text().replace('kind = "sync"', 'kind = "teleport"'))
    with pytest.raises(UserError, match=r"commands.toml: \[command.M400\] field 'kind'"):
        load_marlin(str(tmp_path / "t"))


def _conform(*args):
    return subprocess.run([sys.executable, "-m", "conform", *args], capture_output=True,
                          text=True, timeout=60)


def test_spec_cli_shows_marlin():
    listing = _conform("spec", "list")
    assert listing.returncode == 0 and "marlin-2.1-adv" in listing.stdout
    delta = _conform("spec", "show", "marlin-2.1-adv", "base", "--json")
    assert delta.returncode == 0 and "EMERGENCY_PARSER" in delta.stdout
    check = _conform("spec", "check")
    assert "ok: marlin: 2 variants" in check.stdout
    bad = _conform("spec", "show", "marlin-2.1", "nonsense")
    assert bad.returncode == 2 and "nothing called 'nonsense'" in bad.stderr


def test_spec_show_names_one_command():
    m115 = _conform("spec", "show", "marlin-2.1", "M115", "--json")
    assert m115.returncode == 0, m115.stderr
    rows = {r["field"]: r["value"] for r in json.loads(m115.stdout)["rows"]}
    assert rows["in this build"] == "yes" and "M115.cpp" in rows["source"]
    assert "Cap:REPEAT:0" in rows["capabilities"] and "PROTOCOL_VERSION:1.0" in rows["first line"]
    m92 = {r["field"]: r["value"] for r in json.loads(_conform(
        "spec", "show", "marlin-2.1", "m92", "--json").stdout)["rows"]}
    assert m92["power-up"] == "M92 X80.00 Y80.00 Z400.00 E500.00"
    t7 = {r["field"]: r["value"] for r in json.loads(_conform(
        "spec", "show", "marlin-2.1", "T7", "--json").stdout)["rows"]}
    assert "echo:T<n> Invalid extruder" in t7["tools"]
    # a command the tables do not have is refused, saying what the unit answers to it
    g20 = _conform("spec", "show", "marlin-2.1", "G20", "--json")
    assert g20.returncode == 2 and not g20.stdout, g20.stdout
    assert "no command G20 in marlin-2.1's tables" in g20.stderr
    assert 'echo:Unknown command: \"G20\"' in g20.stderr
    # printed as written: ':REPEAT:' is not an emoji code for the terminal table
    assert "Cap:REPEAT:0" in _conform("spec", "show", "marlin-2.1", "M115").stdout
