"""``conform capture info|recover``: look inside a capture, salvage a killed one."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import click

from conform.capture.recover import capture_info, format_info, recover
from conform.cli.params import INPUT_PATH, OUTPUT_FILE, echo_json, json_option, quiet_option
from conform.cli.progress import progress


@click.group(name="capture")
def cli() -> None:
    """Inspect and repair MCAP capture files.

    \b
    Example:
      conform capture info captures/good-rs232.mcap
    """


@cli.command()
@click.argument("file", type=INPUT_PATH)
@json_option()
@quiet_option()
def info(file: str, as_json: bool, quiet: bool) -> None:
    """Duration, bytes each way, messages per channel, clean or truncated.

    \b
    Example:
      conform capture info captures/good-rs232.mcap --json
    """
    with progress("conform capture info", quiet=quiet, transient=True) as bar:
        bar.task(f"reading {file}")
        result = capture_info(file)
    if as_json:
        s = result.status
        echo_json({
            "file": str(result.path), "state": result.state, "problem": s.problem,
            "intact_bytes": s.valid_bytes, "size": s.size, "duration": result.duration,
            "bytes": result.bytes, "reads": result.reads, "gaps": result.gaps,
            "messages": dict(result.messages), "unreadable_messages": result.bad_messages,
            "metadata": result.metadata,
        })
    else:
        click.echo(format_info(result))
    if result.state not in ("clean", "recovered"):
        raise SystemExit(1)  # truncated or damaged: said above, and in the exit status


@cli.command(name="recover")
@click.argument("file", type=INPUT_PATH)
@click.option("-o", "--output", type=OUTPUT_FILE, default=None,
              help="Where to write (default: FILE without .part, or FILE.recovered.mcap).")
@click.option("--force", is_flag=True, help="Replace OUTPUT if it exists.")
@quiet_option()
def recover_cmd(file: str, output: str | None, force: bool, quiet: bool) -> None:
    """Rewrite the intact part of a killed or damaged recording as a complete MCAP.

    \b
    Example:
      conform capture recover session.mcap.part
    """
    if output:   # a folder that cannot be written: one line before the work
        from conform.errors import writable_folder

        writable_folder(Path(output).parent, f"-o {output}: its folder")
    with progress("conform capture recover", quiet=quiet, transient=True) as bar:
        bar.task(f"salvaging {file}")
        res = recover(file, output, force=force)
    s = res.status
    last = "-"
    if res.last_ns is not None:
        last = datetime.fromtimestamp(res.last_ns / 1e9, UTC).isoformat(timespec="milliseconds")
    click.echo(f"{res.output}: {res.messages} messages salvaged, last at {last}")
    if s.complete and s.clean:
        click.echo(f"{res.source} was already complete; rewritten unchanged")
    else:
        lost = s.size - s.valid_bytes
        click.echo(f"lost: {s.problem or 'damaged records'} ({lost} bytes after the intact "
                   f"part, {s.damaged_chunks} damaged chunks and {s.damaged_records} damaged "
                   "records skipped)")
        if not res.messages:   # nothing to salvage: the command did not do its job
            raise SystemExit(1)
    # a salvage that wrote a complete file succeeded (exit 0); what was lost is said above
