"""Findings: what a session did wrong (or right), each tied to the manual clause it concerns.

Every finding has a stable ``kind``, a time (seconds from the start of the capture), a
severity, the frames it refers to (``host:<line>`` / ``unit:<line>``) and a message. The
severities: ``info`` (good practice, notable events), ``warning`` (cost or link trouble),
``error`` (the sender broke a protocol rule), ``hazard`` (the machine may have moved other
than the job says). A careful sender on a clean or noisy line produces no ``hazard``.
Detectors are vectorised over the exchange table; only the rows they report are visited in
Python, and each kind lists at most ``MAX_LISTED`` rows (the metrics keep the full counts).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from conform.analysis.result import Finding as BaseFinding
from conform.families.gve.analysis.columns import AXES, isin, packet_numbers, vectors
from conform.families.gve.analysis.frames import ANSWER, CS_BAD, CS_MISSING, ECHO, GARBLED, PARTIAL

MAX_LISTED = 50
SEVERITIES = ("info", "warning", "error", "hazard")
HAZARDS = ("blind-resend", "double-move", "lost-vector")
MOTION = ("C", "L")

CLAUSES = {
    "simplex-violation": "GVE64 §13.3 (strictly simplex: wait for the answer)",
    "checksum-error": "GVE64 §13.3.2 (checksums)",
    "garbled-answer": "GVE64 §13.7 (answer: hex digit, fields, CR)",
    "error-code": "GVE64 §13.7 (error codes)",
    "queue-full-polling": "GVE64 §13.5.2, §13.7 code 1 (vector not accepted, send again)",
    "repeat-used": "GVE64 §13.5.13 (`>` repeats the last command and its answer)",
    "index-checked": "GVE64 §13.5.13 (`@` index of the last command)",
    "blind-resend": "GVE64 §13.5.13 (`@` / `>` tell whether a vector arrived)",
    "double-move": "GVE64 §13.5.2 (relative vectors: executed twice moves twice)",
    "lost-vector": "GVE64 §13.5.2, §13.7 (a vector not accepted is not executed)",
    "long-wait": "GVE64 §13.3, §13.5.9 (HALT and W answer when the motion has ended)",
    "reset": "GVE64 §13.4 (reset state: position, checksums, modal values)",
    "starvation": "GVE64 §13.5.3 (C vectors join at B only if the next one is queued)",
    "no-answer": "GVE64 §13.3 (the unit answers every command)",
    "unsolicited-answer": "GVE64 §13.3 (answers come only after commands)",
    "garbage-sent": "GVE64 §13.5 (command: `!`, address, mnemonic)",
    "baud-mismatch": "GVE64 §13.3 (baud rate by DIP switch)",
    "capture-damaged": "docs/capture-format.md",
    "position-mismatch": "GVE64 §13.5.6 (P, PF, P4 report the position counters)",
}


@dataclass
class Finding(BaseFinding):
    """The engine's finding with the frames it rests on, its row of the frames table and
    how many it stands for (an "… and N more" finding)."""

    frames: list[str] = field(default_factory=list)
    row: int | None = None
    count: int = 1


class Findings:
    """Collects findings, keeping the full count of each kind but listing at most a few.

    Times are given absolute and made relative to ``t0`` by ``finish`` (a stream knows its
    start only at the end). ``many`` lists at most ``limit`` rows per kind and call site
    over the whole capture, however many calls (windows) feed it; the rest are counted and
    summed up in one "… and N more" finding per site.
    """

    def __init__(self, t0: float = 0.0) -> None:
        self.t0 = t0
        self.items: list[Finding] = []
        self.counts: dict[str, int] = {}
        self.listed: dict[tuple[str, str], int] = {}
        self.more: dict[tuple[str, str], list[Any]] = {}  # site -> [severity, after, count]
        self.last: dict[tuple[str, str], Finding] = {}  # the last finding listed per site
        self.finished = False

    def add(self, kind: str, t: float, severity: str, message: str, *,
            frames: list[str] | None = None, row: int | None = None, count: int = 1,
            listed: bool = True, **extra: Any) -> None:
        assert severity in SEVERITIES, severity
        self.counts[kind] = self.counts.get(kind, 0) + count
        if not listed:
            return
        self.items.append(Finding(kind, float(t), severity, message, CLAUSES.get(kind, ""),
                                  extra, frames=frames or [], row=row, count=count))

    def many(self, kind: str, rows: np.ndarray, severity: str, make: Any,
             limit: int = MAX_LISTED, side: str | None = None) -> None:
        """One finding per row, listing the first ``limit`` of this kind and call site;
        ``make(row) -> (t, msg, frames, extra)``; ``side``: see ``Shifted``."""
        site = (kind, getattr(make, "__qualname__", ""))
        for r in np.asarray(rows).tolist():
            n = self.listed.get(site, 0)
            if n >= limit:
                self.counts[kind] = self.counts.get(kind, 0) + 1
                self.more.setdefault(site, [severity, self.last.get(site), 0])[2] += 1
                continue
            t, msg, frames, extra = make(r)
            row = int(extra.pop("row", r))
            self.add(kind, t, severity, msg, frames=frames, row=row, **extra)
            self.listed[site] = n + 1
            self.last[site] = self.items[-1]

    def finish(self, t0: float) -> None:
        """Times relative to ``t0``; the "… and N more" findings added."""
        if self.finished:
            return
        self.t0 = t0
        for f in self.items:
            f.t = round(float(f.t - t0), 6) if f.t == f.t else float("nan")
        for (kind, _), (severity, after, n) in self.more.items():
            t = after.t if after is not None else 0.0
            self.items.insert(self.items.index(after) + 1 if after is not None else 0,
                              Finding(kind, t, severity, f"… and {n} more like these",
                                      CLAUSES.get(kind, ""), count=n))
        self.finished = True

    def sorted(self) -> list[Finding]:
        return sorted(self.items, key=lambda f: (f.t if f.t == f.t else 0.0, f.kind))

    def hazards(self) -> list[Finding]:
        return [f for f in self.items if f.severity == "hazard"]


class Shifted:
    """A window's view of the capture's :class:`Findings`: detectors number rows and unit
    lines within the table they are given; this adds the window's bases (``host:N``,
    ``unit:N``, ``row`` and ``*_row`` fields) and drops the rows the window does not own
    (``own_host`` / ``own_unit``: masks over the window's rows and unit lines)."""

    def __init__(self, out: Findings, host_base: int, unit_base: int,
                 own_host: np.ndarray, own_unit: np.ndarray) -> None:
        self.out, self.hb, self.ub = out, host_base, unit_base
        self.own_host, self.own_unit = own_host, own_unit

    def _frames(self, frames: list[str]) -> list[str]:
        out = []
        for f in frames:
            side, _, n = f.partition(":")
            out.append(f"{side}:{int(n) + (self.hb if side == 'host' else self.ub)}")
        return out

    def _extra(self, extra: dict[str, Any]) -> dict[str, Any]:
        return {k: (v + self.hb if k.endswith("_row") and isinstance(v, int) else v)
                for k, v in extra.items()}

    def add(self, kind: str, t: float, severity: str, message: str, *,
            frames: list[str] | None = None, row: int | None = None, **extra: Any) -> None:
        self.out.add(kind, t, severity, message, frames=self._frames(frames or []),
                     row=None if row is None else row + self.hb, **self._extra(extra))

    def many(self, kind: str, rows: np.ndarray, severity: str, make: Any,
             limit: int = MAX_LISTED, side: str | None = None) -> None:
        rows = np.asarray(rows, np.int64)
        if side is not None:
            rows = rows[(self.own_host if side == "host" else self.own_unit)[rows]]

        def shifted(r: int) -> tuple:
            t, msg, frames, extra = make(r)
            extra["row"] = int(extra.get("row", r)) + (self.ub if side == "unit" else self.hb)
            return t, msg, self._frames(frames), self._extra(extra)

        shifted.__qualname__ = getattr(make, "__qualname__", "")
        self.out.many(kind, rows, severity, shifted, limit)


def _fr(side: str, i: int) -> str:
    return f"{side}:{int(i)}"


class Context:
    """What the detectors share: the exchange table and how to print a row."""

    def __init__(self, ex: pd.DataFrame, host_text: Any, unit_text: Any, baud: float | None,
                 errors: dict[int, Any]) -> None:
        self.ex = ex
        self.host_text = host_text
        self.unit_text = unit_text
        self.baud = baud
        self.errors = errors
        self.name = ex["name"].to_numpy()
        self.status = ex["status"].to_numpy()
        self.code = ex["code"].to_numpy()
        self.t = ex["t_cmd_first"].to_numpy()
        self.answer = ex["answer_frame"].to_numpy()
        self.base = 0  # the capture's number of row 0 (a window of a stream)
        self.unit_base = 0  # and of unit line 0
        self._units: pd.DataFrame | None = None

    def motion_units(self) -> pd.DataFrame:
        """``motion_units(ex)``, worked out once for every detector that needs it."""
        if self._units is None:
            self._units = motion_units(self.ex)
        return self._units

    def cmd(self, r: int) -> str:
        return self.host_text(int(r))

    def ans(self, r: int) -> str:
        a = int(self.answer[r])
        return self.unit_text(a) if a >= 0 else "(no answer)"

    def frames(self, r: int) -> list[str]:
        out = [_fr("host", r)]
        if self.answer[r] >= 0:
            out.append(_fr("unit", self.answer[r]))
        return out


def motion_units(ex: pd.DataFrame) -> pd.DataFrame:
    """Rows that deliver motion: single vectors and whole packets (their ``*E`` row).

    ``sig`` identifies the content (same vector or same packet content = same signature).
    """
    name = ex["name"].to_numpy()
    packet = packet_numbers(ex)
    role = ex["packet_role"].to_numpy()
    single = isin(name, MOTION) & (packet < 0) & (ex["kind"].to_numpy() == "command")
    end = role == "end"
    rows = np.flatnonzero(single | end)
    # column by column: no (units, 6) matrix and no consolidated copy of one
    cols = {f"s{j}": ex[c].to_numpy()[rows].astype(np.int64, copy=False) for j, c in enumerate(AXES)}
    cols["s4"] = np.where(name[rows] == "L", 1, 0)
    cols["s5"] = np.zeros(len(rows), np.int64)
    if end.any():
        members = (role == "member") & isin(name, MOTION)
        vec = vectors(ex, np.flatnonzero(members))
        pk = packet[members]
        npk = int(packet.max()) + 1
        cnt = np.bincount(pk, minlength=npk)
        ends = np.flatnonzero(end[rows])
        p = packet[rows[ends]]
        for j in range(4):
            sums = np.bincount(pk, weights=vec[:, j], minlength=npk).astype(np.int64)
            cols[f"s{j}"][ends] = sums[p]
        cols["s5"][ends] = cnt[p] + 1000  # never equal to a single vector's signature
    return pd.DataFrame({"row": rows, **cols}, copy=False)


def recovery_analysis(ctx: Context, out: Findings, decide: np.ndarray | None = None,
                      polls: QueueFull | None = None) -> dict[str, np.ndarray]:
    """blind-resend, lost-vector (possible), index-checked, repeat-used, queue-full polling.

    ``decide`` (per motion unit): the units to judge now, in a window of a stream (the
    others were judged before or wait for the unit after them); ``polls`` gathers the
    queue-full polls over the windows (without it they are reported at once)."""
    ex = ctx.ex
    mu = ctx.motion_units()
    rows = mu["row"].to_numpy()
    dec = np.ones(len(rows), bool) if decide is None else decide
    uncertain = ex["uncertain"].to_numpy()
    name = ctx.name
    expects = isin(ctx.status, ("answered", "unanswered"))
    is_rec = expects & isin(name, ("@", ">"))
    cum_rec = np.cumsum(is_rec)
    res: dict[str, np.ndarray] = {"doubles": np.zeros(0, np.int64),
                                  "checked_resends": np.zeros(0, np.int64),
                                  "unclear_resends": np.zeros(0, np.int64),
                                  "lost": np.zeros(0, np.int64),
                                  "contrib": np.zeros(len(ex), bool),
                                  "recovered": np.zeros(len(ex), bool)}
    if len(rows) == 0:
        _repeat_used(ctx, out, uncertain, is_rec)
        return res
    nxt = np.concatenate([rows[1:], [-1]])
    same_next = np.zeros(len(rows), bool)
    same_next[:-1] = True
    for c in ("s0", "s1", "s2", "s3", "s4", "s5"):  # the same signature, a column at a time
        col = mu[c].to_numpy()
        same_next[:-1] &= col[1:] == col[:-1]
    rec_between = np.zeros(len(rows), bool)
    rec_between[:-1] = cum_rec[rows[1:]] - cum_rec[rows[:-1]] > 0
    # after the last unit: any recovery at all later?
    rec_between[-1] = cum_rec[-1] - cum_rec[rows[-1]] > 0
    unc = uncertain[rows]
    code = ctx.code[rows]
    answered_clean = (ctx.status[rows] == "answered") & ~unc
    has_next = nxt >= 0

    # a careful sender may ask `>`, learn that the vector arrived, and go on to the next job
    # vector which happens to be the same: that is not a resend (GVE64 §13.5.13)
    went_on = np.zeros(len(rows), bool)
    unclear = np.zeros(len(rows), bool)
    for i in np.flatnonzero(unc & rec_between & same_next).tolist():
        said = _repeat_says_arrived(ctx, rows[i], nxt[i])
        went_on[i], unclear[i] = said is True, said is None
    resent = same_next & ~went_on

    blind = unc & same_next & ~rec_between & dec
    moved_on = unc & has_next & ~same_next & ~rec_between & dec
    refused = answered_clean & isin(code, (1, 2, 4, 5, 7)) & has_next & ~same_next & dec
    checked = unc & rec_between & dec

    def mk_blind(i: int) -> tuple:
        r = rows[i]
        return (ctx.t[nxt[i]],
                f"`{ctx.cmd(r)}` got {ctx.ans(r)}; the sender sent the same motion again "
                f"(host:{nxt[i] + ctx.base}) without asking `@` or `>` first: if the first one was "
                "accepted the machine moves twice",
                [_fr("host", r), _fr("host", nxt[i])], {"resent_row": int(nxt[i]), "row": int(r)})

    out.many("blind-resend", np.flatnonzero(blind), "hazard", mk_blind)

    def mk_lost(i: int) -> tuple:
        r = rows[i]
        return (ctx.t[nxt[i]],
                f"`{ctx.cmd(r)}` got {ctx.ans(r)}; the sender moved on to `{ctx.cmd(nxt[i])}` "
                "without asking `@` or `>`: if the unit did not take it, this motion is lost.",
                [_fr("host", r), _fr("host", nxt[i])], {"confirmed": False, "row": int(r)})

    out.many("lost-vector", np.flatnonzero(moved_on), "hazard", mk_lost)

    def mk_refused(i: int) -> tuple:
        r = rows[i]
        meaning = ctx.errors.get(int(code[i]))
        why = meaning.meaning if meaning is not None else f"error {code[i]}"
        return (ctx.t[nxt[i]],
                f"`{ctx.cmd(r)}` was answered {ctx.ans(r)} ({why}) and the sender moved on to "
                f"`{ctx.cmd(nxt[i])}` without sending it again: this motion is lost",
                [_fr("host", r), _fr("host", nxt[i])], {"confirmed": True, "row": int(r)})

    out.many("lost-vector", np.flatnonzero(refused), "hazard", mk_refused)

    def mk_checked(i: int) -> tuple:
        r = rows[i]
        lo = r + 1
        hi = nxt[i] if nxt[i] >= 0 else len(ex)
        which = [k for k in range(lo, hi) if is_rec[k]][:3]
        asked = ", ".join(f"`{ctx.cmd(k)}` → {ctx.ans(k)}" for k in which)
        then = "sent it again" if resent[i] else "moved on"
        return (ctx.t[which[0]] if which else ctx.t[r],
                f"`{ctx.cmd(r)}` got {ctx.ans(r)}; the sender asked {asked} and then {then}",
                [_fr("host", r)] + [_fr("host", k) for k in which], {"row": int(r)})

    idx_checked = np.flatnonzero(checked)
    uses_at = np.zeros(len(idx_checked), bool)
    for j, i in enumerate(idx_checked.tolist()):
        hi = nxt[i] if nxt[i] >= 0 else len(ex)
        seg = name[rows[i] + 1 : hi]
        uses_at[j] = bool((seg == "@").any())
    out.many("index-checked", idx_checked[uses_at], "info", mk_checked)
    _repeat_used(ctx, out, uncertain, is_rec)
    own = polls is None
    polls = polls or QueueFull()
    polls.feed(ctx, rows[dec], code[dec], answered_clean[dec])
    if own:
        polls.report(out, int(ex["cmd_bytes"].sum()),
                     float(np.nanmax(ex["t_cmd_first"]) - np.nanmin(ex["t_cmd_first"])))

    # what the sender meant to move: every unit once, except one replaced by a resend
    contrib = np.zeros(len(ex), bool)
    contrib[rows] = ((answered_clean & (code == 0)) | (unc & ~resent)) & dec
    res["contrib"] = contrib
    # uncertain, then checked with @ / > and not sent again: the unit had taken it
    recovered = np.zeros(len(ex), bool)
    recovered[rows] = unc & rec_between & ~resent & has_next & dec
    res["recovered"] = recovered
    res["doubles"] = rows[blind]
    # sent again after asking `@`/`>`: safe only if the answers said it had not arrived, so
    # these too may explain a position that shows a vector executed twice
    res["checked_resends"] = rows[checked & resent]
    res["unclear_resends"] = rows[checked & resent & unclear]
    res["lost"] = rows[moved_on]
    return res


def _repeat_says_arrived(ctx: Context, r: int, hi: int) -> bool | None:
    """What the `>` answers after row ``r`` (up to row ``hi``) say about it: True it arrived
    and was taken (the repeated line is ours, answered 0), False it was not, None unclear
    (no clean echo, or the line before ours was the same text)."""
    if ctx.name[r] not in MOTION:
        return None
    ours = ctx.cmd(r)
    before = ctx.cmd(r - 1) if r > 0 else ""
    if before == ours:
        return None
    kind = ctx.ex["answer_kind"].to_numpy()
    for k in range(r + 1, hi if hi >= 0 else len(ctx.ex)):
        if ctx.name[k] != ">" or ctx.status[k] != "answered" or kind[k] != ANSWER:
            continue
        e = int(ctx.answer[k]) - 1
        echo = ctx.unit_text(e) if e >= 0 else ""
        if not echo.startswith("!"):
            continue  # the unit line before the answer is not the echo of the repeated line
        if echo == ours:
            return bool(ctx.code[k] == 0)
        if echo == before:
            return False
    return None


def _repeat_used(ctx: Context, out: Findings, uncertain: np.ndarray, is_rec: np.ndarray) -> None:
    """``>`` sent right after an uncertain answer: the careful way to learn what happened."""
    rep = np.flatnonzero(is_rec & (ctx.name == ">"))
    if len(rep) == 0:
        return
    exp_rows = np.flatnonzero(isin(ctx.status, ("answered", "unanswered")))
    pos = np.searchsorted(exp_rows, rep) - 1
    prev = np.where(pos >= 0, exp_rows[np.maximum(pos, 0)], -1)
    good = (prev >= 0) & uncertain[np.maximum(prev, 0)]

    def mk(r: int) -> tuple:
        p = int(prev[np.searchsorted(rep, r)])
        return (ctx.t[r], f"after `{ctx.cmd(p)}` got {ctx.ans(p)}, the sender asked `>` "
                f"and got {ctx.ans(r)}", [_fr("host", p)] + ctx.frames(r), {})

    out.many("repeat-used", rep[good], "info", mk, side="host")


class QueueFull:
    """Vectors answered 1 (queue full), gathered over the windows of a capture and reported
    once: polls, runs, bytes, the median retry gap (``summaries.Quantiles``)."""

    def __init__(self) -> None:
        from conform.analysis.summaries import Quantiles

        self.polls = 0
        self.runs = 0
        self.bytes = 0
        self.cmd_bytes = 0
        self.first: tuple[float, int] | None = None  # (t, row) of the first poll
        self.gaps = Quantiles()
        self.prev_full = False  # the last unit judged was a poll (a run goes on)
        self.baud: float | None = None

    def feed(self, ctx: Context, rows: np.ndarray, code: np.ndarray, clean: np.ndarray
             ) -> None:
        self.baud = ctx.baud
        full = clean & (code == 1)
        if len(full) == 0:
            return
        starts = full & ~np.concatenate([[self.prev_full], full[:-1]])
        self.prev_full = bool(full[-1])
        if not full.any():
            return
        ex = ctx.ex
        polls = rows[full]
        self.runs += int(starts.sum())
        self.polls += len(polls)
        cb = int(ex["cmd_bytes"].to_numpy()[polls].sum())
        self.cmd_bytes += cb
        self.bytes += cb + int(ex["ans_bytes"].to_numpy()[polls].sum())
        if self.first is None:
            self.first = (float(ctx.t[polls[0]]), int(polls[0]) + ctx.base)
        self.gaps.add(ex["host_time"].to_numpy()[polls])

    def report(self, out: Any, host_total: int, span: float) -> None:
        if not self.polls:
            return
        assert self.first is not None
        host_total = host_total or 1
        span = span or 1.0
        line_time = self.bytes * 10.0 / self.baud if self.baud else float("nan")
        gap = self.gaps.median() if self.gaps.n else float("nan")
        pattern = "immediate" if gap == gap and gap < 0.002 else "paced"
        share = float(self.cmd_bytes) / host_total
        sev = "warning" if share > 0.10 else "info"
        t, row = self.first
        runs = self.runs
        out.add("queue-full-polling", t, sev,
                f"{self.polls} vector(s) answered 1 (queue full) in {runs} run(s), "
                f"{self.polls / max(runs, 1):.1f} tries per run, resent {pattern} "
                f"(median {gap * 1000:.2f} ms after the answer); the retries took "
                f"{share:.0%} of the bytes sent and {line_time / span:.1%} of the line time",
                frames=[_fr("host", row)], row=row, count=self.polls,
                runs=runs, polls=self.polls, bytes=self.bytes, share_of_host_bytes=share,
                pattern=pattern, median_retry_gap_s=gap)


def protocol_findings(ctx: Context, host: Any, unit: Any, unsolicited: np.ndarray,
                      out: Findings) -> None:
    ex = ctx.ex
    n = len(ex)
    byte_t = 10.0 / ctx.baud if ctx.baud else 0.0
    answered = ctx.status == "answered"
    # simplex: the next line started before this answer had arrived
    t_next = np.concatenate([ctx.t[1:], [np.inf]])
    t_ans_last = ex["t_ans_last"].to_numpy()
    viol = answered & (t_next < t_ans_last - 0.5 * byte_t)
    viol &= ctx.name != "J"

    def mk_viol(r: int) -> tuple:
        return (ctx.t[r + 1], f"`{ctx.cmd(r + 1)}` was sent before the answer to "
                f"`{ctx.cmd(r)}` ({ctx.ans(r)}) had arrived",
                [_fr("host", r), _fr("host", r + 1)] + ctx.frames(r)[1:], {})

    out.many("simplex-violation", np.flatnonzero(viol), "error", mk_viol, side="host")

    # checksum errors, both directions
    bad_cmd = np.flatnonzero(isin(host.checksum, (CS_BAD, CS_MISSING)))

    def mk_cs_cmd(r: int) -> tuple:
        what = "does not match" if host.checksum[r] == CS_BAD else "is missing"
        return (host.t_first[r], f"command `{ctx.cmd(r)}`: checksum {what}; the unit "
                f"answered {ctx.ans(r)}", ctx.frames(r), {"direction": "host"})

    out.many("checksum-error", bad_cmd, "warning", mk_cs_cmd, side="host")
    bad_ans = np.flatnonzero(isin(unit.checksum, (CS_BAD, CS_MISSING))
                             & (unit.kind == ANSWER))

    def mk_cs_ans(u: int) -> tuple:
        what = "does not match" if unit.checksum[u] == CS_BAD else "is missing"
        return (unit.t_first[u], f"answer `{ctx.unit_text(u)}`: checksum {what}",
                [_fr("unit", u)], {"direction": "unit"})

    out.many("checksum-error", bad_ans, "warning", mk_cs_ans, side="unit")

    garbled = np.flatnonzero(isin(unit.kind, (GARBLED, PARTIAL)))

    def mk_garbled(u: int) -> tuple:
        return (unit.t_first[u], f"`{ctx.unit_text(u)}` is not an answer: {unit.detail[u]}",
                [_fr("unit", u)], {})

    out.many("garbled-answer", garbled, "warning", mk_garbled, side="unit")

    # error codes (queue-full on motion is reported as polling)
    clean = answered & (ex["answer_kind"].to_numpy() == ANSWER)
    err = clean & (ctx.code > 0)
    err &= ~((ctx.code == 1) & isin(ctx.name, ("C", "L", "*E")))

    def mk_err(r: int) -> tuple:
        c = int(ctx.code[r])
        meaning = ctx.errors.get(c)
        why = meaning.meaning if meaning is not None else "unknown code"
        prev = f" after `{ctx.cmd(r - 1)}`" if r > 0 else ""
        cause = ""
        if host.checksum[r] in (CS_BAD, CS_MISSING):
            cause = " (the command's checksum was wrong)"
        elif c == 4 and host.checksum[r] == 1:
            cause = " (its checksum is right as sent: the line was damaged on the way)"
        elif host.kind[r] == "rejection" and host.detail[r]:
            cause = f" ({host.detail[r]})"
        return (ctx.t[r], f"`{ctx.cmd(r)}`{prev} answered {ctx.ans(r)}: error {c}, {why}"
                f"{cause}", ctx.frames(r), {"code": c})

    out.many("error-code", np.flatnonzero(err), "warning", mk_err, side="host")

    # unanswered commands
    unans = np.flatnonzero((ctx.status == "unanswered") & (ctx.name != "J"))

    def mk_unans(r: int) -> tuple:
        return (ctx.t[r], f"`{ctx.cmd(r)}` got no answer", [_fr("host", r)], {})

    out.many("no-answer", unans, "warning", mk_unans, side="host")

    def mk_unsol(u: int) -> tuple:
        return (unit.t_first[u], f"`{ctx.unit_text(u)}` arrived before any command",
                [_fr("unit", u)], {})

    out.many("unsolicited-answer", unsolicited[unit.kind[unsolicited] != ECHO]
             if len(unsolicited) else unsolicited, "warning", mk_unsol, side="unit")

    garbage = np.flatnonzero((host.kind == "rejection") & (host.code < 0))

    def mk_garbage(r: int) -> tuple:
        return (ctx.t[r], f"`{ctx.cmd(r)}` is not a command the unit answers: "
                f"{host.detail[r]}", [_fr("host", r)], {})

    out.many("garbage-sent", garbage, "warning", mk_garbage, side="host")

    # long waits: HALT and W answer when the motion has ended
    lw = np.flatnonzero(isin(ctx.name, ("H", "W")) & answered
                        & (ex["unit_time"].to_numpy() > 0.02))

    def mk_lw(r: int) -> tuple:
        ut = float(ex["unit_time"].to_numpy()[r])
        return (ctx.t[r], f"`{ctx.cmd(r)}` answered {ctx.ans(r)} after {ut * 1000:.0f} ms "
                "(it answers when the motion has stopped; the line is busy meanwhile)",
                ctx.frames(r), {"wait_s": ut})

    out.many("long-wait", lw, "info", mk_lw, side="host")

    resets = np.flatnonzero((ctx.name == "J") & (ex["kind"].to_numpy() == "command"))

    def mk_reset(r: int) -> tuple:
        return (ctx.t[r], f"`{ctx.cmd(r)}` resets the unit: position, checksums and modal "
                "values return to the reset state and it is deaf for about 2 s",
                ctx.frames(r), {"cause": "J"})

    out.many("reset", resets, "info", mk_reset, side="host")
    del n
