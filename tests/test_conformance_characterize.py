"""Characterisation: a profile taken from an emulator dialect reproduces that dialect."""

from __future__ import annotations

import pytest

from conform.cli.main import main
from conform.families.gve.conformance.characterize import characterize, to_profile
from conform.families.gve.conformance.profile import (
    diff_profiles,
    load_profile,
    load_profile_dialect,
    write_profile,
)
from conform.families.gve.conformance.target import open_target

DIALECTS = [
    {},
    {"A10": "every-line", "A13": "20ms", "A15": "no-effect-0", "A14": "reset-blocks"},
    {"A1": "cr-or-lf", "A6": "1-65535", "A9": "hex-index", "A24": "ok-only"},
    {"A5": "excludes-running", "A11": "watchdog-2", "A12": "skip-bad", "A17": "silent",
     "A26": "vk-unlimited-100"},
    {"A2": "s-too", "A3": "zero-too", "A4": "queued", "A21": "any-case", "A23": "error-3",
     "A25": "1ms", "A27": "all-allowed", "A28": "all-ff", "A16": "discarded",
     "A18": "hex-bytes", "A29": "every-line"},
]


@pytest.mark.parametrize("choices", DIALECTS, ids=lambda d: ",".join(d) or "defaults")
def test_profile_of_an_emulator_reproduces_its_dialect(spec, choices, tmp_path):
    dialect = spec.dialect(choices)
    target, _ = open_target("emu:gve64-v10", spec, dialect=dialect)
    found, findings = characterize(spec, target, "gve64-v10")
    assert found.changed() == dialect.changed()
    # what cannot be told apart on this variant is said so, not guessed silently
    assert findings["A19"].status == "ambiguous" and findings["A2"].status == "determined"
    path = tmp_path / "unit.toml"
    write_profile(to_profile(spec, found, findings, target="emu:gve64-v10",
                             variant="gve64-v10"), path)
    assert load_profile_dialect(spec, path).changed() == dialect.changed()
    assert load_profile(path).evidence["A2"]["probe"] == ["!0S100"]


def test_gve124_questions_it_can_answer(spec):
    dialect = spec.dialect({"A20": "missing-reads-0", "A7": "rate-limited", "A19": "none",
                            "A8": "1-255"})
    target, _ = open_target("emu:gve124", spec, dialect=dialect)
    found, findings = characterize(spec, target, "gve124")
    assert found.changed() == dialect.changed()
    assert findings["A18"].status == "not-probed"


def test_profile_diff_and_cli(spec, tmp_path, capsys):
    paths = []
    for name, choices in (("a", {}), ("b", {"A15": "no-effect-0"})):
        target, _ = open_target("emu:gve64-v19", spec, dialect=spec.dialect(choices))
        found, findings = characterize(spec, target, "gve64-v19")
        path = tmp_path / f"{name}.toml"
        write_profile(to_profile(spec, found, findings, target="emu", variant="gve64-v19"), path)
        paths.append(path)
    assert diff_profiles(load_profile(paths[0]), load_profile(paths[1])) == [
        ("A15", "error-6", "no-effect-0")]
    with pytest.raises(SystemExit) as info:
        main(["profile", "diff", str(paths[0]), str(paths[1])])
    assert info.value.code == 1
    assert "no-effect-0" in capsys.readouterr().out
    out = tmp_path / "c.toml"
    with pytest.raises(SystemExit) as info:
        main(["characterize", "emu:gve64-v19", "-o", str(out)])
    assert info.value.code == 0
    assert load_profile(out).dialect == dict(spec.dialect().choices)
    partial = tmp_path / "partial.toml"
    partial.write_text('[dialect]\nA15 = "no-effect-0"\n')
    with pytest.raises(SystemExit) as info:
        main(["profile", "diff", str(paths[1]), str(partial)])
    assert info.value.code == 0  # a question left out is its default
    bad = tmp_path / "bad.toml"
    bad.write_text('[dialect]\nA10 = "sometimes"\n')
    with pytest.raises(SystemExit) as info:
        main(["run", "--dialect", str(bad)])
    assert info.value.code == 2


def test_lenient_number_syntax_is_characterised(spec):
    dialect = spec.dialect({"A22": "lenient", "A11": "watchdog-2"})
    target, _ = open_target("emu:gve64-v19", spec, dialect=dialect)
    found, _ = characterize(spec, target, "gve64-v19")
    assert found.changed() == dialect.changed()


def test_a_partial_profile_is_refused_as_a_dialect(spec, tmp_path, capsys):
    """Its unanswered questions would silently take the defaults: `run --dialect` and
    `emulate serve --profile` refuse it in one line (exit 2); `profile diff` reads it."""
    from conform.families.gve.conformance.characterize import Finding

    found = {q: Finding(q, "determined", spec.dialect().choices[q], [], [], [])
             for q in ("A1", "A2")}
    partial = tmp_path / "partial.toml"
    write_profile(to_profile(spec, None, found, target="emu:gve64-v19", variant="gve64-v19",
                             interrupted="Ctrl-C after 2 of 29 questions"), partial)
    for args in (["run", "--dialect", str(partial), "-q"],
                 ["emulate", "serve", "gve64-v19", "--profile", str(partial)]):
        with pytest.raises(SystemExit) as info:
            main(args)
        assert info.value.code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "a partial profile (Ctrl-C after 2 of 29 questions) leaves " \
            "A3, A4" in err[0], err


def test_characterize_help_says_what_each_family_asks(capsys):
    """The command's own text names no family's questions; each family describes its probes
    (Family.characterize_about) under the help."""
    from conform.cli.main import cli
    from conform.families import families

    with pytest.raises(SystemExit):
        cli.main(["characterize", "--help"], prog_name="conform")
    text = capsys.readouterr().out
    own, listed = text.split("What each family asks:")
    assert "A1" not in own and "A18" not in own and "open question" not in own
    for fam in families():
        if fam.characterize_about:
            assert f"\n  {fam.name} " in listed
    assert "A1-A29" in listed.split("\n  grbl")[0]          # GVE's questions, under GVE
