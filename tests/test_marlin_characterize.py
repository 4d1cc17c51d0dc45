"""``conform characterize`` on a Marlin unit: the build's configuration read by harmless probes,
each observed value beside the tables' (which cite Marlin's Configuration.h and queue.cpp)."""

from __future__ import annotations

import subprocess
import sys
import tomllib

import pytest

from conform.conformance.target import EmuTarget
from conform.families import family
from conform.families.marlin.conformance.characterize import characterize


def observed(variant: str, mutant: str | None = None) -> dict:
    fam = family("marlin")
    options = {"mutant": mutant} if mutant else {}
    target = EmuTarget(lambda: fam.make_unit(variant, **options), f"emu:{variant}")
    return {o.name: o for o in characterize(target, variant)}


@pytest.mark.parametrize("variant", ["marlin-2.1", "marlin-2.1-adv"])
def test_the_reference_units_are_what_their_tables_say(variant) -> None:
    obs = observed(variant)
    assert [n for n, o in obs.items() if not o.same] == []
    assert obs["max_cmd_size"].observed == 96 and obs["keepalive"].observed == 2
    assert obs["advanced_ok"].observed is (variant == "marlin-2.1-adv")
    # ADVANCED_OK's ok of an idle unit tells the queue and planner sizes
    assert ("bufsize" in obs) is (variant == "marlin-2.1-adv")
    assert obs["cap.EEPROM"].observed == 1            # EEPROM_SETTINGS (linux_native)


@pytest.mark.parametrize(("mutant", "item", "value"), [
    ("no-keepalive", "keepalive", 0),
    ("answers-duplicate", "repeat_is_silent", False),
])
def test_a_deviant_build_is_told_apart(mutant, item, value) -> None:
    obs = observed("marlin-2.1", mutant)
    assert obs[item].observed == value and not obs[item].same


@pytest.mark.slow
def test_over_a_pty_the_profile_is_written(tmp_path, emulate) -> None:
    _, path = emulate("serve", "marlin-2.1", "--baud", "115200")
    out = tmp_path / "unit.toml"
    r = subprocess.run([sys.executable, "-m", "conform", "characterize", path, "--variant",
                        "marlin-2.1", "--baud", "115200", "-o", str(out)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert f"{out}: 0 item(s) differ from the tables" in r.stdout
    prof = tomllib.loads(out.read_text())
    assert prof["variant"] == "marlin-2.1"
    assert prof["observed"]["keepalive"] == prof["table"]["keepalive"] == 2
    assert prof["observed"]["cap.AUTOREPORT_TEMP"] == 1
    assert "busy: lines at" in prof["evidence"]["keepalive"]


def test_the_emergency_parser_is_told_by_m108_ending_m0() -> None:
    assert observed("marlin-2.1")["emergency_parser"].observed is False      # M0 unknown
    ep = observed("marlin-2.1-adv")["emergency_parser"]
    assert ep.observed is True and ep.same and "M108 sent at 0.5 s" in ep.evidence
    # a build whose M0 waits out its time although M108 came: no emergency parser at work
    deaf = observed("marlin-2.1-adv", "user-wait-always")["emergency_parser"]
    assert deaf.observed is False and not deaf.same


def test_interrupted_it_writes_what_it_found_marked_partial(tmp_path, monkeypatch) -> None:
    """Ctrl-C during the keepalive dwell: M115's items, the ok format and MAX_CMD_SIZE are
    written, marked partial, with the items not reached listed; exit 130's one line."""
    from conform.errors import UserError
    from conform.families.marlin.conformance import characterize as probe

    def interrupted(*_a, **_kw):
        raise KeyboardInterrupt

    monkeypatch.setattr(probe, "_keepalive", interrupted)
    out = tmp_path / "m.toml"
    with pytest.raises(UserError) as info:
        family("marlin").characterize("emu:marlin-2.1", str(out), None, echo=lambda *_: None)
    assert info.value.exit_code == 130 and f"partial profile {out}" in str(info.value)
    prof = tomllib.loads(out.read_text())
    assert prof["partial"] is True and prof["interrupted"].startswith("Ctrl-C after")
    assert prof["unanswered"] == ["keepalive", "repeat_is_silent", "emergency_parser"]
    assert prof["observed"]["max_cmd_size"] == 96 and "keepalive" not in prof["observed"]


def test_profile_diff_names_what_differs_between_two_builds(tmp_path) -> None:
    paths = []
    for variant in ("marlin-2.1", "marlin-2.1-adv"):
        paths.append(tmp_path / f"{variant}.toml")
        r = subprocess.run([sys.executable, "-m", "conform", "characterize", f"emu:{variant}",
                            "-o", str(paths[-1]), "-q"], capture_output=True, text=True,
                           timeout=120)
        assert r.returncode == 0, r.stderr
    same = subprocess.run([sys.executable, "-m", "conform", "profile", "diff", str(paths[0]),
                           str(paths[0])], capture_output=True, text=True, timeout=60)
    assert same.returncode == 0 and same.stdout.strip() == "same observations"
    d = subprocess.run([sys.executable, "-m", "conform", "profile", "diff", *map(str, paths)],
                       capture_output=True, text=True, timeout=60)
    assert d.returncode == 1
    rows = {line.split()[0]: line.split()[1:] for line in d.stdout.splitlines()[1:]}
    # what the -adv variant's tables add (ADVANCED_OK, EMERGENCY_PARSER), and only that
    assert rows == {"cap.EMERGENCY_PARSER": ["0", "1"], "advanced_ok": ["false", "true"],
                    "emergency_parser": ["false", "true"], "planner_blocks": ["(absent)", "15"],
                    "bufsize": ["(absent)", "4"]}
    grbl = tmp_path / "g.toml"
    subprocess.run([sys.executable, "-m", "conform", "characterize", "emu:grbl-1.1f", "-o",
                    str(grbl), "-q"], capture_output=True, timeout=120, check=True)
    mixed = subprocess.run([sys.executable, "-m", "conform", "profile", "diff", str(grbl),
                            str(paths[0])], capture_output=True, text=True, timeout=60)
    assert mixed.returncode == 2 and "profiles of one family only" in mixed.stderr
