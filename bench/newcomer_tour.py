"""A newcomer's pass from a wheel: build the wheel, install it in a fresh virtual
environment, write the samples (`conform samples`) into a fresh folder, run the README's
commands there, then a set of deliberate mistakes across every command and family.

    python bench/newcomer_tour.py [--keep DIR] [--skip-build]

Each command is one line: OK (a tour command that ran; exit 1 where the README says a run
fails), SAID (a mistake refused in one line with a non-zero exit), ANSWERED (a mistake
that exits 0 saying what it did instead), SILENT (a mistake that exits 0 without saying
so), MULTILINE (refused in more than one line), TRACEBACK, HANG (past its bound) or FAILED
(a tour command that failed). Last, the counts as one JSON object; the exit status is 1
when any command was SILENT, TRACEBACK, HANG or FAILED.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# the README's commands that end by themselves (the serving ones are below); exit 1 allowed
# where the README says the run fails. {T}: the tour's output folder.
TOUR = [
    ("conform run -q --report {T}/r1", 0),
    ("conform run --matrix -q --report {T}/m", 0),
    ("conform run --target emu:gve64-v10 --variant gve64-v19 -q --report {T}/v10", 1),
    ("conform run --list --check 'gve64-v19/13.5.2/*'", 0),
    ("conform report {T}/r1/results.json -o {T}/again/", 0),
    ("conform characterize emu:gve64-v19 -o {T}/unit.toml", 0),
    ("conform characterize emu:gve64-v10 -o {T}/unit-v10.toml", 0),
    ("conform profile diff {T}/unit.toml {T}/unit-v10.toml", 0),
    ("conform analyze captures/careless-noisy.mcap", 0),
    ("conform analyze captures/careless-noisy.mcap --report {T}/out/", 0),
    ("conform analyze captures/usb-latency.mcap --parquet {T}/tables/", 0),
    ("conform capture info captures/good-rs232.mcap", 0),
    ("conform analyze captures/ --report {T}/fleet/ --parquet {T}/t/", 0),
    ("conform diagnose captures/careless-noisy.mcap", 0),
    ("conform bundle captures/good-rs232.mcap -o {T}/support.zip --redact", 0),
    ("conform analyze {T}/support.zip", 0),
    ("conform send captures/jobs/part.nc --target emu:gve64-v19 --checksums --packet 20 "
     "--policy careful -q", 0),
    ("conform send captures/jobs/grbl-arc.nc --target emu:grbl-1.1f --method send-response -q",
     0),
    ("conform check-sender --scenario clean --scenario stop --report {T}/sender/ -q -- "
     "python tests/senders/careful.py {{port}} {{job}}", 0),
    ("conform ports", 0),
    ("conform --help", 0),
    ("conform spec list", 0),
    ("conform spec show gve64-v19", 0),
    ("conform spec show gve124 V", 0),
    ("conform spec diff gve64-v19 gve124", 0),
    ("conform spec questions", 0),
    ("conform run --target emu:grbl-1.1f -q --report {T}/g", 0),
    ("conform run --target emu:marlin-2.1 -q --report {T}/mr", 0),
    ("conform characterize emu:marlin-2.1-adv -o {T}/printer.toml", 0),
    ("conform characterize emu:marlin-2.1 -o {T}/printer-0.toml", 0),
    ("conform profile diff {T}/printer-0.toml {T}/printer.toml", 1),
    ("conform emulate judge tests/data/marlin/facts-2.1.2.4.transcript --variant marlin-2.1",
     0),
    ("conform check-sender --variant marlin-2.1 --scenario clean -q --report {T}/ms -- "
     "python tests/senders/marlin_careful.py {{port}} {{job}}", 0),
]
SERVING = ["conform emulate serve gve64-v19", "conform emulate serve grbl-1.1f --baud 115200",
           "conform emulate serve marlin-2.1 --baud 250000", "conform emulate gve124 --tcp 0"]

# mistakes a new user makes; True: exiting 0 is right when the command says what it did
# instead (one capture with --scheduler is analysed here; an unknown M-code is described as
# what the unit answers)
MISTAKES = [
    ("conform run --target emu:nope", False), ("conform run --target /dev/ttyNOPE", False),
    ("conform run --variant nope", False), ("conform run --check 'zzz/*'", False),
    ("conform run --seed abc", False), ("conform run --max-steps -5", False),
    ("conform run --matrix --target emu:grbl-1.1f", False),
    ("conform run --inputs-control /missing.sock", False),
    ("conform run --dialect {T}/printer.toml -q", False),
    ("conform run --report {T}/file/x", False),
    ("conform report {T}/empty.mcap", False), ("conform report /nonexistent.json", False),
    ("conform analyze /nonexistent.mcap", False), ("conform analyze {T}/junk.bin", False),
    ("conform analyze {T}/empty.mcap", False),
    ("conform analyze captures/good-rs232.mcap --time-range 5:1", False),
    ("conform analyze captures/good-rs232.mcap --report {T}/file/x", False),
    ("conform analyze captures/good-rs232.mcap --scheduler tcp://127.0.0.1:1", True),
    ("conform analyze captures/ --scheduler tcp://127.0.0.1:1", False),
    ("conform analyze captures/grbl-counting.mcap --variant marlin-2.1", False),
    ("conform capture info {T}/junk.bin", False),
    ("conform capture recover captures/good-rs232.mcap -o {T}/file/x.mcap", False),
    ("conform diagnose {T}/junk.bin", False),
    ("conform diagnose captures/good-rs232.mcap --variant nope", False),
    ("conform bundle {T}/junk.bin -o {T}/x.zip", False),
    ("conform bundle captures/good-rs232.mcap -o {T}/file/x.zip", False),
    ("conform characterize emu:gve64-v19 -o {T}/unit.toml", False),
    ("conform characterize emu:nope -o {T}/u.toml", False),
    ("conform profile diff {T}/unit.toml", False),
    ("conform profile diff {T}/unit.toml {T}/junk.bin", False),
    ("conform send captures/jobs/raster.txt --target emu:grbl-1.1f", False),
    ("conform send captures/jobs/raster.txt --target emu:marlin-2.1", False),
    ("conform send captures/jobs/marlin-ring.gcode --target emu:gve64-v19", False),
    ("conform send /nonexistent.nc --target emu:gve64-v19", False),
    ("conform send captures/jobs/part.nc --target emu:gve64-v19 --record {T}/file/x.mcap",
     False),
    ("conform send captures/jobs/part.nc --target emu:gve64-v19 --timeout -1", False),
    ("conform send captures/jobs/part.nc --target /dev/ttyNOPE", False),
    ("conform send captures/jobs/part.nc --target emu:", False),
    ("conform send {T}/junk.bin --target emu:gve64-v19", False),
    ("conform check-sender", False), ("conform check-sender --scenario nope -- true", False),
    ("conform check-sender -- /nonexistent/sender {{port}}", False),
    ("conform check-sender --timeout -1 -- true", False),
    ("conform check-sender --variant marlin-2.1 --job captures/jobs/raster.txt -- true {{port}}",
     False),
    ("conform check-sender --variant grbl-1.1f --job captures/jobs/raster.txt -- true {{port}}",
     False),
    ("conform check-sender --job captures/jobs/marlin-ring.gcode -- true {{port}}", False),
    ("conform emulate nope", False),
    ("conform emulate judge tests/data/marlin/facts-2.1.2.4.transcript --variant grbl-1.1f",
     False),
    ("conform emulate judge /nonexistent.transcript --variant marlin-2.1", False),
    ("conform emulate control {T}/file state", False),
    ("conform emulate control /missing.sock state", False),
    ("conform emulate serve gve64-v19 --faults corrupt=abc", False),
    ("conform spec show nope", False), ("conform spec show marlin-2.1 M999999", True),
    ("conform spec show grbl-1.1f G99", False),
    ("conform spec diff gve64-v19 marlin-2.1", False),
    ("conform spec check --specs /nonexistent", False),
    ("conform proxy --unit /dev/ttyNOPE -o {T}/p.mcap --link {T}/p.pty", False),
    ("conform proxy --unit /dev/ttyNOPE -o {T}/file/p.mcap --link {T}/p.pty", False),
    ("conform ports --probe --timeout -3", False), ("conform nope", False),
    ("conform samples {T}/file", False),
]


def run(cmd: str, env: dict[str, str], cwd: Path, timeout: float) -> tuple[int | None, str, float]:
    """Exit status (None: still running at ``timeout``), what it printed, seconds."""
    t = time.monotonic()
    try:
        p = subprocess.run(cmd, shell=True, cwd=cwd, env=env, capture_output=True, text=True,
                           timeout=timeout, stdin=subprocess.DEVNULL)
        return p.returncode, p.stdout + p.stderr, time.monotonic() - t
    except subprocess.TimeoutExpired as exc:
        said = b"".join(x for x in (exc.stdout, exc.stderr) if isinstance(x, bytes))
        return None, said.decode(errors="replace"), time.monotonic() - t


def grade(kind: str, rc: int | None, said: str, allowed: int | bool) -> str:
    if "Traceback" in said:
        return "TRACEBACK"
    if kind == "serve":
        return "OK" if rc is None or rc == 0 else "FAILED"
    if rc is None:
        return "HANG"
    if kind == "tour":
        return "OK" if rc in (0, allowed) else "FAILED"
    if rc == 0:
        return "ANSWERED" if allowed else "SILENT"
    return "SAID" if said.strip().count("\n") == 0 else "MULTILINE"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--keep", type=Path, help="work in this folder (default: a temporary one)")
    ap.add_argument("--skip-build", action="store_true",
                    help="reuse DIR/venv (a wheel installed there before)")
    args = ap.parse_args()
    home = args.keep or Path(tempfile.mkdtemp(prefix="conform-newcomer-"))
    home.mkdir(parents=True, exist_ok=True)
    venv, samples, out = home / "venv", home / "samples", home / "tour"
    if not args.skip_build:
        subprocess.run([sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-q",
                        "-w", str(home / "wheel")], check=True)
        subprocess.run([sys.executable, "-m", "venv", "--clear", str(venv)], check=True)
        wheel = next((home / "wheel").glob("conform-*.whl"))
        subprocess.run([str(venv / "bin" / "pip"), "install", "-q", str(wheel)], check=True)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PATH"] = f"{venv / 'bin'}:{env['PATH']}"
    out.mkdir(exist_ok=True)
    (out / "junk.bin").write_bytes(os.urandom(3000))
    (out / "empty.mcap").write_bytes(b"")
    (out / "file").write_text("x\n")
    counts: Counter[str] = Counter()

    def one(kind: str, cmd: str, allowed: int | bool, timeout: float, cwd: Path) -> None:
        rc, said, dt = run(cmd.format(T=out), env, cwd, timeout)
        g = grade(kind, rc, said, allowed)
        counts[g] += 1
        last = (said.strip().splitlines() or [""])[-1][:150]
        print(f"{g:10} {'-' if rc is None else rc:>3} {dt:6.1f}s {cmd[:100]}\n{'':22}{last}",
              flush=True)

    one("tour", f"conform samples {samples}", 0, 120, home)
    for cmd, allowed in TOUR:
        one("tour", cmd.replace(" -o {T}/", " --force -o {T}/") if "characterize" in cmd
            or "bundle" in cmd else cmd, allowed, 600, samples)
    for cmd in SERVING:
        one("serve", cmd, 0, 5, samples)
    for cmd, answered in MISTAKES:
        one("mistake", cmd, answered, 120, samples)
    print(json.dumps(dict(counts)))
    if any(counts[k] for k in ("SILENT", "TRACEBACK", "HANG", "FAILED")):
        raise SystemExit(1)


if __name__ == "__main__":
    main()
