"""Queue feeding: replay the accepted vectors through the unit's own motion executor.

The vectors the unit accepted are pushed into ``conform.unit.motion.MotionExecutor`` at the
time their line arrived, with the modal parameters (V, A, B, $, T, VK/VN) the sender set.
What comes out is what the unit's queue should have done: its depth over time, the moments
it ran dry while the job went on (starvation: the motion had to stop at a junction it would
have passed at the B speed), and how fast vectors were supplied versus consumed. The same
replay with made-up arrival times answers "what would packets or a faster link change".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from conform.analysis.columns import AXES, isin
from conform.families.gve.spec.model import Variant

MODAL = {"V", "A", "B", "$", "T", "VK", "VN"}
CONTROL = {"H", "G", "D", "J", "K", "R"}
WHATIF_MAX_VECTORS = 200_000


@dataclass
class QueueReplay:
    pushes: np.ndarray  # times vectors were pushed
    push_rows: np.ndarray  # exchange row of each pushed vector
    starts: np.ndarray  # per completed vector: start, end, starved, exit speed, push index
    ends: np.ndarray
    starved: np.ndarray
    v_out: np.ndarray
    done_rows: np.ndarray
    removals: np.ndarray  # times vectors left the queue unfinished (D, J)
    depth_t: np.ndarray
    depth: np.ndarray
    starvations: list[dict[str, Any]] = field(default_factory=list)
    whatif: list[dict[str, Any]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    capacity: int = 0

    @property
    def vectors(self) -> int:
        return len(self.pushes)


def _params(variant: Variant) -> Any:
    from conform.families.gve.unit.motion import MotionParams

    r = variant.reset
    return MotionParams(v=float(r.get("V", 1000)), a=float(r.get("A", 20)) * 1000.0,
                        b=float(r.get("B", 35000)), short=int(r.get("$", 512)),
                        pause=float(r.get("T", 5)) / 1000.0, vk=bool(r.get("VK", False)))


def replay(ex: pd.DataFrame, accepted: np.ndarray, host_parsed: Any, variant: Variant,
           arrival: np.ndarray | None = None, compiled: bool | None = None,
           chunk: int | None = None) -> QueueReplay:
    """Push ``ex`` rows flagged in ``accepted`` (vectors) at their arrival times.

    ``host_parsed(row)`` returns the parsed Command of a row (for modal values).
    ``arrival`` overrides the arrival time of each row (what-if replays).
    ``compiled``: None takes the compiled scan (``replay_kernel``) when the session has no
    H/G/D/K/R/J, True insists on it, False always runs ``MotionExecutor`` itself;
    ``chunk``: events per compiled call (the result never depends on it).
    """
    names = ex["name"].to_numpy()
    code = ex["code"].to_numpy()
    t = ex["t_cmd_last"].to_numpy() if arrival is None else arrival
    t = np.nan_to_num(t, nan=0.0)
    np.maximum.accumulate(t, out=t)
    ok = (code == 0) & (ex["status"].to_numpy() == "answered")
    ctrl = isin(names, list(MODAL | CONTROL)) & ok
    rows = np.flatnonzero(accepted | ctrl)
    naxes = len(variant.axes)
    is_vec = accepted[rows]
    vec = _PushedVectors(ex, rows[is_vec], naxes)  # the pushed vectors, in order
    cont = names[rows] == "C"
    control = bool(isin(names[rows[~is_vec]], list(CONTROL)).any())
    if compiled is None:
        compiled = not control
    if compiled and control:
        raise ValueError("the compiled replay takes no H/G/D/K/R/J")
    run = _run_compiled if compiled else _run_python
    (seq, starts, ends, v_out, starved), removals, notes = run(
        rows, t, vec, is_vec, cont, names, host_parsed, variant, chunk)
    # every vector row was pushed, in order, at its arrival time
    push_rows_a = rows[is_vec].astype(np.int64)
    # seq counts pushes per executor; J makes a new executor: map by order of completion
    done_rows = push_rows_a[np.minimum(_global_seq(seq), max(len(push_rows_a) - 1, 0))] \
        if len(seq) and len(push_rows_a) else np.zeros(0, np.int64)
    pushes_a = t[push_rows_a].astype(float)
    removals_a = np.asarray(removals, float)
    depth_t, depth = queue_depth(pushes_a, ends, removals_a)
    rep = QueueReplay(pushes_a, push_rows_a, starts, ends, starved, v_out, done_rows,
                      removals_a, depth_t, depth, notes=notes, capacity=variant.queue)
    rep.starvations = _starvation_events(rep)
    return rep


class _PushedVectors:
    """The pushed vectors, taken from the exchange table a slice at a time when sliced:
    the compiled replay never holds the session's (vectors, axes) array at once."""

    def __init__(self, ex: pd.DataFrame, rows: np.ndarray, naxes: int) -> None:
        self.ex, self.rows, self.naxes = ex, rows, naxes

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, sl: slice) -> np.ndarray:
        rows = self.rows[sl]
        out = np.empty((len(rows), self.naxes), np.int64)
        for j, c in enumerate(AXES[: self.naxes]):  # a column at a time: no (rows, 4) copies
            out[:, j] = self.ex[c].to_numpy()[rows]
        return out

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        out = self[:]
        return out if dtype is None else out.astype(dtype, copy=False)


def queue_depth(pushes: np.ndarray, ends: np.ndarray, removals: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """(time, depth after it) at every push (+1), end and removal (-1), by time; at equal
    times the departures first. Pushes and ends come sorted: merged without a sort."""
    n = len(pushes) + len(ends)
    if len(removals) == 0 and (np.diff(pushes) >= 0).all() and (np.diff(ends) >= 0).all():
        at = np.searchsorted(pushes, ends, side="left") + np.arange(len(ends))
        t = np.empty(n)
        d = np.ones(n, np.int8)
        arrive = np.ones(n, bool)
        arrive[at] = False
        t[at] = ends
        t[arrive] = pushes
        d[at] = -1
        return t, np.cumsum(d, dtype=np.int32)
    ev_t = np.concatenate([pushes, ends, removals])
    ev_d = np.concatenate([np.ones(len(pushes), np.int8), -np.ones(len(ends), np.int8),
                           -np.ones(len(removals), np.int8)])
    order = np.lexsort((ev_d, ev_t))
    return ev_t[order], np.cumsum(ev_d[order], dtype=np.int32)


def _modal(p: Any, name: str, args: Any) -> Any:
    """The motion parameters after a modal command (ValueError if out of range)."""
    if name == "V" and args:
        return p.replace(v=float(args[0]))
    if name == "A" and args:
        return p.replace(a=float(args[0]) * 1000.0)
    if name == "B" and args:
        return p.replace(b=float(args[0]))
    if name == "$" and args:
        return p.replace(short=int(args[0]))
    if name == "T" and args:
        return p.replace(pause=float(args[0]) / 1000.0)
    if name in ("VK", "VN"):
        return p.replace(vk=name == "VK")
    return p


Completions = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _run_compiled(rows: np.ndarray, t: np.ndarray, vec: np.ndarray, is_vec: np.ndarray,
                  cont: np.ndarray, names: np.ndarray, host_parsed: Any, variant: Variant,
                  chunk: int | None = None) -> tuple[Completions, list[float], list[str]]:
    """Vectors and modal commands only: the parameters each vector captures are worked out
    here (few modal rows), the scan runs compiled, ``chunk`` events (``REPLAY_CHUNK``) at a
    time with the executor's state and its queued vectors carried from one to the next."""
    from conform.analysis.replay_kernel import H, N, new_state, replay_vectors

    p = _params(variant)
    states = [p]
    notes: list[str] = []
    for i in np.flatnonzero(~is_vec).tolist():
        r = int(rows[i])
        name = str(names[r])
        try:
            p = _modal(p, name, getattr(host_parsed(r), "args", ()) or ())
        except ValueError as err:
            notes.append(f"replay: {name} at row {r} refused by the model: {err}")
        states.append(p)
    state = np.cumsum(~is_vec, dtype=np.int32)[is_vec]  # parameters in force at each push
    col = lambda f, dt: np.array([getattr(s, f) for s in states], dt)  # noqa: E731
    tables = (col("v", float), col("a", float), col("b", float), col("short", np.int64),
              col("pause", float), col("vk", bool))
    ev_t = t[rows].astype(float)
    tacc = ev_t[is_vec]
    cont_v = cont[is_vec]
    pushed = np.cumsum(is_vec)  # vectors pushed up to and including each event
    F, I = new_state()  # noqa: E741
    first = 0  # index of the first queued vector, among all the session's vectors
    parts = []
    step = max(1, int(chunk or REPLAY_CHUNK))
    for lo in range(0, max(len(rows), 1), step):  # a chunk of events at a time
        hi = min(len(rows), lo + step)
        first += int(I[H])  # what finished is gone; the queue moves to the front
        I[N] -= I[H]
        I[H] = 0
        sl = slice(first, int(pushed[hi - 1]) if hi else 0)
        push = np.where(is_vec[lo:hi], pushed[lo:hi] - 1 - first, -1)
        out = replay_vectors(ev_t[lo:hi], push, vec[sl], cont_v[sl], state[sl], tacc[sl],
                             *tables, float(variant.max_rate or 0.0),
                             variant.queue + 10_000 if hi == len(rows) else -1, F, I)
        # copies: the kernel's results are views of arrays as long as every queued vector,
        # which would keep a queue-sized buffer alive per chunk (v_in, rest: not used)
        parts.append((out[0] + first, out[1].copy(), out[2].copy(), out[4].copy(),
                      out[6].copy()))
        del out
    seq, starts, ends, v_out, starved = (np.concatenate(c) for c in zip(*parts, strict=True))
    return (seq, starts, ends, v_out, starved), [], notes


def _run_python(rows: np.ndarray, t: np.ndarray, vec: np.ndarray, is_vec: np.ndarray,
                cont: np.ndarray, names: np.ndarray, host_parsed: Any, variant: Variant,
                chunk: int | None = None) -> tuple[Completions, list[float], list[str]]:
    """Every row through ``MotionExecutor`` (any session, H/G/D/K/R/J included)."""
    from conform.families.gve.unit.motion import Completion, MotionExecutor, MotionStateError

    naxes = len(variant.axes)
    vec = vec[:]  # the whole (vectors, axes) array: the Python replay takes small sessions
    log: list = []

    def executor() -> Any:
        return MotionExecutor(axes=naxes, capacity=variant.queue, max_rate=variant.max_rate,
                              params=_params(variant), log=log)

    exe = executor()
    removals: list[float] = []
    notes: list[str] = []
    advance, push = exe.advance, exe.push
    done: list[np.ndarray] = []  # finished vectors, drained from the log block by block
    for r, tk, vk, is_v, c in _blocks(rows, t, vec, is_vec, cont, log, done):
        advance(tk)
        if is_v:
            push(vk, c)
            continue
        name = names[r]
        try:
            if name in MODAL:
                exe.params = _modal(exe.params, name,
                                    getattr(host_parsed(r), "args", ()) or ())
            elif name == "H":
                exe.halt(tk)
            elif name == "G":
                exe.resume(tk)
            elif name == "D":
                removals.extend([tk] * exe.queue_len)
                exe.clear()
            elif name == "K":
                exe.park()
            elif name == "R":
                exe.restore()
            elif name == "J":
                removals.extend([tk] * exe.queue_len)
                exe = executor()
                advance, push = exe.advance, exe.push
                exe.advance(tk)
        except (MotionStateError, ValueError) as err:
            notes.append(f"replay: {name} at row {r} refused by the model: {err}")
    end = exe.next_event_time()
    guard = 0
    while end is not None and guard < variant.queue + 10_000:
        exe.advance(end)
        end = exe.next_event_time()
        guard += 1
    _drain(log, done)
    if done:
        arr = np.concatenate(done)  # one row per finished vector: the Completion fields
        f = Completion._fields
        seq = arr[:, f.index("seq")].astype(np.int64)
        starts, ends = arr[:, f.index("t_start")], arr[:, f.index("t_end")]
        v_out, starved = arr[:, f.index("v_out")], arr[:, f.index("starved")] > 0
    else:
        seq = np.zeros(0, np.int64)
        starts = ends = v_out = np.zeros(0)
        starved = np.zeros(0, bool)
    return (seq, starts, ends, v_out, starved), removals, notes


REPLAY_CHUNK = 262_144  # events per call of the compiled scan
REPLAY_BLOCK = 65_536  # rows turned into Python values at a time (memory stays flat)


def _drain(log: list, done: list[np.ndarray]) -> None:
    """Move the executor's Completion tuples into a float array (the list is reused)."""
    if log:
        done.append(np.array(log, float))
        del log[:]


def _blocks(rows: np.ndarray, t: np.ndarray, vec: np.ndarray, is_vec: np.ndarray,
            cont: np.ndarray, log: list, done: list[np.ndarray]) -> Any:
    """(row, time, vector, is a vector, continuous) for every replayed row, converted
    to Python values one block at a time; the completion log is drained between blocks."""
    vpos = np.maximum(np.cumsum(is_vec) - 1, 0)  # each row's place among the vectors
    empty = np.zeros((1, vec.shape[1]), np.int64)
    for b in range(0, len(rows), REPLAY_BLOCK):
        sl = slice(b, b + REPLAY_BLOCK)
        r = rows[sl]
        v = vec[vpos[sl]] if len(vec) else np.repeat(empty, len(r), axis=0)
        yield from zip(r.tolist(), t[r].tolist(), v.tolist(), is_vec[sl].tolist(),
                       cont[sl].tolist(), strict=True)
        _drain(log, done)


def _global_seq(seq: np.ndarray) -> np.ndarray:
    """Executor sequence numbers restart after J; make them a running count of pushes."""
    if len(seq) == 0:
        return seq
    out = seq.copy()
    base = 0
    restart = np.flatnonzero(np.diff(seq) < 0) + 1
    prev = 0
    for r in restart.tolist():
        base += int(seq[prev:r].max()) + 1
        out[r:] = seq[r:] + base
        prev = r
    return out


def _starvation_events(rep: QueueReplay) -> list[dict[str, Any]]:
    """Each starved vector: when the queue ran dry (the previous vector ended at rest) and
    how long until this vector arrived; it starts after that, plus the T pause."""
    out = []
    idx = np.flatnonzero(rep.starved)
    if len(idx) == 0:
        return out
    k = np.clip(np.searchsorted(rep.push_rows, rep.done_rows[idx]), 0, len(rep.pushes) - 1)
    arrived = rep.pushes[k]
    for j, i in enumerate(idx.tolist()):
        dry_from = float(rep.ends[i - 1]) if i > 0 else float(rep.starts[i])
        out.append({"t": dry_from, "from": dry_from, "arrived": float(arrived[j]),
                    "start": float(rep.starts[i]),
                    "gap": max(0.0, float(arrived[j]) - dry_from),
                    "stop": float(rep.starts[i]) - dry_from,
                    "row": int(rep.done_rows[i]) if i < len(rep.done_rows) else -1})
    return out


def supply_consumption(rep: QueueReplay, edges: np.ndarray) -> pd.DataFrame:
    """Vectors accepted and finished per time bin."""
    sup, _ = np.histogram(rep.pushes, bins=edges)
    con, _ = np.histogram(rep.ends, bins=edges)
    width = np.diff(edges)
    return pd.DataFrame({"t": edges[:-1], "supplied_per_s": sup / width,
                         "consumed_per_s": con / width})


def whatif(ex: pd.DataFrame, accepted: np.ndarray, host_parsed: Any, variant: Variant,
           baud: float | None, rep: QueueReplay) -> list[dict[str, Any]]:
    """What packets of n, or a link without converter latency, would change."""
    vec_rows = np.flatnonzero(accepted)
    if len(vec_rows) < 2 or not baud:
        return []
    byte_t = 10.0 / baud
    # medians of three columns over the single (unpacketed) vectors: no copy of the table
    plain = vec_rows[ex["packet"].to_numpy()[vec_rows] < 0]
    src = plain if len(plain) else vec_rows
    cmd_w = float(np.median(ex["cmd_bytes"].to_numpy()[src])) * byte_t
    ans_w = 2 * byte_t
    ut = ex["unit_time"].to_numpy()[src]
    ht = ex["host_time"].to_numpy()[src]
    lat = float(np.nanmedian(ut)) if np.isfinite(ut).any() else 0.0
    host = float(np.nanmedian(ht)) if np.isfinite(ht).any() else 0.0
    lat, host = max(lat, 0.0), max(host, 0.0)
    durations = rep.ends - rep.starts
    need = float(np.median(durations)) if len(durations) else float("nan")
    observed = float(np.median(np.diff(ex["t_cmd_first"].to_numpy()[vec_rows])))
    scenarios = [("as captured", observed)]
    scenarios.append(("no converter latency (RS232)", cmd_w + ans_w + min(lat, 0.0005)
                      + min(host, 0.0005)))
    for n in (10, 20):
        overhead = (6 + 8) * byte_t + 6 * byte_t + lat + host
        scenarios.append((f"packets of {n}", cmd_w + overhead / n))
    out = []
    for label, cycle in scenarios:
        row: dict[str, Any] = {"scenario": label, "seconds_per_vector": cycle,
                               "supply_per_s": 1.0 / cycle if cycle > 0 else float("inf"),
                               "consumption_per_s": 1.0 / need if need > 0 else float("nan")}
        row["keeps_up"] = bool(cycle <= need) if need == need else None
        if label != "as captured" and len(vec_rows) <= WHATIF_MAX_VECTORS:
            t0 = float(ex["t_cmd_last"].to_numpy()[vec_rows[0]])
            arrival = ex["t_cmd_last"].to_numpy().astype(float).copy()
            arrival[vec_rows] = t0 + cycle * np.arange(len(vec_rows))
            arrival = np.maximum.accumulate(np.nan_to_num(arrival, nan=t0))
            sim = replay(ex, accepted, host_parsed, variant, arrival=arrival)
            row["starvations"] = len(sim.starvations)
            row["job_seconds"] = float(sim.ends.max() - t0) if len(sim.ends) else 0.0
        elif label == "as captured":
            row["starvations"] = len(rep.starvations)
            row["job_seconds"] = (float(rep.ends.max() - rep.pushes.min())
                                  if len(rep.ends) else 0.0)
        out.append(row)
    return out
