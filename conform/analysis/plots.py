"""Plots of an analysis, as base64 PNG for a self-contained HTML report (matplotlib, Agg).

Large sessions are decimated for drawing only (never for the numbers): at most
``MAX_POINTS`` points per line.
"""

from __future__ import annotations

import base64
import io
from typing import Any

import numpy as np

MAX_POINTS = 20_000


def _use_agg() -> None:
    import matplotlib

    matplotlib.use("Agg")


def _fig(w: float = 7.5, h: float = 3.2) -> Any:
    _use_agg()
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(w, h), dpi=100)
    return fig, ax


def _png(fig: Any) -> str:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _thin(*arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    n = len(arrays[0])
    if n <= MAX_POINTS:
        return arrays
    step = int(np.ceil(n / MAX_POINTS))
    return tuple(a[::step] for a in arrays)


def latency_plots(a: Any) -> str | None:
    ex = a.exchanges
    ok = ex["status"].to_numpy() == "answered"
    rtt = ex["rtt"].to_numpy()[ok] * 1000
    rtt = rtt[np.isfinite(rtt)]
    if len(rtt) == 0:
        return None
    _use_agg()
    import matplotlib.pyplot as plt

    fig, (h, c) = plt.subplots(1, 2, figsize=(9, 3.2), dpi=100)
    hi = float(np.quantile(rtt, 0.995)) if len(rtt) > 10 else float(rtt.max())
    h.hist(np.clip(rtt, 0, hi), bins=60, color="#4477aa")
    h.set_xlabel("round trip, ms (clipped at p99.5)")
    h.set_ylabel("exchanges")
    h.set_title("Latency histogram")
    for col, label, color in (("rtt", "round trip", "#4477aa"), ("unit_time", "unit", "#228833"),
                              ("host_time", "host turnaround", "#cc6677")):
        v = ex[col].to_numpy()[ok] * 1000
        v = np.sort(v[np.isfinite(v)])
        if len(v):
            y = np.arange(1, len(v) + 1) / len(v)
            xs, ys = _thin(v, y)
            c.plot(xs, ys, label=label, color=color)
    c.set_xscale("symlog", linthresh=0.1)
    c.set_xlabel("ms")
    c.set_ylabel("fraction")
    c.set_title("Latency CDF")
    c.legend(fontsize=8)
    return _png(fig)


def throughput_plot(a: Any) -> str | None:
    s = a.series
    if len(s) == 0:
        return None
    fig, ax = _fig()
    ax.plot(s["t"], s["exchanges_per_s"], label="exchanges/s", color="#4477aa")
    ax.plot(s["t"], s["vectors_per_s"], label="vectors/s", color="#228833")
    ax.set_xlabel("s")
    ax.set_ylabel("per second")
    if "utilisation_host" in s:
        ax2 = ax.twinx()
        ax2.plot(s["t"], 100 * s["utilisation_host"], label="line use host→unit %",
                 color="#aa3377", alpha=0.6)
        ax2.set_ylabel("line utilisation %")
        ax2.set_ylim(0, max(100, float(100 * s["utilisation_host"].max()) * 1.1))
        ax2.legend(loc="upper right", fontsize=8)
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title("Throughput over time")
    return _png(fig)


def queue_plot(a: Any) -> str | None:
    rep = a.queue
    if rep is None or len(rep.depth_t) == 0:
        return None
    fig, ax = _fig()
    t, d = _thin(rep.depth_t - a.t0, rep.depth)
    ax.step(t, d, where="post", color="#4477aa", label="predicted queue depth")
    ax.axhline(rep.capacity, color="#999999", ls="--", lw=0.8, label=f"capacity {rep.capacity}")
    if rep.starvations:
        st = np.array([e["t"] for e in rep.starvations]) - a.t0
        ax.plot(st, np.zeros(len(st)), "v", color="#cc3311", ms=7,
                label=f"starvation ({len(st)})")
    ax.set_xlabel("s")
    ax.set_ylabel("vectors queued")
    ax.legend(fontsize=8)
    ax.set_title("Queue depth (replayed through the unit's motion model)")
    return _png(fig)


def path_plot(a: Any) -> str | None:
    rep = a.queue
    if rep is None or rep.vectors == 0:
        return None
    ex = a.exchanges
    rows = rep.push_rows
    dx = ex["dx"].to_numpy()[rows]
    dy = ex["dy"].to_numpy()[rows]
    x = np.concatenate([[0], np.cumsum(dx)])
    y = np.concatenate([[0], np.cumsum(dy)])
    fig, ax = _fig(6.5, 6.0)
    xs, ys = _thin(x, y)
    ax.plot(xs, ys, color="#4477aa", lw=0.8)
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
                kx, ky = _thin(x[k], y[k])
                ax.plot(kx, ky, "o", ms=3, color=color, label=f"{label} ({int(mask.sum())})")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("X pulses")
    ax.set_ylabel("Y pulses")
    ax.set_title("X/Y path, junctions where the motion stopped or slowed")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8)
    return _png(fig)


def all_plots(a: Any) -> dict[str, str]:
    out = {}
    for key, fn in (("latency", latency_plots), ("throughput", throughput_plot),
                    ("queue", queue_plot), ("path", path_plot)):
        try:
            img = fn(a)
        except Exception as exc:  # noqa: BLE001 - a plot must not sink the report
            a.notes.append(f"plot {key} failed: {type(exc).__name__}: {exc}")
            img = None
        if img:
            out[key] = img
    return out
