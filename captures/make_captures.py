"""Regenerate the sample captures in this folder (see README.md for what each shows).

    python captures/make_captures.py            # all four
    python captures/make_captures.py good-rs232 # one

Each session runs the reference sender against the in-process reference unit on a virtual
clock (``conform.families.gve.sender.session.send_emulated``, the same code as
``conform send JOB --target emu:gve64-v19 --record FILE``) with the link model of
``conform.families.gve.sender.links``: 115200 baud, converter latency, noise and scripted faults.
Everything is seeded, so the files are reproducible.
"""

from __future__ import annotations

import sys
from pathlib import Path

from conform.families.gve.sender.job import load_job
from conform.families.gve.sender.links import LinkModel
from conform.families.gve.sender.session import send_emulated
from conform.families.gve.spec import load_spec

HERE = Path(__file__).resolve().parent
JOBS = HERE / "jobs"

# name -> (job, sender options, link options, gcode options, note)
SESSIONS: dict[str, tuple[str, dict, dict, dict, str]] = {
    "good-rs232": (
        "part.nc", {"policy": "careful", "checksums": True},
        {"latency": 0.0, "corrupt_answers": {40}, "corrupt_commands": {120}},
        {},
        "careful sender, checksums, RS232-like link; one answer garbled and one command "
        "damaged on the way to show the recovery",
    ),
    "usb-latency": (
        "circles.nc", {"policy": "careful"}, {"latency": 0.008}, {"accel": 3000.0},
        "careful sender behind a USB converter (8 ms each way), one command per round trip",
    ),
    "usb-packets": (
        "circles.nc", {"policy": "careful", "packet": 20}, {"latency": 0.008},
        {"accel": 3000.0},
        "the same job and link with packets of 20 vectors",
    ),
    "careless-noisy": (
        "raster.txt", {"policy": "careless", "checksums": True},
        {"noise": 0.0003, "seed": 3, "corrupt_answers": {200}, "corrupt_commands": {300}},
        {},
        "careless sender on a noisy line: blind resends, moving on after silence, "
        "hammering a full queue",
    ),
}


def make(name: str) -> Path:
    job, sopts, lopts, gopts, note = SESSIONS[name]
    spec = load_spec()
    var = spec.variant("gve64-v19")
    dia = spec.dialect()
    items = load_job(JOBS / job, var, dia, **gopts)
    link = LinkModel(baud=115200, **lopts)
    out = HERE / f"{name}.mcap"
    res = send_emulated(items, var, dia, link=link, record=out, note=note, **sopts)
    s = res.sender.stats
    print(f"{out.name}: {out.stat().st_size} bytes, {s.sent} writes, {s.garbled} garbled, "
          f"{s.timeouts} timeouts, {s.queue_full} queue full, {s.resent} resent; "
          f"final position {res.position}")
    return out


if __name__ == "__main__":
    for n in sys.argv[1:] or list(SESSIONS):
        make(n)
