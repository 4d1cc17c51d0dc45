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

from conform.families.gve.analysis.columns import AXES, isin
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
    # seq counts the session's pushes (a J's new executor goes on counting): K/R finish
    # vectors out of push order, so each completion is mapped by its own number
    done_rows = push_rows_a[seq] if len(seq) else np.zeros(0, np.int64)
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


def _command(exe: Any, name: str, t: float, host_parsed: Any, row: int) -> list[int] | None:
    """A modal or control row on the executor at ``t``; raises what the executor refuses.
    Returns the push numbers of the vectors D deleted (none for the others), or None for J:
    the caller counts what is queued as removed and starts a new executor (a reset unit)."""
    if name in MODAL:
        exe.params = _modal(exe.params, name, getattr(host_parsed(row), "args", ()) or ())
    elif name == "H":
        exe.halt(t)
    elif name == "G":
        exe.resume(t)
    elif name == "D":
        gone = [q[4] for q in exe._q]
        exe.clear()  # refused while running: then nothing left the queue
        return gone
    elif name == "K":
        exe.park()
    elif name == "R":
        exe.restore()
    elif name == "J":
        return None
    return []


Completions = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _run_compiled(rows: np.ndarray, t: np.ndarray, vec: np.ndarray, is_vec: np.ndarray,
                  cont: np.ndarray, names: np.ndarray, host_parsed: Any, variant: Variant,
                  chunk: int | None = None) -> tuple[Completions, list[float], list[str]]:
    """Vectors and modal commands only: the parameters each vector captures are worked out
    here (few modal rows), the scan runs compiled, ``chunk`` events (``REPLAY_CHUNK``) at a
    time with the executor's state and its queued vectors carried from one to the next."""
    from conform.families.gve.analysis.replay_kernel import H, N, new_state, replay_vectors

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
    pushed = 0
    for r, tk, vk, is_v, c in _blocks(rows, t, vec, is_vec, cont, log, done):
        advance(tk)
        if is_v:
            push(vk, c)
            pushed += 1
            continue
        name = names[r]
        try:
            gone = _command(exe, name, tk, host_parsed, r)
        except (MotionStateError, ValueError) as err:
            notes.append(f"replay: {name} at row {r} refused by the model: {err}")
            continue
        if gone is None:  # J
            removals.extend([tk] * exe.queue_len)
            exe = executor()
            exe._seq = pushed  # sequence numbers run on over the whole session
            advance, push = exe.advance, exe.push
            exe.advance(tk)
        else:
            removals.extend([tk] * len(gone))
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
    # medians of three columns over the single (unpacketed) vectors: no copy of the table
    plain = vec_rows[ex["packet"].to_numpy()[vec_rows] < 0]
    src = plain if len(plain) else vec_rows
    ut = ex["unit_time"].to_numpy()[src]
    ht = ex["host_time"].to_numpy()[src]
    durations = rep.ends - rep.starts
    rows = scenarios(baud, float(np.median(ex["cmd_bytes"].to_numpy()[src])),
                     float(np.nanmedian(ut)) if np.isfinite(ut).any() else 0.0,
                     float(np.nanmedian(ht)) if np.isfinite(ht).any() else 0.0,
                     float(np.median(durations)) if len(durations) else float("nan"),
                     float(np.median(np.diff(ex["t_cmd_first"].to_numpy()[vec_rows]))))
    for row in rows:
        if row["scenario"] != "as captured" and len(vec_rows) <= WHATIF_MAX_VECTORS:
            cycle = row["seconds_per_vector"]
            t0 = float(ex["t_cmd_last"].to_numpy()[vec_rows[0]])
            arrival = ex["t_cmd_last"].to_numpy().astype(float).copy()
            arrival[vec_rows] = t0 + cycle * np.arange(len(vec_rows))
            arrival = np.maximum.accumulate(np.nan_to_num(arrival, nan=t0))
            sim = replay(ex, accepted, host_parsed, variant, arrival=arrival)
            row["starvations"] = len(sim.starvations)
            row["job_seconds"] = float(sim.ends.max() - t0) if len(sim.ends) else 0.0
        elif row["scenario"] == "as captured":
            row["starvations"] = len(rep.starvations)
            row["job_seconds"] = (float(rep.ends.max() - rep.pushes.min())
                                  if len(rep.ends) else 0.0)
    return rows


def scenarios(baud: float, cmd_bytes: float, unit_time: float, host_time: float,
              need: float, observed: float) -> list[dict[str, Any]]:
    """The what-if rows from the medians of the single vectors (command bytes, unit time,
    host turnaround), of the time a vector takes to run and between two vectors sent."""
    byte_t = 10.0 / baud
    cmd_w = cmd_bytes * byte_t
    ans_w = 2 * byte_t
    lat, host = max(unit_time, 0.0), max(host_time, 0.0)
    cycles = [("as captured", observed)]
    cycles.append(("no converter latency (RS232)", cmd_w + ans_w + min(lat, 0.0005)
                   + min(host, 0.0005)))
    for n in (10, 20):
        overhead = (6 + 8) * byte_t + 6 * byte_t + lat + host
        cycles.append((f"packets of {n}", cmd_w + overhead / n))
    out = []
    for label, cycle in cycles:
        row: dict[str, Any] = {"scenario": label, "seconds_per_vector": cycle,
                               "supply_per_s": 1.0 / cycle if cycle > 0 else float("inf"),
                               "consumption_per_s": 1.0 / need if need > 0 else float("nan")}
        row["keeps_up"] = bool(cycle <= need) if need == need else None
        out.append(row)
    return out


class WhatIfInputs:
    """The medians ``scenarios`` needs, gathered window by window (``summaries``)."""

    def __init__(self) -> None:
        from conform.analysis.summaries import Quantiles

        self.q = {k: Quantiles() for k in ("cmd_bytes", "unit_time", "host_time",
                                           "all_cmd_bytes", "all_unit_time", "all_host_time",
                                           "gap")}
        self.vectors = 0
        self.last_t: float | None = None

    def feed(self, ex: pd.DataFrame, vec_rows: np.ndarray) -> None:
        if len(vec_rows) == 0:
            return
        plain = vec_rows[ex["packet"].to_numpy()[vec_rows] < 0]
        for col in ("cmd_bytes", "unit_time", "host_time"):
            v = ex[col].to_numpy()
            self.q[col].add(v[plain])
            if not self.q["cmd_bytes"].n:  # every vector counts only while none is single
                self.q["all_" + col].add(v[vec_rows])
        t = ex["t_cmd_first"].to_numpy()[vec_rows]
        self.q["gap"].add(np.diff(t if self.last_t is None else np.concatenate([[self.last_t],
                                                                                 t])))
        self.last_t = float(t[-1])
        self.vectors += len(vec_rows)

    def rows(self, baud: float | None, need: float, starvations: int,
             job_seconds: float) -> list[dict[str, Any]]:
        if self.vectors < 2 or not baud:
            return []
        pre = "" if self.q["cmd_bytes"].n else "all_"
        med = {c: self.q[pre + c].median() if self.q[pre + c].n else 0.0
               for c in ("cmd_bytes", "unit_time", "host_time")}
        rows = scenarios(baud, med["cmd_bytes"], med["unit_time"], med["host_time"], need,
                         self.q["gap"].median())
        rows[0]["starvations"] = starvations
        rows[0]["job_seconds"] = job_seconds
        return rows


class _Queue:
    """The vectors still queued in a stream replay (pulses, continuity, parameter row,
    arrival, exchange row), in buffers that grow by half when full and drop finished
    vectors from the front by moving a start index: no copy of the queue per window."""

    def __init__(self, naxes: int) -> None:
        self.start = self.end = 0
        self.bufs = [np.zeros((0, naxes), np.int64), np.zeros(0, bool), np.zeros(0, np.int32),
                     np.zeros(0), np.zeros(0, np.int64)]

    def drop(self, n: int) -> None:
        self.start += n

    def append(self, *parts: np.ndarray) -> None:
        n = len(parts[0])
        live = self.end - self.start
        if self.end + n > len(self.bufs[0]):  # room for half as much again, queue to the front
            size = max(1024, (live + n) * 3 // 2)
            new = []
            for b in self.bufs:
                nb = np.empty((size,) + b.shape[1:], b.dtype)
                nb[:live] = b[self.start : self.end]
                new.append(nb)
            self.bufs, self.start, self.end = new, 0, live
        for b, p in zip(self.bufs, parts, strict=True):
            b[self.end : self.end + n] = p
        self.end += n

    def views(self) -> list[np.ndarray]:
        return [b[self.start : self.end] for b in self.bufs]


# the planned head, in the compiled scan's float state and in the executor's attributes
_HEAD = (("T0", "_t0"), ("TEND", "_tend"), ("LEN", "_len"), ("VJ", "_vj"),
         ("VPEAK", "_vpeak"), ("TDEC", "_tdec"), ("VSTART", "_vstart"), ("VIN", "_vin"))
PYTHON_ROWS = 4096  # rows given to the executor at a time (it may stop at any vector)
COMPILED_ROWS = 512  # the least run of rows without a control for the scan to take over again


class StreamReplay:
    """The compiled replay fed a window of exchange rows at a time (``feed``), finished
    with the final drain (``finish``). Carried: the executor's state, the vectors still
    queued (pulses, continuity, parameter row, arrival, exchange row), the running maximum
    of the arrival times, the modal parameters (one table row per distinct set), the queue
    depth and the last completion. What comes out is summed up as it comes
    (``summaries``); while ``keep`` the whole arrays are kept too, for a ``QueueReplay``.

    At an H/G/D/K/R/J (the first: ``control_row``) the compiled scan's state is handed to
    a ``MotionExecutor`` (the Python executor, which knows those commands), its completion
    log drained into the same summaries; at the first vector after that where the executor
    is in a state the scan can carry (not halted, braking or parked, its queue in push
    order) and no control row follows for ``COMPILED_ROWS`` rows, the scan takes it back.
    The result is the one ``replay`` gives on the whole session, at the compiled speed for
    all but the stretches around the control commands.
    """

    def __init__(self, variant: Variant, keep: bool = True) -> None:
        from conform.analysis.summaries import Quantiles, TimeBins
        from conform.families.gve.analysis.replay_kernel import new_state

        self.variant = variant
        self.naxes = len(variant.axes)
        self.F, self.I = new_state()
        self.params = _params(variant)
        self.states: dict[Any, int] = {self._key(self.params): 0}
        self.table: list[Any] = [self.params]
        self.t_max = -np.inf
        self._new_queue()
        self.first = 0  # push index of q_*[0]
        self.pushed = 0
        self.control_row = -1  # the first H/G/D/K/R/J: from there on the executor replays
        self.exe: Any = None  # conform.families.gve.unit.motion.MotionExecutor, for a while
        self.hand_backs = 0  # times the executor gave the scan back its state
        self.log: list = []  # its completions since the last drain
        self.live: dict[int, tuple[float, int]] = {}  # push number: arrival, exchange row
        self.now = 0.0  # the time of the last event replayed
        self.final = False  # the final drain: no event is held back any more
        self.held = (np.zeros(0), np.zeros(0), np.zeros(0))  # depth events at ``now``
        self.notes: list[str] = []
        self.depth = 0
        self.max_depth = 0
        self.area = 0.0  # sum of depth x time between depth events
        self.depth_last: tuple[float, int] | None = None
        self.depth_t0: float | None = None
        self.depth_n, self.depth_sum = 0, 0.0
        self.first_depth = 0
        self.completed = 0
        self.durations = Quantiles()
        self.end_max = -np.inf
        self.last_end: float | None = None
        self.push_min = np.inf
        self.starvations: list[dict[str, Any]] = []  # the first ones (findings list 10)
        self.starved = 0
        self.starved_s = 0.0
        self.standstill_s = 0.0
        self.supply, self.consume = TimeBins(), TimeBins()
        self.starve_t = TimeBins()
        self.inputs = WhatIfInputs()
        self.sink: Any = None  # depth (t, depth) for the Parquet table once not kept
        self.depth_x: Any = None  # summaries.Extremes of the depth for long captures' plots
        self.path: Any = None  # plots.PathSample for long captures' plots
        self.keep = keep
        self.kept: dict[str, list[np.ndarray]] = {k: [] for k in (
            "pushes", "push_rows", "starts", "ends", "starved", "v_out", "done_rows",
            "removals", "depth_t", "depth")}
        if not keep:
            self.stop_keeping()

    @staticmethod
    def _key(p: Any) -> tuple:
        return (p.v, p.a, p.b, p.short, p.pause, p.vk)

    def feed(self, ex: pd.DataFrame, accepted: np.ndarray, host_parsed: Any, lo: int, hi: int,
             base: int) -> None:
        """Rows ``lo:hi`` of ``ex`` (the capture's rows ``base + lo`` …)."""
        if hi <= lo:
            return
        sl = slice(lo, hi)
        names = ex["name"].to_numpy()[sl]
        code = ex["code"].to_numpy()[sl]
        t = np.nan_to_num(ex["t_cmd_last"].to_numpy()[sl], nan=0.0)
        t = np.maximum.accumulate(np.concatenate([[self.t_max], t]))[1:]
        if len(t):
            self.t_max = float(t[-1])
        ok = (code == 0) & (ex["status"].to_numpy()[sl] == "answered")
        ctrl = isin(names, list(MODAL | CONTROL)) & ok
        acc = accepted[sl]
        self.inputs.feed(ex, np.flatnonzero(acc) + lo)
        rows = np.flatnonzero(acc | ctrl)
        is_vec = acc[rows]
        stops = np.flatnonzero(~is_vec & isin(names[rows], list(CONTROL)))
        far = None  # per row: no control row within COMPILED_ROWS (only the executor asks)
        k = 0  # the compiled scan up to a control row, the executor from there for a while
        while k < len(rows):
            if self.exe is None:
                j = np.searchsorted(stops, k)
                stop = int(stops[j]) if j < len(stops) else len(rows)
                self._feed_compiled(ex, names, t, rows[k:stop], is_vec[k:stop], host_parsed,
                                    lo, base)
                if stop < len(rows):
                    if self.control_row < 0:
                        self.control_row = int(rows[stop]) + lo + base
                    self._hand_over()
                k = stop
            else:  # a part at a time: the scan may take over again at any vector
                if far is None:  # a hand-over and back costs a few hundred executor rows
                    at = np.arange(len(rows))
                    far = np.append(stops, len(rows) + COMPILED_ROWS)[
                        np.searchsorted(stops, at)] - at >= COMPILED_ROWS
                end = k + PYTHON_ROWS
                k += self._feed_python(ex, names, t, rows[k:end], is_vec[k:end], far[k:end],
                                       host_parsed, lo, base)

    def _pulses(self, ex: pd.DataFrame, vrows: np.ndarray, pushed: bool = True) -> np.ndarray:
        """The vectors of ``vrows``; ``pushed``: they are pushed now (for the path plot)."""
        d = np.empty((len(vrows), self.naxes), np.int64)
        for j, c in enumerate(AXES[: self.naxes]):
            d[:, j] = ex[c].to_numpy()[vrows]
        if self.path is not None and pushed:
            self.path.push(d)
        return d

    def _feed_compiled(self, ex: pd.DataFrame, names: np.ndarray, t: np.ndarray,
                       rows: np.ndarray, is_vec: np.ndarray, host_parsed: Any, lo: int,
                       base: int) -> None:
        modal = np.flatnonzero(~is_vec)  # few: the parameters they set, one by one
        after = np.empty(len(modal) + 1, np.int32)  # parameter row after each of them
        after[0] = self._state_row(self.params)
        for j, i in enumerate(modal.tolist()):
            r = int(rows[i]) + lo
            name = str(names[rows[i]])
            try:
                self.params = _modal(self.params, name,
                                     getattr(host_parsed(r), "args", ()) or ())
            except ValueError as err:
                self.notes.append(f"replay: {name} at row {r + base} refused by the model: "
                                  f"{err}")
            after[j + 1] = self._state_row(self.params)
        state = after[np.cumsum(~is_vec)]  # in force at each row
        vrows = rows[is_vec] + lo
        d = self._pulses(ex, vrows)
        self._run(t[rows], is_vec, d, names[rows[is_vec]] == "C", state[is_vec],
                  vrows + base, -1)

    def _run(self, ev_t: np.ndarray, is_vec: np.ndarray, d: np.ndarray, cont: np.ndarray,
             state: np.ndarray, vrows: np.ndarray, guard: int) -> None:
        from conform.families.gve.analysis.replay_kernel import H, N, replay_vectors

        F, I = self.F, self.I  # noqa: E741
        done = int(I[H])  # what finished is gone; the queue moves to the front
        I[N] -= done
        I[H] = 0
        self.first += done
        tacc = ev_t[is_vec]
        self.q.drop(done)
        self.q.append(d, cont, state, tacc, vrows)
        self.q_d, self.q_cont, self.q_state, self.q_t, self.q_row = self.q.views()
        push = np.where(is_vec, np.cumsum(is_vec) - 1 + (self.pushed - self.first), -1)
        col = lambda f, dt: np.array([getattr(s, f) for s in self.table], dt)  # noqa: E731
        out = replay_vectors(ev_t.astype(float), push, self.q_d, self.q_cont, self.q_state,
                             self.q_t, col("v", float), col("a", float), col("b", float),
                             col("short", np.int64), col("pause", float), col("vk", bool),
                             float(self.variant.max_rate or 0.0), guard, F, I)
        if len(ev_t):
            self.now = float(ev_t[-1])
        self.pushed += int(is_vec.sum())
        seq, starts, ends, v_out, starved = out[0], out[1], out[2], out[4], out[6]
        if self.path is not None:
            self.path.done(seq + self.first, v_out)
        self._summarise(tacc, vrows, starts.copy(), ends.copy(), v_out.copy(),
                        starved.copy(), self.q_t[seq], self.q_row[seq], np.zeros(0))

    def _hand_over(self) -> None:
        """The compiled scan's state as a ``MotionExecutor`` (at the first H/G/D/K/R/J):
        the queued vectors with their parameters and arrival times, the planned head and
        what the last completion left (exit speed, ready time, whether the queue ran dry).
        The executor numbers its pushes on from the session's count."""
        import conform.families.gve.analysis.replay_kernel as k
        from conform.families.gve.unit.motion import MotionExecutor

        F, I = self.F, self.I  # noqa: E741
        exe = MotionExecutor(axes=self.naxes, capacity=self.variant.queue,
                             max_rate=self.variant.max_rate, params=self.params, log=self.log)
        for i in range(int(I[k.H]), int(I[k.N])):
            g = self.first + i
            exe._q.append((self.q_d[i].tolist(), bool(self.q_cont[i]),
                           self.table[int(self.q_state[i])], float(self.q_t[i]), g))
            self.live[g] = (float(self.q_t[i]), int(self.q_row[i]))
        exe._seq = self.pushed
        exe._now = self.now
        exe._v, exe._ready, exe._dry = float(F[k.V]), float(F[k.READY]), bool(I[k.DRY])
        if I[k.PLANNED]:
            exe._planned = True
            for name, attr in _HEAD:
                setattr(exe, attr, float(F[getattr(k, name)]))
            exe._dom = max(map(abs, exe._q[0][0]))
            exe._prof = tuple(float(x) for x in F[k.PROF : k.PROF + 8])
            exe._exit = int(I[k.EXIT])
            exe._vstarved = bool(I[k.STARVED])
        self.exe = exe
        self._new_queue()  # the executor holds the queue from here on

    def _new_queue(self, *columns: np.ndarray) -> None:
        """A fresh queue buffer, holding ``columns`` (pulses, continuity, parameter row,
        arrival, exchange row) when given."""
        self.q = _Queue(self.naxes)
        if columns:
            self.q.append(*columns)
        self.q_d, self.q_cont, self.q_state, self.q_t, self.q_row = self.q.views()

    def _state_row(self, p: Any) -> int:
        """The parameter table's row for ``p`` (added when new)."""
        key = self._key(p)
        if key not in self.states:
            self.states[key] = len(self.table)
            self.table.append(p)
        return self.states[key]

    def _hand_back(self) -> None:
        """The executor's state back to the compiled scan (``_hand_over`` the other way),
        once it is one the scan can carry (``_compilable``): the queued vectors with their
        parameters, arrival times and exchange rows, the planned head and what the last
        completion left."""
        import conform.families.gve.analysis.replay_kernel as k

        exe = self.exe
        F, I = k.new_state()  # noqa: E741
        F[k.V], F[k.READY], I[k.DRY] = exe._v, exe._ready, int(exe._dry)
        queued = list(exe._q)
        n = len(queued)
        I[k.N] = n
        if exe._planned:
            I[k.PLANNED], I[k.EXIT], I[k.STARVED] = 1, exe._exit, int(exe._vstarved)
            for name, attr in _HEAD:
                F[getattr(k, name)] = getattr(exe, attr)
            F[k.PROF : k.PROF + 8] = exe._prof
        self.F, self.I = F, I
        self.params = exe.params
        self._state_row(self.params)
        gone = [self.live.pop(q[4]) for q in queued]
        self._new_queue(np.array([q[0] for q in queued], np.int64).reshape(n, self.naxes),
                        np.array([q[1] for q in queued], bool),
                        np.array([self._state_row(q[2]) for q in queued], np.int32),
                        np.array([q[3] for q in queued], float),
                        np.array([r for _, r in gone], np.int64))
        self.first = self.pushed - n
        self.exe = None
        self.hand_backs += 1

    def _compilable(self, exe: Any) -> bool:
        """An executor in a state the compiled scan can carry: not halted, braking, parked
        or part-way through a vector, its queue the last pushes in push order (not a queue
        that K and R put back around newer vectors) and no longer than the unit's."""
        if (exe._halted or exe._parked is not None or exe._forced or exe._hoff
                or not exe._final or (exe._planned and exe._soff)):
            return False
        q = exe._q
        if not q:
            return True
        if len(q) > self.variant.queue:  # more than the unit holds: a capture off the model
            return False  # (and a hand-back would copy it all, again and again)
        seqs = [v[4] for v in q]
        return seqs[0] == self.pushed - len(q) and seqs == list(range(seqs[0], self.pushed))

    def _new_executor(self) -> None:
        """J: a unit just reset; its pushes are numbered on from the session's count."""
        from conform.families.gve.unit.motion import MotionExecutor

        self.exe = MotionExecutor(axes=self.naxes, capacity=self.variant.queue,
                                  max_rate=self.variant.max_rate, params=_params(self.variant),
                                  log=self.log)
        self.exe._seq = self.pushed

    def _feed_python(self, ex: pd.DataFrame, names: np.ndarray, t: np.ndarray,
                     rows: np.ndarray, is_vec: np.ndarray, far: np.ndarray, host_parsed: Any,
                     lo: int, base: int) -> int:
        """Rows through the executor itself, as ``_run_python`` replays a whole session,
        until a vector comes when the scan can take the executor's state back
        (``_compilable``) and no control row follows within ``COMPILED_ROWS`` (``far``);
        there it hands back (``_hand_back``). Returns how many rows it took (all of them,
        or up to that vector, which the compiled scan takes)."""
        from conform.families.gve.unit.motion import MotionStateError

        vrows = rows[is_vec] + lo
        d = self._pulses(ex, vrows, pushed=False)
        vecs = iter(d.tolist())
        removals: list[float] = []
        tk_all = t[rows]
        taken, nvec = len(rows), 0
        for i, (r, tk, is_v, name, f) in enumerate(zip(
                (rows + lo).tolist(), tk_all.tolist(), is_vec.tolist(), names[rows].tolist(),
                far.tolist(), strict=True)):
            exe = self.exe
            exe.advance(tk)
            if is_v:
                if f and self._compilable(exe):
                    taken = i
                    break
                exe.push(next(vecs), name == "C")
                self.live[self.pushed] = (tk, r + base)
                self.pushed += 1
                nvec += 1
                continue
            try:
                gone = _command(exe, name, tk, host_parsed, r)
            except (MotionStateError, ValueError) as err:
                self.notes.append(f"replay: {name} at row {r + base} refused by the model: "
                                  f"{err}")
                continue
            if gone is None:  # J
                removals.extend([tk] * exe.queue_len)
                self._drain_python(np.zeros(0), np.zeros(0, np.int64), [])
                self.live.clear()  # queued and parked: gone with the old executor
                self._new_executor()
                self.exe.advance(tk)
            else:
                removals.extend([tk] * len(gone))
                for g in gone:
                    self.live.pop(g, None)
        if self.path is not None:
            self.path.push(d[:nvec])
        if taken:
            self.now = float(tk_all[taken - 1])
        self._drain_python(tk_all[:taken][is_vec[:taken]], vrows[:nvec] + base, removals)
        if taken < len(rows):
            self._hand_back()
        return taken

    def _drain_python(self, pushes: np.ndarray, push_rows: np.ndarray,
                      removals: list[float]) -> None:
        """The executor's completions since the last drain, summed up as the compiled
        scan's are (with the vectors removed by D and J)."""
        from conform.families.gve.unit.motion import Completion

        log = self.log
        f = Completion._fields
        arr = np.array(log, float).reshape(len(log), len(f))
        del log[:]
        seq = arr[:, f.index("seq")].astype(np.int64)
        v_out = arr[:, f.index("v_out")]
        gone = [self.live.pop(g) for g in seq.tolist()]
        arrived = np.array([a for a, _ in gone], float)
        done_rows = np.array([r for _, r in gone], np.int64)
        if self.path is not None:
            self.path.done(seq, v_out)
        self._summarise(pushes, push_rows, arr[:, f.index("t_start")],
                        arr[:, f.index("t_end")], v_out, arr[:, f.index("starved")] > 0,
                        arrived, done_rows, np.asarray(removals, float))

    def _summarise(self, pushes: np.ndarray, push_rows: np.ndarray, starts: np.ndarray,
                   ends: np.ndarray, v_out: np.ndarray, starved: np.ndarray,
                   arrived: np.ndarray, done_rows: np.ndarray, removals: np.ndarray) -> None:
        if len(pushes):
            self.push_min = min(self.push_min, float(pushes.min()))
        self.completed += len(ends)
        self.durations.add(ends - starts)
        if len(ends):
            self.end_max = max(self.end_max, float(ends.max()))
        self.supply.add(pushes)
        self.consume.add(ends)
        for i in np.flatnonzero(starved).tolist():
            dry = float(ends[i - 1]) if i > 0 else (
                self.last_end if self.last_end is not None else float(starts[i]))
            gap = max(0.0, float(arrived[i]) - dry)
            stop = float(starts[i]) - dry
            self.starved += 1
            self.starved_s += gap
            self.standstill_s += stop
            self.starve_t.add(np.array([dry]))
            if len(self.starvations) < 10 or self.keep:
                self.starvations.append({"t": dry, "from": dry, "arrived": float(arrived[i]),
                                         "start": float(starts[i]), "gap": gap, "stop": stop,
                                         "row": int(done_rows[i])})
        if len(ends):
            self.last_end = float(ends[-1])
        dt, dv = self._depth_events(pushes, ends, removals)
        dv = dv.astype(np.int64) + self.depth
        if len(dv):
            if self.depth_last is None:
                self.depth_t0 = float(dt[0])
                self.first_depth = int(dv[0])
            else:
                self.area += self.depth_last[1] * (float(dt[0]) - self.depth_last[0])
            self.area += float((dv[:-1] * np.diff(dt)).sum())
            self.depth_last = (float(dt[-1]), int(dv[-1]))
            self.depth = int(dv[-1])
            self.max_depth = max(self.max_depth, int(dv.max()))
            self.depth_n += len(dv)
            self.depth_sum += float(dv.sum())
        if not self.keep:
            if self.sink is not None:
                self.sink(dt, dv)
            if self.depth_x is not None:
                self.depth_x.add(dt, dv.astype(float))
        else:
            for k, v in (("pushes", pushes), ("push_rows", push_rows), ("starts", starts),
                         ("ends", ends), ("starved", starved), ("v_out", v_out),
                         ("done_rows", done_rows), ("removals", removals),
                         ("depth_t", dt), ("depth", dv)):
                self.kept[k].append(v)

    def _depth_events(self, pushes: np.ndarray, ends: np.ndarray, removals: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
        """``queue_depth`` of the events up to the last time replayed (exclusive), the
        ones at that time held for the next call: a later window may add events at that
        very time, and the whole session's order puts departures first at equal times."""
        hp, he, hr = self.held
        if len(hp) or len(he) or len(hr):
            pushes, ends = np.concatenate([hp, pushes]), np.concatenate([he, ends])
            removals = np.concatenate([hr, removals])
        if self.final:
            self.held = (np.zeros(0), np.zeros(0), np.zeros(0))
            return queue_depth(pushes, ends, removals)
        cut = self.now
        mp, me, mr = pushes < cut, ends < cut, removals < cut
        self.held = (pushes[~mp], ends[~me], removals[~mr])
        return queue_depth(pushes[mp], ends[me], removals[mr])

    def stop_keeping(self) -> None:
        """From now on only summaries: what was kept goes to the sink and the plot series."""
        from conform.analysis.summaries import Extremes
        from conform.families.gve.analysis.plots import PathSample

        self.keep = False
        self.depth_x = Extremes()
        self.path = PathSample(self.naxes)
        k = self.kept
        if k["depth_t"]:
            dt, dv = np.concatenate(k["depth_t"]), np.concatenate(k["depth"])
            if self.sink is not None:
                self.sink(dt, dv)
            self.depth_x.add(dt, dv.astype(float))
        self.kept = {name: [] for name in k}
        self.starvations = self.starvations[:10]

    def finish(self) -> None:
        """The final drain (as ``replay``: at most capacity + 10 000 steps)."""
        self.final = True
        if self.exe is not None:
            exe, guard = self.exe, 0
            end = exe.next_event_time()
            while end is not None and guard < self.variant.queue + 10_000:
                exe.advance(end)
                end = exe.next_event_time()
                guard += 1
            self._drain_python(np.zeros(0), np.zeros(0, np.int64), [])
            self.live.clear()  # the rest never ran
            return
        z = np.zeros(0, np.int64)
        self._run(np.zeros(0), np.zeros(0, bool), np.zeros((0, self.naxes), np.int64),
                  np.zeros(0, bool), np.zeros(0, np.int32), z, self.variant.queue + 10_000)
        self._new_queue()  # the rest never ran

    def mean_depth(self) -> float:
        if self.depth_n < 2:
            return float(self.first_depth) if self.depth_n else 0.0
        total = self.depth_last[0] - self.depth_t0 if self.depth_last and self.depth_t0 is not None else 0.0
        return self.area / total if total > 0 else self.depth_sum / self.depth_n

    def result(self) -> QueueReplay:
        """The whole replay (only while ``keep``)."""
        k = {name: (np.concatenate(v) if v else np.zeros(0)) for name, v in self.kept.items()}
        rep = QueueReplay(k["pushes"].astype(float), k["push_rows"].astype(np.int64),
                          k["starts"], k["ends"], k["starved"].astype(bool), k["v_out"],
                          k["done_rows"].astype(np.int64), k["removals"], k["depth_t"],
                          k["depth"].astype(np.int32), notes=list(self.notes),
                          capacity=self.variant.queue)
        rep.starvations = list(self.starvations)
        return rep

    def metrics(self, t0: float, whatif_rows: list[dict[str, Any]]) -> dict[str, Any]:
        return {
            "capacity": self.variant.queue,
            "vectors_replayed": self.pushed,
            "vectors_completed": self.completed,
            "max_depth": self.max_depth,
            "mean_depth": float(self.mean_depth()),
            "starvations": self.starved,
            "starved_s": float(self.starved_s),
            "standstill_s": float(self.standstill_s),
            "median_vector_s": float(self.durations.median()) if self.durations.n else None,
            "motion_end_s": float(self.end_max - t0) if self.completed else None,
            "whatif": whatif_rows,
        }
