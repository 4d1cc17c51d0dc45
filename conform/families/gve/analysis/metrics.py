"""Session metrics gathered a window of exchanges at a time (``summaries``).

Counts, sums, minima and maxima are exact; latency percentiles are exact up to
``summaries.EXACT_VALUES`` answered exchanges and within 0.1 % beyond; the time series
(exchanges, vectors and bytes per second) are exact while the capture is small and
re-binned from a fine grid (``summaries.TimeBins``) when it is long.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from conform.analysis.summaries import Extremes, Quantiles, TimeBins

LATENCY = ("rtt", "unit_time", "host_time", "wire_cmd", "wire_ans")
ERROR_CODES = (2, 3, 4, 5, 6, 7)


def _line_bytes(d: Any) -> np.ndarray:
    return d.lines.end - d.lines.start + d.lines.term


class Metrics:
    """What ``compute`` reports, fed window by window (``feed_rows`` / ``feed_lines``)."""

    def __init__(self) -> None:
        self.t0 = np.inf
        self.t_end = -np.inf
        self.frames = {"host": 0, "unit": 0}
        self.n_ex = self.commands = self.n_vec = 0
        self.hb = self.ub = 0
        self.status: dict[str, int] = {}
        self.codes: dict[int, int] = {}
        self.lat = {c: Quantiles() for c in LATENCY}
        self.by_cmd: dict[str, list[Any]] = {}  # name -> [count, Quantiles of rtt]
        self.answered_t, self.vector_t = TimeBins(), TimeBins()
        self.host_bytes_t, self.unit_bytes_t = TimeBins(), TimeBins()
        self.t_cmd_lo, self.t_cmd_hi = np.inf, -np.inf
        self.slope: dict[int, Quantiles] = {}  # answer length -> answer time after the command
        self.rtt_t = Extremes()  # round trip over time: per bin count, min, max
        self.errors_t, self.bad_t = TimeBins(), TimeBins()

    def feed_lines(self, d: Any) -> None:
        """Decoded lines of one direction (each line once over the capture)."""
        self.frames[d.direction] += len(d)
        if len(d) == 0:
            return
        tf = d.t_first[np.isfinite(d.t_first)]
        if len(tf):
            self.t0 = min(self.t0, float(tf.min()))
        tl = d.t_last[~np.isnan(d.t_last)]
        if len(tl):
            self.t_end = max(self.t_end, float(tl.max()))
        nb = _line_bytes(d)
        if d.direction == "unit":
            self.ub += int(nb.sum())
            self.unit_bytes_t.add(d.t_last, nb)
        else:
            self.host_bytes_t.add(d.t_last, nb)

    def feed_rows(self, ex: pd.DataFrame, accepted: np.ndarray) -> None:
        """Exchange rows (each row once over the capture) and which vectors were taken."""
        status = ex["status"].to_numpy()
        answered = status == "answered"
        self.n_ex += int(answered.sum())
        self.commands += len(ex)
        self.n_vec += int(accepted.sum())
        self.hb += int(ex["cmd_bytes"].sum())
        for k, v in pd.Series(status, dtype=object).value_counts(sort=False).items():
            self.status[str(k)] = self.status.get(str(k), 0) + int(v)
        codes = ex["code"].to_numpy()[answered]
        for k in np.unique(codes).tolist():
            self.codes[int(k)] = self.codes.get(int(k), 0) + int((codes == k).sum())
        for c in LATENCY:
            self.lat[c].add(ex[c].to_numpy()[answered])
        rtt = ex["rtt"].to_numpy()[answered]
        which, uniq = pd.factorize(ex["name"].to_numpy()[answered])  # None: -1, left out
        if len(uniq):
            order = np.argsort(which, kind="stable")
            bounds = np.searchsorted(which[order], np.arange(len(uniq) + 1))
            for j, k in enumerate(uniq):
                g = rtt[order[bounds[j] : bounds[j + 1]]]
                entry = self.by_cmd.setdefault(str(k), [0, Quantiles()])
                entry[0] += len(g)
                entry[1].add(g)
        t_cmd = ex["t_cmd_first"].to_numpy()
        self.answered_t.add(t_cmd[answered])
        self.vector_t.add(ex["t_cmd_last"].to_numpy()[accepted])
        fin = t_cmd[np.isfinite(t_cmd)]
        if len(fin):
            self.t_cmd_lo = min(self.t_cmd_lo, float(fin.min()))
            self.t_cmd_hi = max(self.t_cmd_hi, float(fin.max()))
        y = (ex["t_ans_last"].to_numpy() - ex["t_cmd_last"].to_numpy())[answered]
        x = ex["ans_bytes"].to_numpy()[answered]
        for length in np.unique(x).tolist():
            self.slope.setdefault(int(length), Quantiles()).add(y[x == length])
        self.rtt_t.add(t_cmd[answered], rtt * 1000)
        code = ex["code"].to_numpy()
        err = answered & np.isfinite(ex["rtt"].to_numpy()) & np.isin(code, ERROR_CODES)
        self.errors_t.add(t_cmd[err])
        bad = np.isfinite(t_cmd) & ((status == "unanswered")
                                   | (ex["answer_kind"].to_numpy() == "garbled"))
        self.bad_t.add(t_cmd[bad])

    def start(self) -> float:
        return float(self.t0) if np.isfinite(self.t0) else 0.0

    def end(self) -> float:
        return float(self.t_end) if np.isfinite(self.t0) else 0.0

    def slope_baud(self) -> float | None:
        """The baud from how answer time grows with answer length (10 bits a byte)."""
        if self.n_ex < 10:
            return None
        pts = [(length, q.quantile([0.05])[0]) for length, q in sorted(self.slope.items())
               if q.n >= 3]
        if len(pts) < 2 or pts[-1][0] - pts[0][0] < 3:
            return None
        px, py = np.array(pts).T
        slope = np.polyfit(px, py, 1)[0]
        if slope <= 0:
            return None
        return 10.0 / slope

    def compute(self, baud: float | None, replay: Any) -> tuple[dict[str, Any], pd.DataFrame]:
        t0 = self.start()
        duration = max(self.end() - t0, 1e-9)
        hb, ub = self.hb, self.ub
        m: dict[str, Any] = {
            "duration_s": duration,
            "frames": dict(self.frames),
            "exchanges": self.n_ex,
            "commands": self.commands,
            "vectors_accepted": self.n_vec,
            "exchanges_per_s": self.n_ex / duration,
            "vectors_per_s": self.n_vec / duration,
            "bytes": {"host": hb, "unit": ub},
            "bytes_per_s": {"host": hb / duration, "unit": ub / duration},
            "utilisation": {"host": hb * 10 / baud / duration if baud else None,
                            "unit": ub * 10 / baud / duration if baud else None},
            "status": dict(sorted(self.status.items(), key=lambda kv: -kv[1])),
            "codes": dict(sorted(self.codes.items(), key=lambda kv: -kv[1])),
        }
        lat = {}
        for col in LATENCY:
            q = self.lat[col]
            if q.n:
                p = q.quantile([0.5, 0.95, 0.99])
                lat[col] = {"median": p[0], "p95": p[1], "p99": p[2], "max": q.hi,
                            "mean": q.mean()}
        m["latency"] = lat
        m["latency_by_command"] = {
            k: {"n": n, "median": q.median() if q.n else float("nan"),
                "max": q.hi if q.n else float("nan")}
            for k, (n, q) in sorted(self.by_cmd.items())}
        nb = int(min(600, max(10, duration)))
        edges = np.linspace(t0, t0 + duration, nb + 1)
        width = duration / nb   # the bins are equal: a capture's end may sit at t0 in floats
        series = pd.DataFrame({
            "t": edges[:-1] - t0,
            "exchanges_per_s": self.answered_t.histogram(edges) / width,
            "vectors_per_s": self.vector_t.histogram(edges) / width,
            "host_bytes_per_s": self.host_bytes_t.histogram(edges) / width,
            "unit_bytes_per_s": self.unit_bytes_t.histogram(edges) / width,
        })
        if baud:
            series["utilisation_host"] = series["host_bytes_per_s"] * 10 / baud
            series["utilisation_unit"] = series["unit_bytes_per_s"] * 10 / baud
        if replay is not None:
            series["supplied_per_s"] = replay.supply.histogram(edges) / width
            series["consumed_per_s"] = replay.consume.histogram(edges) / width
        return m, series
