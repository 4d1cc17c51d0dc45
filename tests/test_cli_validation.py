"""Every command checks its options the same way: a mistake is one line and exit status 2."""

from __future__ import annotations

import pytest

from conform.cli.main import main

GOOD_CAPTURE = "captures/good-rs232.mcap"
JOB = "captures/jobs/part.nc"

MISTAKES = [
    # (argv, a word the one line must name)
    (["run", "--baud", "-5"], "--baud"),
    (["run", "--baud", "fast"], "--baud"),
    (["run", "--variant", "nonsense"], "nonsense"),
    (["run", "--target", "emu:gve64-v91"], "gve64-v91"),
    (["run", "--target", "emu:gve64-v19:no-such-mutant"], "no-such-mutant"),
    (["run", "--target", "emu:gve64-v19:a:b"], "emu:VARIANT"),
    (["run", "--max-steps", "0"], "--max-steps"),
    (["run", "--seed", "-1"], "--seed"),
    (["run", "--profile", "huge"], "--profile"),
    (["run", "--dialect", "no-such-profile.toml"], "no-such-profile.toml"),
    (["run", "--allow-motion"], "--max-steps"),
    (["run", "--replay", "gve64-v19/13.5.3/V/valid@x"], "seed"),
    (["analyze", GOOD_CAPTURE, "--variant", "nonsense"], "nonsense"),
    (["analyze", "no-such.mcap"], "no-such.mcap"),
    (["analyze", GOOD_CAPTURE, "--baud", "0"], "--baud"),
    (["capture", "info", "no-such.mcap"], "no-such.mcap"),
    (["capture", "recover", "no-such.mcap.part"], "no-such.mcap.part"),
    (["spec", "show", "nonsense"], "nonsense"),
    (["spec", "diff", "gve64-v19", "gve64-v91"], "gve64-v91"),
    (["spec", "show", "gve64-v19", "NOPE"], "'NOPE'"),
    (["spec", "show", "gve64-v10", "VL"], "absent in this version"),
    (["proxy", "--unit", "/dev/null", "-o", "x.mcap", "--variant", "gve64-v91"], "gve64-v91"),
    (["proxy", "--unit", "/dev/null", "-o", "x.mcap", "--baud", "0"], "--baud"),
    (["sniff", "--host-port", "a", "--unit-port", "b", "-o", "x.mcap", "--variant", "v"], "'v'"),
    (["emulate", "nonsense"], "nonsense"),
    (["emulate", "serve", "gve64-v19", "--baud", "-1"], "--baud"),
    (["emulate", "gve64-v19", "--tcp", "70000"], "--tcp"),
    (["emulate", "gve64-v19", "--answer-delay", "-1"], "--answer-delay"),
    (["emulate", "gve64-v19", "--faults", "corrupt=2"], "corrupt"),
    (["send", "no-such.nc", "--target", "emu:gve64-v19"], "no-such.nc"),
    (["send", JOB, "--target", "emu:gve64-v91"], "gve64-v91"),
    (["send", JOB, "--target", "emu:gve64-v19", "--noise", "1.5"], "--noise"),
    (["send", JOB, "--target", "emu:gve64-v19", "--packet", "0"], "--packet"),
    (["send", JOB, "--target", "emu:gve64-v19", "--timeout", "0"], "--timeout"),
    (["send", JOB, "--target", "emu:gve64-v19", "--variant", "nonsense"], "nonsense"),
    (["send", JOB, "--target", "emu:gve64-v19", "--corrupt-command", "x"], "--corrupt-command"),
    (["send", JOB, "--target", "emu:gve64-v19", "--corrupt-command", "1,,2"], "--corrupt-command"),
    (["send", JOB, "--target", "emu:gve64-v19", "--corrupt-answer", "-1"], "--corrupt-answer"),
    (["characterize", "emu:gve64-v91", "-o", "x.toml"], "gve64-v91"),
    (["characterize", "emu:gve64-v19", "-o", "x.toml", "--max-steps", "-3"], "--max-steps"),
    (["profile", "diff", "no-such-a.toml", "no-such-b.toml"], "no-such-a.toml"),
    (["report", "no-such-results.json"], "no-such-results.json"),
    (["ports", "--baud", "0"], "--baud"),
    (["ports", "--probe", "--timeout", "0"], "--timeout"),
    (["check-sender", "--variant", "nope", "--", "true"], "nope"),
    (["check-sender", "--job", "no-such-job.txt", "--", "true"], "no-such-job.txt"),
    (["check-sender", "--seed", "-2", "--", "true"], "--seed"),
    (["no-such-command"], "no-such-command"),
]


@pytest.mark.parametrize("argv, named", MISTAKES, ids=[" ".join(a) for a, _ in MISTAKES])
def test_a_mistake_is_one_line_and_exit_2(argv, named, capsys, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    argv = [a.replace("captures/", f"{_repo()}/captures/") for a in argv]
    with pytest.raises(SystemExit) as info:
        main(argv)
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert info.value.code == 2, (out, err)
    assert len(lines) == 1 and lines[0].startswith("conform: "), err
    assert named in lines[0], err
    assert not list(tmp_path.iterdir()), "a refused command must not leave files behind"


def _repo() -> str:
    from pathlib import Path

    return str(Path(__file__).resolve().parent.parent)
