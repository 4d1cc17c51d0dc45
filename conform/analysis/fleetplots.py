"""The fleet report's plots (drawn with the engine's pieces, conform.analysis.plots): per
session over time (each session at its start, coloured by machine) and per machine, the
error findings, round-trip latency and the families' counted columns (``FleetColumn``
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


def sessions_plot(s: JsonObject) -> str | None:
    """Every analysed session at its start: its counts and its round trip (p50 to p99,
    p95 marked), one colour per machine."""
    rows = [r for r in s["sessions"] if r["state"] != "error" and r.get("started") is not None]
    if not rows:
        return None
    use_agg()
    import matplotlib.pyplot as plt

    counted = _counted(s)
    fig, axes = plt.subplots(len(counted) + 1, 1, figsize=(9.0, 1.6 * (len(counted) + 1) + 0.8),
                             dpi=100, sharex=True)
    machines = sorted({str(r["machine"]) for r in rows})
    colors = plt.get_cmap("tab10")
    for k, m in enumerate(machines):
        mine = [r for r in rows if str(r["machine"]) == m]
        t = [datetime.fromtimestamp(r["started"], UTC) for r in mine]
        for ax, (key, _label) in zip(axes, counted, strict=False):
            ax.plot(t, [_value(r, key) for r in mine], "o", ms=5, color=colors(k % 10), label=m)
        p50, p95, p99 = (np.array([_value(r, c) for r in mine])
                         for c in ("rtt_p50_ms", "rtt_p95_ms", "rtt_p99_ms"))
        axes[-1].vlines(t, p50, p99, color=colors(k % 10), lw=2, alpha=0.6)
        axes[-1].plot(t, p95, "_", ms=10, color=colors(k % 10))
    for ax, (_key, label) in zip(axes, counted, strict=False):
        ax.set_ylabel(label, fontsize=8)
        ax.set_ylim(bottom=0)
    axes[-1].set_ylabel("round trip ms\n(p50–p99, p95 –)", fontsize=8)
    axes[-1].set_xlabel("session start (UTC)")
    axes[0].set_title("Sessions over time")
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
    for j, (key, label) in enumerate((("rtt_p95_ms_worst", "worst p95"),
                                      ("rtt_p99_ms_worst", "worst p99"))):
        lax.bar(x + (j - 0.5) * 0.4, [m.get(key) or 0 for m in ms], 0.4, label=label)
    for ax, title in ((cax, "Counts per machine"), (lax, "Round trip per machine, ms")):
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
