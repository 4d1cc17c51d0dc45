"""``conform emulate judge``: a reference unit held to what a unit answered in a recording.

The Marlin transcript's answers are those Marlin 2.1.2.4's queue.cpp prints and the three the
Marlin issue reports from the real firmware (see the transcript's header), written by hand, not
produced by the reference unit; deviant units must disagree with it where they deviate."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conform.emulator.judge import judge, lines_of, parse_text, read_transcript
from conform.errors import UserError
from conform.families import family
from conform.link import open_port

FACTS = Path(__file__).parent / "data" / "marlin" / "facts-2.1.2.4.transcript"
REPO = Path(__file__).resolve().parent.parent


def conform(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "conform", *args], capture_output=True,
                          text=True, timeout=120, cwd=cwd)


def judged(mutant: str | None, variant: str = "marlin-2.1", source: Path = FACTS):
    fam = family("marlin")
    unit = fam.make_unit(variant, mutant=mutant) if mutant else fam.make_unit(variant)
    return judge(read_transcript(source), unit, fam.judge_mask(variant), variant)


def test_the_reference_agrees_with_marlins_answers() -> None:
    r = conform("emulate", "judge", str(FACTS), "--variant", "marlin-2.1")
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.startswith("facts-2.1.2.4.transcript: AGREES with the reference marlin-2.1: "
                               "21 of 21 recorded answer lines matched")


@pytest.mark.parametrize(("mutant", "after", "recorded", "reference"), [
    # a repeat gets no answer in 2.1.2.4; the deviant one asks for a resend
    ("answers-duplicate", "N1 M105*38", [], ["Error:Line Number is not Last Line Number+1, "
                                             "Last Line: 1\n", "Resend: 2\n", "ok\n"]),
    # the checksum after a ';' is lost with the comment
    ("comment-keeps-checksum", "N2 G4 P0;wait*111",
     ["Error:No Checksum with line number, Last Line: 1\n"],
     ["Error:checksum mismatch, Last Line: 1\n"]),
    # it takes the last line accepted to be one less, and asks for that one again
    ("resend-off-by-one", "N2 G4 P0;wait*111",
     ["Error:No Checksum with line number, Last Line: 1\n", "Resend: 2\n"],
     ["Error:No Checksum with line number, Last Line: 0\n", "Resend: 1\n"]),
    ("silent-unknown", "G20", ['echo:Unknown command: "G20"\n'], []),
])
def test_a_deviant_unit_disagrees_where_it_deviates(mutant, after, recorded, reference) -> None:
    v = judged(mutant)
    assert not v.agrees
    first = v.differences[0]
    assert first.after_host == after
    assert first.recorded == recorded
    assert first.reference == reference


def test_advanced_ok_is_a_difference_of_the_ok_lines_only() -> None:
    v = judged(None, "marlin-2.1-adv")
    assert not v.agrees
    # ok_to_send adds " N<n>" for a numbered line and P/B; the ok after Resend: is plain
    assert [d.reference for d in v.differences] == [
        ["ok P15 B3\n"], ["ok N2 P15 B3\n"], ["ok N3 P15 B3\n"],
        ["ok P15 B3\n", "ok P15 B3\n"]]    # G20's and G21's, one after the other
    assert all(d.recorded == ["ok\n"] * len(d.reference) for d in v.differences)


def test_a_session_recorded_over_ptys_is_judged(tmp_path, emulate) -> None:
    """The user's way: a session recorded by `conform proxy` in front of a unit, then judged."""
    from tests.test_capture_live import start_proxy

    _, unit_path = emulate("serve", "marlin-2.1", "--baud", "115200")
    out = tmp_path / "session.mcap"
    proxy, host_path = start_proxy("--unit", unit_path, "-o", str(out), "--baud", "115200", "-q")
    try:
        with open_port(host_path, 115200) as port:
            time.sleep(0.3)
            for line in (b"M110 N0\n", b"N1 M105*38\n", b"N1 M105*38\n", b"N2 G4 P0;c*111\n",
                         b"N2 G4 P0*111\n", b"N3 M114*36\n", b"G21\n"):
                port.write(line)
                time.sleep(0.15)
            time.sleep(0.3)
        proxy.send_signal(2)
        assert proxy.wait(15) == 0, proxy.stderr.read().decode()
    finally:
        proxy.kill()
    r = conform("emulate", "judge", str(out), "--variant", "marlin-2.1", "--json")
    assert r.returncode == 0, r.stdout + r.stderr
    assert '"agrees": true' in r.stdout and '"recorded_lines": 0' not in r.stdout
    deviant = judged("answers-duplicate", source=out)
    assert not deviant.agrees and deviant.differences[0].after_host == "N1 M105*38"


def test_lines_keep_their_terminators() -> None:
    assert lines_of(b"0,5C\r1\r\nok\nrest") == ["0,5C\r", "1\r\n", "ok\n", "rest"]


def test_transcript_times_and_raw_bytes() -> None:
    t = parse_text("> M105\n1.5 >! \\x18\n< ok\n< ok\n", "x")
    assert [(e.t, e.host, e.data) for e in t.events] == [
        (0.0, True, b"M105\n"), (1.5, True, b"\x18"), (1.7, False, b"ok\n"),
        (1.9, False, b"ok\n")]


@pytest.mark.parametrize(("text", "message"), [
    ("> M105\nok\n", "x:2: expected '[SECONDS] > LINE'"),
    ("2 > M105\n1 < ok\n", "x:2: time 1.0 is before the previous event's 2.0"),
    ("< ok\n", "x: no host line ('>') in the transcript"),
    ("> a\n>! \\x1\n", "x:2: bad escape"),
])
def test_a_bad_transcript_is_one_line_naming_the_line(text, message) -> None:
    with pytest.raises(UserError, match="^" + message.replace("(", r"\(").replace(")", r"\)")
                       .replace("[", r"\[").replace("]", r"\]").replace("+", r"\+")):
        parse_text(text, "x")


def test_bad_input_on_the_command_line(tmp_path) -> None:
    bad = tmp_path / "bad.transcript"
    bad.write_bytes(b"> M105\n\xff\xfe < ok\n")
    no_variant = tmp_path / "n.transcript"
    no_variant.write_text("> M105\n< ok\n")
    for args, says in (
        ((str(bad), "--variant", "marlin-2.1"), "not an MCAP capture nor a UTF-8 transcript"),
        ((str(no_variant),), "names no variant: give --variant"),
        ((str(tmp_path / "missing"), "--variant", "marlin-2.1"), "cannot read"),
    ):
        r = conform("emulate", "judge", *args)
        assert r.returncode == 2, r.stderr
        assert says in r.stderr and "Traceback" not in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1


def test_the_readme_path_works_from_a_clean_cwd(tmp_path) -> None:
    env_ok = os.path.exists(FACTS)
    assert env_ok
    r = conform("emulate", "judge", str(FACTS), "--variant", "marlin-2.1", cwd=tmp_path)
    assert r.returncode == 0 and not list(tmp_path.iterdir())
