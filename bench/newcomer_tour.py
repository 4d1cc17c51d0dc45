"""A newcomer's pass from a wheel: build the wheel, install it in a fresh virtual
environment, write the samples (`conform samples`) into a fresh folder, run the README's
commands there, then a set of deliberate mistakes across every command and family.

    python bench/newcomer_tour.py [--keep DIR] [--skip-build] [--mistakes-only] [--jobs N]

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
import threading
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
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
# instead (one capture with --scheduler is analysed here). {T}: the tour's folder, where
# main() leaves junk, empty, truncated and unreadable files; /proc/... cannot be written
# even by root.
_FAMILY = {"gve64-v19": ("captures/good-rs232.mcap", "captures/jobs/raster.txt", "{T}/unit.toml"),
           "grbl-1.1f": ("captures/grbl-counting.mcap", "captures/jobs/grbl-arc.nc", None),
           "marlin-2.1": ("captures/marlin-noisy.mcap", "captures/jobs/marlin-ring.gcode",
                          "{T}/printer.toml")}
_NOWHERE = "/proc/conform-nowhere"
MISTAKES: list[tuple[str, bool]] = [(c, False) for c in [
    # run
    "conform run --target emu:nope", "conform run --target /dev/ttyNOPE",
    "conform run --variant nope", "conform run --check 'zzz/*'",
    "conform run --seed abc", "conform run --seed -1", "conform run --max-steps -5",
    "conform run --max-steps 0", "conform run --baud 0", "conform run --baud abc",
    "conform run --baud -9600", "conform run --profile nope", "conform run --replay nope",
    "conform run --matrix --target emu:grbl-1.1f",
    "conform run --inputs-control /missing.sock", "conform run --inputs-control {T}/file",
    "conform run --dialect {T}/printer.toml -q", "conform run --dialect /nonexistent.toml",
    "conform run --dialect {T}/empty.toml", "conform run --dialect {T}/bad.toml",
    "conform run --dialect {T}/adir", "conform run --dialect {T}/junk.bin",
    "conform run --report {T}/file/x", "conform run --report {T}/file",
    f"conform run --report {_NOWHERE}/r", "conform run --target emu:",
    "conform run --target emu:grbl-9", "conform run --target {T}/file",
    "conform run --target {T}/adir", "conform run extra", "conform run --target",
    "conform run --list --check 'zzz/*'", "conform run --replay 'x@abc'",
    "conform run --mutants --target /dev/ttyNOPE", "conform run --json --report {T}/file/x",
    "conform run --target emu:gve64-v19:nope", "conform run --nope",
    # send
    "conform send /nonexistent.nc --target emu:gve64-v19", "conform send {T}/adir --target emu:gve64-v19",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --record {T}/file/x.mcap",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --record {T}/adir",
    f"conform send captures/jobs/part.nc --target emu:gve64-v19 --record {_NOWHERE}/x.mcap",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --record captures/good-rs232.mcap",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --timeout -1",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --timeout 0",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --timeout abc",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --baud 0",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --baud abc",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --packet 0",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --packet abc",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --policy nope",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --latency -1",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --noise 2",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --noise abc",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --seed abc",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --seed -1",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --steps-per-mm abc",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --steps-per-mm 1,2",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --feed 0",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --accel -5",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --method nope",
    "conform send captures/jobs/part.nc --target /dev/ttyNOPE",
    "conform send captures/jobs/part.nc --target emu:", "conform send captures/jobs/part.nc --target emu:nope",
    "conform send captures/jobs/part.nc --target {T}/file",
    "conform send captures/jobs/part.nc --target emu:gve64-v19 --variant marlin-2.1",
    "conform send captures/jobs/grbl-arc.nc --target emu:grbl-1.1f --variant gve64-v19",
    "conform send captures/jobs/marlin-ring.gcode --target emu:marlin-2.1 --variant grbl-1.1f",
    "conform send --target emu:gve64-v19", "conform send a.nc b.nc --target emu:gve64-v19",
    "conform send captures/jobs/raster.txt --target emu:grbl-1.1f",
    "conform send captures/jobs/raster.txt --target emu:marlin-2.1",
    "conform send captures/jobs/marlin-ring.gcode --target emu:gve64-v19",
    "conform send captures/good-rs232.mcap --target emu:gve64-v19",
    "conform send captures/jobs/part.nc --target /dev/ttyNOPE --record {T}/rec.mcap",
    # characterize
    "conform characterize emu:gve64-v19 -o {T}/unit.toml",
    "conform characterize emu:marlin-2.1 -o {T}/printer.toml",
    "conform characterize emu:nope -o {T}/u.toml", "conform characterize emu: -o {T}/u.toml",
    "conform characterize /dev/ttyNOPE -o {T}/u.toml", "conform characterize {T}/file -o {T}/u.toml",
    "conform characterize -o {T}/u.toml", "conform characterize emu:gve64-v19 -o {T}/adir",
    f"conform characterize emu:gve64-v19 -o {_NOWHERE}/u.toml",
    "conform characterize emu:gve64-v19 -o {T}/u.toml --max-steps 0",
    "conform characterize emu:gve64-v19 -o {T}/u.toml --baud 0",
    "conform characterize emu:gve64-v19 -o {T}/u.toml --variant grbl-1.1f",
    "conform characterize emu:grbl-1.1f -o {T}/u.toml --variant marlin-2.1",
    "conform characterize emu:marlin-2.1 -o {T}/u.toml --variant gve64-v19",
    "conform characterize emu:gve64-v19 -o {T}/u.toml --variant nope",
    "conform characterize emu:gve64-v19:nope -o {T}/u.toml",
    "conform characterize emu:gve64-v19 emu:gve124 -o {T}/u.toml",
    # check-sender
    "conform check-sender", "conform check-sender --scenario nope -- true {{port}}",
    "conform check-sender -- /nonexistent/sender {{port}}",
    "conform check-sender --timeout -1 -- true {{port}}", "conform check-sender --timeout 0 -- true {{port}}",
    "conform check-sender --timeout abc -- true {{port}}", "conform check-sender --variant nope -- true {{port}}",
    "conform check-sender --variant grbl-1.1f --scenario clean -- true {{port}}",
    "conform check-sender --variant marlin-2.1 --scenario stream -- true {{port}}",
    "conform check-sender --scenario busy -- true {{port}}",
    "conform check-sender --job /nonexistent.nc -- true {{port}}",
    "conform check-sender --job {T}/adir -- true {{port}}",
    "conform check-sender --job {T}/empty.nc -- true {{port}}",
    "conform check-sender --job {T}/junk.bin -- true {{port}}",
    "conform check-sender --report {T}/file/x -- true {{port}}",
    f"conform check-sender --report {_NOWHERE}/r -- true {{{{port}}}}",
    "conform check-sender --seed abc -- true {{port}}", "conform check-sender --seed -1 -- true {{port}}",
    "conform check-sender -- {T}/file {{port}}", "conform check-sender -- {T}/adir {{port}}",
    "conform check-sender --variant marlin-2.1 -- /nonexistent/sender {{port}}",
    "conform check-sender --variant grbl-1.1f -- /nonexistent/sender {{port}}",
    "conform check-sender --variant marlin-2.1 --job captures/jobs/raster.txt -- true {{port}}",
    "conform check-sender --variant grbl-1.1f --job captures/jobs/raster.txt -- true {{port}}",
    "conform check-sender --job captures/jobs/marlin-ring.gcode -- true {{port}}",
    "conform check-sender --variant grbl-1.1f --job captures/jobs/marlin-ring.gcode -- true {{port}}",
    "conform check-sender --variant marlin-2.1 --job captures/jobs/grbl-arc.nc -- true {{port}}",
    # analyze
    "conform analyze /nonexistent.mcap", "conform analyze {T}/junk.bin", "conform analyze {T}/empty.mcap",
    "conform analyze {T}/adir", "conform analyze {T}/file", "conform analyze",
    "conform analyze captures/good-rs232.mcap --time-range 5:1",
    "conform analyze captures/good-rs232.mcap --time-range abc",
    "conform analyze captures/good-rs232.mcap --time-range 999:1000",
    "conform analyze captures/good-rs232.mcap --report {T}/file/x",
    f"conform analyze captures/good-rs232.mcap --report {_NOWHERE}/r",
    "conform analyze captures/good-rs232.mcap --parquet {T}/file/x",
    f"conform analyze captures/good-rs232.mcap --parquet {_NOWHERE}/t",
    "conform analyze captures/ --scheduler tcp://127.0.0.1:1",
    "conform analyze captures/ --scheduler nope",
    "conform analyze captures/good-rs232.mcap --variant nope",
    "conform analyze captures/good-rs232.mcap --baud 0",
    "conform analyze captures/good-rs232.mcap --baud abc",
    "conform analyze captures/good-rs232.mcap --dialect A99=x",
    "conform analyze captures/good-rs232.mcap --dialect nope",
    "conform analyze captures/good-rs232.mcap --dialect A10=nope",
    "conform analyze captures/ --jobs 0", "conform analyze captures/ --jobs abc",
    "conform analyze captures/good-rs232.mcap --fail-on nope",
    "conform analyze captures/jobs/part.nc", "conform analyze {T}/r1/results.json",
    # diagnose
    "conform diagnose {T}/junk.bin", "conform diagnose /nonexistent.mcap", "conform diagnose {T}/empty.mcap",
    "conform diagnose {T}/adir", "conform diagnose {T}/file", "conform diagnose",
    "conform diagnose captures/good-rs232.mcap --variant nope",
    "conform diagnose captures/jobs/part.nc",
    # report
    "conform report {T}/empty.mcap", "conform report /nonexistent.json", "conform report {T}/junk.json",
    "conform report {T}/empty.json", "conform report captures/good-rs232.mcap", "conform report",
    "conform report {T}/adir", "conform report {T}/r1/results.json -o {T}/file/x",
    f"conform report {{T}}/r1/results.json -o {_NOWHERE}/r",
    "conform report {T}/r1/results.json -o {T}/file", "conform report {T}/list.json",
    # bundle
    "conform bundle {T}/junk.bin -o {T}/x.zip", "conform bundle /nonexistent.mcap -o {T}/x.zip",
    "conform bundle {T}/empty.mcap -o {T}/x.zip", "conform bundle {T}/adir -o {T}/x.zip",
    "conform bundle captures/good-rs232.mcap -o {T}/file/x.zip",
    f"conform bundle captures/good-rs232.mcap -o {_NOWHERE}/x.zip",
    "conform bundle captures/good-rs232.mcap", "conform bundle -o {T}/x.zip",
    "conform bundle captures/good-rs232.mcap -o {T}/support.zip",
    "conform bundle captures/good-rs232.mcap -o {T}/adir",
    "conform bundle captures/jobs/part.nc -o {T}/x.zip",
    # capture
    "conform capture info {T}/junk.bin", "conform capture info {T}/empty.mcap",
    "conform capture info /nonexistent.mcap", "conform capture info {T}/adir", "conform capture info",
    "conform capture info captures/jobs/part.nc", "conform capture nope",
    "conform capture recover captures/good-rs232.mcap -o {T}/file/x.mcap",
    f"conform capture recover captures/good-rs232.mcap -o {_NOWHERE}/x.mcap",
    "conform capture recover captures/good-rs232.mcap -o captures/usb-latency.mcap",
    "conform capture recover {T}/junk.bin -o {T}/rj.mcap", "conform capture recover /nonexistent.mcap",
    "conform capture recover {T}/empty.mcap -o {T}/re.mcap", "conform capture recover {T}/adir",
    # profile
    "conform profile diff {T}/unit.toml", "conform profile diff {T}/unit.toml {T}/junk.bin",
    "conform profile diff {T}/unit.toml /nonexistent.toml", "conform profile diff {T}/unit.toml {T}/empty.toml",
    "conform profile diff {T}/unit.toml {T}/bad.toml", "conform profile diff {T}/unit.toml {T}/adir",
    "conform profile diff {T}/unit.toml {T}/printer.toml", "conform profile nope",
    # emulate
    "conform emulate nope", "conform emulate serve nope", "conform emulate serve gve64-v19:nope",
    "conform emulate serve gve64-v19 --faults corrupt=abc", "conform emulate serve gve64-v19 --faults nope",
    "conform emulate serve gve64-v19 --baud 0", "conform emulate serve gve64-v19 --baud abc",
    "conform emulate serve gve64-v19 --tcp -1", "conform emulate serve gve64-v19 --tcp abc",
    "conform emulate serve gve64-v19 --seed abc", "conform emulate serve gve64-v19 --answer-delay -1",
    f"conform emulate serve gve64-v19 --control {_NOWHERE}/c.sock",
    "conform emulate serve gve64-v19 --link {T}/file/x",
    "conform emulate serve gve64-v19 --record {T}/file/x.mcap",
    "conform emulate serve gve64-v19 --record captures/good-rs232.mcap",
    "conform emulate serve gve64-v19 --dialect A99=x", "conform emulate serve gve64-v19 --dialect A10=nope",
    "conform emulate serve gve64-v19 --profile /nonexistent.toml",
    "conform emulate serve gve64-v19 --profile {T}/printer.toml",
    "conform emulate serve gve64-v19 --profile {T}/bad.toml",
    "conform emulate serve gve64-v19 --switch X=abc", "conform emulate serve gve64-v19 --switch Q=10",
    "conform emulate serve gve64-v19 --truth {T}/file/x.json",
    "conform emulate serve grbl-1.1f --dialect A10=every-line",
    "conform emulate serve marlin-2.1 --profile {T}/unit.toml",
    "conform emulate serve grbl-1.1f --faults nope", "conform emulate serve marlin-2.1 --baud 0",
    "conform emulate serve grbl-1.1f --switch X=10", "conform emulate serve marlin-2.1 --truth {T}/t.json",
    "conform emulate control {T}/file state", "conform emulate control /missing.sock state",
    "conform emulate control {T}/adir state", "conform emulate control",
    "conform emulate judge tests/data/marlin/facts-2.1.2.4.transcript --variant grbl-1.1f",
    "conform emulate judge tests/data/marlin/facts-2.1.2.4.transcript --variant gve64-v19",
    "conform emulate judge tests/data/marlin/facts-2.1.2.4.transcript --variant nope",
    "conform emulate judge tests/data/marlin/facts-2.1.2.4.transcript --settle -1",
    "conform emulate judge /nonexistent.transcript --variant marlin-2.1",
    "conform emulate judge {T}/junk.bin --variant marlin-2.1",
    "conform emulate judge {T}/empty.transcript --variant marlin-2.1",
    "conform emulate judge {T}/adir --variant marlin-2.1", "conform emulate judge",
    "conform emulate judge captures/grbl-counting.mcap --variant marlin-2.1",
    "conform emulate judge captures/marlin-noisy.mcap --variant grbl-1.1f",
    "conform emulate judge captures/good-rs232.mcap --variant marlin-2.1",
    # spec
    "conform spec show nope", "conform spec show marlin-2.1 M999999", "conform spec show grbl-1.1f G99",
    "conform spec show grbl-1.1f '$ZZ'", "conform spec show gve64-v19 QQ", "conform spec show gve124 nope",
    "conform spec show", "conform spec diff gve64-v19 marlin-2.1", "conform spec diff grbl-1.1f marlin-2.1",
    "conform spec diff nope gve124", "conform spec diff gve64-v19", "conform spec check --specs /nonexistent",
    "conform spec check --specs {T}/file", "conform spec check --specs {T}/adir", "conform spec nope",
    "conform spec list extra", "conform spec show marlin-2.1-adv M999999",
    # proxy and sniff
    "conform proxy --unit /dev/ttyNOPE -o {T}/p.mcap --link {T}/p.pty",
    "conform proxy --unit /dev/ttyNOPE -o {T}/file/p.mcap --link {T}/p.pty",
    f"conform proxy --unit /dev/ttyNOPE -o {_NOWHERE}/p.mcap",
    "conform proxy --unit /dev/ttyNOPE", "conform proxy -o {T}/p.mcap",
    "conform proxy --unit /dev/ttyNOPE -o {T}/p.mcap --baud 0",
    "conform proxy --unit /dev/ttyNOPE -o {T}/p.mcap --variant nope",
    "conform proxy --unit /dev/ttyNOPE -o captures/good-rs232.mcap",
    "conform proxy --unit {T}/file -o {T}/p2.mcap",
    "conform sniff --host-port /dev/ttyNOPE --unit-port /dev/ttyNOPE2 -o {T}/s.mcap", "conform sniff",
    "conform sniff --host-port /dev/ttyNOPE --unit-port /dev/ttyNOPE2 -o {T}/file/s.mcap",
    "conform sniff --host-port /dev/ttyNOPE --unit-port /dev/ttyNOPE2 -o {T}/s.mcap --baud 0",
    "conform sniff --host-port /dev/ttyNOPE --unit-port /dev/ttyNOPE2 -o {T}/s.mcap --variant nope",
    # ports, samples, the command line itself
    "conform ports --probe --timeout -3", "conform ports --probe --timeout abc",
    "conform ports --probe --baud 0", "conform ports /dev/ttyNOPE", "conform ports {T}/file",
    "conform ports --nope", "conform samples {T}/file", f"conform samples {_NOWHERE}/s", "conform samples",
    "conform samples .", "conform nope", "conform --nope", "conform sned x",
]]
# the same mistakes in every family: another family's variant, capture, job or profile
for _v, (_cap, _job, _prof) in _FAMILY.items():
    _others = [o for o in _FAMILY if o != _v]
    MISTAKES += [(c, False) for c in [
        f"conform run --target emu:{_v} --variant {_others[0]}",
        f"conform run --target emu:{_v} --check '{_others[1]}/*'",
        f"conform run --target emu:{_v}:nope",
        f"conform run --target emu:{_v} --report {{T}}/file/x",
        f"conform run --target emu:{_v} --seed abc",
        f"conform send {{T}}/empty.nc --target emu:{_v}",
        f"conform send {{T}}/junk.bin --target emu:{_v}",
        f"conform send /nonexistent.nc --target emu:{_v}",
        f"conform send {_job} --target emu:{_v} --record {{T}}/file/x.mcap",
        f"conform send {_job} --target emu:{_v} --baud 0",
        f"conform send {_job} --target emu:{_v} --timeout -1",
        f"conform send {_job} --target /dev/ttyNOPE --variant {_v}",
        f"conform characterize emu:{_v} -o {{T}}/file/x.toml",
        f"conform characterize emu:{_v} -o {{T}}/u.toml --variant {_others[1]}",
        f"conform check-sender --variant {_v} --scenario nope -- true {{{{port}}}}",
        f"conform check-sender --variant {_v} --job {_FAMILY[_others[0]][1]} -- true {{{{port}}}}",
        f"conform check-sender --variant {_v} --report {{T}}/file/x -- true {{{{port}}}}",
        f"conform analyze {_cap} --variant {_others[0]}",
        f"conform analyze {_cap} --variant {_others[1]}",
        f"conform analyze {{T}}/trunc-{_v}.mcap --report {{T}}/file/x",
        f"conform diagnose {_cap} --variant {_others[0]}",
        f"conform emulate judge {_cap} --variant {_others[1]}",
        f"conform emulate serve {_v} --baud -1",
        f"conform spec show {_v} NOSUCH",
        f"conform spec diff {_v} {_others[0]}",
        f"conform spec diff {_v} nope",
        f"conform proxy --unit /dev/ttyNOPE -o {{T}}/p.mcap --variant {_v}x",
    ]]
    if _prof:
        MISTAKES += [(f"conform run --target emu:{_others[0]} --dialect {_prof} -q", False),
                     (f"conform emulate serve {_others[1]} --profile {_prof}", False)]
MISTAKES += [
    # answered: one capture with --scheduler is analysed here, and says so; a truncated
    # capture is analysed up to where it ends, and says so (exit 1 for the damage)
    ("conform analyze captures/good-rs232.mcap --scheduler tcp://127.0.0.1:1", True),
    # not a mistake after all: Marlin has two variants, and the matrix runs both, naming them
    ("conform run --matrix --target emu:marlin-2.1 -q", True),
    # a grbl G-code job is G-code to Marlin too: sent, and the lines it skipped are named
    ("conform send captures/jobs/grbl-arc.nc --target emu:marlin-2.1", True),
    # --probe says of each port why no unit answered ("cannot open: ...")
    ("conform ports --probe {T}/file", True),
    # the default family's analysis options on another family's capture: named as not used
    ("conform analyze captures/grbl-counting.mcap --dialect A10=every-line", True),
    ("conform analyze captures/marlin-noisy.mcap --time-range 1:2 --report {T}/mt", True),
]
MISTAKES = list(dict.fromkeys(MISTAKES))
# commands that serve until stopped get a short bound: a mistake must be refused at once
_SERVING = ("conform emulate serve", "conform proxy", "conform sniff")



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
    ap.add_argument("--mistakes-only", action="store_true",
                    help="skip the tour (reuse DIR/tour from a pass before)")
    ap.add_argument("--only", metavar="TEXT", help="only the mistakes whose command has TEXT")
    ap.add_argument("--jobs", type=int, default=2, help="mistakes run at once (default 2)")
    args = ap.parse_args()
    home = args.keep or Path(tempfile.mkdtemp(prefix="conform-newcomer-"))
    home.mkdir(parents=True, exist_ok=True)
    venv, samples, out = home / "venv", home / "samples", home / "tour"
    if not args.skip_build:
        subprocess.run([sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-q",
                        "-w", str(home / "wheel")], check=True)
        # the dependencies come from the system's site packages; conform from the wheel only
        subprocess.run([sys.executable, "-m", "venv", "--clear", "--system-site-packages",
                        str(venv)], check=True)
        wheel = next((home / "wheel").glob("conform-*.whl"))
        subprocess.run([str(venv / "bin" / "pip"), "install", "-q", "--no-deps", str(wheel)],
                       check=True)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PATH"] = f"{venv / 'bin'}:{env['PATH']}"
    counts: Counter[str] = Counter()
    lock = threading.Lock()

    def make_files() -> None:
        out.mkdir(exist_ok=True)
        (out / "junk.bin").write_bytes(os.urandom(3000))
        (out / "empty.mcap").write_bytes(b"")
        (out / "file").write_text("x\n")
        (out / "adir").mkdir(exist_ok=True)
        for name, text in (("empty.nc", ""), ("empty.toml", ""), ("bad.toml", "x = [\n"),
                           ("junk.json", "{not json"), ("empty.json", ""), ("list.json", "[]"),
                           ("empty.transcript", "")):
            (out / name).write_text(text)
        for variant, cap in (("gve64-v19", "good-rs232"), ("grbl-1.1f", "grbl-counting"),
                             ("marlin-2.1", "marlin-noisy")):
            whole = (samples / "captures" / f"{cap}.mcap")
            if whole.exists():
                data = whole.read_bytes()
                (out / f"trunc-{variant}.mcap").write_bytes(data[: len(data) // 2])


    def one(kind: str, cmd: str, allowed: int | bool, timeout: float, cwd: Path) -> str:
        rc, said, dt = run(cmd.format(T=out), env, cwd, timeout)
        g = grade(kind, rc, said, allowed)
        with lock:
            counts[g] += 1
        last = (said.strip().splitlines() or [""])[-1][:150]
        return f"{g:10} {'-' if rc is None else rc:>3} {dt:6.1f}s {cmd[:100]}\n{'':22}{last}"

    if not args.mistakes_only:
        print(one("tour", f"conform samples {samples}", 0, 120, home), flush=True)
        make_files()
        for cmd, allowed in TOUR:
            print(one("tour", cmd.replace(" -o {T}/", " --force -o {T}/") if "characterize"
                      in cmd or "bundle" in cmd else cmd, allowed, 600, samples), flush=True)
        for cmd in SERVING:
            print(one("serve", cmd, 0, 5, samples), flush=True)
    else:
        make_files()
    mistakes = [m for m in MISTAKES if args.only is None or args.only in m[0]]
    with ThreadPoolExecutor(args.jobs) as pool:
        for line in pool.map(lambda m: one("mistake", m[0], m[1], 15 if m[0].startswith(
                _SERVING) else 120, samples), mistakes):
            print(line, flush=True)
    print(json.dumps(dict(counts)))
    if any(counts[k] for k in ("SILENT", "TRACEBACK", "HANG", "FAILED")):
        raise SystemExit(1)


if __name__ == "__main__":
    main()
