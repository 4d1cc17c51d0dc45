"""Benchmark: the diagnosis against its labelled corpus, and its cost next to the analysis.

1. The confusion matrix: every session of tests/diag_corpus.py (in-process clean and injected
   sessions of each family, the sample captures, the real Marlin firmware's recordings; with
   ``--proxied`` also real sender programs through ``conform proxy``, a few minutes) is
   diagnosed; what led is counted against its label. Clean sessions must lead with
   ``completed`` and claim no loss; injected ones with their cause (target: 95 % per family).
2. Side by side on a long capture (bench_analysis.py's synthetic GVE session, ``--exchanges``
   1 000 000 by default): ``conform analyze`` and ``conform diagnose``, each in its own
   process, CPU seconds and peak memory; target: the diagnosis within 2x of the analysis.

    python bench/bench_diagnosis.py                      # matrix + 1 M timing
    python bench/bench_diagnosis.py --proxied            # real senders too
    python bench/bench_diagnosis.py --exchanges 0        # the matrix only

Prints the matrix, the figures and, last, one JSON object.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "bench"))

RATIO_TARGET = 2.0
ACCURACY_TARGET = 0.95


def _child(args: list[str]) -> tuple[float, float]:
    """CPU seconds and peak memory (MB) of one ``conform`` run in its own process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    code = ("import resource, runpy, sys; sys.argv = ['conform', *sys.argv[1:]]\n"
            "try:\n    runpy.run_module('conform', run_name='__main__')\n"
            "except SystemExit:\n    pass\n"
            "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr)")
    p = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                       cwd=ROOT, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    rss = int(p.stderr.strip().splitlines()[-1]) / 1024.0
    return cpu, rss


def corpus(proxied: bool, varied: int, seed: int) -> list[dict]:
    import diag_corpus as C

    tmp = Path(tempfile.mkdtemp(prefix="conform-diag-bench-"))
    entries = C.fast(tmp / "fast") + C.samples()
    if varied:
        entries += C.varied(tmp / "varied", varied, seed=seed)
    if proxied:
        entries += C.proxied(tmp / "proxied")
    return C.judge(entries)


def calibrate() -> None:
    """The confidence table from the calibration corpus, written and printed."""
    import diag_corpus as C

    from conform.diagnosis import calibration

    calibration.write(calibration.count([]), C.CALIBRATION_CORPUS)    # measured afresh
    tmp = Path(tempfile.mkdtemp(prefix="conform-diag-calibrate-"))
    rows = C.judge(C.calibration_corpus(tmp))
    counts = calibration.count((r["key"], r["agreed"]) for r in rows)
    calibration.write(counts, C.CALIBRATION_CORPUS)
    print(f"confidence table ({C.CALIBRATION_CORPUS}, {len(rows)} sessions) written to "
          f"{calibration.TABLE.relative_to(ROOT)}")
    for key, (k, n) in counts.items():
        print(f"  {key:55} {k / n:5.2f}  ({k}/{n})")
    print()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--exchanges", type=int, default=1_000_000,
                    help="exchanges in the long capture timed (0: no timing)")
    ap.add_argument("--capture", help="time this capture instead of a synthetic one")
    ap.add_argument("--proxied", action="store_true",
                    help="add real sender programs through conform proxy (minutes)")
    ap.add_argument("--varied", type=int, default=3,
                    help="held-out variations of each kind, parameters drawn at random")
    ap.add_argument("--seed", type=int, default=7, help="seed of the variations")
    ap.add_argument("--repeat", type=int, default=3,
                    help="timed runs of each, alternating (the median is compared)")
    ap.add_argument("--no-matrix", action="store_true", help="the timing only")
    ap.add_argument("--calibrate", action="store_true",
                    help="measure the confidence table on the calibration corpus and write it "
                         "(conform/diagnosis/calibration.toml)")
    ns = ap.parse_args()
    from diag_corpus import CLEAN

    if ns.calibrate:
        calibrate()
    rows = [] if ns.no_matrix else corpus(ns.proxied, ns.varied, ns.seed)
    labels = sorted({r["label"] for r in rows}, key=lambda x: (x not in CLEAN, x))
    got = sorted({r["got"] for r in rows}, key=lambda x: (x not in CLEAN, x))
    cells: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for r in rows:
        cells[r["label"]][r["got"]] += 1
    width = max(len(x) for x in [*labels, "label \\ led"]) + 1
    print("confusion matrix (rows: label, columns: what the diagnosis put first)")
    print("label \\ led".ljust(width) + "".join(g[:15].rjust(16) for g in got))
    for lab in labels:
        print(lab.ljust(width) + "".join(str(cells[lab].get(g, 0) or ".").rjust(16)
                                         for g in got))
    per_family: dict[str, dict[str, int]] = {}
    for r in rows:
        fam = per_family.setdefault(r["family"], {"clean": 0, "clean_ok": 0, "injected": 0,
                                                  "injected_ok": 0, "false_claims": 0})
        kind = "clean" if r["label"] in CLEAN else "injected"
        fam[kind] += 1
        fam[f"{kind}_ok"] += r["got"] == r["label"]
        fam["false_claims"] += len(r["false_claims"])
    print()
    for name, f in sorted(per_family.items()):
        acc = f["injected_ok"] / f["injected"] if f["injected"] else None
        print(f"{name}: clean {f['clean_ok']}/{f['clean']} with their outcome and no stop cause, "
              f"{f['false_claims']} false loss claims; injected "
              f"{f['injected_ok']}/{f['injected']} led by their cause"
              + (f" ({acc:.0%}, target {ACCURACY_TARGET:.0%})" if acc is not None else ""))
    wrong = [f"{r['name']}: {r['label']} -> {r['got']}" for r in rows if r["got"] != r["label"]]
    for w in wrong:
        print("  wrong:", w)

    timing: dict[str, float] = {}
    if ns.capture or ns.exchanges:
        path = Path(ns.capture) if ns.capture else \
            Path(tempfile.mkdtemp(prefix="conform-diag-bench-")) / "long.mcap"
        if not ns.capture:
            from bench_analysis import make_capture

            make_capture(path, ns.exchanges)
        runs: dict[str, list[tuple[float, float]]] = {"analyze": [], "diagnose": []}
        for _ in range(max(1, ns.repeat)):
            for what in runs:
                runs[what].append(_child([what, str(path)]))
        med = {k: sorted(v)[len(v) // 2] for k, v in runs.items()}
        (a_cpu, a_rss), (d_cpu, d_rss) = med["analyze"], med["diagnose"]
        ratio = d_cpu / a_cpu if a_cpu else float("inf")
        print()
        print(f"long capture {path.name} ({ns.exchanges if not ns.capture else '?'} exchanges)")
        for what, v in runs.items():
            print(f"  {what + ':':9} " + ", ".join(f"{c:.2f}" for c, _ in v) + " s CPU; median "
                  f"{med[what][0]:.2f} s, {med[what][1]:.0f} MB peak")
        print(f"  ratio {ratio:.2f} (target at most {RATIO_TARGET:g}); memory ratio "
              f"{d_rss / a_rss:.2f}")
        timing = {"exchanges": ns.exchanges if not ns.capture else None,
                  "analyze_cpu_s": round(a_cpu, 3), "diagnose_cpu_s": round(d_cpu, 3),
                  "analyze_peak_mb": round(a_rss), "diagnose_peak_mb": round(d_rss),
                  "cpu_ratio": round(ratio, 3), "cpu_ratio_target": RATIO_TARGET,
                  "runs": {k: [round(c, 3) for c, _ in v] for k, v in runs.items()}}
    print(json.dumps({"sessions": len(rows), "varied": ns.varied, "seed": ns.seed,
                      "proxied": ns.proxied, "matrix": {k: dict(v) for k, v in cells.items()},
                      "families": per_family, "wrong": wrong, "timing": timing}))


if __name__ == "__main__":
    main()
