"""What a new user meets (issue: no false success): a command that could not do its job says
so in one line and exits non-zero; nothing reports success for something that did not
happen. Grouped so that each command-line behaviour costs at most one subprocess."""

from __future__ import annotations

import json
import os
import pty
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from conform.cli.main import main

REPO = Path(__file__).resolve().parent.parent
GOOD = str(REPO / "captures" / "good-rs232.mcap")
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


def _code(argv: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as info:
        main(argv)
    out, err = capsys.readouterr()
    assert "Traceback" not in err and "internal error" not in err, err
    return info.value.code, out, err


@pytest.fixture
def silent_port():
    """A pty nobody answers on (what is written to it is read and dropped)."""
    master, slave = pty.openpty()
    stop = threading.Event()

    def drain() -> None:
        while not stop.is_set():
            try:
                os.read(master, 4096)
            except OSError:
                return

    threading.Thread(target=drain, daemon=True).start()
    yield os.ttyname(slave)
    stop.set()
    os.close(slave)
    os.close(master)


# -- false success: a dead port is not a unit that matches the manual ------------------------

@pytest.mark.slow
@pytest.mark.parametrize("variant", [None, "gve64-v19", "grbl-1.1f", "marlin-2.1"])
def test_characterize_on_a_silent_port_fails_fast_and_writes_nothing(variant, silent_port,
                                                                      tmp_path, capsys):
    out = tmp_path / "unit.toml"
    t0 = time.monotonic()
    code, _, err = _code(["characterize", silent_port, "-o", str(out), "-q",
                          *(["--variant", variant] if variant else [])], capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert "answer" in err and "--baud" in err, err
    assert not out.exists(), "a profile of defaults was written for a dead port"
    assert time.monotonic() - t0 < 20


@pytest.mark.slow
def test_run_on_a_silent_port_is_refused_before_any_check(silent_port, tmp_path, capsys):
    code, _, err = _code(["run", "--target", silent_port, "-q", "--report",
                          str(tmp_path / "r")], capsys)
    assert code == 2 and f"{silent_port}: no unit answered" in err, err
    assert not (tmp_path / "r" / "results.json").exists()


def test_an_interrupted_characterisation_counts_only_answered_questions(tmp_path, capsys,
                                                                        monkeypatch):
    """Questions whose probe got no answer (a silent link, a refused probe) are not answered."""
    from conform.families.gve import cli as gve_cli
    from conform.families.gve.conformance.characterize import Finding

    def probe(spec, tgt, vid, *, progress, findings, probing):  # noqa: ANN001, ANN202
        for q in list(spec.questions)[:2]:
            findings[q] = Finding(q, "not-probed", "x", [], [], [], "no answer (link lost)")
        raise KeyboardInterrupt

    monkeypatch.setattr(gve_cli, "probe", probe)
    out = tmp_path / "unit.toml"
    code, _, err = _code(["characterize", "emu:gve64-v19", "-o", str(out), "-q"], capsys)
    assert code == 130 and "0 of 29 questions answered" in err, err
    text = out.read_text()
    assert "partial = true" in text and "after 0 of 29" in text


def test_characterize_refuses_an_existing_profile_without_force(tmp_path, capsys):
    out = tmp_path / "unit.toml"
    out.write_text("mine\n")
    code, _, err = _code(["characterize", "emu:gve64-v19", "-o", str(out)], capsys)
    assert code == 2 and "-o" in err and "--force" in err, err
    assert out.read_text() == "mine\n"
    code, _, err = _code(["characterize", "emu:gve64-v19", "-o", str(out), "-q", "--force"],
                         capsys)
    assert code == 0 and out.read_text().startswith("# conform characterisation"), err


@pytest.mark.slow
def test_run_without_variant_asks_harmlessly_and_runs_the_family_that_answers(tmp_path,
                                                                                emulate):
    """A grbl on the port: `conform ports --probe`'s questions find it; GVE's `!0?` (`!` is
    grbl's feed hold) never reaches it, and the run is grbl's."""
    from conform.capture.reader import open_capture

    rec = tmp_path / "grbl.mcap"
    proc, port = emulate("serve", "grbl-1.1f", "--baud", "115200", "--record", str(rec))
    run = subprocess.run([sys.executable, "-m", "conform", "run", "--target", port, "--check",
                          "*/guide/example/build-info", "-q", "--report", str(tmp_path / "r")],
                         capture_output=True, text=True, timeout=120, env=ENV)
    proc.send_signal(signal.SIGINT)
    proc.wait(20)
    assert run.returncode == 0, run.stdout + run.stderr
    results = json.loads((tmp_path / "r" / "results.json").read_text())
    assert [r["variant"] for r in results["runs"]] == ["grbl-1.1f"]
    host = open_capture(rec).stream("host")
    assert b"?" in host and b"!" not in host, host[:200]


@pytest.mark.slow
def test_check_sender_stopped_by_sigterm_exits_143(tmp_path):
    prog = "import sys, time; time.sleep(60)"
    proc = subprocess.Popen([sys.executable, "-m", "conform", "check-sender", "--scenario",
                             "clean", "--report", str(tmp_path / "r"), "--", sys.executable,
                             "-c", prog, "{port}"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=ENV, cwd=tmp_path)
    assert "clean" in proc.stderr.readline()   # the scenario has started
    time.sleep(1.0)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, out + err
    assert "interrupted (SIGTERM)" in err and "Ctrl-C" not in err, err


@pytest.mark.parametrize("argv, says", [
    (["run", "--matrix", "--target", "emu:grbl-1.1f"], "--matrix"),
    (["run", "--target", "emu:", "--check", "*/V/valid"], "'emu:' names no variant"),
    (["send", str(REPO / "captures" / "jobs" / "part.nc"), "--target", "emu:"],
     "'emu:' names no variant"),
    (["run", "--inputs-control", "/missing.sock"], "--inputs-control /missing.sock"),
], ids=["matrix-of-one", "run-emu-empty", "send-emu-empty", "inputs-control-emu"])
def test_run_options_that_would_be_dropped_are_refused(argv, says, tmp_path, capsys,
                                                       monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, _, err = _code([*argv, "-q"] if argv[0] == "run" else argv, capsys)
    assert code == 2 and err.count("\n") == 1 and says in err, err
    assert not (tmp_path / "reports").exists(), "a run was made"


def test_bundle_of_a_file_that_is_no_capture_fails(tmp_path, capsys):
    junk = tmp_path / "random.bin"
    junk.write_bytes(os.urandom(3000))
    code, _, err = _code(["bundle", str(junk), "-o", str(tmp_path / "x.zip")], capsys)
    assert code == 2 and "not an MCAP file" in err, err
    assert not (tmp_path / "x.zip").exists()


def test_analyze_one_capture_says_the_scheduler_is_not_used(capsys):
    code, _, err = _code(["analyze", GOOD, "--scheduler", "tcp://127.0.0.1:1"], capsys)
    assert code in (0, None) and "--scheduler spreads several captures" in err, err


# -- unclear messages: what is wrong and what to do ------------------------------------------

def _marlin_profile(tmp_path: Path) -> str:
    path = tmp_path / "printer.toml"
    path.write_text('target = "emu:marlin-2.1"\nvariant = "marlin-2.1"\n\n[observed]\n'
                    'firmware = "2.1.2.4"\n')
    return str(path)


@pytest.mark.parametrize("argv, code, says", [
    (["run", "--seed", "abc"], 2, "'abc' is not a whole number"),
    (["profile", "diff", GOOD], 2, "conform profile diff [OPTIONS] A B"),
    (["emulate", "control", "{file}", "state"], 2, "a file, not a control socket"),
    (["run", "--dialect", "{marlin}", "-q"], 2, "a marlin profile (marlin-2.1), not a GVE one"),
    (["report", "{empty}.mcap"], 2, "`conform analyze"),
    (["report", "{empty}.json"], 2, "not a conform results file"),
    (["send", str(REPO / "captures" / "jobs" / "part.nc"), "--target", "emu:gve64-v19",
      "--record", "{file}/x.mcap"], 2, "a file is in the way"),
    (["send", str(REPO / "captures" / "jobs" / "raster.txt"), "--target", "emu:grbl-1.1f"], 2,
     "is it a job of another family? Nothing was sent"),
    (["send", str(REPO / "captures" / "jobs" / "raster.txt"), "--target", "emu:marlin-2.1"], 2,
     "raster.txt: it looks like a gve job: no line of it is a move a marlin unit executes; "
     "is it a job of another family? Nothing was sent"),
    (["send", str(REPO / "captures" / "jobs" / "marlin-ring.gcode"), "--target",
      "emu:gve64-v19"], 2, "marlin-ring.gcode:4:1: word M82 is not in the supported subset"),
    (["bundle", GOOD, "-o", "{file}/x.zip"], 2, "a file is in the way"),
    (["capture", "recover", GOOD, "-o", "{file}/x.mcap"], 2, "a file is in the way"),
    (["report", "{results}", "-o", "{file}/again"], 2, "-o {file}/again"),
    (["spec", "show", "marlin-2.1", "nothing"], 2, "or a command of marlin-2.1 (e.g. M115"),
], ids=["seed", "missing-argument", "control-regular-file", "dialect-of-marlin",
        "report-capture", "report-empty", "record-under-file", "send-other-family",
        "send-gve-job-to-marlin", "send-marlin-job-to-gve",
        "bundle-under-file", "recover-under-file", "report-under-file", "spec-show-nothing"])
def test_mistakes_say_what_is_wrong_and_what_to_do(argv, code, says, tmp_path, capsys):
    file = tmp_path / "file"
    file.write_text("x\n")
    (tmp_path / "empty.mcap").write_bytes(b"")
    (tmp_path / "empty.json").write_bytes(b"")
    results = tmp_path / "results.json"
    if "{results}" in argv:
        assert _code(["run", "--check", "*/V/valid", "--no-machine", "-q", "--report",
                      str(tmp_path)], capsys)[0] == 0
    names = {"file": str(file), "empty": str(tmp_path / "empty"), "results": str(results),
             "marlin": _marlin_profile(tmp_path) if "{marlin}" in argv else ""}
    got, _, err = _code([a.format(**names) for a in argv], capsys)
    assert got == code and err.count("\n") == 1 and says.format(**names) in err, err


@pytest.mark.parametrize("variant, name, shows", [
    ("marlin-2.1", "M115", "gcode/host/M115.cpp"), ("marlin-2.1", "m115", "M115"),
    ("grbl-1.1f", "$H", "homing cycle"), ("grbl-1.1f", "$J=G0X1F100", "Jog"),
])
def test_spec_show_one_command_of_every_family(variant, name, shows, capsys):
    code, out, err = _code(["spec", "show", variant, name], capsys)
    assert code == 0 and shows in out, err


def test_a_cut_short_capture_is_not_said_to_have_run_to_its_end(tmp_path, capsys):
    cut = tmp_path / "cut.mcap"
    cut.write_bytes((REPO / "captures" / "usb-latency.mcap").read_bytes()[:9000])
    code, out, _ = _code(["analyze", str(cut)], capsys)
    assert code == 1 and "capture damaged" in out
    assert "ran to its end" not in out and "cut short" in out, out


def test_a_check_that_could_not_run_says_why_in_words():
    from conform.conformance.target import HarnessError, LinkSilent
    from conform.families.gve.conformance.target import could_not

    said = could_not(LinkSilent("/dev/ttyUSB0: no answer 5.0 s after J, the reset command"))
    assert said.startswith("the unit stopped answering: ") and "LinkSilent" not in said
    assert could_not(HarnessError("x")) == "could not be run: x"
    from conform.conformance.runner import LINK_FAILURES  # still counted towards "link lost"

    assert said.startswith(LINK_FAILURES) and could_not(HarnessError("x")).startswith(LINK_FAILURES)


@pytest.mark.slow
def test_send_records_a_real_port_and_says_when_the_link_is_lost(tmp_path, emulate):
    """send --help's own example records a real port; a link pulled mid-job is said in
    words with how far the job got, not pyserial's message."""
    from conform.capture.reader import open_capture

    job = str(REPO / "captures" / "jobs" / "part.nc")
    _, port = emulate("serve", "gve64-v19", "--baud", "115200")
    rec = tmp_path / "session.mcap"
    run = subprocess.run([sys.executable, "-m", "conform", "send", job, "--target", port,
                          "--variant", "gve64-v19", "--allow-motion", "--record", str(rec),
                          "-q"], capture_output=True, text=True, timeout=120, env=ENV)
    assert run.returncode == 0, run.stderr
    cap = open_capture(rec)
    assert cap.clean and cap.metadata["conform.session"]["variant"] == "gve64-v19"
    assert b"!0L" in cap.stream("host") or b"!0C" in cap.stream("host")
    emu, port = emulate("serve", "gve64-v19", "--baud", "115200")
    send = subprocess.Popen([sys.executable, "-m", "conform", "send", job, "--target", port,
                             "--variant", "gve64-v19", "--allow-motion"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    while "job lines" not in send.stderr.readline():   # the first progress line: streaming
        assert send.poll() is None
    emu.kill()
    _, err = send.communicate(timeout=60)
    assert send.returncode == 1, err
    assert "link lost after" in err and "multiple access" not in err, err


# -- the wheel user's tour -------------------------------------------------------------------

def test_samples_writes_the_tours_files_as_in_a_clone(tmp_path, capsys):
    from conform.families import default_family
    from conform.families.peek import peek_family

    out = tmp_path / "samples"
    code, said, err = _code(["samples", str(out)], capsys)
    assert code == 0 and "sample files" in said, err
    repo = sorted(p.name for p in (REPO / "captures").glob("*.mcap"))
    assert sorted(p.name for p in (out / "captures").glob("*.mcap")) == repo
    for p in (REPO / "captures" / "jobs").iterdir():
        assert (out / "captures" / "jobs" / p.name).read_bytes() == p.read_bytes()
    assert (out / "tests" / "senders" / "careful.py").read_bytes() == \
        (REPO / "tests" / "senders" / "careful.py").read_bytes()
    linked = set(re.findall(r"docs/[\w-]+\.md", (REPO / "README.md").read_text()))
    assert linked and all((out / d).is_file() for d in linked), "README's links work in DIR"

    def families(folder: Path) -> set[str]:
        found = (peek_family(str(p), None)[0] for p in folder.glob("*.mcap"))
        return {default_family().name if d is None else d.family for d in found}

    assert families(out / "captures") == families(REPO / "captures") >= {"gve", "grbl"}
    code, _, err = _code(["samples", str(out)], capsys)
    assert code == 2 and "--force" in err and err.count("\n") == 1, err
    assert _code(["samples", str(out), "--force"], capsys)[0] == 0


# -- reports and output ----------------------------------------------------------------------

def test_emulator_runs_with_fails_do_not_say_the_checks_and_the_model_agree(tmp_path, capsys):
    code, out, _ = _code(["run", "--target", "emu:gve64-v10", "--variant", "gve64-v19",
                          "--check", "*/13.5.1/?/valid", "--no-machine", "-q", "--report",
                          str(tmp_path / "r")], capsys)
    assert code == 1 and "FAIL" in out
    assert "the checks and the model agree" not in out
    assert "emu:gve64-v10 judged as gve64-v19" in out
    assert "the checks and the model agree" not in (tmp_path / "r" / "index.html").read_text()
    code, out, _ = _code(["run", "--check", "*/13.5.1/?/valid", "--no-machine", "-q",
                          "--report", str(tmp_path / "ok")], capsys)
    assert code == 0 and "the checks and the model agree" in out


def test_the_open_question_legend_only_on_reports_of_a_family_that_has_them(tmp_path, capsys):
    for target, pattern, legend in (("emu:grbl-1.1f", "*/guide/example/build-info", False),
                                    ("emu:gve64-v19", "*/13.5.1/?/valid", True)):
        out = tmp_path / target[4:]
        assert _code(["run", "--target", target, "--check", pattern, "--no-machine", "-q",
                      "--report", str(out)], capsys)[0] == 0
        for page in ("index.html", "summary.md"):
            assert ("A1–A29" in (out / page).read_text()) is legend, (target, page)


def test_gve_send_progress_off_a_terminal_every_5_s_and_never_the_same_line_twice(
        monkeypatch, capsys):
    from conform.families.gve.sender.command import Progress

    class Stats:
        timeouts = garbled = queue_full = 0

    class Sender:
        progress = (330, 330)
        stats = Stats()

    monkeypatch.delenv("CONFORM_PROGRESS_SECONDS", raising=False)
    shown = Progress(Sender())
    assert shown.every == 5.0   # stderr is not a terminal here
    shown.every = 0.0
    for _ in range(5):   # motion still ending after the last line: nothing new to say
        shown(0.0)
    assert capsys.readouterr().err.count("330/330") == 1


def test_a_stopped_gve_run_turns_checksums_back_off():
    from conform.families.gve.conformance.safety import Guard
    from conform.families.gve.conformance.target import open_target
    from conform.families.gve.spec import load_spec

    spec = load_spec()
    target, _ = open_target("emu:gve64-v19", spec, baud=115200, guard=Guard.emulated())
    assert target.exchange(target.frame("!0%+", checksum=False)).lines == [b"0,5C"]
    said = target.safe_stop()
    assert "%- → checksums off" in said and not target.checksum_on
    assert target.exchange(target.frame("!0?", checksum=False)).lines[0].startswith(b"0,IP64")


def _wait_until_caught(pid: int, sig: int, bound: float = 60.0) -> None:
    """Until process ``pid`` has a handler for ``sig`` (the SigCgt mask of /proc/PID/status)."""
    end = time.monotonic() + bound
    while time.monotonic() < end:
        with open(f"/proc/{pid}/status") as f:
            caught = next(int(line.split()[1], 16) for line in f if line.startswith("SigCgt:"))
        if caught & (1 << (sig - 1)):
            return
        time.sleep(0.005)
    raise AssertionError(f"process {pid} caught no signal {sig} within {bound} s")


@pytest.mark.slow
@pytest.mark.long(45)
def test_proxy_stopped_by_sigint_always_finishes_within_its_bound(tmp_path, emulate):
    """50 proxies stopped by SIGINT at random moments — half started as a shell's background
    job (`conform proxy … &`: SIGINT ignored at start) and signalled while still loading, half
    once recording, idle or forwarding: each ends (within a minute: a stop that is lost never
    ends; a start on a loaded machine alone took over 10 s), with the capture complete, or
    (stopped while loading) with nothing started and no .part left. Before, a SIGINT during
    loading was dropped and the proxy recorded on for good, leaving only the .part."""
    import random

    from conform.capture.reader import open_capture

    def background() -> None:
        signal.signal(signal.SIGINT, signal.SIG_IGN)

    _, unit = emulate("serve", "gve64-v19", "--baud", "115200")
    rnd = random.Random(1)
    for n in range(50):
        out = tmp_path / f"s{n}.mcap"
        loading = n % 2 == 0
        proxy = subprocess.Popen([sys.executable, "-m", "conform", "proxy", "-q", "--unit", unit,
                                  "-o", str(out)], stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True, env=ENV,
                                 preexec_fn=background if loading else None)
        try:
            if loading:
                # a stop sent before the interpreter has run a line is dropped by the kernel
                # (SIGINT ignored), for any program: the random moment is counted from when
                # conform catches SIGINT, not from the start (on a loaded machine the start
                # alone took longer than the old fixed 0.3 s)
                _wait_until_caught(proxy.pid, signal.SIGINT)
                time.sleep(rnd.uniform(0.0, 1.2))
            else:
                sender = proxy.stdout.readline().strip()
                assert sender, proxy.stderr.read()
                if n % 4 == 1:
                    fd = os.open(sender, os.O_RDWR | os.O_NOCTTY)
                    os.write(fd, b"!0?\r" * rnd.randint(1, 20))
                    os.close(fd)
                time.sleep(rnd.uniform(0.0, 0.3))
            proxy.send_signal(signal.SIGINT)
            code = proxy.wait(60)
        finally:
            if proxy.poll() is None:
                proxy.kill()
                proxy.wait()
        err = proxy.stderr.read()
        assert code in (0, 130), (n, code, err)
        if code == 0:
            assert open_capture(out).clean, n
        else:
            assert loading and "interrupted" in err, (n, err)
            assert not list(tmp_path.glob(f"s{n}.mcap*")), "a stop while loading leaves nothing"


def test_check_sender_failing_page_says_what_to_fix_first_in_words(tmp_path, capsys):
    out = tmp_path / "r"
    code, _, err = _code(["check-sender", "-q", "--scenario", "noisy", "--report", str(out),
                          "--", sys.executable, str(REPO / "tests" / "senders" / "blind.py"),
                          "{port}", "{job}"], capsys)
    assert code == 1, err
    page = (out / "index.html").read_text()
    assert page.index("What to fix") < page.index("Rules × scenarios")
    assert "&#39;accepted_index&#39;" not in page and "{&#39;" not in page
    assert "accepted index" in page


@pytest.mark.parametrize("variant, scenario", [("gve64-v19", "clean"), ("grbl-1.1f", "stream"),
                                               ("marlin-2.1", "clean")])
def test_check_sender_page_has_one_look_and_well_formed_lines_in_every_family(
        variant, scenario, tmp_path, monkeypatch):
    """Every family's check-sender page opens with the analysis reports' page head (their
    fonts and styles), and a scenario's line joins no empty part (a family that compares no
    job against the ground truth, or one whose comparison says nothing)."""
    import conform.link.pty
    from conform.analysis.report import template_env
    from conform.sendercheck.grade import check
    from conform.sendercheck.report import render_html

    def no_pty(*_a, **_k):
        raise OSError("out of ptys")

    monkeypatch.setattr(conform.link.pty, "PtyEndpoint", no_pty)   # a run in no time
    r = check([sys.executable, "-c", "pass", "{port}"], variant=variant, names=[scenario],
              directory=tmp_path / "r", timeout=10)
    shared = template_env().from_string(
        '{% import "analysis_pieces.html.j2" as p %}{{ p.head("x") }}').render()
    style = re.search(r"<style>.*?</style>", shared, re.S).group(0)

    class Silent:
        def summary(self) -> str:
            return ""

    for comparison in (None, Silent()):
        r.scenarios[0].session.comparison = comparison
        page = render_html(r)
        assert style in page, variant
        line = re.search(r"<h3 id=[^>]*>.*?</h3>\s*<p>(.*?)</p>", page, re.S).group(1)
        assert re.fullmatch(r"[\d.]+ s, exit status \S+; capture \S+session\.mcap", line), line


def _matrix_cells(page: str) -> list[str]:
    table = page[page.index('id="sections"'):]
    table = table[:table.index("</table>")]
    return [re.sub(r"<[^>]+>", "", c).strip()
            for c in re.findall(r'<td class="cell"[^>]*>(.*?)</td>', table, re.S)]


def test_matrix_cells_hold_grades_and_long_citations_go_under_the_table(tmp_path, capsys):
    """A source citation (grbl's, Marlin's: files and functions) is a numbered note under the
    Commands × variants table, the cell keeping its grades and the note's number; a manual's
    section (GVE's) stays in the cell."""
    out = tmp_path / "marlin"
    assert _code(["run", "--target", "emu:marlin-2.1", "--no-machine", "-q", "--report",
                  str(out)], capsys)[0] == 0
    page = (out / "index.html").read_text()
    cells = _matrix_cells(page)
    assert cells and all(re.fullmatch(r"(\d+ [A-Z-]+ ?)+ \[\d+\]", c) for c in cells), cells
    assert '<li id="cite-1">queue.cpp' in page
    assert "GcodeSuite::M110" in page[page.index('<ol class="sources'):]
    md = (out / "summary.md").read_text()
    table = md[md.index("## Commands × variants"):].split("\n\n")[2]
    assert max(len(line) for line in table.splitlines()) < 80, table
    out = tmp_path / "gve"
    assert _code(["run", "--matrix", "--check", "*/13.5.1/*", "-q", "--report", str(out)],
                 capsys)[0] == 0
    cells = [c for c in _matrix_cells((out / "index.html").read_text()) if c != "—"]
    assert cells and all(re.fullmatch(r"GVE\d+ §[\d.]+ (\d+ [A-Z-]+ ?)+", c) for c in cells), cells


# -- spec show: a command the tables do not have is refused alike in every family -----------

@pytest.mark.parametrize("variant, word", [("marlin-2.1", "M999999"), ("marlin-2.1-adv", "G999"),
                                           ("grbl-1.1f", "G99"), ("gve64-v19", "QQ"),
                                           ("gve124", "nope")])
def test_spec_show_of_an_unknown_command_is_refused_in_every_family(variant, word, capsys):
    code, out, err = _code(["spec", "show", variant, word], capsys)
    assert code == 2 and not out, out
    assert err.count("\n") == 1 and f"{word}" in err and f"in {variant}'s tables" in err, err


# -- an empty answer is no answer: a port that is not there, a glob or range that selects nothing

@pytest.mark.parametrize("path, said", [("/dev/ttyNOPE", "no such port"),
                                        (str(REPO), "not a serial port")])
def test_ports_of_a_path_that_is_no_port_is_refused(path, said, capsys):
    code, out, err = _code(["ports", path], capsys)
    assert code == 2 and not out and f"{path}: {said}" in err and err.count("\n") == 1, err


def test_run_list_of_a_glob_that_matches_nothing_is_refused(capsys):
    code, out, err = _code(["run", "--list", "--check", "zzz/*"], capsys)
    assert code == 2 and not out and "no check matches zzz/*" in err, err


@pytest.mark.parametrize("extra, said", [([], "give --report DIR too"),
                                         (["--report", "R"], "outside the capture (0 to")])
def test_analyze_time_range_that_draws_nothing_is_refused(extra, said, tmp_path, capsys):
    extra = [str(tmp_path / x) if x == "R" else x for x in extra]
    code, _, err = _code(["analyze", GOOD, "-q", "--time-range", "999:1000", *extra], capsys)
    assert code == 2 and said in err and err.count("\n") == 1, err
    assert not (tmp_path / "R" / "index.html").exists()


@pytest.mark.parametrize("value", ["1,2", "80,80,400,500"])
def test_send_steps_per_mm_takes_one_number_or_three(value, capsys):
    code, _, err = _code(["send", str(REPO / "captures" / "jobs" / "part.nc"), "--target",
                          "emu:gve64-v19", "-q", "--steps-per-mm", value], capsys)
    assert code == 2 and f"--steps-per-mm: one number for every axis or three (X,Y,Z), not " \
        f"'{value}'" in err, err


@pytest.mark.parametrize("where, said", [("file/x.json", "a file is in the way"),
                                         ("adir", "is a folder")])
def test_emulate_serve_truth_that_cannot_be_written_is_refused_before_serving(where, said,
                                                                               tmp_path, capsys):
    (tmp_path / "file").write_text("x\n")
    (tmp_path / "adir").mkdir()
    code, out, err = _code(["emulate", "serve", "gve64-v19", "--truth", str(tmp_path / where)],
                           capsys)
    assert code == 2 and not out and said in err and err.count("\n") == 1, err


def test_analyze_says_which_options_another_familys_capture_does_not_use(capsys):
    code, _, err = _code(["analyze", str(REPO / "captures" / "grbl-counting.mcap"), "-q",
                          "--dialect", "A10=every-line"], capsys)
    assert code == 0 and "--dialect A10=every-line: not used" in err, err
