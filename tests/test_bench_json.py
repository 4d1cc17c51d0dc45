"""Every benchmark ends with one JSON object on its last stdout line (the machine-readable
figures): run the ones that are cheap at their smallest sizes and read that line back."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# script, its smallest sensible arguments, keys its JSON must hold
CASES = [
    ("bench_unit.py", ["--vectors", "2000", "--throughput", "2000"],
     {"variant", "target_rate", "fed_vectors_per_s", "fed_ratio", "blind_vectors_per_s",
      "blind_queue_full", "blind_ratio", "job_vectors", "job_wall_s", "job_target_s",
      "job_ratio", "peak_rss_mb", "rss_target_mb", "rss_ratio", "starvations"}),
    ("bench_motion.py", ["--vectors", "2000", "--ops", "2000"],
     {"vectors", "job_wall_s", "job_target_s", "job_ratio", "peak_rss_mb", "rss_ratio",
      "push_per_s", "model_commands_per_s", "model_target_per_s", "model_ratio",
      "final_position", "starvations"}),
    ("bench_capture_latency.py", ["--count", "50"],
     {"count", "direct_p50_ms", "direct_p99_ms", "proxy_p99_ms", "proxy_max_ms",
      "added_p99_ms", "target_added_p99_ms", "ratio", "capture_state", "exchanges_recorded"}),
    ("bench_capture_writer.py", ["--seconds", "1"],
     {"seconds", "lines", "reads", "messages", "capture_mb", "writer_cpu_s", "writer_cpu_per_s"}),
]
SLOW_CASES = [
    ("bench_conformance.py", ["--variant", "gve64-v19", "--mutants", "1"],
     {"variants_run", "variants", "quick_s", "quick_target_s", "quick_ratio", "mutants",
      "mutants_killed", "kill_rate", "kill_rate_target", "kill_rate_ratio",
      "state_machine_found", "state_machine_s"}),
]


def last_json(script: str, args: list[str]) -> dict:
    r = subprocess.run([sys.executable, str(ROOT / "bench" / script), *args],
                       capture_output=True, text=True, timeout=300, cwd=ROOT,
                       env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert r.returncode in (0, 1), r.stderr[-2000:]  # 1: a target missed, still a result
    lines = r.stdout.strip().splitlines()
    assert len(lines) > 1, r.stdout  # the figures in words come first
    assert not any(line.startswith("{") for line in lines[:-1])
    # strict JSON: NaN and Infinity are not numbers a reader can take
    out = json.loads(lines[-1], parse_constant=lambda c: pytest.fail(f"{c} in JSON"))
    assert isinstance(out, dict)
    return out


def check(out: dict, keys: set[str]) -> None:
    assert keys <= set(out), sorted(keys - set(out))
    assert all(k == k.lower() and " " not in k for k in out)
    for k in keys:
        if k.endswith(("_s", "_ms", "_mb", "_per_s", "ratio")):
            assert isinstance(out[k], (int, float)) and not isinstance(out[k], bool), (k, out[k])


@pytest.mark.parametrize("script,args,keys", CASES, ids=[c[0] for c in CASES])
def test_bench_ends_with_json(script, args, keys):
    check(last_json(script, args), keys)


@pytest.mark.slow
@pytest.mark.parametrize("script,args,keys", SLOW_CASES, ids=[c[0] for c in SLOW_CASES])
@pytest.mark.long(55)
def test_slow_bench_ends_with_json(script, args, keys):
    out = last_json(script, args)
    check(out, keys)
    assert out["variants_run"] == ["gve64-v19"] and out["mutants"] == 1
