"""Reported positions against what the sender's vectors add up to.

Vectors are relative (GVE64 §13.5.2), so the position counters are the sum of every vector
the unit executed since the last ``N`` / ``J``. Where the unit reports a position at rest
(``P``/``PF``/``P4`` answered twice the same, or last), the difference from the sum of the
vectors the sender meant to move either is zero, or is explained by the uncertain vectors:
one sent again blindly and executed twice (``double-move``), one given up and never
executed (``lost-vector``). A jump to zero with no ``N`` or ``J`` is a power-up (``reset``).
"""

from __future__ import annotations

from itertools import combinations
from typing import Any

import numpy as np

from conform.families.gve.analysis.columns import isin
from conform.families.gve.analysis.findings import Context

POSITION = {"P": 2, "PF": 3, "P4": 4}


CUM_BLOCK = 65_536  # motion units summed at a time (bounded temporaries)


class _Motion:
    """Per row, the motion it delivers (a vector's pulses, a packet's sum at its ``*E``),
    looked up in the motion units: no (rows, 4) matrix of the whole table."""

    def __init__(self, ctx: Context) -> None:
        mu = ctx.motion_units()
        self.rows = mu["row"].to_numpy()
        self.cols = [mu[c].to_numpy() for c in ("s0", "s1", "s2", "s3")]

    def __getitem__(self, r: int) -> np.ndarray:
        i = int(np.searchsorted(self.rows, r))
        if i < len(self.rows) and self.rows[i] == r:
            return np.array([int(c[i]) for c in self.cols], np.int64)
        return np.zeros(4, np.int64)

    def cum_at(self, at: np.ndarray, weight: np.ndarray) -> np.ndarray:
        """(len(at), 4): the motion of the rows ``<= at[j]`` that ``weight`` keeps, for
        sorted ``at``, summed a block of units at a time."""
        acc = np.zeros((len(at) + 1, 4), np.int64)
        for lo in range(0, len(self.rows), CUM_BLOCK):
            rows = self.rows[lo : lo + CUM_BLOCK]
            w = weight[rows].astype(np.int64)
            bucket = np.searchsorted(at, rows, side="left")
            u, first = np.unique(bucket, return_index=True)
            for j, c in enumerate(self.cols):
                acc[u, j] += np.add.reduceat(c[lo : lo + CUM_BLOCK] * w, first)
        return np.cumsum(acc[:-1], axis=0)


class _Report:
    """A position report waiting for the next one (which says whether it was at rest)."""

    def __init__(self, row: int, vals: tuple[int, ...], t: float, text: str,
                 frames: list[str], cum: np.ndarray, zero: tuple | None, cut_after: int
                 ) -> None:
        self.row, self.vals, self.t, self.text, self.frames = row, vals, t, text, frames
        self.cum, self.zero, self.cut_after = cum, zero, cut_after


class PositionCheck:
    """Reported positions against the vectors, fed a window of rows at a time.

    Carried: the running sum of the motion the sender meant (``contrib``), the last reset
    (``N``/``J``) with the sum at it, the last H/D/K, the doubled and lost candidates of the
    current segment with their motion and text, and the last report (its stability is known
    at the next one).
    """

    def __init__(self) -> None:
        self.summary: dict[str, Any] = {"position_reports": 0, "checked": 0,
                                        "confirmed_double": 0, "confirmed_lost": 0}
        self.cum = np.zeros(4, np.int64)
        self.zero: tuple[int, np.ndarray, str] | None = None  # (row, cum at it, name)
        self.last_cut = -1
        self.doubles: list[int] = []
        self.checked: list[int] = []
        self.lost: list[int] = []
        self.checked_set: set[int] = set()
        self.unclear: set[int] = set()
        self.motion: dict[int, np.ndarray] = {}
        self.text: dict[int, str] = {}
        self.used: set[int] = set()
        self.prev_vals: tuple[int, ...] | None = None
        self.expected_prev: np.ndarray | None = None
        self.adjust = np.zeros(4, np.int64)
        self.seg: int | None = None
        self.pending: _Report | None = None

    def feed(self, ctx: Context, unit: Any, rec: dict[str, np.ndarray], out: Any,
             lo: int, hi: int, base: int) -> None:
        """Rows ``lo:hi`` of ``ctx.ex`` (row 0 is the capture's row ``base``); ``unit``'s
        ``result(i)`` reads the answer ``ctx.answer[r]``; ``out`` numbers the capture."""
        ex = ctx.ex
        name = ctx.name
        own = np.zeros(len(ex), bool)
        own[lo:hi] = True
        answered = ctx.status == "answered"
        clean = answered & (ex["answer_kind"].to_numpy() == "answer") & (ctx.code == 0)
        pos_rows = np.flatnonzero(isin(name, list(POSITION)) & clean & own)
        zero = np.flatnonzero(clean & isin(name, ("N", "J", "N<axis>")) & own)
        cut = np.flatnonzero(clean & isin(name, ("H", "D", "K")) & own)
        mot = _Motion(ctx)
        units = (mot.rows >= lo) & (mot.rows < hi)
        for key, lst in (("doubles", self.doubles), ("checked_resends", self.checked),
                         ("lost", self.lost)):
            for r in rec.get(key, np.zeros(0, np.int64)).tolist():
                lst.append(r + base)
                self.motion[r + base] = mot[r]
                self.text[r + base] = ctx.cmd(r)
        self.checked_set.update(int(r) + base for r in rec.get("checked_resends", []))
        self.unclear.update(int(r) + base for r in rec.get("unclear_resends", []))
        self.summary["position_reports"] += len(pos_rows)
        at = np.union1d(pos_rows, zero)
        w = rec["contrib"].copy()
        w[~own] = False
        sel = np.flatnonzero(units)
        mot_own = _Motion.__new__(_Motion)
        mot_own.rows = mot.rows[sel]
        mot_own.cols = [c[sel] for c in mot.cols]
        cum_at = mot_own.cum_at(at, w) + self.cum
        if len(sel):
            self.cum = self.cum + np.array(
                [int((c * w[mot_own.rows]).sum()) for c in mot_own.cols], np.int64)
        cum = {int(r): cum_at[j] for j, r in enumerate(at.tolist())}
        events = sorted([(int(r), 0) for r in zero.tolist()] + [(int(r), 1) for r in pos_rows.tolist()]
                        + [(int(r), 2) for r in cut.tolist()])
        for r, what in events:
            if what == 0:
                self.zero = (r + base, cum[r], str(name[r]))
            elif what == 2:
                self.last_cut = r + base
            else:
                res = unit.result(int(ctx.answer[r]))
                try:
                    vals = tuple(int(f) for f in res.fields[: POSITION[name[r]]])
                except (ValueError, AttributeError):
                    continue
                if len(vals) != POSITION[name[r]]:
                    continue
                frames = [f"host:{r + base}"] + (
                    [f"unit:{int(ctx.answer[r]) + ctx.unit_base}"] if ctx.answer[r] >= 0 else [])
                rep = _Report(r + base, vals, float(ctx.t[r]), ctx.cmd(r), frames, cum[r],
                              self.zero, self.last_cut)
                if self.pending is not None:
                    self._judge(self.pending, rep.vals, out)
                self.pending = rep

    def finish(self, out: Any) -> dict[str, Any]:
        if self.pending is not None:
            self._judge(self.pending, None, out)
            self.pending = None
        return self.summary

    def _judge(self, rp: _Report, nxt: tuple[int, ...] | None, out: Any) -> None:
        r, vals = rp.row, rp.vals
        stable = nxt == vals or nxt is None
        z = rp.zero[0] if rp.zero is not None else -1
        base = rp.zero[1] if rp.zero is not None else np.zeros(4, np.int64)
        if rp.zero is not None and rp.zero[2] == "N<axis>":
            stable = False  # the set value is not tracked here
        if z != self.seg:
            self.seg, self.adjust = z, np.zeros(4, np.int64)
            keep = lambda lst: [x for x in lst if x > z]  # noqa: E731 - before z: never again
            self.doubles, self.checked, self.lost = (keep(self.doubles), keep(self.checked),
                                                     keep(self.lost))
        expected = (rp.cum - base + self.adjust)[: len(vals)]
        rep = np.asarray(vals)
        pv, ep = self.prev_vals, self.expected_prev
        if pv is not None and not any(rep) and any(expected) and \
                (ep is None or any(ep)) and any(pv):
            out.add("reset", rp.t, "warning",
                    f"`{rp.text}` reports {vals} where the vectors sent add up to "
                    f"{tuple(int(x) for x in expected)} and no N or J was sent: the unit "
                    "seems to have been reset (power-up?)", frames=list(rp.frames), row=r,
                    cause="power-up")
        self.prev_vals, self.expected_prev = vals, expected
        if not stable or rp.cut_after > z:
            return
        self.summary["checked"] += 1
        delta = rep - expected
        doubles = self.doubles + self.checked
        cand_d = [int(x) for x in doubles if z < x < r and x not in self.used]
        cand_l = [int(x) for x in self.lost if z < x < r and x not in self.used]
        if not delta.any():
            self.used.update(cand_d + cand_l)
            return
        found = _explain(delta, cand_d, cand_l, self.motion, len(vals))
        if found is None:
            out.add("position-mismatch", rp.t, "warning",
                    f"`{rp.text}` reports {vals}; the accepted vectors add up to "
                    f"{tuple(int(x) for x in expected)} (off by "
                    f"{tuple(int(x) for x in delta)})", frames=list(rp.frames), row=r,
                    delta=[int(x) for x in delta])
            return
        dd, ll = found
        for d in dd:
            self.adjust = self.adjust + self.motion[d]
        for lv in ll:
            self.adjust = self.adjust - self.motion[lv]
        for d in dd:
            self.used.add(d)
            if d in self.unclear:
                # the line before it was the same text: `>` cannot tell a resend from the
                # job's next identical vector, and neither can a position
                self.summary["possible_double"] = self.summary.get("possible_double", 0) + 1
                out.add("double-move", rp.t, "hazard",
                        f"`{self.text[d]}` may have been executed twice: the sender asked "
                        "`@`/`>` and sent the same vector again, but with the same line just "
                        "before it neither the answers nor the position "
                        f"(`{rp.text}` reports {vals}) tell a resend from the job's next "
                        "identical vector", frames=[f"host:{d}"] + rp.frames, row=d,
                        position_row=r, confirmed=False)
                continue
            self.summary["confirmed_double"] += 1
            how = (" The sender asked `@`/`>` before sending it again, but the unit had taken "
                   "the first copy." if d in self.checked_set else "")
            out.add("double-move", rp.t, "hazard",
                    f"`{self.text[d]}` was executed twice: `{rp.text}` reports {vals}, "
                    f"which is the job's position plus that vector once more.{how}",
                    frames=[f"host:{d}"] + rp.frames, row=d, position_row=r,
                    confirmed=True)
        for lv in ll:
            self.used.add(lv)
            self.summary["confirmed_lost"] += 1
            why = (f" Confirmed: `{rp.text}` reports {vals}, the job's position less "
                   "that vector.")
            for f in out.items:
                if f.kind == "lost-vector" and f.row == lv:
                    f.message += why
                    f.extra["confirmed"] = True
                    f.extra["position_row"] = r
                    f.frames += rp.frames
                    break
            else:
                out.add("lost-vector", rp.t, "hazard",
                        f"`{self.text[lv]}` was never executed.{why}",
                        frames=[f"host:{lv}"] + rp.frames, row=lv, position_row=r,
                        confirmed=True)


def _explain(delta: np.ndarray, doubles: list[int], lost: list[int], motion: Any,
             naxes: int) -> tuple[list[int], list[int]] | None:
    """A small set of doubled and lost vectors whose sum is ``delta``, if there is one."""
    mot = {r: motion[r][:naxes] for r in set(doubles) | set(lost)}
    items = [(r, 1) for r in doubles] + [(r, -1) for r in lost]
    if len(items) > 16:
        sign = [s for _, s in items]
        total = sum(mot[r] * s for r, s in items)
        if np.array_equal(total, delta):
            return doubles, lost
        del sign
        items = items[:16]
    for size in range(1, min(len(items), 4) + 1):
        for combo in combinations(items, size):
            total = np.zeros(len(delta), np.int64)
            for r, s in combo:
                total = total + mot[r] * s
            if np.array_equal(total, delta):
                return [r for r, s in combo if s > 0], [r for r, s in combo if s < 0]
    if items:
        total = sum(mot[r] * s for r, s in items)
        if np.array_equal(total, delta):
            return doubles, lost
    return None
