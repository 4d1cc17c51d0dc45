"""Progress: bars naming the step on a terminal, a line every few seconds off one."""

from __future__ import annotations

import io
import time

from conform.cli.progress import mode_for, progress


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_off_a_terminal_a_line_every_interval_naming_the_step():
    out = io.StringIO()
    with progress("conform run", stream=out, interval=0.05) as p:
        task = p.task("emu:gve64-v19 (gve64-v19)", 363)
        task.update(advance=362, step="gve64-v19/13.5/sequences")
        deadline = time.monotonic() + 10
        while out.getvalue().count("\n") < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
    lines = out.getvalue().splitlines()
    assert len(lines) >= 2
    assert lines[0].startswith("conform run: emu:gve64-v19 (gve64-v19) 362/363 (100%) — "
                               "gve64-v19/13.5/sequences, ")


def test_finished_tasks_and_quiet_print_nothing():
    out = io.StringIO()
    with progress("x", stream=out, interval=0.02) as p:
        p.task("done", 2).update(advance=2)
        time.sleep(0.15)
    assert out.getvalue() == ""
    with progress("x", stream=out, interval=0.02, quiet=True) as p:
        p.task("running", 2)
        p.say("hello")
        time.sleep(0.1)
    assert out.getvalue() == ""


def test_open_ended_task_polls_and_reports_bytes():
    out = io.StringIO()
    counts = iter(range(1000))
    with progress("conform proxy", stream=out, interval=0.05) as p:
        p.say("recording a to b")
        p.task("recording", None, poll=lambda: f"host {next(counts)} B")
        time.sleep(0.3)
    lines = out.getvalue().splitlines()
    assert lines[0] == "conform proxy: recording a to b"
    assert any(line.startswith("conform proxy: recording — host ") for line in lines[1:])


def test_on_a_terminal_a_bar_with_the_step():
    out = _Terminal()
    assert mode_for(out) == "bar" and mode_for(io.StringIO()) == "lines"
    with progress("conform analyze", stream=out) as p:
        t = p.task("part.mcap", 1000, unit="bytes")
        t.update(completed=500, step="decoding frames")
    assert "part.mcap" in out.getvalue() and "decoding frames" in out.getvalue()
