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

from conform.analysis.columns import isin
from conform.analysis.findings import Context, Findings

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


def check_positions(ctx: Context, unit: Any, rec: dict[str, np.ndarray],
                    out: Findings) -> dict[str, Any]:
    ex = ctx.ex
    name = ctx.name
    answered = ctx.status == "answered"
    clean = answered & (ex["answer_kind"].to_numpy() == "answer") & (ctx.code == 0)
    pos_rows = np.flatnonzero(isin(name, list(POSITION)) & clean)
    summary: dict[str, Any] = {"position_reports": int(len(pos_rows)), "checked": 0,
                               "confirmed_double": 0, "confirmed_lost": 0}
    if len(pos_rows) == 0:
        return summary
    mot_all = _Motion(ctx)
    reports: list[tuple[int, tuple[int, ...]]] = []
    for r in pos_rows.tolist():
        res = unit.result(int(ctx.answer[r]))
        try:
            vals = tuple(int(f) for f in res.fields[: POSITION[name[r]]])
        except (ValueError, AttributeError):
            continue
        if len(vals) == POSITION[name[r]]:
            reports.append((r, vals))
    # segments between resets; unreliable after H / D / K (motion cut short on purpose)
    zero = np.flatnonzero(clean & isin(name, ("N", "J", "N<axis>")))
    cut = np.flatnonzero(clean & isin(name, ("H", "D", "K")))
    at = np.union1d(pos_rows, zero)
    cum_at = mot_all.cum_at(at, rec["contrib"])
    cum = {int(r): cum_at[j] for j, r in enumerate(at.tolist())}
    doubles = np.concatenate([rec["doubles"], rec.get("checked_resends", np.zeros(0, np.int64))])
    checked_resends = set(rec.get("checked_resends", np.zeros(0, np.int64)).tolist())
    unclear = set(rec.get("unclear_resends", np.zeros(0, np.int64)).tolist())
    lost = rec["lost"]
    used: set[int] = set()
    prev_vals: tuple[int, ...] | None = None
    expected_prev = None
    adjust = np.zeros(4, np.int64)  # doubles and losses already confirmed in this segment
    seg = None
    for k, (r, vals) in enumerate(reports):
        nxt = reports[k + 1][1] if k + 1 < len(reports) else None
        stable = nxt == vals or nxt is None
        zi = np.searchsorted(zero, r) - 1
        z = int(zero[zi]) if zi >= 0 else -1
        base = cum[z] if z >= 0 else np.zeros(4, np.int64)
        if z >= 0 and name[z] == "N<axis>":
            stable = False  # the set value is not tracked here
        if z != seg:
            seg, adjust = z, np.zeros(4, np.int64)
        expected = (cum[r] - base + adjust)[: len(vals)]
        rep = np.asarray(vals)
        if prev_vals is not None and not any(rep) and any(expected) and \
                (expected_prev is None or any(expected_prev)) and any(prev_vals):
            out.add("reset", ctx.t[r], "warning",
                    f"`{ctx.cmd(r)}` reports {vals} where the vectors sent add up to "
                    f"{tuple(int(x) for x in expected)} and no N or J was sent: the unit "
                    "seems to have been reset (power-up?)", frames=ctx.frames(r), row=r,
                    cause="power-up")
        prev_vals, expected_prev = vals, expected
        if not stable or ((cut > z) & (cut < r)).any():
            continue
        summary["checked"] += 1
        delta = rep - expected
        cand_d = [int(x) for x in doubles if z < x < r and x not in used]
        cand_l = [int(x) for x in lost if z < x < r and x not in used]
        if not delta.any():
            used.update(cand_d + cand_l)
            continue
        found = _explain(delta, cand_d, cand_l, mot_all, len(vals))
        if found is None:
            out.add("position-mismatch", ctx.t[r], "warning",
                    f"`{ctx.cmd(r)}` reports {vals}; the accepted vectors add up to "
                    f"{tuple(int(x) for x in expected)} (off by "
                    f"{tuple(int(x) for x in delta)})", frames=ctx.frames(r), row=r,
                    delta=[int(x) for x in delta])
            continue
        dd, ll = found
        for d in dd:
            adjust += mot_all[d]
        for lv in ll:
            adjust -= mot_all[lv]
        for d in dd:
            used.add(d)
            if d in unclear:
                # the line before it was the same text: `>` cannot tell a resend from the
                # job's next identical vector, and neither can a position
                summary["possible_double"] = summary.get("possible_double", 0) + 1
                out.add("double-move", ctx.t[r], "hazard",
                        f"`{ctx.cmd(d)}` may have been executed twice: the sender asked `@`/`>` "
                        "and sent the same vector again, but with the same line just before "
                        "it neither the answers nor the position "
                        f"(`{ctx.cmd(r)}` reports {vals}) tell a resend from the job's next "
                        "identical vector", frames=[f"host:{d}"] + ctx.frames(r), row=d,
                        position_row=r, confirmed=False)
                continue
            summary["confirmed_double"] += 1
            how = (" The sender asked `@`/`>` before sending it again, but the unit had taken "
                   "the first copy." if d in checked_resends else "")
            out.add("double-move", ctx.t[r], "hazard",
                    f"`{ctx.cmd(d)}` was executed twice: `{ctx.cmd(r)}` reports {vals}, "
                    f"which is the job's position plus that vector once more.{how}",
                    frames=[f"host:{d}"] + ctx.frames(r), row=d, position_row=r,
                    confirmed=True)
        for lv in ll:
            used.add(lv)
            summary["confirmed_lost"] += 1
            why = (f" Confirmed: `{ctx.cmd(r)}` reports {vals}, the job's position less "
                   "that vector.")
            for f in out.items:
                if f.kind == "lost-vector" and f.row == lv:
                    f.message += why
                    f.extra["confirmed"] = True
                    f.extra["position_row"] = r
                    f.frames += ctx.frames(r)
                    break
            else:
                out.add("lost-vector", ctx.t[r], "hazard",
                        f"`{ctx.cmd(lv)}` was never executed.{why}",
                        frames=[f"host:{lv}"] + ctx.frames(r), row=lv, position_row=r,
                        confirmed=True)
    return summary


def _explain(delta: np.ndarray, doubles: list[int], lost: list[int], motion: _Motion,
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
