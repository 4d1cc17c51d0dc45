"""`conform run` against a unit over a serial link: wall time per variant and the grades compared
check by check with the in-process emulator, against the targets (quick ≤ 5 min, full ≤ 20 min
per variant at 115 200 Bd).

For each variant: `conform emulate serve V --baud 115200` on a pty, then
`conform run --target PTY --variant V --allow-motion --max-steps 1000000 --allow-eeprom` (with
`--inputs-control` to the emulator's control socket unless --no-inputs), and the same run with
`--target emu:V`; both as a user runs them (subprocesses).

    python bench/bench_link_run.py [--profile quick|full] [--variant V ...] [--baud N] [--no-inputs]
                                   [--no-opt-in]

``--no-opt-in`` measures the default run a user gets against a real unit (no motion, no EEPROM
writes, no driven inputs): the emulator's run is still everything, and the grades are compared
on the checks the link ran (the SKIPPED ones are counted, not compared).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = {"quick": 300.0, "full": 1200.0}
VARIANTS = ("gve64-v10", "gve64-v19", "gve64-phantom", "gve124")
OPTIN = ["--allow-motion", "--max-steps", "1000000", "--allow-eeprom"]


def _conform(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "conform", *args], capture_output=True,
                          text=True, **kw)


def _grades(report: Path) -> tuple[dict[str, str], dict]:
    data = json.loads((report / "results.json").read_text())
    run = data["runs"][0] if data["runs"] else {}
    return {c["id"]: c["grade"] for c in data["checks"]}, run


def run_variant(variant: str, profile: str, baud: int, work: Path, inputs: bool,
                opt_in: bool = True) -> dict:
    options = [*(OPTIN if opt_in else []), "-q"]
    control = work / f"{variant}.sock"
    emu = subprocess.Popen([sys.executable, "-m", "conform", "emulate", "serve", variant,
                            "--baud", str(baud), "--control", str(control)],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    drive = ["--inputs-control", str(control)] if inputs else []
    try:
        assert emu.stdout is not None
        pty = emu.stdout.readline().strip()
        link_dir = work / f"{variant}-link"
        t0 = time.perf_counter()
        c0 = os.times()
        link = _conform("run", "--target", pty, "--variant", variant, "--profile", profile,
                        "--baud", str(baud), "--report", str(link_dir), *options, *drive)
        c1 = os.times()
        wall = time.perf_counter() - t0
    finally:
        emu.send_signal(signal.SIGINT)
        try:
            emu.wait(10)
        except subprocess.TimeoutExpired:
            emu.kill()
    emu_dir = work / f"{variant}-emu"
    t0 = time.perf_counter()
    _conform("run", "--target", f"emu:{variant}", "--profile", profile, "--report",
             str(emu_dir), *options)
    emu_wall = time.perf_counter() - t0
    got, run = _grades(link_dir)
    data = json.loads((link_dir / "results.json").read_text())
    bad = [{"id": c["id"], "grade": c["grade"], "expected": c["expected"],
            "actual": c["actual"], "detail": c["detail"],
            "log": [f"{e['t']:.4f} {e['dir']} {e['data']!r}" for e in c["log"]][-30:]}
           for c in data["checks"] if c["grade"] in ("FAIL", "ERROR")]
    want, _ = _grades(emu_dir)
    mismatches = sorted(k for k in set(got) | set(want)
                        if got.get(k) != want.get(k) and got.get(k) != "SKIPPED")
    counts: dict[str, int] = {}
    for g in got.values():
        counts[g] = counts.get(g, 0) + 1
    return {"variant": variant, "wall_s": round(wall, 1),
            "cpu_s": round((c1.children_user + c1.children_system)
                           - (c0.children_user + c0.children_system), 1),
            "exit": link.returncode, "checks": len(got), "grades": counts,
            "mismatches": len(mismatches), "mismatch_ids": mismatches[:20],
            "emu_wall_s": round(emu_wall, 1), "estimate_s": run.get("estimate_s"),
            "state": run.get("state", {}), "complete": run.get("complete", False),
            "failures": bad,
            "ratio": round(wall / TARGET_S[profile], 3)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", choices=sorted(TARGET_S), default="quick")
    ap.add_argument("--variant", action="append", choices=VARIANTS)
    ap.add_argument("--baud", type=int, default=115200)
    ap.add_argument("--no-inputs", action="store_true",
                    help="do not drive the emulator's inputs (--inputs-control): the two checks "
                         "that need inputs are then SKIPPED on the link")
    ap.add_argument("--no-opt-in", action="store_true",
                    help="the default run: no --allow-motion/--allow-eeprom, no driven inputs")
    args = ap.parse_args()
    target = TARGET_S[args.profile]
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-link-") as tmp:
        for variant in args.variant or VARIANTS:
            r = run_variant(variant, args.profile, args.baud, Path(tmp),
                            not args.no_inputs and not args.no_opt_in, not args.no_opt_in)
            rows.append(r)
            shown = ", ".join(f"{k} {v}" for k, v in sorted(r["grades"].items()))
            st = r["state"]
            print(f"{variant:14} {r['wall_s']:7.1f} s (estimate {r['estimate_s']} s, cpu "
                  f"{r['cpu_s']} s)  {r['checks']} checks: {shown}; vs emu:{variant}: "
                  f"{r['mismatches']} mismatches; states: {st.get('tidy')} tidy, "
                  f"{st.get('resets', 0) + st.get('quiet_resets', 0)} J; "
                  f"ratio to {target:.0f} s: {r['ratio']:.3f}", flush=True)
            for m in r["mismatch_ids"]:
                print(f"    mismatch: {m}")
            for f in r["failures"]:
                print(f"    {f['grade']} {f['id']}: expected {f['expected']} / got {f['actual']}"
                      f" ({f['detail']})")
                for line in f["log"]:
                    print(f"        {line}")
    worst = max(r["wall_s"] for r in rows)
    bad = sum(r["grades"].get("FAIL", 0) + r["grades"].get("ERROR", 0) for r in rows)
    mism = sum(r["mismatches"] for r in rows)
    print(f"{args.profile} at {args.baud} Bd over a pty: slowest variant {worst:.1f} s "
          f"(target ≤ {target:.0f} s: ratio {worst / target:.3f}); FAIL+ERROR {bad}; "
          f"grade mismatches vs emu {mism}")
    print(json.dumps({"bench": "link_run", "profile": args.profile, "baud": args.baud,
                      "opt_in": not args.no_opt_in,
                      "target_s": target, "slowest_s": worst, "ratio": round(worst / target, 3),
                      "fail_error": bad, "mismatches": mism, "variants": rows}))


if __name__ == "__main__":
    main()
