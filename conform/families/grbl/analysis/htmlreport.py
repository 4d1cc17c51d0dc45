"""The grbl analysis as a self-contained ``index.html``: findings, the receive buffer (bytes in
flight per line against its size, hazards marked) and line-to-answer latency, with the page
pieces every analysis report shares (conform/report/templates/analysis_pieces.html.j2) and
the engine's plotting helpers (conform.analysis.plots: matplotlib, Agg, base64 PNG)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from conform.analysis.plots import legend_beside, new_figure, over_time, thin_points

HERE = Path(__file__).resolve().parent


def _times(a: Any) -> tuple[float, np.ndarray, np.ndarray]:
    """(the session's start, each line's time from it, its line-to-answer time): the
    session-time axis of every plot, as the findings' times and the engine's plots."""
    ex = a.exchanges
    t0 = a.t0
    t = np.fromiter((e.t_sent - t0 for e in ex), float, len(ex))
    lat = np.fromiter((np.nan if e.t_answer is None else e.t_answer - e.t_sent for e in ex),
                      float, len(ex))
    return t0, t, lat


def buffer_plot(a: Any) -> str | None:
    ex = a.exchanges
    if not ex:
        return None
    _t0, t, _lat = _times(a)
    b = np.fromiter((e.bytes_in_flight for e in ex), float, len(ex))
    limit = a.metrics["rx_buffer"]
    fig, ax = new_figure()
    tt, bb = thin_points(t, b)
    ax.step(tt, bb, where="post", lw=0.8, label="bytes in flight")
    ax.axhline(limit, color="tab:red", lw=1, ls="--", label=f"receive buffer ({limit})")
    over = b > limit
    if over.any():
        ax.plot(t[over], b[over], "x", color="tab:red", ms=4, label="over the buffer")
    return over_time(fig, ax, a, "bytes", "Bytes in flight per line")


def latency_plot(a: Any) -> str | None:
    _t0, t, lat = _times(a)
    ok = np.isfinite(lat)
    if not ok.any():
        return None
    fig, ax = new_figure()
    tt, ll = thin_points(t[ok], lat[ok] * 1000)
    ax.plot(tt, ll, ".", ms=2, label="line to answer")
    errs = [e for e in a.exchanges if e.answer and e.answer.startswith("error:")]
    if errs:
        t0 = _t0
        ax.plot([e.t_sent - t0 for e in errs], [(e.t_answer - e.t_sent) * 1000 for e in errs],
                "o", color="tab:red", ms=4, label="error:N")
    return over_time(fig, ax, a, "ms", "Line to answer")


STATE_ROWS = ("Idle", "Run", "Jog", "Hold", "Door", "Home", "Check", "Alarm", "Sleep")


def machine_plot(a: Any) -> str | None:
    """What the status reports said over time: the state, and with ``Bf:`` the planner blocks
    and receive-buffer bytes in use (where starvation and a full buffer show)."""
    if not a.reports:
        return None
    t0 = a.t0
    t, state, blocks, rx = [], [], [], []
    for when, text in a.reports:
        fields = text.strip("<>").split("|")
        name = fields[0].split(":")[0]
        bf = next((f[3:].split(",") for f in fields if f.startswith("Bf:")), None)
        t.append(when - t0)
        state.append(STATE_ROWS.index(name) if name in STATE_ROWS else -1)
        blocks.append(_in_use(a, bf, 0))
        rx.append(_in_use(a, bf, 1))
    fig, ax = new_figure(7.5, 2.6 if all(b is None for b in blocks) else 3.6)
    ax.plot(t, state, "|", ms=10, label="state")
    ax.set_yticks(range(len(STATE_ROWS)), STATE_ROWS, fontsize=8)
    ax2 = None
    if any(b is not None for b in blocks):
        ax2 = ax.twinx()
        ax2.step(t, [np.nan if b is None else b for b in blocks], where="post", color="tab:green",
                 lw=0.8, label="planner blocks in use")
        ax2.step(t, [np.nan if r is None else r for r in rx], where="post", color="tab:orange",
                 lw=0.8, label="receive bytes in use")
        ax2.set_ylabel("in use")
        h1, l1 = ax.get_legend_handles_labels()
        h2, l2 = ax2.get_legend_handles_labels()
        legend_beside(ax2, h1 + h2, l1 + l2)
        ax2.get_legend().set_bbox_to_anchor((1.12, 1.0))  # beyond the right axis's labels
    return over_time(fig, ax, a, "", "Machine state from the status reports",
                     legend=ax2 is None)


def _in_use(a: Any, bf: list[str] | None, i: int) -> float | None:
    """Blocks (i=0) or bytes (i=1) in use from a ``Bf:`` field of free ones."""
    if bf is None or len(bf) < 2:
        return None
    size = a.metrics.get("planner_blocks", 15) if i == 0 else a.metrics["rx_buffer"]
    try:
        return float(size - int(bf[i]))
    except ValueError:
        return None


def latency_stats(a: Any) -> dict[str, float] | None:
    _t0, _t, lat = _times(a)
    lat = lat[np.isfinite(lat)] * 1000
    if not len(lat):
        return None
    return {"median": float(np.median(lat)), "p95": float(np.percentile(lat, 95)),
            "max": float(lat.max())}


def render_html(a: Any) -> str:
    from conform.analysis.report import severity_counts, template_env

    env = template_env(HERE)
    by_sev = severity_counts(a.findings)
    plots = {"buffer": buffer_plot(a), "latency": latency_plot(a), "machine": machine_plot(a)}
    return env.get_template("report.html.j2").render(a=a, m=a.metrics, by_sev=by_sev,
                                                      plots=plots, latency=latency_stats(a))
