"""The Marlin analysis as a self-contained ``index.html``, laid out as grbl's: the verdict in
a sentence, the diagnosis (when conform.diagnosis gave one), the severity badges and the
session's figures in words, then the findings and the plots (ok latency over time, the
unit's Resend: requests, busy periods, lines in flight), with the page pieces every analysis
report shares (conform/report/templates/analysis_pieces.html.j2) and the engine's plotting
helpers (conform.analysis.plots)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from conform.analysis.plots import new_figure, over_time, thin_points

HERE = Path(__file__).resolve().parent


def verdict(a: Any) -> tuple[str, str]:
    """(word, sentence): HAZARD (a line ran twice or never, for sure), ERROR (lines rejected,
    a storm, a halt), INCOMPLETE (a line that may have run twice or never), CLEAN."""
    m = a.metrics
    rejected = m["checksum_errors"] + m["line_number_errors"] + m["no_checksum_errors"]
    halted = m["finding_counts"].get("halted", 0)
    if m["twice_confirmed"] or m["never_confirmed"]:
        parts = [f"{m['twice_confirmed']} line(s) ran twice" if m["twice_confirmed"] else "",
                 f"{m['never_confirmed']} line(s) never ran" if m["never_confirmed"] else ""]
        return "HAZARD", " and ".join(p for p in parts if p) + \
            f" of {m['numbered']} numbered lines: the job on the machine is not the job sent."
    if m["twice_possible"] or m["never_possible"]:
        return "INCOMPLETE", (f"{m['twice_possible']} line(s) may have run twice and "
                              f"{m['never_possible']} may never have run: the capture cannot "
                              "tell (an ok that never came, or the capture ends first).")
    if rejected or m["storms"] or halted:
        what = [f"{m['checksum_errors']} checksum mismatch(es)" if m["checksum_errors"] else "",
                f"{m['line_number_errors']} line-number error(s)" if m["line_number_errors"]
                else "", f"{m['no_checksum_errors']} line(s) without a checksum"
                if m["no_checksum_errors"] else ""]
        text = f"the unit rejected {rejected} line(s) ({', '.join(w for w in what if w)}) " \
            f"and asked {m['resends']} time(s) for a resend" if rejected else ""
        if m["storms"]:
            text += ("; " if text else "") + f"{m['storms']} resend storm(s)"
        if halted:
            text += ("; " if text else "") + "the unit halted"
        tail = ("; every line was taken once in the end." if not halted else ".")
        return "ERROR", text[0].upper() + text[1:] + tail
    return "CLEAN", (f"{m['accepted']} of {m['host_lines']} lines taken, each once, and "
                     f"{m['oks']} ok answers; no line rejected.")


def figures(a: Any) -> list[tuple[str, str]]:
    """The session's figures in words: (what, value)."""
    m = a.metrics

    def ms(x: float | None) -> str:
        return "–" if x is None else f"{x:.1f}"

    rows = [
        ("lines the host sent", f"{m['host_lines']} ({m['numbered']} with a line number)"),
        ("lines the unit took", str(m["accepted"])),
        ("ok answers", str(m["oks"])),
        ("session length", f"{m['duration_s']:.3f} s ({m['lines_per_s']:.1f} lines a second)"),
        ("time from a line to its ok", f"median {ms(m['ok_p50_ms'])} ms, 95 % within "
         f"{ms(m['ok_p95_ms'])} ms, 99 % within {ms(m['ok_p99_ms'])} ms, longest "
         f"{ms(m['ok_max_ms'])} ms"),
        ("resend requests (Resend:)", f"{m['resends']} ({100 * m['resend_ratio']:.1f} % of "
         f"the numbered lines), {m['storms']} storm(s)"),
        ("lines rejected", f"{m['checksum_errors']} checksum mismatch, "
         f"{m['line_number_errors']} line number, {m['no_checksum_errors']} no checksum"),
        ("line numbers sent again", str(m["repeats"])),
        ("busy (busy: processing)", f"{m['busy_periods']} period(s), {m['busy_s']:.1f} s in all"),
        ("planner empty when a line was answered (ADVANCED_OK)", str(m["planner_empty"])),
        ("lines run twice", f"{m['twice_confirmed']} certain, {m['twice_possible']} possible"),
        ("lines never run", f"{m['never_confirmed']} certain, {m['never_possible']} possible"),
    ]
    return rows


def _span(ax: Any, a: Any) -> None:
    """Every plot over the whole session (the report's --time-range narrows it after)."""
    ax.set_xlim(0.0, max(float(a.metrics["duration_s"]), 1e-3))


def _xy(series: Any) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(series.t, float), np.asarray(series.y, float)


def latency_plot(a: Any) -> str | None:
    p = a.plotted
    if p is None or not p.latency.t:
        return None
    t, y = _xy(p.latency)
    fig, ax = new_figure()
    tt, yy = thin_points(t, y)
    ax.plot(tt, yy, ".", ms=2, label="line to its ok")
    if p.errors.t:
        et, _ = _xy(p.errors)
        ax.plot(et, np.full(len(et), np.nanmax(y) if len(y) else 0.0), "v", color="tab:red",
                ms=5, label="line rejected")
    _span(ax, a)
    return over_time(fig, ax, a, "ms", "Time from a line to its ok")


def resend_plot(a: Any) -> str | None:
    p = a.plotted
    if p is None or not p.resends.t:
        return None
    t, y = _xy(p.resends)
    fig, ax = new_figure(7.5, 2.6)
    ax.plot(t, y, "o", color="tab:red", ms=3, label="Resend: N (the line asked for)")
    _span(ax, a)
    return over_time(fig, ax, a, "line number", "The unit's resend requests")


def busy_plot(a: Any) -> str | None:
    p = a.plotted
    if p is None or not p.busy:
        return None
    fig, ax = new_figure(7.5, 1.8)
    ax.broken_barh([(s, max(e - s, 0.05)) for s, e in p.busy], (0, 1), color="tab:orange",
                   label="busy: processing")
    ax.set_yticks([])
    _span(ax, a)
    return over_time(fig, ax, a, "", "When the unit said busy (a command blocking)")


def in_flight_plot(a: Any) -> str | None:
    p = a.plotted
    if p is None or not p.in_flight.t:
        return None
    t, y = _xy(p.in_flight)
    fig, ax = new_figure(7.5, 2.6)
    tt, yy = thin_points(t, y)
    ax.step(tt, yy, where="post", lw=0.8, label="lines sent, not yet answered")
    ax.set_ylim(0, max(yy.max(), 1) + 1)
    ax.yaxis.get_major_locator().set_params(integer=True)
    _span(ax, a)
    return over_time(fig, ax, a, "lines", "Lines in flight when each line was sent")


def render_html(a: Any) -> str:
    from conform.analysis.report import severity_counts, template_env

    env = template_env(HERE)
    by_sev = severity_counts(a.findings)
    plots = {"latency": latency_plot(a), "resends": resend_plot(a), "busy": busy_plot(a),
             "in_flight": in_flight_plot(a)}
    word, sentence = verdict(a)
    return env.get_template("report.html.j2").render(
        a=a, m=a.metrics, by_sev=by_sev, plots=plots, verdict=word, sentence=sentence,
        figures=figures(a))
