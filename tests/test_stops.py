"""Every way a run is ended — Ctrl-C, SIGTERM (``timeout``, ``kill``, a cancelled CI job),
SIGHUP (a closed terminal), Ctrl-C on a job started with ``&`` (SIGINT inherited as ignored) —
halts the unit, writes the partial report and exits 128 + the signal's number. The pty tests
run ``conform run`` against ``conform emulate serve`` and read what reached the unit from the
emulator's own recording."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import pytest

from conform.stops import Stopped, exit_status, shield, stop_signals

REPO = Path(__file__).resolve().parent.parent


def _env(**extra: str) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(REPO), **extra}


# -- the mechanism, in-process -----------------------------------------------------------------

@pytest.mark.parametrize("sig,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143),
                                      (signal.SIGHUP, 129)])
def test_each_signal_is_one_exception_and_its_exit_status(sig, code):
    with stop_signals() as state:
        with pytest.raises(KeyboardInterrupt) as caught:
            os.kill(os.getpid(), sig)
            time.sleep(5)   # the handler runs at the next bytecode
        assert isinstance(caught.value, Stopped) and caught.value.exit_code == code
        assert exit_status(2) == code   # a command that then reports "run aborted" exits 128+N
        os.kill(os.getpid(), sig)       # later signals are counted, never raised: the halt
        time.sleep(0.05)                # and the report that follow must finish
        assert state.later == 1
    assert exit_status(2) == 2          # outside the block nothing is changed
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


def test_a_report_being_written_is_finished_first():
    with stop_signals() as state:
        with shield():
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.05)
            written = True
        assert written and state.exit_code == 143


def test_handlers_are_installed_over_an_inherited_ignore():
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)   # what `cmd &` in a script does
    try:
        with stop_signals():
            with pytest.raises(Stopped):
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(5)
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_stop_while_a_command_loads_waits_for_its_modules(monkeypatch, capsys, sig, code):
    """A stop signal that comes while a subcommand's modules are imported is acted on once
    they are in: raised inside an extension module's import (orjson's), it crashed the
    interpreter (`conform proxy … &` stopped while loading ended with SIGSEGV)."""
    import conform.cli.main as cli_main

    loaded = []
    real = cli_main._add_subcommand

    def interrupted_import(name: str) -> None:
        os.kill(os.getpid(), sig)      # delivered here, in the middle of the import
        loaded.append(name)            # not reached when the signal raises at once
        real(name)

    monkeypatch.setattr(cli_main, "_add_subcommand", interrupted_import)
    monkeypatch.delitem(cli_main.cli.commands, "proxy", raising=False)
    with pytest.raises(SystemExit) as exc:
        cli_main.main(["proxy", "--help"])
    assert loaded == ["proxy"] and "proxy" in cli_main.cli.commands   # the import finished
    assert exc.value.code == code                                     # and then it stopped
    out, err = capsys.readouterr()
    assert "interrupted" in err and "Usage" not in out


@contextmanager
def _recorded(variant: str, recording: Path):
    """``conform emulate serve VARIANT`` at 115 200 Bd on a pty, recording what reaches it; the
    recording is complete when the block ends (the emulator is stopped cleanly)."""
    emu = subprocess.Popen([sys.executable, "-m", "conform", "emulate", "serve", variant,
                            "--baud", "115200", "--record", str(recording)],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                           env=_env())
    try:
        pty = emu.stdout.readline().strip()
        assert pty.startswith("/dev/"), pty
        yield pty
    finally:
        emu.send_signal(signal.SIGINT)
        emu.wait(20)


def _until(proc: subprocess.Popen, marker: str) -> None:
    """Read the process's stderr up to a line holding ``marker``."""
    seen = [proc.stderr.readline()]
    while seen[-1] and marker not in seen[-1]:
        seen.append(proc.stderr.readline())
    assert seen[-1], "".join(seen)


def _host_tail(recording: Path, n: int = 80) -> bytes:
    from conform.capture.reader import open_capture

    return open_capture(recording).stream("host")[-n:]


# -- over a pty: the halt reaches the unit, the report is written ------------------------------

def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


# the family's halt as the unit receives it (each framing the unit may be in: GVE's checksum
# mode may be on when the signal comes, and the halt is sent in it), and the run's options
HALTS = {
    "gve64-v19": ((b"!0H\r", b"!0H,C5\r"), (b"!0D\r!0O0,FF\r", b"!0D,C1\r!0O0,FF,B4\r"),
                  ["--no-machine"]),                                       # H (retried), D, O0,FF
    "grbl-1.1f": ((b"!",), (b"\x18",), ["--variant", "grbl-1.1f"]),      # feed hold, soft reset
}


@pytest.mark.slow
@pytest.mark.parametrize("variant,sig,inherit_ignore", [
    ("gve64-v19", signal.SIGTERM, False),
    ("gve64-v19", signal.SIGINT, True),
    ("grbl-1.1f", signal.SIGHUP, False),
    ("grbl-1.1f", signal.SIGINT, True),
])
def test_a_signal_mid_run_halts_the_unit_and_writes_the_report(tmp_path, variant, sig,
                                                               inherit_ignore):
    recording = tmp_path / "emu.mcap"
    with _recorded(variant, recording) as pty:
        stop, then, options = HALTS[variant]
        run = subprocess.Popen(
            [sys.executable, "-m", "conform", "run", "--target", pty, "--report",
             str(tmp_path / "report"), "--json", *options],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
            env=_env(), preexec_fn=_ignore_sigint if inherit_ignore else None)
        _until(run, "estimate")        # "<pty> (<variant>): N checks, estimate m:ss"
        time.sleep(4)                  # checks under way
        run.send_signal(sig)
        try:
            out, err = run.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            run.kill()
            pytest.fail(f"conform run did not stop on {sig.name}")
    assert run.returncode == 128 + sig, (run.returncode, err)
    assert json.loads(out)["exit"] == 128 + sig   # --json says the status it exits with
    name = "Ctrl-C" if sig == signal.SIGINT else sig.name
    assert f"run aborted: interrupted ({name}) after " in err, err
    assert "Traceback" not in err
    results = json.loads((tmp_path / "report" / "results.json").read_text())
    aborted = results["runs"][0]["aborted"]
    assert aborted.startswith(f"interrupted ({name})") and "NOT acknowledged" not in aborted
    assert results["checks"], "the checks done before the signal are reported"
    tail = _host_tail(recording)   # nothing is sent after the halt: it ends the host's traffic
    tail = tail.removesuffix(b"!0%-,CF\r")   # but checksums turned back off (GVE, when on)
    stop = next((x for x in stop if x in tail), None)
    then = next((x for x in then if tail.endswith(x)), None)
    assert stop is not None and then is not None, tail
    assert tail.rindex(stop) < tail.rindex(then)


def _programs_under(folder: Path) -> list[str]:
    """Command lines of live processes naming a path under ``folder`` (the judged sender's)."""
    found = []
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            text = cmdline.read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if str(folder) in text and "check-sender" not in text:
            found.append(text)
    return found


@pytest.mark.slow
@pytest.mark.parametrize("variant,first,second,sender", [
    ("gve64-v19", "clean", "slow-unit", "careful.py"),
    ("grbl-1.1f", "stream", "slow-link", "grbl_counting.py"),
])
def test_check_sender_interrupted_reports_the_scenarios_that_finished(tmp_path, variant, first,
                                                                       second, sender):
    report = tmp_path / "report"
    proc = subprocess.Popen(
        [sys.executable, "-m", "conform", "check-sender", "--variant", variant, "--scenario",
         first, "--scenario", second, "--report", str(report), "--", sys.executable,
         str(REPO / "tests" / "senders" / sender), "{port}", "{job}"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path, env=_env())
    seen = [proc.stderr.readline()]
    while seen[-1] and not seen[-1].startswith(f"check-sender: {second}: "):
        seen.append(proc.stderr.readline())
    assert seen[-1], "".join(seen)
    time.sleep(1.0)   # the second scenario's program is running
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, (out, err)
    assert "Traceback" not in err
    results = json.loads((report / "results.json").read_text())
    text = json.dumps(results)
    assert f"interrupted (Ctrl-C) during {second}" in text, text[:2000]
    assert first in text and (report / "index.html").exists()
    assert "INCOMPLETE" in (report / "index.html").read_text()
    assert not _programs_under(tmp_path), "the judged program was left running"


def _stopped(args: list[str], marker: str, wait: float, sig: int) -> tuple[int, str]:
    """Run ``conform ARGS``, send ``sig`` ``wait`` s after a stderr line holding ``marker``;
    its exit status and stderr."""
    proc = subprocess.Popen([sys.executable, "-m", "conform", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            env=_env(CONFORM_PROGRESS_SECONDS="0.2"))
    _until(proc, marker)
    time.sleep(wait)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    return proc.returncode, err


@pytest.mark.slow
def test_send_stopped_by_sigterm_halts_the_unit(tmp_path):
    recording = tmp_path / "emu.mcap"
    with _recorded("gve64-v19", recording) as pty:   # stopped once a progress line is out
        code, err = _stopped(["send", str(REPO / "captures/jobs/part.nc"), "--target", pty,
                              "--allow-motion"], "job lines", 1.0, signal.SIGTERM)
    assert code == 143, err
    assert "interrupted (SIGTERM): sent H and D" in err and "Traceback" not in err
    assert _host_tail(recording, 40).endswith(b"!0H\r!0D\r")


@pytest.mark.slow
def test_characterize_stopped_by_sighup_halts_the_unit(tmp_path):
    recording = tmp_path / "emu.mcap"
    with _recorded("gve64-v19", recording) as pty:   # stopped once the probes are under way
        code, err = _stopped(["characterize", pty, "-o", str(tmp_path / "unit.toml")],
                             "variant: ", 2.0, signal.SIGHUP)
    assert code == 129, err
    assert "interrupted (SIGHUP): sent H" in err and "Traceback" not in err
    assert _host_tail(recording, 40).endswith(b"!0D\r!0O0,FF\r")


@pytest.mark.slow
def test_characterize_stopped_by_ctrl_c_writes_a_partial_profile(tmp_path):
    """Ctrl-C while A4 is being probed (it takes seconds: H, vectors, D): the unit is halted,
    the questions answered so far are written marked partial (the rest listed), and
    `profile diff` names what is missing."""
    from conform.families.gve.conformance.profile import load_profile
    from conform.families.gve.spec import load_spec

    recording, out = tmp_path / "emu.mcap", tmp_path / "unit.toml"
    with _recorded("gve64-v19", recording) as pty:
        code, err = _stopped(["characterize", pty, "-o", str(out)], "— A4", 0.0, signal.SIGINT)
    assert code == 130, err
    assert "interrupted (Ctrl-C): sent H" in err and "Traceback" not in err
    assert f"partial profile {out}: " in err
    assert _host_tail(recording, 40).endswith(b"!0D\r!0O0,FF\r")
    profile = load_profile(out)
    questions = list(load_spec().questions)
    assert profile.meta["partial"] is True
    assert profile.meta["interrupted"].startswith("Ctrl-C after ")
    answered, missing = list(profile.dialect), profile.meta["unanswered"]
    assert {"A1", "A2", "A3"} <= set(answered) and "A29" in missing
    assert sorted(answered + missing) == sorted(questions)
    defaults = load_spec().dialect().choices   # the emulator follows the tables' defaults
    assert all(profile.dialect[q] == defaults[q] for q in answered)
    assert set(profile.evidence) == set(answered)
    full = tmp_path / "full.toml"
    subprocess.run([sys.executable, "-m", "conform", "characterize", "emu:gve64-v19", "-q",
                    "-o", str(full)], check=True, env=_env(), capture_output=True)
    diff = subprocess.run([sys.executable, "-m", "conform", "profile", "diff", str(out),
                           str(full)], env=_env(), capture_output=True, text=True)
    assert diff.returncode == 1, diff.stderr
    head = diff.stdout.splitlines()[0]
    assert head.startswith(f"{out}: partial profile (Ctrl-C after ")
    assert head.endswith(f"{len(missing)} question(s) not answered: {', '.join(missing)}")
    rows = {line.split()[0]: line for line in diff.stdout.splitlines()[2:]}
    assert set(rows) == set(missing)
    assert all("(not answered)" in rows[q] for q in missing)
