"""README.md and --help as a user reads them: every `conform …` line parses as written (options,
variants, paths), the quick start is two commands, and every command's --help has an example."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import warnings
from pathlib import Path

import click
import pytest

from conform.cli.main import cli

REPO = Path(__file__).resolve().parent.parent
README = (REPO / "README.md").read_text(encoding="utf-8")
# where the tour's commands write (README, "A short tour"), and the files that earlier README
# commands make (a run, characterize, a recording), relative to a test's folder
TOUR = "/tmp/conform-tour/"
MADE_BY_THE_README = ("reports/latest/results.json", "tour/unit.toml", "tour/unit-v10.toml",
                      "tour/printer.toml", "tour/printer-0.toml",
                      "tour/session.mcap", "tour/grbl.mcap", "session.mcap.part", "tour/support.zip")


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
    args = shlex.split(line.replace(TOUR, f"{tmp_path}/tour/"))[1:]
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


# -- the tour leaves no file in the clone -------------------------------------------------------

WRITES = re.compile(r"(?:^|\s)(?:-o|--output|--report|--parquet|--record|--junitxml)[= ](\S+)")
# not run by the tour test: servers, long runs, real ports, and what needs a recorded session
NOT_RUN = re.compile(r"&|--matrix|--mutants|/dev/tty|--probe|check-sender|emulate|\bsend\b|"
                     r"proxy|sniff|session\.mcap|grbl\.mcap|support\.zip|--help|_CONFORM_COMPLETE")


def _tour() -> list[str]:
    """The tour's command lines."""
    tour = README.split("## A short tour", 1)[1].split("\n## Benchmarks", 1)[0]
    lines = []
    for block in re.findall(r"```sh\n(.*?)```", tour, flags=re.S):
        lines += [x.split(" #", 1)[0].strip() for x in block.splitlines()]
    return [x for x in lines if x.startswith(("conform ", "python -m pytest"))]


def test_every_tour_command_writes_under_the_tour_folder_or_reports():
    writes = [(line, m) for line in _tour() for m in WRITES.findall(line)]
    assert len(writes) >= 8
    for line, path in writes:
        assert path.startswith((TOUR, "reports/")), line


@pytest.mark.slow
@pytest.mark.long(82)
def test_the_tour_leaves_no_untracked_file(tmp_path):
    """The tour's commands (those that finish by themselves on an emulator) run in a fresh
    repository holding the project's .gitignore: afterwards git sees no new file."""
    clone, tour = tmp_path / "clone", tmp_path / "tour"
    clone.mkdir()
    tour.mkdir()
    for name in ("captures", "conform", "specs", "tests"):
        (clone / name).symlink_to(REPO / name)
    (clone / ".gitignore").write_text((REPO / ".gitignore").read_text())
    git = ["git", "-C", str(clone), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "add", "-A"], check=True)
    subprocess.run([*git, "commit", "-qm", "clone"], check=True)
    # the command lines run one after another in one process (as `conform ARGS` would, in the
    # clone), so that the tour pays for Python and conform's imports once
    from hostile_captures import run_commands

    env = {**os.environ, "PYTHONPATH": str(REPO), "CORPUS_TIMEOUT": "600"}
    ran = [line for line in _tour() if line.startswith("conform ") and not NOT_RUN.search(line)]
    results = run_commands([shlex.split(line.replace(TOUR, f"{tour}/"))[1:] for line in ran],
                           env, cwd=clone)
    for line, r in zip(ran, results, strict=True):
        assert r["code"] in (0, 1) and not (r.get("exc") or r.get("hang") or r.get("signal")), \
            f"{line}: {r}"
    assert len(ran) >= 12 and any(x.startswith("conform characterize") for x in ran)
    status = subprocess.run([*git, "status", "--porcelain", "--untracked-files=all"],
                            check=True, capture_output=True, text=True).stdout
    assert status == "", status
    assert (clone / "reports" / "latest" / "index.html").is_file()   # written, and ignored
    assert {"unit.toml", "unit-v10.toml", "again"} <= {p.name for p in tour.iterdir()}
