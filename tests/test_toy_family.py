"""The seam's proof: a toy family (tests/toyfamily/toyline), registered through the
``conform.families`` entry point group by its own dist-info and written against the family
contract only, goes through every command with no engine file naming it: ``spec list``,
``run`` (in-process, its mutants, and over a pty against ``emulate serve``), ``proxy`` capture,
``analyze`` of one file and of a fleet, ``check-sender`` with its own scenarios and rules."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

TOY = Path(__file__).resolve().parent / "toyfamily"
ROOT = Path(__file__).resolve().parent.parent / "conform"


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(TOY), env.get("PYTHONPATH", "")) if p)
    return env


def conform(*args: str, cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "conform", *args], capture_output=True,
                          text=True, env=_env(), cwd=cwd, timeout=timeout)


def test_the_engine_does_not_know_the_toy():
    for path in ROOT.rglob("*.py"):
        assert "toyline" not in path.read_text(encoding="utf-8"), path


@pytest.mark.slow
def test_toy_is_found_and_runs_in_process(tmp_path):
    listed = conform("spec", "list", "--json", cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    doc = json.loads(listed.stdout)
    assert [v["variant"] for v in doc["families"]["toy"]["variants"]] == ["toy-1", "toy-2"]

    ran = conform("run", "--target", "emu:toy-2", "-q", "--report", str(tmp_path / "r"),
                  cwd=tmp_path)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert "emu:toy-2 (toy-2, quick): PASS 4" in ran.stdout
    results = json.loads((tmp_path / "r" / "results.json").read_text())
    assert {c["id"] for c in results["checks"]} == {
        "toy-2/ping", "toy-2/set-max", "toy-2/set-over", "toy-2/unknown"}

    # the engine's mutant run kills both of the toy's deviant units, each by its own check
    mut = conform("run", "--target", "emu:toy-1", "--mutants", "-q", "--json", "--report",
                  str(tmp_path / "m"), cwd=tmp_path)
    assert mut.returncode == 0, mut.stderr
    caught = {m["name"]: m["caught_by"] for m in json.loads(mut.stdout)["mutants"]}
    assert caught == {"range-plus-one": ["toy-1/set-over"], "no-pong": ["toy-1/ping"]}

    # a deviant unit as a target FAILs the check meant for it
    bad = conform("run", "--target", "emu:toy-1:no-pong", "-q", "--report", str(tmp_path / "b"),
                  cwd=tmp_path)
    assert bad.returncode == 1 and "FAIL toy-1/ping" in bad.stdout

    listing = conform("run", "--target", "emu:toy-1", "--list", "--json", cwd=tmp_path)
    assert [c["id"] for c in json.loads(listing.stdout)["checks"]][0] == "toy-1/ping"


def _wait_for(path: Path, seconds: float = 30) -> None:
    end = time.monotonic() + seconds
    while not path.exists() and time.monotonic() < end:
        time.sleep(0.1)
    assert path.exists(), f"{path} never appeared"


@pytest.mark.slow
def test_toy_over_a_pty_capture_and_analysis(tmp_path):
    import serial

    unit_link, sender_link = tmp_path / "unit.pty", tmp_path / "sender.pty"
    capture = tmp_path / "fleet" / "bench-1" / "s1.mcap"
    capture.parent.mkdir(parents=True)
    env = _env()
    emu = subprocess.Popen([sys.executable, "-m", "conform", "emulate", "serve", "toy-1",
                            "--baud", "115200", "--link", str(unit_link)], env=env, cwd=tmp_path,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proxy = None
    try:
        _wait_for(unit_link)
        ran = conform("run", "--target", str(unit_link), "--variant", "toy-1", "-q", "--report",
                      str(tmp_path / "r"), cwd=tmp_path)
        assert ran.returncode == 0, ran.stdout + ran.stderr
        assert f"{unit_link} (toy-1, quick): PASS 4" in ran.stdout

        proxy = subprocess.Popen([sys.executable, "-m", "conform", "proxy", "-q", "--unit",
                                  str(unit_link), "-o", str(capture), "--variant", "toy-1",
                                  "--link", str(sender_link)], env=env, cwd=tmp_path,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        _wait_for(sender_link)
        answers = []
        with serial.Serial(str(sender_link), 115200, timeout=2) as port:
            for line in (b"PING", b"SET 5", b"GET", b"SET 500", b"JUMP"):
                port.write(line + b"\r")
                answers.append(port.read_until(b"\r"))
        assert answers == [b"PONG\r", b"OK\r", b"VAL 5\r", b"ERR range\r", b"ERR unknown\r"]
        proxy.send_signal(signal.SIGINT)
        proxy.wait(timeout=30)
    finally:
        for p in (proxy, emu):
            if p is not None and p.poll() is None:
                p.send_signal(signal.SIGINT)
                p.wait(timeout=30)
    assert capture.exists()

    one = conform("analyze", str(capture), cwd=tmp_path)
    assert one.returncode == 0, one.stderr
    assert "protocol family toy" in one.stdout
    assert "toy: 5 lines, 5 answered, 2 errors" in one.stdout

    (capture.parent / "s2.mcap").write_bytes(capture.read_bytes())
    fleet = conform("analyze", str(tmp_path / "fleet"), "--report", str(tmp_path / "fr"),
                    cwd=tmp_path)
    assert fleet.returncode == 0, fleet.stderr
    assert "2 captures" in fleet.stdout and "10 exchanges" in fleet.stdout
    assert (tmp_path / "fr" / "index.html").exists()


def _check_sender(tmp_path: Path, name: str, *sender_args: str) -> tuple[int, dict[str, str]]:
    """`conform check-sender --variant toy-1 -- python toy_sender.py {port} {job} ARGS`: its
    exit status and every verdict (SCENARIO/RULE -> grade)."""
    report = tmp_path / name
    ran = conform("check-sender", "--variant", "toy-1", "--report", str(report), "--json", "--",
                  sys.executable, str(TOY / "toy_sender.py"), "{port}", "{job}", *sender_args,
                  cwd=tmp_path)
    assert ran.returncode in (0, 1), ran.stdout + ran.stderr
    verdicts = json.loads(ran.stdout)["verdicts"]
    return ran.returncode, {f"{v['scenario']}/{v['rule']}": v["grade"] for v in verdicts}


@pytest.mark.slow
def test_toy_check_sender_grades_from_the_units_ground_truth(tmp_path):
    """The toy's check-sender (scenarios, rules, hooks in its own package) through the engine's
    supervisor: a sender that asks GET when an answer is lost passes both scenarios; one that
    leaves out a line fails the rule for skipped lines only; one that sends a line again when its
    answer is lost executes it twice and fails the once-in-order rule."""
    rules = ("none-skipped", "once-in-order")
    code, got = _check_sender(tmp_path, "good")
    assert code == 0 and got == {f"{s}/{r}": "PASS" for s in ("clean", "lost-answers")
                                 for r in rules}
    truth = json.loads((tmp_path / "good" / "lost-answers" / "truth.json").read_text())
    assert truth["executed"] == [f"SET {i}" for i in range(1, 41)]
    results = json.loads((tmp_path / "good" / "results.json").read_text())
    assert results["scenarios"][1]["faults"]["lost_answers"] > 0  # the engine's faults acted

    code, got = _check_sender(tmp_path, "skips", "--skip", "5")
    assert code == 1
    assert got["clean/none-skipped"] == got["lost-answers/none-skipped"] == "FAIL"
    assert got["clean/once-in-order"] == got["lost-answers/once-in-order"] == "PASS"

    code, got = _check_sender(tmp_path, "blind", "--blind")
    assert code == 1
    assert got["lost-answers/once-in-order"] == "FAIL"
    assert got["clean/once-in-order"] == got["lost-answers/none-skipped"] == "PASS"
