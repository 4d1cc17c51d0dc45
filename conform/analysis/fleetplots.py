"""The fleet report's plots (drawn with the engine's pieces, conform.analysis.plots): per
session over time (each session at its start, coloured by machine) and per machine, the
error findings, latency (each family's measure on its own axis, ``Family.latency_measure``)
and the families' counted columns (``FleetColumn``
with ``summary``: hazards, starvations), so a machine or a shift that goes wrong stands out
before the tables are read."""

from __future__ import annotations

from datetime import UTC, datetime

import numpy as np

from conform.analysis.plots import legend_beside, to_png, use_agg
from conform.jsondoc import JsonObject


def _counted(s: JsonObject) -> list[tuple[str, str]]:
    """(key, label) of what is counted per session: error findings, then the families'
    summary columns."""
    return [("error_findings", "error findings"),
            *((c["key"], c["label"]) for c in s.get("columns", []) if c["summary"])]


def _value(r: JsonObject, key: str) -> float:
    if key == "error_findings":
        return float((r.get("severities") or {}).get("error", 0))
    v = r.get(key)
    return float(v) if isinstance(v, (int, float)) else np.nan


def timed(s: JsonObject) -> list[JsonObject]:
    """The analysed sessions with a wall-clock start (one on an emulator's virtual clock has
    none: the fleet's notes say so)."""
    return [r for r in s["sessions"] if r["state"] != "error" and r.get("started") is not None]


def time_span(rows: list[JsonObject]) -> tuple[datetime, datetime]:
    """The time axis: the sessions' first start to the last one's end, with a margin of a
    twentieth of that (at least a minute) each side, so no session sits on an edge."""
    first = min(float(r["started"]) for r in rows)
    last = max(float(r["started"]) + float(r.get("duration_s") or 0) for r in rows)
    pad = max((last - first) / 20, 60.0)
    return (datetime.fromtimestamp(first - pad, UTC), datetime.fromtimestamp(last + pad, UTC))


def sessions_plot(s: JsonObject) -> str | None:
    """Every analysed session at its start: its counts and its latency (p50 to p99, p95
    marked; one axis per measure the families name: ``latencies``), one colour per
    machine."""
    rows = timed(s)
    by_time = bool(rows)
    if not by_time:   # no wall-clock start at all: the sessions side by side, in order
        rows = [r for r in s["sessions"] if r["state"] != "error"]
    if not rows:
        return None
    place = {id(r): (datetime.fromtimestamp(r["started"], UTC) if by_time else i)
             for i, r in enumerate(rows)}
    use_agg()
    import matplotlib.pyplot as plt

    counted = _counted(s)
    measures = [m for m in s.get("latencies") or [] if any(r.get("latency") == m for r in rows)]
    n = len(counted) + max(len(measures), 1)
    fig, grid = plt.subplots(n, 1, figsize=(9.0, 1.6 * n + 0.8), dpi=100, sharex=True,
                             squeeze=False)
    axes = list(grid[:, 0])
    machines = sorted({str(r["machine"]) for r in rows})
    colors = plt.get_cmap("tab10")
    for k, m in enumerate(machines):
        mine = [r for r in rows if str(r["machine"]) == m]
        t = [place[id(r)] for r in mine]
        for ax, (key, _label) in zip(axes, counted, strict=False):
            ax.plot(t, [_value(r, key) for r in mine], "o", ms=5, color=colors(k % 10), label=m)
        for ax, measure in zip(axes[len(counted):], measures, strict=False):
            its = [(ti, r) for ti, r in zip(t, mine, strict=True) if r.get("latency") == measure]
            if not its:
                continue
            ts = [ti for ti, _r in its]
            p50, p95, p99 = (np.array([_value(r, c) for _t, r in its])
                             for c in ("rtt_p50_ms", "rtt_p95_ms", "rtt_p99_ms"))
            ax.vlines(ts, p50, p99, color=colors(k % 10), lw=2, alpha=0.6)
            ax.plot(ts, p95, "_", ms=10, color=colors(k % 10))
    for ax, (_key, label) in zip(axes, counted, strict=False):
        ax.set_ylabel(label, fontsize=8)
        top = ax.dataLim.y1 if np.isfinite(ax.dataLim.y1) else 0.0
        top = max(top, 1.0)
        ax.set_ylim(-0.06 * top, 1.12 * top)   # a count of 0 is a dot above the axis line
    for ax, measure in zip(axes[len(counted):], measures, strict=False):
        ax.set_ylabel(f"{measure} ms\n(p50–p99, p95 –)", fontsize=8)
    if by_time:
        axes[0].set_xlim(*time_span(rows))
        axes[-1].set_xlabel("session start (UTC)")
    else:
        axes[-1].set_xticks(range(len(rows)), [str(r["session"]) for r in rows], fontsize=7)
        axes[0].set_xlim(-0.5, len(rows) - 0.5)
        axes[-1].set_xlabel("session (no wall-clock start: recorded on an emulator's clock)")
    axes[0].set_title("Sessions over time" if by_time else "Sessions")
    fig.autofmt_xdate()
    legend_beside(axes[0])
    return to_png(fig)


def machines_plot(s: JsonObject) -> str | None:
    """Per machine: the counts summed over its sessions, and its worst p95 and p99 round
    trip."""
    ms = s["machines"]
    if not ms:
        return None
    use_agg()
    import matplotlib.pyplot as plt

    counted = _counted(s)
    fig, (cax, lax) = plt.subplots(1, 2, figsize=(10.0, 3.6), dpi=100)
    x = np.arange(len(ms))
    width = 0.8 / len(counted)
    for j, (key, label) in enumerate(counted):
        cax.bar(x + (j - (len(counted) - 1) / 2) * width, np.nan_to_num([_value(m, key) for m in ms]),
                width, label=label)
    bars = [(measure, q) for measure in s.get("latencies") or [] for q in ("p95", "p99")]
    lw = 0.8 / max(len(bars), 1)
    for j, (measure, q) in enumerate(bars):
        lax.bar(x + (j - (len(bars) - 1) / 2) * lw,
                [((m.get("latency") or {}).get(measure) or {}).get(q) or 0 for m in ms], lw,
                label=f"worst {q}, {measure}")
    for ax, title in ((cax, "Counts per machine"), (lax, "Latency per machine, ms")):
        ax.set_xticks(x, [str(m["machine"]) for m in ms], rotation=30, ha="right", fontsize=8)
        ax.set_title(title)
        legend_beside(ax)
    return to_png(fig)


def fleet_plots(s: JsonObject) -> dict[str, str]:
    """The fleet report's plots (key -> base64 PNG); one that fails is left out and said."""
    out: dict[str, str] = {}
    for key, fn in (("sessions", sessions_plot), ("machines", machines_plot)):
        try:
            img = fn(s)
        except Exception as exc:  # noqa: BLE001 - a plot must not sink the report
            s.setdefault("notes", []).append(f"plot {key} failed: {type(exc).__name__}: {exc}")
            img = None
        if img:
            out[key] = img
    return out
