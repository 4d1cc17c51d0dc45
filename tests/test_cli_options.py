"""Options that mean the same everywhere (README, "Options that mean the same everywhere"):
``-q/--quiet`` on every long-running command, ``--seed`` with one default and meaning,
``--timeout`` in seconds, and the output options by kind. ``send`` is left out: its options are
being reworked with its move into the engine."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import click
import pytest

from conform.cli.main import cli
from conform.cli.params import DEFAULT_SEED

REPO = Path(__file__).resolve().parent.parent
LONG_RUNNING = ["run", "characterize", "analyze", "check-sender", "proxy", "sniff",
                "emulate serve", "capture info", "capture recover", "ports"]
QUIET_HELP = "No progress display (by default: bars on a terminal, a line every few seconds " \
             "off one)."
SEED_HELP = ("Seed of everything random this command does (state-machine sequences, injected "
             "faults): the same seed repeats the run.")
LEFT_OUT = {"send"}


def _commands() -> dict[str, click.Command]:
    out: dict[str, click.Command] = {}

    def walk(cmd: click.Command, path: list[str], ctx: click.Context) -> None:
        if isinstance(cmd, click.Group):
            for name in cmd.list_commands(ctx):
                walk(cmd.get_command(ctx, name), [*path, name], ctx)
        else:
            out[" ".join(path)] = cmd

    with click.Context(cli) as ctx:
        walk(cli, [], ctx)
    return {k: v for k, v in out.items() if k not in LEFT_OUT}


COMMANDS = _commands()


def _option(command: str, name: str) -> click.Option | None:
    return next((p for p in COMMANDS[command].params
                 if isinstance(p, click.Option) and name in p.opts), None)


def _with(name: str) -> list[str]:
    return sorted(c for c in COMMANDS if _option(c, name) is not None)


@pytest.mark.parametrize("command", LONG_RUNNING)
def test_every_long_running_command_has_quiet(command, capsys):
    opt = _option(command, "-q")
    assert opt is not None and "--quiet" in opt.opts and opt.is_flag
    assert opt.help == QUIET_HELP
    with pytest.raises(SystemExit):
        cli.main([*command.split(), "--help"], prog_name="conform")
    assert "-q, --quiet" in capsys.readouterr().out


def test_the_seed_commands_are_the_expected_ones():
    assert _with("--seed") == ["check-sender", "emulate serve", "run"]


@pytest.mark.parametrize("command", _with("--seed"))
def test_seed_has_one_default_and_one_meaning(command):
    opt = _option(command, "--seed")
    assert opt.default == DEFAULT_SEED == 1 and opt.show_default
    assert opt.help == SEED_HELP
    assert opt.type.min == 0


@pytest.mark.parametrize("command", _with("--timeout"))
def test_timeout_is_in_seconds_everywhere(command):
    opt = _option(command, "--timeout")
    assert opt.metavar == "SECONDS" and opt.help.startswith("Seconds ")


@pytest.mark.parametrize("name,kind", [("--report", "dir"), ("--parquet", "dir"),
                                       ("--record", "file")])
def test_output_options_are_one_kind_of_path(name, kind):
    assert _with(name), name
    for command in _with(name):
        t = _option(command, name).type
        assert isinstance(t, click.Path), (command, name)
        assert (t.file_okay, t.dir_okay) == ((False, True) if kind == "dir" else (True, False)), \
            (command, name)


def test_o_is_the_file_written_except_reports_folder():
    for command in _with("-o"):
        t = _option(command, "-o").type
        want = (False, True) if command == "report" else (True, False)
        assert isinstance(t, click.Path) and (t.file_okay, t.dir_okay) == want, command


def _serve(variant: str, *extra: str) -> str:
    """stderr of `conform emulate serve` left serving for a second off a terminal."""
    env = {**os.environ, "PYTHONPATH": str(REPO), "CONFORM_PROGRESS_SECONDS": "0.2"}
    p = subprocess.Popen([sys.executable, "-m", "conform", "emulate", "serve", variant, *extra],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    assert p.stdout.readline().startswith("/dev/")
    time.sleep(1.0)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=30)
    assert p.returncode == 0, err
    return err


@pytest.mark.slow
@pytest.mark.parametrize("variant", ["gve64-v19", "marlin-2.1"])   # the engine's serve, Marlin's
def test_emulate_serve_shows_progress_and_q_silences_it(variant):
    assert re.search(r"conform emulate: serving — 0 bytes in, \d+ out", _serve(variant))
    quiet = _serve(variant, "-q")
    assert "serving —" not in quiet and "conform emulate: stopped (" in quiet


def test_the_readme_table_names_the_commands_each_option_is_on():
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    table = readme.split("#### Options that mean the same everywhere", 1)[1].split("\n\n", 2)[1]
    rows = {}
    for line in table.splitlines()[2:]:
        option, on, _means = (c.strip() for c in line.strip("|").split("|"))
        rows[option] = sorted(re.findall(r"`([a-z][a-z -]*)`", on))
    assert rows["`-q`, `--quiet`"] == sorted(LONG_RUNNING)
    assert rows["`--seed N`"] == _with("--seed")
    assert rows["`--timeout SECONDS`"] == _with("--timeout")
    assert rows["`--report DIR`"] == _with("--report")
    assert rows["`-o FILE`"] == [c for c in _with("-o") if c != "report"]
    assert rows["`--record FILE`"] == _with("--record")
    assert rows["`--parquet DIR`"] == _with("--parquet")
