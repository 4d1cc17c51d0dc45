"""specs/grbl: the tables load, cover what the protocol has, cite a source on every row, and a
broken row is one clear line naming file, row and field."""

from __future__ import annotations

import shutil

import pytest

from conform.errors import UserError
from conform.families import detect_family, family, family_for_variant
from conform.families.grbl.spec.load import load_grbl, spec_dir


@pytest.fixture(scope="module")
def g():
    return load_grbl()


def test_codes_settings_and_sizes(g):
    assert sorted(g.errors) == [*range(1, 18), *range(20, 39)]
    assert sorted(g.alarms) == list(range(1, 10))
    v = g.variant("grbl-1.1f")
    assert (v.rx_buffer, v.line_max, v.planner_blocks, v.baud) == (128, 79, 15, 115200)
    assert v.banner == "Grbl 1.1f ['$' for help]"
    assert [n for n in g.settings if n >= 100] == [100, 101, 102, 110, 111, 112, 120, 121, 122,
                                                  130, 131, 132]
    assert g.settings[10].default == 1 and g.settings[0].lo == 3
    assert g.settings[11].text(0.01) == "0.010" and g.settings[30].text(1000.0) == "1000"


def test_every_row_cites_a_source(g):
    rows = [*g.errors.values(), *g.alarms.values(), *g.settings.values(), *g.messages.values(),
            *g.realtime.values(), *g.commands.values(), *g.examples]
    assert all(r.cite.strip() for r in rows)
    v = g.variant("grbl-1.1f")
    for name in ("rx_buffer", "line_max", "planner_blocks", "version", "baud"):
        assert v.cite[name]


def test_realtime_bytes_and_commands(g):
    want = {0x18, 0x3F, 0x21, 0x7E, 0x84, 0x85, 0x86, 0x87, 0xA0, 0xA1,
            *range(0x90, 0x98), *range(0x99, 0x9E)}
    assert want <= set(g.realtime)
    assert {"$", "$$", "$#", "$G", "$I", "$N", "$x=val", "$Nx=line", "$C", "$X", "$H",
            "$J=line", "$RST=$", "$RST=#", "$RST=*", "$SLP"} == set(g.commands)


@pytest.mark.parametrize("line,kind", [
    ("ok", "ok"), ("error:22", "error"), ("ALARM:3", "alarm"),
    ("Grbl 1.1f ['$' for help]", "banner"), ("<Idle|MPos:0.000,0.000,0.000|FS:0,0>", "status"),
    ("[MSG:Pgm End]", "msg"), ("[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]", "gc"),
    ("[HLP:$$ $#]", "hlp"), ("[VER:1.1f.20170801:]", "ver"), ("[OPT:V,15,128]", "opt"),
    ("[PRB:0.000,0.000,0.000:0]", "param"), ("[echo:G1X1]", "echo"), ("$10=1", "setting"),
    ("$N0=G54", "startup"), (">G54:ok", "startup_run"), ("0,5C", "unknown"),
])
def test_message_kinds(g, line, kind):
    assert g.classify(line)[0] == kind


@pytest.mark.parametrize("file,old,new,msg", [
    ("codes", 'name = "bad number format"', "name = 2", "[error.2] field 'name': expected str"),
    ("settings", "default = 10\n", "default = 1\n", "[setting.0] default 1 is outside 3..255"),
    ("protocol", "pattern = '^ok$'", "pattern = '^(ok$'", "[message.ok] pattern"),
    ("variants", "rx_buffer = 128", "rx_buffer = 64", "line_max must be below rx_buffer"),
    ("examples", 'id = "help"', "idx = 1", "[example #1] field 'id' is missing"),
    ("protocol", '[realtime."0x84"]', '[realtime."0x1FF"]', "within 0x00..0xFF"),
])
def test_a_broken_row_is_one_line(tmp_path, file, old, new, msg):
    root = tmp_path / "grbl"
    shutil.copytree(spec_dir(), root)
    path = root / f"{file}.toml"
    text = path.read_text(encoding="utf-8")
    assert old in text
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    with pytest.raises(UserError) as exc:
        load_grbl(root)
    assert msg in str(exc.value) and str(path) in str(exc.value)
    assert "\n" not in str(exc.value)


def test_registry_and_detection():
    assert family_for_variant("grbl-1.1f").name == "grbl"
    assert family_for_variant("gve64-v19").name == "gve"
    assert [v.id for v in family("grbl").variants()] == ["grbl-1.1f"]
    grbl = detect_family(b"G1X1F100\n?", b"\r\nGrbl 1.1f ['$' for help]\r\nok\r\n"
                                            b"<Idle|MPos:0.000,0.000,0.000|FS:0,0>\r\n")
    assert grbl.family == "grbl" and grbl.score > 0.9
    gve = detect_family(b"!0L100,0,0\r!0?\r", b"0\r0,IP64MPG v19\r")
    assert gve.family == "gve"
    assert detect_family(b"", b"0\r0,5C\r1\r8\r" * 30).family == "gve"   # a unit-only tap
    noise = detect_family(b"AT+CSQ\r\n" * 40, b"+CSQ: 20,99\r\nOK\r\n" * 40)
    assert noise.family == "unknown"
    assert detect_family(b"", b"", {"variant": "grbl-1.1f"}).family == "grbl"


def test_spec_commands_show_grbl():
    from click.testing import CliRunner

    from conform.cli.main import cli

    r = CliRunner()
    listed = r.invoke(cli, ["spec", "list"])
    assert listed.exit_code == 0 and "grbl-1.1f" in listed.output and "gve64-v19" in listed.output
    shown = r.invoke(cli, ["spec", "show", "grbl-1.1f", "settings"], terminal_width=200)
    assert shown.exit_code == 0 and "$130" in shown.output and "step pulse time" in shown.output
    assert r.invoke(cli, ["spec", "show", "grbl-1.1f", "bogus"]).exit_code != 0
    homing = r.invoke(cli, ["spec", "show", "grbl-1.1f", "$H"], terminal_width=200)
    assert homing.exit_code == 0 and "homing cycle" in homing.output and "Idle, Alarm" in \
        homing.output
    rate = r.invoke(cli, ["spec", "show", "grbl-1.1f", "$110"], terminal_width=200)
    assert rate.exit_code == 0 and "X-axis maximum rate" in rate.output
    lock = r.invoke(cli, ["spec", "show", "grbl-1.1f", "error:9"], terminal_width=200)
    assert lock.exit_code == 0 and "g-code lock" in lock.output
    status = r.invoke(cli, ["spec", "show", "grbl-1.1f", "?"], terminal_width=200)
    assert status.exit_code == 0 and "status report query" in status.output
    checked = r.invoke(cli, ["spec", "check"])
    assert checked.exit_code == 0 and "grbl: 1 variant, 36 error codes" in checked.output


def test_gve_only_options_are_usage_errors_for_grbl():
    import subprocess
    import sys

    for args, said in ((["emulate", "serve", "grbl-1.1f", "--dialect", "A1=crlf"],
                        "--dialect is an option of gve units; this emulate serve addresses a grbl unit"),
                       (["run", "--target", "emu:grbl-1.1f", "--dialect", "README.md"],
                        "--dialect is an option of gve units; this run addresses a grbl unit"),
                       (["emulate", "serve", "grbl-1.1f", "--answer-delay", "nan"],
                        "expected 0..60 seconds")):
        p = subprocess.run([sys.executable, "-m", "conform", *args], capture_output=True,
                           text=True, timeout=60)
        assert p.returncode == 2 and "Traceback" not in p.stderr
        assert said in p.stderr, p.stderr


def test_an_unknown_or_other_family_variant_names_every_family(tmp_path):
    import subprocess
    import sys

    from conform.errors import UserError
    from conform.families.grbl.spec.load import load_grbl
    from conform.families.gve.spec import load_spec

    with pytest.raises(UserError) as exc:
        load_spec().variant("grbl-1.1f")          # a GVE-only path given a grbl variant
    assert "is a grbl variant" in str(exc.value) and "gve64-v19" in str(exc.value)
    with pytest.raises(UserError) as exc:
        load_grbl().variant("nope")
    assert "grbl: grbl-1.1f" in str(exc.value) and "gve: gve64-v10" in str(exc.value)
    job = tmp_path / "job.txt"
    job.write_text("C100,0,0\n")
    for args in (["run", "--target", "emu:nope"], ["emulate", "nope"],
                 ["check-sender", "--variant", "nope", "--", "true"],
                 ["send", str(job), "--target", "emu:nope"]):
        p = subprocess.run([sys.executable, "-m", "conform", *args], capture_output=True,
                           text=True, timeout=60)
        assert p.returncode == 2 and p.stderr.count("\n") == 1, (args, p.stderr)
        assert "grbl-1.1f" in p.stderr and "gve124" in p.stderr, (args, p.stderr)


def test_the_report_names_the_command_as_typed(tmp_path):
    """In-process, sys.argv is pytest's: the command comes from the root context's argv."""
    import json

    from conform.cli.main import main

    args = ["run", "--target", "emu:grbl-1.1f", "--check", "*/example/help", "--report",
            str(tmp_path), "-q"]
    with pytest.raises(SystemExit) as exc:
        main(args)
    assert exc.value.code in (0, None)
    results = json.loads((tmp_path / "results.json").read_text())
    import shlex

    assert results["command"] == "conform " + shlex.join(args)
