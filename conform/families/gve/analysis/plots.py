"""The GVE analysis's plots (drawn with the engine's pieces, conform.analysis.plots): latency
histogram and CDF, latency over time with errors and starvations, throughput of exchanges
and vectors, the replayed queue depth and the X/Y path; and ``PlotData``, the bounded series
a streamed (long) capture keeps for them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from conform.analysis.plots import (
    MAX_POINTS,
    draw,
    legend_beside,
    limit,
    new_figure,
    over_time,
    thin_points,
    to_png,
    use_agg,
    window,
)


def _latency_values(a: Any, col: str) -> tuple[np.ndarray, np.ndarray]:
    """(sorted values in ms, counts) of a latency column: every answered exchange of a
    whole analysis, the summary's grid for a streamed one."""
    if a.whole:
        ex = a.exchanges
        ok = ex["status"].to_numpy() == "answered"
        v = ex[col].to_numpy()[ok] * 1000
        v = np.sort(v[np.isfinite(v)])
        return v, np.ones(len(v), np.int64)
    q = a.plot.latency[col]
    if q.n == 0:
        return np.zeros(0), np.zeros(0, np.int64)
    v, c = q.grid()
    return v * 1000, c


def latency_plots(a: Any) -> str | None:
    """Histogram and CDF of the latencies (every exchange, or a long capture's summaries)."""
    rtt, n = _latency_values(a, "rtt")
    if len(rtt) == 0:
        return None
    use_agg()
    import matplotlib.pyplot as plt

    fig, (h, c) = plt.subplots(1, 2, figsize=(9, 3.2), dpi=100)
    if not a.whole:
        hi = a.plot.rtt_values.quantile([0.995])[0] * 1000
    else:
        hi = float(np.quantile(rtt, 0.995)) if len(rtt) > 10 else float(rtt.max())
    h.hist(np.clip(rtt, 0, hi), bins=60, weights=None if a.whole else n, color="#4477aa")
    h.set_xlabel("round trip, ms (clipped at p99.5)")
    h.set_ylabel("exchanges")
    h.set_title("Latency histogram")
    top = 0.0
    for col, label, color in (("rtt", "round trip", "#4477aa"), ("unit_time", "unit", "#228833"),
                              ("host_time", "host turnaround", "#cc6677")):
        v, k = _latency_values(a, col)
        if len(v):
            xs, ys = thin_points(v, np.cumsum(k) / k.sum())
            c.plot(xs, ys, label=label, color=color)
            top = max(top, float(v[-1]))
    c.set_xscale("symlog", linthresh=0.1)
    if top > 0:  # room beyond the slowest value of any curve: none cut off the axis
        c.set_xlim(right=top * 1.5)
    c.set_xlabel("ms")
    c.set_ylabel("fraction")
    c.set_title("Latency CDF")
    legend_beside(c)
    return to_png(fig)


ERROR_CODES = (2, 3, 4, 5, 6, 7)


def _marks(a: Any, bins: Any) -> tuple[np.ndarray, int, bool]:
    """(times from the start, total, bucketed) of events kept in a ``TimeBins``: every event
    while few, else the grid bins that hold any."""
    t = bins.times()
    if t is not None:
        return t - a.t0, len(t), False
    width = bins.width
    has = np.flatnonzero(bins.bins > 0)
    return bins.origin + (has + 0.5) * width - a.t0, int(bins.bins.sum()), True


def _latency_time_summary(a: Any) -> str | None:
    """Per time bin the fastest and slowest round trip (the whole range, not samples), with
    every error and every missing or garbled answer marked (or, when there are more than
    the summaries keep, every bin that holds any)."""
    t, n, lo, hi = a.plot.rtt
    if len(t) == 0:
        return None
    t = t - a.t0
    w = window(a, t)
    fig, ax = new_figure(9.0, 3.4)
    ax.fill_between(t[w], lo[w], hi[w], step="post", color="#4477aa", alpha=0.5, lw=0,
                    label="round trip, min to max per bin")
    top = float(hi[w].max()) if w.any() else 1.0
    for bins, color, marker, label in ((a.plot.errors, "#cc3311", "x", "error answer"),
                                       (a.plot.bad, "#aa3377", "|", "no or garbled answer")):
        et, total, bucketed = _marks(a, bins)
        et = et[window(a, et)]
        if total:
            ax.plot(et, np.full(len(et), top * 1.05), marker, ms=8, color=color, ls="",
                    label=f"{label} ({total}{', bins with any' if bucketed else ''})")
    if a.plot.starvations is not None:
        st, total, bucketed = _marks(a, a.plot.starvations)
        st = st[window(a, st)]
        for k, x in enumerate(thin_points(st)[0]):
            ax.axvline(x, color="#ee7733", lw=0.8, alpha=0.5,
                       label=f"starvation ({total}{', bins with any' if bucketed else ''})"
                       if k == 0 else None)
    pos = lo[w][lo[w] > 0]
    if len(pos) and hi[w].max() / pos.min() > 30:
        ax.set_yscale("log")
    return over_time(fig, ax, a, "round trip, ms", "Latency over time")


def latency_time_plot(a: Any) -> str | None:
    """Round trip of every exchange over time, errors and starvations marked."""
    if not a.whole:
        return _latency_time_summary(a)
    ex = a.exchanges
    t = ex["t_cmd_first"].to_numpy() - a.t0
    rtt = ex["rtt"].to_numpy() * 1000
    status = ex["status"].to_numpy()
    ok = (status == "answered") & np.isfinite(rtt) & np.isfinite(t)
    if not ok.any():
        return None
    w = window(a, t)
    fig, ax = new_figure(9.0, 3.4)
    ts, ys = thin_points(t[ok & w], rtt[ok & w])
    ax.plot(ts, ys, ".", ms=2, color="#4477aa", alpha=0.6, label="round trip")
    code = ex["code"].to_numpy()
    err = ok & w & np.isin(code, ERROR_CODES)
    bad = w & np.isfinite(t) & ((status == "unanswered") | (
        ex["answer_kind"].to_numpy() == "garbled"))
    top = float(np.nanmax(ys)) if len(ys) else 1.0
    if err.any():
        et, ey = thin_points(t[err], rtt[err])
        ax.plot(et, ey, "x", ms=6, color="#cc3311", label=f"error answer ({int(err.sum())})")
    if bad.any():
        bt = thin_points(t[bad])[0]
        ax.plot(bt, np.full(len(bt), top * 1.05), "|", ms=10, color="#aa3377",
                label=f"no or garbled answer ({int(bad.sum())})")
    rep = a.queue
    if rep is not None and rep.starvations:
        st = np.array([e["t"] for e in rep.starvations]) - a.t0
        st = st[window(a, st)]
        for k, x in enumerate(thin_points(st)[0]):
            ax.axvline(x, color="#ee7733", lw=0.8, alpha=0.5,
                       label=f"starvation ({len(st)})" if k == 0 else None)
    pos = ys[ys > 0]
    if len(pos) and pos.max() / pos.min() > 30:  # long tails: a log scale keeps both visible
        ax.set_yscale("log")
    return over_time(fig, ax, a, "round trip, ms", "Latency over time")


def throughput_plot(a: Any) -> str | None:
    s = a.series
    if len(s) == 0:
        return None
    fig, ax = new_figure()
    ax.plot(s["t"], s["exchanges_per_s"], label="exchanges/s", color="#4477aa")
    ax.plot(s["t"], s["vectors_per_s"], label="vectors/s", color="#228833")
    ax.set_xlabel("s from the start")
    ax.set_ylabel("per second")
    handles, labels = ax.get_legend_handles_labels()
    if "utilisation_host" in s:
        ax2 = ax.twinx()
        ax2.plot(s["t"], 100 * s["utilisation_host"], label="line use host→unit %",
                 color="#aa3377", alpha=0.6)
        ax2.set_ylabel("line utilisation %")
        ax2.set_ylim(0, max(100, float(100 * s["utilisation_host"].max()) * 1.1))
        ax.set_ylim(bottom=0)   # both axes count from 0 at the same height
        h2, l2 = ax2.get_legend_handles_labels()
        handles, labels = handles + h2, labels + l2
        fig.subplots_adjust(right=0.7)
    legend_beside(ax, handles, labels)
    if "utilisation_host" in s:  # the right axis's labels sit between the plot and the legend
        ax.get_legend().set_bbox_to_anchor((1.12, 1.0))
    ax.set_title("Throughput over time")
    limit(ax, a)
    return to_png(fig)


def _queue_summary(a: Any) -> str | None:
    p = a.plot
    if p.depth is None or len(p.depth[0]) == 0:
        return None
    t, _n, lo, hi = p.depth
    t = t - a.t0
    w = window(a, t)
    fig, ax = new_figure(9.0, 3.4)
    ax.fill_between(t[w], lo[w], hi[w], step="post", color="#4477aa", alpha=0.6, lw=0,
                    label="predicted queue depth, min to max per bin")
    ax.axhline(p.capacity, color="#999999", ls="--", lw=0.8, label=f"capacity {p.capacity}")
    if p.starvations is not None:
        st, total, bucketed = _marks(a, p.starvations)
        st = st[window(a, st)]
        if total:
            ax.plot(st, np.zeros(len(st)), "^", color="#cc3311", ms=7,
                    label=f"starvation ({total}{', bins with any' if bucketed else ''})")
    return over_time(fig, ax, a, "vectors queued",
                      "Queue depth over time (replayed through the unit's motion model)")


def queue_plot(a: Any) -> str | None:
    if not a.whole:
        return _queue_summary(a)
    rep = a.queue
    if rep is None or len(rep.depth_t) == 0:
        return None
    fig, ax = new_figure(9.0, 3.4)
    t_all = rep.depth_t - a.t0
    w = window(a, t_all)
    t, d = thin_points(t_all[w], rep.depth[w])
    ax.step(t, d, where="post", color="#4477aa", label="predicted queue depth")
    ax.axhline(rep.capacity, color="#999999", ls="--", lw=0.8, label=f"capacity {rep.capacity}")
    if rep.starvations:
        st = np.array([e["t"] for e in rep.starvations]) - a.t0
        st = st[window(a, st)]
        ax.plot(st, np.zeros(len(st)), "^", color="#cc3311", ms=7,
                label=f"starvation ({len(st)})")
    return over_time(fig, ax, a, "vectors queued",
                      "Queue depth over time (replayed through the unit's motion model)")


def _path_png(fig: Any, ax: Any, title: str) -> str:
    """An X/Y path figure finished (equal scales, axis names, legend beside) as PNG."""
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("X pulses")
    ax.set_ylabel("Y pulses")
    ax.set_title(title)
    legend_beside(ax)
    return to_png(fig)


def _path_summary(a: Any) -> str | None:
    ps = a.plot.path
    if ps is None or ps.pushed == 0:
        return None
    x, y, stops = ps.points()
    fig, ax = new_figure(8.0, 6.0)
    ax.plot(x, y, color="#4477aa", lw=0.8,
            label="path" + (f" (every {ps.step}th junction)" if ps.step > 1 else ""))
    if len(stops):
        sx, sy, every = sparse_markers(stops[:, 0], stops[:, 1])
        ax.plot(sx, sy, "o", ms=3, color="#cc3311", label=f"stopped ({ps.n_stops}" + _drawn(every))
    return _path_png(fig, ax, "X/Y path, junctions where the motion stopped")


def path_plot(a: Any) -> str | None:
    if not a.whole:
        return _path_summary(a)
    rep = a.queue
    if rep is None or rep.vectors == 0:
        return None
    ex = a.exchanges
    rows = rep.push_rows
    dx = ex["dx"].to_numpy()[rows]
    dy = ex["dy"].to_numpy()[rows]
    x = np.concatenate([[0], np.cumsum(dx)])
    y = np.concatenate([[0], np.cumsum(dy)])
    fig, ax = new_figure(8.0, 6.0)
    xs, ys = thin_points(x, y)
    ax.plot(xs, ys, color="#4477aa", lw=0.8, label="path")
    if 2 < len(x) <= JUNCTION_MARKERS + 2:  # every junction (a vector's end where the next
        ax.plot(x[1:-1], y[1:-1], ".", ms=2, color="#88aacc",  # starts), while few
                label=f"junction ({len(x) - 2})")
    if len(rep.done_rows):
        # exit speed of every finished vector marks the junction at its end
        idx = np.searchsorted(rows, rep.done_rows)
        idx = np.clip(idx, 0, len(rows) - 1)
        has_next = idx < len(rows) - 1
        vout = rep.v_out
        moving = vout[vout > 0]
        slow_lim = 0.5 * float(np.median(moving)) if len(moving) else 0.0
        stop = has_next & (vout <= 0)
        slow = has_next & (vout > 0) & (vout < slow_lim)
        for mask, color, label in ((slow, "#ddaa33", "slowed"), (stop, "#cc3311", "stopped")):
            k = idx[mask] + 1
            if len(k):
                kx, ky, every = sparse_markers(x[k], y[k])
                ax.plot(kx, ky, "o", ms=3, color=color, label=f"{label} ({int(mask.sum())}"
                        + _drawn(every))
    return _path_png(fig, ax, "X/Y path, junctions where the motion stopped or slowed")


JUNCTION_MARKERS = 100  # junctions drawn as dots only up to this many: more hide the path
MARKERS = 150  # stopped or slowed junctions drawn, at most: every k-th of more


def sparse_markers(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """At most ``MARKERS`` of the points (every k-th, evenly along the path) and k, so
    markers on a long job leave the path visible."""
    every = max(1, int(np.ceil(len(x) / MARKERS)))
    return x[::every], y[::every], every


def _drawn(every: int) -> str:
    """The end of a marker's legend label: how many of them are drawn."""
    return f", 1 in {every} drawn)" if every > 1 else ")"


PLOTS = (("latency", latency_plots), ("latency_time", latency_time_plot),
         ("throughput", throughput_plot), ("queue", queue_plot), ("path", path_plot))


def gve_plots(a: Any) -> dict[str, str]:
    return draw(a, PLOTS)


class PathSample:
    """The X/Y path of a long capture, decimated as it streams: every ``step``-th junction
    (the step doubles when more than ``2 * MAX_POINTS`` are held), and the push numbers of
    the first ``MAX_POINTS`` junctions where the motion stopped; a stop is drawn at the kept
    junction nearest before it (at most ``step`` junctions early)."""

    def __init__(self, naxes: int) -> None:
        self.pos = np.zeros(2, np.int64)
        self.pushed = 0
        self.step = 1
        self.idx = np.zeros(1, np.int64)
        self.xy = np.zeros((1, 2), np.int64)
        self.stops: list[int] = []
        self.n_stops = 0

    def push(self, d: np.ndarray) -> None:
        if len(d) == 0:
            return
        while (self.pushed + len(d)) // self.step > 2 * MAX_POINTS:  # coarser first
            self.step *= 2
            keep = self.idx % self.step == 0
            self.idx, self.xy = self.idx[keep], self.xy[keep]
        xy = np.cumsum(d[:, :2], axis=0) + self.pos
        k = np.arange(1, len(d) + 1) + self.pushed  # point k ends vector k - 1
        sel = k % self.step == 0
        self.idx = np.concatenate([self.idx, k[sel]])
        self.xy = np.concatenate([self.xy, xy[sel]])
        self.pos = xy[-1]
        self.pushed += len(d)

    def done(self, seq: np.ndarray, v_out: np.ndarray) -> None:
        stop = seq[(v_out <= 0) & (seq + 1 < self.pushed)]
        self.n_stops += len(stop)
        room = MAX_POINTS - len(self.stops)
        if room > 0:
            self.stops.extend((stop[:room] + 1).tolist())

    def points(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, y) of the kept path and of the stops drawn."""
        xy = self.xy
        at = np.searchsorted(self.idx, np.array(self.stops, np.int64), side="right") - 1
        return xy[:, 0], xy[:, 1], xy[np.clip(at, 0, len(xy) - 1)]


@dataclass
class PlotData:
    """Bounded series for the plots of a long capture (see ``summaries``)."""

    t0: float
    rtt: tuple  # (bin start, count, min, max) in ms, bins from the start
    rtt_values: Any  # summaries.Quantiles of the round trip (s)
    latency: dict[str, Any]  # column -> Quantiles
    errors: Any  # TimeBins of error answers
    bad: Any  # TimeBins of missing or garbled answers
    starvations: Any  # TimeBins of starvations
    depth: tuple | None  # (bin start, count, min, max)
    capacity: int
    path: Any

    @classmethod
    def of(cls, m: Any, rep: Any, t0: float) -> PlotData:
        return cls(t0, m.rtt_t.series(), m.lat["rtt"], m.lat, m.errors_t, m.bad_t,
                   rep.starve_t if rep is not None else None,
                   rep.depth_x.series() if rep is not None and rep.depth_x is not None
                   else None, rep.variant.queue if rep is not None else 0,
                   rep.path if rep is not None else None)
