"""README.md and --help as a user reads them: every `conform …` line parses as written (options,
variants, paths), the quick start is two commands, and every command's --help has an example."""

from __future__ import annotations

import re
import shlex
import warnings
from pathlib import Path

import click
import pytest

from conform.cli.main import cli

REPO = Path(__file__).resolve().parent.parent
README = (REPO / "README.md").read_text(encoding="utf-8")
# files that earlier README commands make (a run, characterize, a recording)
MADE_BY_THE_README = ("reports/latest/results.json", "unit.toml", "unit-v10.toml",
                      "session.mcap", "session.mcap.part", "support.zip")


def _blocks() -> list[str]:
    return re.findall(r"```sh\n(.*?)```", README, flags=re.S)


def _commands() -> list[str]:
    out = []
    for block in _blocks():
        for line in block.splitlines():
            for part in re.split(r"&&|&|;", line.split(" #", 1)[0]):
                part = part.strip()
                if part.startswith("conform "):
                    out.append(part)
    return out


def test_quick_start_is_two_commands():
    quick = README.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```sh\n(.*?)```", quick, flags=re.S)
    assert [b.strip() for b in blocks] == ["pip install -e . && conform run",
                                           "pip install -e '.[test]' && python -m pytest"]
    assert "reports/latest/" in quick


def test_no_placeholder_in_a_command():
    for block in _blocks():
        assert not re.search(r"<[a-z]+>|\bjob\.nc\b|\bDIR\b|\bSOCKET\b", block), block


@pytest.mark.parametrize("line", _commands())
def test_readme_command_parses(line, tmp_path, monkeypatch):
    for name in ("captures", "conform"):
        (tmp_path / name).symlink_to(REPO / name)
    for made in MADE_BY_THE_README:
        (tmp_path / made).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / made).write_text("")
    monkeypatch.chdir(tmp_path)
    args = shlex.split(line)[1:]
    if "--help" in args:
        with pytest.raises(click.exceptions.Exit):
            cli.make_context("conform", list(args))
        return
    with warnings.catch_warnings():  # click 8 keeps a group's remaining words in protected_args
        warnings.simplefilter("ignore", DeprecationWarning)
        ctx = cli.make_context("conform", list(args))
        command: click.Command = cli
        rest = ctx.protected_args + ctx.args
        while isinstance(command, click.Group):
            assert rest, f"{line}: no subcommand"
            name, sub, rest = command.resolve_command(ctx, rest)
            if isinstance(sub, click.Group) and rest and rest[0] not in sub.commands:
                rest = ["serve", *rest]  # `conform emulate VARIANT`
            ctx = sub.make_context(name, list(rest), parent=ctx)  # converts and checks values
            command = sub
            rest = ctx.protected_args + ctx.args if isinstance(sub, click.Group) else []


def _leaf_commands(group: click.Group, prefix: tuple[str, ...] = ()):
    yield prefix, group
    for name, cmd in sorted(group.commands.items()):
        if isinstance(cmd, click.Group):
            yield from _leaf_commands(cmd, (*prefix, name))
        else:
            yield (*prefix, name), cmd


LEAVES = list(_leaf_commands(cli))


@pytest.mark.parametrize("path, cmd", LEAVES, ids=[" ".join(p) for p, _ in LEAVES])
def test_help_has_an_example(path, cmd):
    assert "Example" in (cmd.help or ""), f"conform {' '.join(path)} --help has no example"
