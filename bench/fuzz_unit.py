"""Fuzz campaign against the reference unit (not a test): prints figures and the rate's ratio to
its target, then one JSON object as the last line.

Random and mutated frames over every variant and dialect, checksums on and off, packets,
over-long lines and numbers (see conform/families/gve/testing/fuzz.py). Target: >= 50 000 frames/s in-process,
with 0 exceptions, 0 hangs and 0 malformed answers.

    python bench/fuzz_unit.py --frames 10000000 [--seed 1] [--hang 0.5]
"""

from __future__ import annotations

import argparse
import json
import resource
import sys

from conform.families.gve.spec import load_spec
from conform.families.gve.testing.fuzz import Campaign

TARGET_RATE = 50_000


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200_000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--per-config", type=int, default=None,
                    help="frames per variant x dialect run (default: frames / runs, at least "
                         "200; 31 250 gives a short run the mix of a 10 M one)")
    ap.add_argument("--hang", type=float, default=0.5,
                    help="a frame taking longer than this (CPU seconds) counts as a hang")
    args = ap.parse_args(argv)
    if args.frames <= 0:
        ap.error("--frames must be positive")
    if args.per_config is not None and args.per_config <= 0:
        ap.error("--per-config must be positive")
    campaign = Campaign(load_spec(), seed=args.seed, hang_s=args.hang)
    fig = campaign.run(args.frames, per_config=args.per_config)
    cpu_rate = fig.frames / fig.cpu_seconds if fig.cpu_seconds else 0.0
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"frames            {fig.frames:,} ({fig.judged:,} judged against their command, "
          f"{fig.resyncs:,} resynchronisations, {fig.configs} variant x dialect runs)")
    print(f"wall              {fig.seconds:.1f} s  -> {fig.rate:,.0f} frames/s "
          f"(ratio to {TARGET_RATE:,}: {fig.rate / TARGET_RATE:.2f})")
    print(f"cpu               {fig.cpu_seconds:.1f} s  -> {cpu_rate:,.0f} frames/s "
          f"(ratio {cpu_rate / TARGET_RATE:.2f})")
    print(f"slowest frame     {fig.max_frame_s * 1000:.1f} ms of CPU (hang bound {args.hang:g} s)")
    print(f"failures          {fig.failures} (exceptions {fig.exceptions}, hangs {fig.hangs}, "
          f"malformed answers {fig.malformed})")
    print(f"max RSS           {rss_mb:.0f} MB")
    for example in fig.examples:
        print(f"  {example}")
    print(json.dumps({
        "bench": "fuzz_unit", "frames": fig.frames, "judged": fig.judged,
        "configs": fig.configs, "resyncs": fig.resyncs, "seconds": round(fig.seconds, 3),
        "cpu_seconds": round(fig.cpu_seconds, 3), "rate": round(fig.rate),
        "cpu_rate": round(cpu_rate), "target_rate": TARGET_RATE,
        "ratio": round(fig.rate / TARGET_RATE, 3), "exceptions": fig.exceptions,
        "hangs": fig.hangs, "malformed": fig.malformed, "failures": fig.failures,
        "max_frame_ms": round(fig.max_frame_s * 1000, 2), "max_rss_mb": round(rss_mb),
        "seed": args.seed,
    }))
    return 0 if fig.failures == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
