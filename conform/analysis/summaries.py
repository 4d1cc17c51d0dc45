"""Mergeable summaries of a stream of numbers: bounded memory, exact while small.

The streaming analysis never holds a whole-capture column, so its metrics come from these:

* :class:`Quantiles` keeps count, sum, minimum and maximum exactly and, up to ``capacity``
  values, the values themselves (percentiles then exactly as ``numpy.quantile``). Past the
  capacity it moves to a histogram on a fixed logarithmic grid: 512 bins per factor e of
  magnitude from 1e-9 to 1e7 on each side of zero (|v| below 1e-9 counts as 0). A
  percentile from the grid is the geometric middle of its bin, clamped to the exact
  minimum and maximum: its relative error is at most 0.1 % (half a bin). Memory: at most
  ``capacity`` floats or two arrays of 18 900 counts.
* :class:`TimeBins` counts (or sums weights of) events on a grid of time bins that doubles
  its bin width when the span outgrows ``max_bins``; it keeps the events themselves while
  there are at most ``capacity`` of them, so a small capture's histograms over any edges are
  exact, and a long one's are re-binned from its bins (an event can land in the final bin
  next to its own, by at most one grid bin).
* :class:`Extremes` keeps, per grid bin, the count, minimum and maximum of a value over
  time: what the latency-over-time plot draws for a long capture.
"""

from __future__ import annotations

import numpy as np

EXACT_VALUES = 100_000  # values kept as they are before a summary moves to its grid
_PER_E = 512  # log-grid bins per factor e
_LO = np.log(1e-9)
_NBINS = int(np.ceil((np.log(1e7) - _LO) * _PER_E)) + 1


class Quantiles:
    """Count, sum, min, max and percentiles of a stream of numbers (see the module)."""

    def __init__(self, capacity: int = EXACT_VALUES) -> None:
        self.capacity = capacity
        self.n = 0
        self.total = 0.0
        self.lo = np.inf
        self.hi = -np.inf
        self.parts: list[np.ndarray] | None = []
        self.kept = 0
        self.pos: np.ndarray | None = None
        self.neg: np.ndarray | None = None
        self.zero = 0

    def add(self, values: np.ndarray) -> None:
        v = np.asarray(values, float)
        v = v[np.isfinite(v)]
        if len(v) == 0:
            return
        self.n += len(v)
        self.total += float(v.sum())
        self.lo = min(self.lo, float(v.min()))
        self.hi = max(self.hi, float(v.max()))
        if self.parts is not None:
            self.parts.append(v.copy())
            self.kept += len(v)
            if self.kept <= self.capacity:
                return
            v = np.concatenate(self.parts)
            self.parts = None
            self.pos = np.zeros(_NBINS, np.int64)
            self.neg = np.zeros(_NBINS, np.int64)
        self._bin(v)

    def _bin(self, v: np.ndarray) -> None:
        assert self.pos is not None and self.neg is not None
        a = np.abs(v)
        small = a < 1e-9
        self.zero += int(small.sum())
        idx = np.clip(((np.log(np.maximum(a, 1e-9)) - _LO) * _PER_E).astype(np.int64), 0,
                      _NBINS - 1)
        self.pos += np.bincount(idx[(v > 0) & ~small], minlength=_NBINS)
        self.neg += np.bincount(idx[(v < 0) & ~small], minlength=_NBINS)

    def values(self) -> np.ndarray:
        """Every value (only while exact)."""
        assert self.parts is not None
        return np.concatenate(self.parts) if self.parts else np.zeros(0)

    def mean(self) -> float:
        if self.parts is not None and self.n:
            return float(self.values().mean())  # numpy's summation, as over a column
        return self.total / self.n if self.n else float("nan")

    def quantile(self, qs: list[float]) -> list[float]:
        if self.n == 0:
            return [float("nan")] * len(qs)
        if self.parts is not None:
            return [float(x) for x in np.quantile(self.values(), qs)]
        assert self.pos is not None and self.neg is not None
        mids = np.exp(_LO + (np.arange(_NBINS) + 0.5) / _PER_E)
        vals = np.concatenate([-mids[::-1], [0.0], mids])
        counts = np.concatenate([self.neg[::-1], [self.zero], self.pos])
        cum = np.cumsum(counts)
        out = []
        for q in qs:
            rank = q * (self.n - 1)
            lo_i = int(np.searchsorted(cum, np.floor(rank), side="right"))
            hi_i = int(np.searchsorted(cum, np.ceil(rank), side="right"))
            frac = rank - np.floor(rank)
            x = vals[lo_i] * (1 - frac) + vals[hi_i] * frac
            out.append(float(min(max(x, self.lo), self.hi)))
        return out

    def nearest(self, qs: list[float]) -> list[float]:
        """Nearest-rank percentiles: the value at index ``min(n - 1, int(q * n))`` of the
        values in order. Exact while the values are kept; from the grid, the middle of the
        bin holding that rank, clamped to the exact minimum and maximum (within 0.1 %), the
        first and last rank being the exact minimum and maximum."""
        if self.n == 0:
            return [float("nan")] * len(qs)
        ranks = [min(self.n - 1, int(q * self.n)) for q in qs]
        if self.parts is not None:
            v = np.sort(self.values())
            return [float(v[k]) for k in ranks]
        vals, counts = self.grid()
        cum = np.cumsum(counts)
        out = []
        for k in ranks:
            x = self.lo if k == 0 else self.hi if k == self.n - 1 else \
                float(vals[int(np.searchsorted(cum, k, side="right"))])
            out.append(float(min(max(x, self.lo), self.hi)))
        return out

    def grid(self) -> tuple[np.ndarray, np.ndarray]:
        """(value, count) in ascending value: every value while exact, else the grid bins
        that hold anything (at their middles)."""
        if self.parts is not None:
            v = np.sort(self.values())
            return v, np.ones(len(v), np.int64)
        assert self.pos is not None and self.neg is not None
        mids = np.exp(_LO + (np.arange(_NBINS) + 0.5) / _PER_E)
        vals = np.concatenate([-mids[::-1], [0.0], mids])
        counts = np.concatenate([self.neg[::-1], [self.zero], self.pos])
        has = counts > 0
        return np.clip(vals[has], self.lo, self.hi), counts[has]

    def median(self) -> float:
        return self.quantile([0.5])[0]


class TimeBins:
    """Events (time, weight) for histograms over edges chosen at the end (see the module)."""

    def __init__(self, capacity: int = EXACT_VALUES, max_bins: int = 1 << 15,
                 width: float = 1e-3) -> None:
        self.capacity, self.max_bins, self.width = capacity, max_bins, width
        self.t: list[np.ndarray] | None = []
        self.w: list[np.ndarray] = []
        self.kept = 0
        self.origin: float | None = None
        self.bins = np.zeros(0)

    def add(self, t: np.ndarray, weight: np.ndarray | None = None) -> None:
        t = np.asarray(t, float)
        w = np.ones(len(t)) if weight is None else np.asarray(weight, float)
        ok = np.isfinite(t)
        t, w = t[ok], w[ok]
        if len(t) == 0:
            return
        if self.t is not None:
            self.t.append(t)
            self.w.append(w)
            self.kept += len(t)
            if self.kept <= self.capacity:
                return
            t, w = np.concatenate(self.t), np.concatenate(self.w)
            self.t, self.w = None, []
            self.origin = float(t.min())
        self._bin(t, w)

    def _bin(self, t: np.ndarray, w: np.ndarray) -> None:
        assert self.origin is not None
        if t.min() < self.origin:  # earlier than the grid: move the origin back
            shift = int(np.ceil((self.origin - t.min()) / self.width))
            self.bins = np.concatenate([np.zeros(shift), self.bins])
            self.origin -= shift * self.width
        idx = ((t - self.origin) / self.width).astype(np.int64)
        need = int(idx.max()) + 1
        while need > self.max_bins:  # coarser: merge pairs of bins
            if len(self.bins) % 2:
                self.bins = np.append(self.bins, 0.0)
            self.bins = self.bins.reshape(-1, 2).sum(axis=1)
            self.width *= 2
            idx //= 2
            need = int(idx.max()) + 1
        if need > len(self.bins):
            self.bins = np.concatenate([self.bins, np.zeros(need - len(self.bins))])
        self.bins += np.bincount(idx, weights=w, minlength=len(self.bins))

    def histogram(self, edges: np.ndarray) -> np.ndarray:
        if self.t is not None:
            if not self.t:
                return np.zeros(len(edges) - 1)
            h, _ = np.histogram(np.concatenate(self.t), bins=edges, weights=np.concatenate(self.w))
            return h
        assert self.origin is not None
        centres = self.origin + (np.arange(len(self.bins)) + 0.5) * self.width
        h, _ = np.histogram(np.clip(centres, edges[0], edges[-1]), bins=edges, weights=self.bins)
        return h

    def times(self) -> np.ndarray | None:
        """The events' times while they are all kept, else None."""
        return None if self.t is None else (np.concatenate(self.t) if self.t else np.zeros(0))


class Extremes:
    """Per time bin: count, minimum and maximum of a value (bins double as in TimeBins)."""

    def __init__(self, max_bins: int = 2048, width: float = 1e-2) -> None:
        self.max_bins, self.width = max_bins, width
        self.origin: float | None = None
        self.n = np.zeros(0, np.int64)
        self.lo = np.zeros(0)
        self.hi = np.zeros(0)

    def add(self, t: np.ndarray, v: np.ndarray) -> None:
        ok = np.isfinite(t) & np.isfinite(v)
        t, v = t[ok], v[ok]
        if len(t) == 0:
            return
        if self.origin is None:
            self.origin = float(t.min())
        if t.min() < self.origin:
            shift = int(np.ceil((self.origin - t.min()) / self.width))
            self._grow(shift, front=True)
            self.origin -= shift * self.width
        idx = ((t - self.origin) / self.width).astype(np.int64)
        while int(idx.max()) + 1 > self.max_bins:
            self._halve()
            idx //= 2
        need = int(idx.max()) + 1
        if need > len(self.n):
            self._grow(need - len(self.n))
        order = np.argsort(idx, kind="stable")
        idx, v = idx[order], v[order]
        first = np.flatnonzero(np.concatenate([[True], idx[1:] != idx[:-1]]))
        at = idx[first]
        self.n[at] += np.diff(np.append(first, len(idx)))
        self.lo[at] = np.minimum(self.lo[at], np.minimum.reduceat(v, first))
        self.hi[at] = np.maximum(self.hi[at], np.maximum.reduceat(v, first))

    def _grow(self, k: int, front: bool = False) -> None:
        parts = [(self.n, np.zeros(k, np.int64)), (self.lo, np.full(k, np.inf)),
                 (self.hi, np.full(k, -np.inf))]
        out = [np.concatenate([z, a] if front else [a, z]) for a, z in parts]
        self.n, self.lo, self.hi = out

    def _halve(self) -> None:
        if len(self.n) % 2:
            self._grow(1)
        self.n = self.n.reshape(-1, 2).sum(axis=1)
        self.lo = self.lo.reshape(-1, 2).min(axis=1)
        self.hi = self.hi.reshape(-1, 2).max(axis=1)
        self.width *= 2

    def series(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(bin start, count, min, max) of the bins that hold anything."""
        if self.origin is None:
            z = np.zeros(0)
            return z, z.astype(np.int64), z, z
        has = self.n > 0
        t = self.origin + np.arange(len(self.n)) * self.width
        return t[has], self.n[has], self.lo[has], self.hi[has]
