"""The whole hostile-capture corpus (tests/hostile_captures.py) against ``capture info``,
``capture recover`` and ``analyze``, with bigger bombs than the test uses.

Every file must end in one clear line and exit 2, or an honest damaged/truncated status
and a non-zero exit; never a traceback, a signal, a hang or more than 2 GB of RSS. Prints
the outcome counts per command, the failures and, last, one JSON object.

    python bench/bench_hostile_captures.py --bomb-gb 8 --count 12
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))


def main() -> None:
    from hostile_captures import base_files, check_corpus, corpus, intact_info

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bomb-gb", type=float, default=8.0, help="inflated size of each bomb")
    ap.add_argument("--count", type=int, default=12, help="mutants of each kind per base file")
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench-hostile-"))
    t = time.perf_counter()
    paths = corpus(work / "corpus", seed=args.seed, bomb_bytes=int(args.bomb_gb * (1 << 30)),
                   count=args.count)
    make_s = time.perf_counter() - t
    print(f"made {len(paths)} hostile files in {make_s:.1f} s under {work}")
    intact = {name: intact_info(data, work) for name, data in base_files().items()}
    env = dict(os.environ, PYTHONPATH=str(ROOT), CORPUS_TIMEOUT="60")
    t = time.perf_counter()
    counts, failures = check_corpus(paths, intact, work, env, analyze_every=1)
    run_s = time.perf_counter() - t
    print(f"ran in {run_s:.1f} s")
    for cmd, c in counts.items():
        print(f"{cmd:16} " + ", ".join(f"{k} {v}" for k, v in c.items()))
    for f in failures:
        print("FAIL", f)
    print(json.dumps({"files": len(paths), "counts": counts, "failures": len(failures),
                      "target_failures": 0, "bomb_gb": args.bomb_gb, "count": args.count,
                      "seed": args.seed, "make_s": round(make_s, 2), "run_s": round(run_s, 2)}))


if __name__ == "__main__":
    main()
