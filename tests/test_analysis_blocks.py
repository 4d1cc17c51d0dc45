"""The analysis steps that work a block at a time give the same findings and metrics
whatever the block size (vector pattern, cumulative motion, compiled replay)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from conform.families.gve.analysis import analyze, positions, queue

CAPTURES = Path(__file__).resolve().parent.parent / "captures"


def outcome(path: Path) -> tuple[list, str]:
    a = analyze(path)
    found = [json.dumps(f.to_dict(), sort_keys=True, default=str) for f in a.findings]
    return found, json.dumps(a.metrics, sort_keys=True, default=str)


@pytest.mark.parametrize("name", ["careless-noisy", "usb-packets", "usb-latency"])
def test_results_do_not_depend_on_the_block_sizes(name: str,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    path = CAPTURES / f"{name}.mcap"
    found, metrics = outcome(path)
    assert metrics  # usb-packets has no finding: its metrics still compare
    monkeypatch.setattr(positions, "CUM_BLOCK", 3)
    monkeypatch.setattr(queue, "REPLAY_CHUNK", 7)
    tiny_found, tiny_metrics = outcome(path)
    assert tiny_found == found
    assert tiny_metrics == metrics
