"""The compiled queue replay gives exactly what the Python motion executor gives."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from conform.families.gve.analysis import analyze
from conform.families.gve.analysis.analyze import accepted_vectors
from conform.families.gve.analysis.queue import CONTROL, replay
from conform.families.gve.spec import load_spec

CAPTURES = Path(__file__).resolve().parent.parent / "captures"
FIELDS = ("pushes", "push_rows", "starts", "ends", "starved", "v_out", "done_rows",
          "removals", "depth_t", "depth")


def same(a, b) -> None:  # type: ignore[no-untyped-def]
    for f in FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        assert x.shape == y.shape, f
        assert np.array_equal(x, y), f
    assert a.starvations == b.starvations
    assert a.notes == b.notes


def _gve_samples() -> list[str]:
    """The samples of GVE traffic (the motion replay is GVE's): the capture names its variant
    (read from the file's summary: every worker collects this, and the full pass of
    ``Capture.metadata`` took a second of it)."""
    from mcap.reader import make_reader

    from conform.families import family_for_variant

    def variant(path: Path) -> str:
        with path.open("rb") as fh:
            session = {m.name: m.metadata for m in make_reader(fh).iter_metadata()}["conform.session"]
        return session.get("variant", "gve64-v19")

    return [p.stem for p in sorted(CAPTURES.glob("*.mcap"))
            if family_for_variant(variant(p)).name == "gve"]


@pytest.mark.parametrize("name", _gve_samples())
def test_samples_compiled_equals_executor(name: str) -> None:
    a = analyze(CAPTURES / f"{name}.mcap", whatif_replays=False)
    ex = a.exchanges
    acc = accepted_vectors(ex)
    ctrl = np.isin(ex["name"].to_numpy(), list(CONTROL)) & (ex["code"].to_numpy() == 0)
    py = replay(ex, acc, a.host.result, a.variant, compiled=False)
    if ctrl.any():  # the compiled scan refuses H/G/D/K/R/J; the default takes Python
        with pytest.raises(ValueError):
            replay(ex, acc, a.host.result, a.variant, compiled=True)
        same(replay(ex, acc, a.host.result, a.variant), py)
        # the same session without its control commands, compiled against Python
        ex = ex.copy()
        ex.loc[ctrl, "code"] = 3
    same(replay(ex, acc, a.host.result, a.variant, compiled=True),
         replay(ex, acc, a.host.result, a.variant, compiled=False))


class _Cmd:
    def __init__(self, args: tuple) -> None:
        self.args = args


def session(seed: int, n: int) -> tuple[pd.DataFrame, np.ndarray, dict]:
    """A made-up exchange table: C and L vectors of every size (zero, short, long), modal
    V/A/B/$/T/VK/VN changes (some out of range), arrivals from bursts to long gaps."""
    rng = np.random.default_rng(seed)
    kinds = rng.choice(["C", "C", "C", "C", "L", "M"], n)
    modal = rng.choice(["V", "A", "B", "$", "T", "VK", "VN"], n)
    names = np.where(kinds == "M", modal, kinds).astype(object)
    kinds[0], names[0] = "M", "V"
    scale = rng.choice([0, 3, 40, 300, 3000], n, p=[0.03, 0.35, 0.35, 0.25, 0.02])
    vec = (rng.integers(-1, 2, (n, 4)) * rng.integers(0, 1 << 30, (n, 4)) % (scale[:, None] + 1))
    vec[names != "C"] *= names[names != "C"][:, None] == "L"
    slow = (np.arange(n) // 250) % 2 == 1  # stretches where the sender falls behind
    gaps = rng.choice([0.0, 1e-4, 2e-3, 0.02, 0.2], n, p=[0.1, 0.4, 0.3, 0.15, 0.05])
    t = 1.7e9 + np.cumsum(np.where(slow, gaps * 40, gaps * 0.05) * rng.random(n))
    code = np.where(rng.random(n) < 0.05, 1, 0)
    parsed = {}
    values = {"V": (0, 5000, 20000, 40000, 40000), "A": (20, 100, 400), "B": (100, 2000, 35000),
              "$": (0, 50, 512, 5000), "T": (0, 1, 5)}
    for r in np.flatnonzero(kinds == "M").tolist():
        name = names[r]
        parsed[r] = _Cmd((int(rng.choice(values[name])),) if name in values else ())
    ex = pd.DataFrame({"name": names, "code": code, "status": "answered", "t_cmd_last": t,
                       "dx": vec[:, 0], "dy": vec[:, 1], "dz": vec[:, 2], "da": vec[:, 3]})
    acc = np.isin(names, ("C", "L")) & (code == 0)
    return ex, acc, parsed


@pytest.mark.parametrize("seed", range(12))
def test_generated_sessions_compiled_equals_executor(seed: int) -> None:
    spec = load_spec()
    var = spec.variant(("gve64-v19", "gve124", "gve64-v10")[seed % 3])
    ex, acc, parsed = session(seed, 3000)
    fast = replay(ex, acc, parsed.get, var, compiled=True)
    slow = replay(ex, acc, parsed.get, var, compiled=False)
    same(fast, slow)
    # the session moved, ran the queue dry and filled it again
    assert len(fast.ends) > 1000 and fast.depth.max() > 20
    if seed in (0, 1, 4, 6, 7):  # these sessions starve the queue many times
        assert len(fast.starvations) > 20


def test_queue_beyond_capacity_drains_alike() -> None:
    """Every vector answered 0 faster than the motion runs: the queue outgrows its capacity
    and the final drain stops after the same number of steps."""
    var = load_spec().variant("gve64-v19")
    n = var.queue + 12_000
    ex = pd.DataFrame({"name": "C", "code": 0, "status": "answered",
                       "t_cmd_last": 1.7e9 + 1e-4 * np.arange(n),
                       "dx": 300, "dy": -120, "dz": 0, "da": 0})
    acc = np.ones(n, bool)
    fast = replay(ex, acc, {}.get, var, compiled=True)
    same(fast, replay(ex, acc, {}.get, var, compiled=False))
    assert len(fast.ends) < n


@pytest.mark.parametrize("chunk", [1, 2, 7, 450, 100_000])
def test_replay_does_not_depend_on_the_chunk(chunk: int) -> None:
    """The compiled scan carries the executor's state and its queued vectors from one
    chunk of events to the next: any chunk size gives the whole-session result."""
    spec = load_spec()
    for seed in (0, 6):
        var = spec.variant(("gve64-v19", "gve124", "gve64-v10")[seed % 3])
        ex, acc, parsed = session(seed, 2000)
        same(replay(ex, acc, parsed.get, var, compiled=True, chunk=chunk),
             replay(ex, acc, parsed.get, var, compiled=False))
    var = spec.variant("gve64-v19")  # a queue beyond capacity across chunk boundaries
    n = var.queue + 3000
    ex = pd.DataFrame({"name": "C", "code": 0, "status": "answered",
                       "t_cmd_last": 1.7e9 + 1e-4 * np.arange(n),
                       "dx": 300, "dy": -120, "dz": 0, "da": 0})
    same(replay(ex, np.ones(n, bool), {}.get, var, compiled=True, chunk=chunk),
         replay(ex, np.ones(n, bool), {}.get, var, compiled=True, chunk=10**9))


def test_queue_depth_merge_equals_sort() -> None:
    """The merge of sorted pushes and ends gives what sorting all events gives, ties
    (departures first at equal times) included."""
    from conform.families.gve.analysis.queue import queue_depth

    rng = np.random.default_rng(3)
    for _ in range(50):
        pushes = np.sort(rng.integers(0, 40, rng.integers(0, 60))).astype(float)
        ends = np.sort(rng.integers(0, 40, rng.integers(0, 60))).astype(float)
        t, d = queue_depth(pushes, ends, np.zeros(0))
        ev_t = np.concatenate([pushes, ends])
        ev_d = np.concatenate([np.ones(len(pushes)), -np.ones(len(ends))])
        order = np.lexsort((ev_d, ev_t))
        assert np.array_equal(t, ev_t[order])
        assert np.array_equal(d, np.cumsum(ev_d[order]).astype(np.int64))
        t2, d2 = queue_depth(pushes, ends, np.array([5.0]))  # a removal: sorted the long way
        assert len(t2) == len(t) + 1
        assert d2[-1] == (d[-1] if len(d) else 0) - 1
