"""``conform emulate judge``: a reference unit held to what a unit answered in a recording.

The Marlin transcript's answers are those Marlin 2.1.2.4's queue.cpp prints and the three the
Marlin issue reports from the real firmware (see the transcript's header), written by hand, not
produced by the reference unit; deviant units must disagree with it where they deviate."""

from __future__ import annotations

import os
import shutil
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
                               "20 of 20 recorded answer lines matched")


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
        ["ok P15 B3\n"], ["ok N2 P15 B3\n"], ["ok N3 P15 B3\n"], ["ok P15 B3\n"]]
    assert all(d.recorded == ["ok\n"] for d in v.differences)


@pytest.mark.slow
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
        ((str(no_variant),), "names no variant and its folder has no VARIANT file: give --variant"),
        ((str(tmp_path / "missing"), "--variant", "marlin-2.1"), "cannot read"),
    ):
        r = conform("emulate", "judge", *args)
        assert r.returncode == 2, r.stderr
        assert says in r.stderr and "Traceback" not in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1


def test_a_folders_variant_file_names_the_variant(tmp_path) -> None:
    """A folder of one firmware's recordings names its variant once, in ``VARIANT`` (as the
    recordings' README does): its transcripts are judged without --variant; an unknown id is
    one line naming that file; --variant still wins."""
    shutil.copy(FACTS, tmp_path / "facts.transcript")
    (tmp_path / "VARIANT").write_text("marlin-2.1\n")
    r = conform("emulate", "judge", str(tmp_path / "facts.transcript"))
    assert r.returncode == 0 and "AGREES with the reference marlin-2.1" in r.stdout, r.stderr
    r = conform("emulate", "judge", str(tmp_path / "facts.transcript"), "--variant", "grbl-1.1f")
    assert r.returncode == 2 and "not grbl-1.1f" in r.stderr, r.stderr
    (tmp_path / "VARIANT").write_text("marlin-9\n")
    r = conform("emulate", "judge", str(tmp_path / "facts.transcript"))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().splitlines() == [
        f"conform: {tmp_path / 'VARIANT'}: 'marlin-9' is not a variant (known: "
        + r.stderr.split("(known: ", 1)[1].strip()], r.stderr
    assert "marlin-2.1" in r.stderr.split("(known: ", 1)[1]


def test_the_readme_path_works_from_a_clean_cwd(tmp_path) -> None:
    env_ok = os.path.exists(FACTS)
    assert env_ok
    r = conform("emulate", "judge", str(FACTS), "--variant", "marlin-2.1", cwd=tmp_path)
    assert r.returncode == 0 and not list(tmp_path.iterdir())


class _Slow:
    """A sans-I/O unit that takes ``busy`` seconds for each line and answers ``ok`` (or
    ``error:busy`` to a line that arrives while it works); the lines listed in ``silent`` it
    never answers."""

    def __init__(self, busy: float, silent: tuple[str, ...] = (), ending: str = "\n") -> None:
        self.busy, self.silent, self.ending = busy, silent, ending
        self.now, self.free, self.due = 0.0, 0.0, []
        self.got: list[tuple[float, bytes]] = []

    def receive(self, data: bytes, t: float) -> None:
        self.now = max(self.now, t)
        self.got.append((t, data))
        for line in data.decode().splitlines():
            if line in self.silent or not data.endswith(b"\n"):
                continue
            if t < self.free:
                self.due.append((t, f"error:busy{self.ending}".encode()))
                continue
            self.free = t + self.busy
            self.due.append((self.free, f"ok {line}{self.ending}".encode()))

    def poll(self, t: float) -> list[tuple[float, bytes]]:
        self.now = max(self.now, t)
        out = [d for d in self.due if d[0] <= t]
        self.due = [d for d in self.due if d[0] > t]
        return out

    def next_deadline(self) -> float | None:
        return min((d[0] for d in self.due), default=None)


_PACED = "".join(f"{i * 0.2:.3f} > L{i}\n{i * 0.2 + 0.01:.3f} < ok L{i}\n" for i in range(10))


def test_writes_are_paced_by_the_answers_not_the_clock() -> None:
    """The recorded sender waited for each ok; a reference five times slower still gets each
    line after its previous answer (at the recorded clock it would get them while busy)."""
    v = judge(parse_text(_PACED, "paced"), _Slow(0.05), lambda x: x, "slow")
    assert v.agrees, v.differences
    unit = _Slow(0.5)
    assert judge(parse_text(_PACED, "paced"), unit, lambda x: x, "slow").agrees
    times = [t for t, _ in unit.got]
    assert all(b - a >= 0.5 for a, b in zip(times, times[1:], strict=False))


def test_a_line_never_answered_is_one_difference_and_no_hang() -> None:
    unit = _Slow(0.05, silent=("L3",))
    v = judge(parse_text(_PACED, "paced"), unit, lambda x: x, "slow")
    assert [(d.recorded, d.reference, d.after_host) for d in v.differences] == [
        (["ok L3\n"], [], "L3")]
    assert v.same == 9
    # the wait for the missing answer is bounded, and only the one write after it waits
    times = [t for t, _ in unit.got]
    assert times[4] - times[3] <= 0.2 * 1.5 + 2.0 + 1e-9
    assert all(b - a < 0.3 for a, b in zip(times[4:], times[5:], strict=False))


def test_bytes_put_in_before_the_answer_keep_their_relative_timing() -> None:
    text = ("0.000 > G4\n0.500 >! !\n0.700 > M1\n2.000 < ok G4\n2.010 < ok M1\n"
            "2.300 > M2\n2.310 < ok M2\n")
    unit = _Slow(0.0)
    judge(parse_text(text, "x"), unit, lambda x: x, "slow")
    times = [round(t, 3) for t, _ in unit.got]
    assert times[:3] == [0.0, 0.5, 0.7]           # before any answer: as recorded
    # after M1's answer (at 0.7 here) + 0.29 s, but not sooner after M1 than recorded
    assert times[3] == 2.3
    slow = _Slow(3.0)
    judge(parse_text(text, "x"), slow, lambda x: x, "slow")
    # G4's answer comes at 3.0 here (M1's, refused while busy, at 0.7): 0.29 s after it
    assert [round(t, 3) for t, _ in slow.got] == [0.0, 0.5, 0.7, 3.29]


def test_a_family_line_ending_is_given_to_text_transcripts() -> None:
    from conform.emulator.judge import with_line_ending

    text = "0 > L0\n0.01 < ok L0\n"
    plain = parse_text(text, "crlf")
    assert not judge(plain, _Slow(0.0, ending="\r\n"), lambda x: x, "crlf").agrees
    crlf = with_line_ending(plain, "\r\n")
    assert crlf.events[1].data == b"ok L0\r\n" and crlf.events[0].data == b"L0\n"
    assert judge(crlf, _Slow(0.0, ending="\r\n"), lambda x: x, "crlf").agrees


def test_the_family_tolerance_pairs_lines_that_differ_within_it() -> None:
    text = "0 > L0\n0.01 < ok L0\n0.02 < pos 1.00\n0.03 < ok tail\n"

    class Pos(_Slow):
        def receive(self, data: bytes, t: float) -> None:
            super().receive(data, t)
            self.due += [(t, b"pos 1.04\n"), (t, b"ok tail\n")]

    def near(a: str, b: str) -> bool:
        return a.startswith("pos ") and b.startswith("pos ") and \
            abs(float(a[4:]) - float(b[4:])) <= 0.05

    t = parse_text(text, "near")
    assert not judge(t, Pos(0.0), lambda x: x, "x").agrees
    v = judge(t, Pos(0.0), lambda x: x, "x", near=near)
    assert v.agrees and v.same == 3


def test_a_grbl_transcript_is_compared_with_crlf_lines() -> None:
    text = ("# grbl ends every line with \\r\\n\n0.000 >! ?\n"
            "0.020 < <Idle|MPos:0.000,0.000,0.000|FS:0,0|WCO:0.000,0.000,0.000>\n"
            "0.100 > $G\n0.120 < [GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]\n0.120 < ok\n")
    from conform.emulator.judge import judge_recording

    v = judge_recording(parse_text(text, "g"), family("grbl"), "grbl-1.1f")
    assert v.agrees and v.same == 3, v.differences


@pytest.mark.parametrize(("source", "variant", "says"), [
    (FACTS, "grbl-1.1f", "facts-2.1.2.4.transcript: a marlin recording ("),
])
def test_another_familys_recording_is_refused_in_one_line(source, variant, says) -> None:
    r = conform("emulate", "judge", str(source), "--variant", variant)
    assert r.returncode == 2, r.stdout + r.stderr
    assert says in r.stderr and "not grbl-1.1f" in r.stderr and "DIFFERS" not in r.stdout
    assert len(r.stderr.strip().splitlines()) == 1


def test_a_grbl_recording_is_refused_by_another_family(tmp_path) -> None:
    from conform.emulator.judge import judge_recording

    text = ("0.000 >! ?\n0.020 < <Idle|MPos:0.000,0.000,0.000|FS:0,0>\n0.100 > $G\n"
            "0.120 < [GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]\n0.120 < ok\n"
            "0.200 > G4 P0\n0.210 < ok\n0.300 > $I\n0.320 < [VER:1.1f.20170801:]\n0.320 < ok\n")
    with pytest.raises(UserError, match=r"^g: a grbl recording \(.*\), not marlin's: judge it "
                                        r"with a grbl variant \(grbl-1.1f.*\), not marlin-2.1$"):
        judge_recording(parse_text(text, "g"), family("marlin"), "marlin-2.1")


def test_the_family_follows_the_recorded_lines_before_each_write() -> None:
    """``judge_follow`` sees each recorded line before the host write it answered is played,
    so a family can put the reference where the recorded unit was (for an artefact it
    states); the lines are still compared."""
    seen: list[tuple[str, int]] = []
    unit = _Slow(0.0)
    text = "0 > L0\n0.01 < ok L0\n0.2 > L1\n0.21 < ok L1\n0.22 < note\n"
    v = judge(parse_text(text, "f"), unit, lambda x: x, "x",
              follow=lambda u, line: seen.append((line, len(u.got))))
    assert seen == [("ok L0", 0), ("ok L1", 1), ("note", 1)]
    assert [d.recorded for d in v.differences] == [["note\n"]]


class _Queue(_Slow):
    """A unit that queues lines and answers each ``busy`` seconds after the one before."""

    def receive(self, data: bytes, t: float) -> None:
        self.now = max(self.now, t)
        self.got.append((t, data))
        for line in data.decode().splitlines():
            self.free = max(self.free, t) + self.busy
            self.due.append((self.free, f"ok {line}\n".encode()))


def test_a_counting_senders_write_waits_for_room_as_recorded() -> None:
    """Three lines in flight, the fourth written after the first answer (two still owed):
    against a slower reference it goes after that reference's first answer, not before."""
    text = ("0.00 > A\n0.00 > B\n0.00 > C\n0.10 < ok A\n0.11 > D\n0.20 < ok B\n0.30 < ok C\n"
            "0.40 < ok D\n")
    unit = _Queue(1.0)
    v = judge(parse_text(text, "count"), unit, lambda x: x, "q")
    assert v.agrees, v.differences
    assert [round(t, 2) for t, _ in unit.got] == [0.0, 0.0, 0.0, 1.01]
