"""Frames -> exchanges: every command line paired with the answer the unit gave it.

The protocol is simplex (GVE64 §13.3): one command, one answer. Pairing is done in the
order the tap saw the lines (terminator time, then file order): an answer belongs to the
last command that expects one and was complete before it. When a sender broke the simplex
rule and two commands were out before their answers, the answers are handed out first in,
first out. Packet members (``*S`` … ``*E<n>``, §13.3.3) expect no answer of their own.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from conform.capture.session import BITS_PER_BYTE
from conform.families.gve.analysis.frames import (
    ANSWER,
    COMMA,
    COMMAND,
    CS_MISSING,
    CS_NONE,
    ECHO,
    GARBLED,
    PARTIAL,
    REJECTION,
    DecodedLines,
)

VECTORS = ("C", "L")
STATUS_NAMES = np.array(["answered", "unanswered", "in_packet", "silent", "partial"], object)
ANSWERED, UNANSWERED, IN_PACKET, SILENT, CUT = range(5)


def merged_rank(host: DecodedLines, unit: DecodedLines) -> tuple[np.ndarray, np.ndarray]:
    """A common order of all lines: terminator time, then file order, host first on ties."""
    t = np.concatenate([host.t_last, unit.t_last])
    o = np.concatenate([host.order, unit.order])
    side = np.concatenate([np.zeros(len(host), np.int8), np.ones(len(unit), np.int8)])
    perm = np.lexsort((side, o, t))
    rank = np.empty(len(perm), np.int64)
    rank[perm] = np.arange(len(perm))
    return rank[: len(host)], rank[len(host):]


@dataclass
class Packets:
    member: np.ndarray  # bool per host line
    packet: np.ndarray  # int32 packet number (-1 outside)
    role: np.ndarray  # object: start/member/end/None
    open_before: np.ndarray | None = None  # bool: a packet was open before the line
    started: np.ndarray | None = None  # packets started up to and including the line


def find_packets(host: DecodedLines, open0: bool = False, pid0: int = 0) -> Packets:
    """Packet roles; ``open0``: a packet was open before the first line, ``pid0``: the
    number of packets started before it (a stream of windows carries both)."""
    n = len(host)
    name = host.name
    is_s = (name == "*S") & (host.kind == COMMAND)
    is_e = (name == "*E") & (host.kind != PARTIAL)
    ev = np.flatnonzero(is_s | is_e)
    open_before = np.full(n, open0, bool)
    if len(ev):
        pos = np.searchsorted(ev, np.arange(n), side="left") - 1
        has = pos >= 0
        open_before[has] = is_s[ev[pos[has]]]
    pid = np.cumsum(is_s) - 1 + pid0
    member = open_before & ~is_s & ~is_e
    role = np.full(n, None, object)
    role[is_s] = "start"
    role[member] = "member"
    role[is_e & open_before] = "end"
    packet = np.where(is_s | member | (is_e & open_before), pid, -1).astype(np.int32)
    return Packets(member, packet, role, open_before, pid + 1)


def expecting(host: DecodedLines, packets: Packets) -> np.ndarray:
    """Host lines that expect an answer of their own."""
    e = (host.kind == COMMAND) | ((host.kind == REJECTION) & (host.code >= 0))
    return e & ~packets.member & (packets.role != "start")


def pair(host: DecodedLines, unit: DecodedLines, packets: Packets,
         ranks: tuple[np.ndarray, np.ndarray] | None = None
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(answer line per host line or -1, extra answer lines per host line, unsolicited lines).

    ``extra`` counts further non-echo lines that came for the same command.
    """
    n = len(host)
    exp_idx = np.flatnonzero(expecting(host, packets))
    hr, ur = merged_rank(host, unit) if ranks is None else ranks
    # for each unit line, the last expecting command before it (index into exp_idx)
    c = np.searchsorted(hr[exp_idx], ur, side="left") - 1
    answer = np.full(n, -1, np.int32)  # line numbers and counts: int32 halves the columns
    extra = np.zeros(n, np.int32)
    echo = np.flatnonzero(unit.kind == ECHO)
    if len(echo):
        # a line starting with `!` is an echo only right after `>` (A9); else it is noise
        prev = np.where(c[echo] >= 0, exp_idx[np.maximum(c[echo], 0)], -1)
        stray = echo[(prev < 0) | (host.name[np.maximum(prev, 0)] != ">")]
        unit.kind[stray] = GARBLED
        unit.detail[stray] = "starts with '!' but no `>` asked for an echo"
    real = unit.kind != ECHO
    unsolicited = np.flatnonzero(c < 0)
    sel = np.flatnonzero((c >= 0) & real)
    if len(sel):
        cs = c[sel]
        first = np.ones(len(sel), bool)
        first[1:] = cs[1:] != cs[:-1]
        answer[exp_idx[cs[first]]] = sel[first]
        counts = np.bincount(cs, minlength=len(exp_idx))
        multi = np.flatnonzero(counts > 1)
        if len(multi):
            _fifo_fix(exp_idx, cs, sel, counts, multi, answer, extra)
    return answer, extra, unsolicited


def _fifo_fix(exp_idx: np.ndarray, cs: np.ndarray, sel: np.ndarray, counts: np.ndarray,
              multi: np.ndarray, answer: np.ndarray, extra: np.ndarray) -> None:
    """Hand surplus answers back to earlier unanswered commands, first in, first out."""
    starts = np.searchsorted(cs, multi, side="left")
    for e, s0 in zip(multi.tolist(), starts.tolist(), strict=True):
        lines = sel[s0 : s0 + counts[e]].tolist()
        run = []
        j = e - 1
        while j >= 0 and answer[exp_idx[j]] < 0 and len(run) < len(lines) - 1:
            run.append(j)
            j -= 1
        targets = run[::-1] + [e]
        for k, tgt in enumerate(targets):
            answer[exp_idx[tgt]] = lines[k]
        leftover = len(lines) - len(targets)
        if leftover > 0:
            extra[exp_idx[e]] += leftover


def build_exchanges(host: DecodedLines, unit: DecodedLines, packets: Packets, baud: float | None,
                    ranks: tuple[np.ndarray, np.ndarray] | None = None,
                    next_t_first: float = np.nan,
                    paired: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
                    ) -> tuple[pd.DataFrame, np.ndarray]:
    """One row per host line (the exchange it opened) and the unsolicited unit lines;
    ``ranks``: ``merged_rank(host, unit)`` if the caller has it already; ``next_t_first``:
    the first-byte time of the host line after the last one (a window of a stream);
    ``paired``: ``pair``'s result if the caller has it."""
    answer, extra, unsolicited = paired or pair(host, unit, packets, ranks)
    n = len(host)
    has = answer >= 0
    a = np.where(has, answer, 0)

    def pick(col: np.ndarray, fill: object) -> np.ndarray:
        if len(unit) == 0:
            return np.full(n, fill)
        return np.where(has, col[a], fill)

    expects = expecting(host, packets)
    status = np.full(n, SILENT, np.int8)
    status[expects] = UNANSWERED
    status[has] = ANSWERED
    status[packets.member | (packets.role == "start")] = IN_PACKET
    status[host.kind == PARTIAL] = CUT

    cmd_bytes = (host.lines.end - host.lines.start + host.lines.term).astype(np.int32)
    ans_bytes = pick(unit.lines.end - unit.lines.start + unit.lines.term, 0)
    t_af = pick(unit.t_first, np.nan)
    t_al = pick(unit.t_last, np.nan)
    wire_cmd = cmd_bytes * BITS_PER_BYTE / baud if baud else np.full(n, np.nan)
    wire_ans = np.where(has, ans_bytes * BITS_PER_BYTE / baud, np.nan) if baud else np.full(n, np.nan)
    rtt = t_al - host.t_first
    unit_time = rtt - wire_cmd - wire_ans
    nxt = np.concatenate([host.t_first[1:], [next_t_first]])
    host_time = np.where(has, nxt - t_al, np.nan)
    ans_kind = np.full(n, None, object)
    if len(unit):
        ans_kind[has] = unit.kind[a[has]]
    code = pick(unit.code, -1)
    inta = pick(unit.inta, False)
    ans_cs = pick(unit.checksum, 0).astype(np.int8)
    df = pd.DataFrame({
        "frame": np.arange(n, dtype=np.int32),
        "name": pd.Series(host.name, dtype=object),
        "kind": pd.Series(host.kind, dtype=object),
        "status": pd.Series(STATUS_NAMES[status], dtype=object),
        "reject_code": host.code,
        "cmd_checksum": host.checksum,
        "answer_frame": answer,
        "answer_kind": pd.Series(ans_kind, dtype=object),
        "code": code.astype(np.int32),
        "inta": inta.astype(bool),
        "answer_checksum": ans_cs,
        "extra_answers": extra,
        "t_cmd_first": host.t_first,
        "t_cmd_last": host.t_last,
        "t_ans_first": t_af.astype(float),
        "t_ans_last": t_al.astype(float),
        "cmd_bytes": cmd_bytes,
        "ans_bytes": ans_bytes.astype(np.int32),
        "wire_cmd": wire_cmd,
        "wire_ans": wire_ans,
        "rtt": rtt.astype(float),
        "unit_time": unit_time.astype(float),
        "host_time": host_time.astype(float),
        "packet": packets.packet,
        "packet_role": pd.Series(packets.role, dtype=object),
        "dx": host.vec[:, 0], "dy": host.vec[:, 1], "dz": host.vec[:, 2], "da": host.vec[:, 3],
    }, copy=False)  # one block per column: no consolidated copy of a million-row table
    df["uncertain"] = uncertain_mask(df)
    return df, unsolicited


def uncertain_mask(df: pd.DataFrame) -> np.ndarray:
    """Exchanges whose outcome the sender could not know from the answer alone."""
    answered = df["status"].to_numpy() == "answered"
    expects = answered | (df["status"].to_numpy() == "unanswered")
    bad_answer = answered & ((df["answer_kind"].to_numpy() != ANSWER)
                             | (df["answer_checksum"].to_numpy() >= 2))
    return expects & (~answered | bad_answer)


FIRST_LINES = 50  # host lines that decide the checksum mode at the start (frames)
WINDOW_LINES = 65_536  # host lines decoded and paired at a time


def check_answer_shapes(ex: pd.DataFrame, unit: DecodedLines, data: np.ndarray,
                        variant: Any) -> None:
    """An OK answer with the wrong number of fields for its command is garbled (§13.7)."""
    if len(unit) == 0:
        return
    commas = np.flatnonzero(data == COMMA)  # a few per line, not a count per byte
    nf = (np.searchsorted(commas, unit.lines.end) - np.searchsorted(commas, unit.lines.start))
    nf = nf - ((unit.checksum != CS_NONE) & (unit.checksum != CS_MISSING))
    want = {cid: len(c.answer) for cid, c in variant.commands.items()
            if cid not in _FREE_ANSWERS}
    want["*E"] = 1
    names = ex["name"].to_numpy()
    a = ex["answer_frame"].to_numpy()
    expect = pd.Series(names, dtype=object).map(want).fillna(-1).to_numpy(np.int64)
    ok = (a >= 0) & (ex["answer_kind"].to_numpy() == ANSWER) & (expect >= 0)
    ok &= ex["code"].to_numpy() == 0
    bad = np.flatnonzero(ok & (nf[np.maximum(a, 0)] != expect))
    if len(bad) == 0:
        return
    for r in bad.tolist():
        u = int(a[r])
        unit.kind[u] = GARBLED
        unit.detail[u] = f"{expect[r]} field(s) expected after a {names[r]} command"
    ex.loc[bad, "answer_kind"] = GARBLED
    ex.loc[bad, "code"] = -1
    ex["uncertain"] = uncertain_mask(ex)


_FREE_ANSWERS = {">", "?", "Q", "Y", "EFR", "EUR", "@", "J"}


@dataclass
class Window:
    """Host lines ``host_base`` … and the unit lines that came before the next window's
    first command: decoded and paired, final (nothing later changes them)."""

    host: DecodedLines
    unit: DecodedLines
    ex: pd.DataFrame  # ``frame`` and ``answer_frame`` numbered over the whole capture
    unsolicited: np.ndarray  # capture-wide unit line numbers
    cmd_row: np.ndarray  # per unit line: the row of the command it came after, -1 none
    host_base: int
    unit_base: int
    host_offset: int  # stream offset of the byte ``host.lines.start`` counts from
    unit_offset: int
    next_text: bytes | None  # the host line after the window, if any
    final: bool


def _prefix_below(t: np.ndarray, w: float) -> int:
    """How many leading entries of ``t`` are below ``w``."""
    bad = np.flatnonzero(~(t < w))
    return int(bad[0]) if len(bad) else len(t)


class ExchangeStream:
    """Decode and pair a capture a window at a time (see docs/analysis.md, Pipeline).

    Raw parts go in (``feed``); windows come out (``windows``). Carried from one window to
    the next: each direction's bytes after the last consumed line with the reads under
    them (``stream.LineBuffer``), the checksum mode, whether a packet is open and how many
    have started. A window ends just before a command whose previous command was answered
    inside the window: pairing never looks past that point (an answer belongs to the last
    command before it, surplus answers go back only over unanswered commands), so the
    result is the whole capture's, whatever the parts.
    """

    def __init__(self, variant: Any, dialect: Any, parser: Any, baud: float | None,
                 trust: bool, host_exact: bool = False, window_lines: int = WINDOW_LINES
                 ) -> None:
        from conform.analysis.stream import LineBuffer

        self.variant, self.dialect, self.parser, self.baud = variant, dialect, parser, baud
        self.mode_a1 = dialect["A1"]
        self.host = LineBuffer("host", baud, trust or host_exact)
        self.unit = LineBuffer("unit", baud, trust)
        self.mode: bool | None = None
        self.open, self.started = False, 0
        self.rows = self.ulines = 0
        self.window_lines = window_lines
        self.done = False

    def feed(self, part: Any) -> None:
        (self.host if part.name == "host" else self.unit).append(part)

    def end(self) -> None:
        self.host.ended = self.unit.ended = True

    def windows(self) -> Any:
        """Every window that can be made final with the bytes fed so far."""
        while not self.done:
            w = self._next()
            if w is None:
                return
            yield w

    def _next(self) -> Window | None:  # noqa: PLR0915 - one pass, in order
        from conform.families.gve.analysis.frames import (
            decode_host,
            decode_unit,
            infer_initial_mode,
            line_times,
            mode_events,
            order_only,
            split_lines,
            step_state,
        )

        hd, ud = self.host.view(), self.unit.view()
        w = min(self.host.horizon(), self.unit.horizon())

        def lines(d: Any, n: int) -> tuple[Any, Any, bool]:
            """The first ``n`` lines of a buffer, those complete (all at the end of the
            stream), and whether there may be more."""
            cut = split_lines(d.data, self.mode_a1, n)
            done = cut if w == np.inf else cut.head(int((cut.term > 0).sum()))
            return cut, done, len(cut) == n

        limit = self.window_lines
        while True:
            # only the lines this window can hold are cut out and timed, not the whole buffer
            hl_all, hl, more = lines(hd, limit + 2)
            ht = line_times(hd, hl.head(limit + 1), hd.t_first)
            kk = _prefix_below(ht[1], w)  # every line if fewer than limit + 1
            if kk < limit and w != np.inf:
                return None  # not a window's worth yet: wait for more bytes
            k = min(kk, limit)
            # all the lines below the horizon are in: one at or above it was seen, or none left
            full = k == kk and (kk < len(ht[1]) or (len(ht[1]) == len(hl) and not more))
            wc = w if full else min(w, float(ht[1][k]))
            m = 2 * k + 16
            while True:
                ul_all, ul, umore = lines(ud, m)
                ut = line_times(ud, ul, ud.t_first)
                j = _prefix_below(ut[1], wc)
                if j < len(ul) or not umore:
                    break
                m *= 2
            hk = hl.head(k)
            ev_idx, ev_state = mode_events(hd.data, hk)
            mode = self.mode
            if mode is None:
                if w != np.inf and not len(ev_idx) and k < FIRST_LINES:
                    return None
                mode = infer_initial_mode(hd.data, hk, int(ev_idx[0]) if len(ev_idx) else -1)
            host_mode = step_state(ev_idx, ev_state, np.arange(k), mode)
            host = decode_host(hd, hk, (ht[0][:k], ht[1][:k]), self.variant, self.dialect,
                               self.parser, host_mode)
            uk = ul.head(j)
            utj = (ut[0][:j], ut[1][:j])
            hr, ur = merged_rank(host, order_only(ud, uk, utj))
            unit_mode = step_state(hr[ev_idx] if len(ev_idx) else ev_idx, ev_state, ur, mode,
                                   strict=True)
            unit = decode_unit(ud, uk, utj, unit_mode)
            packets = find_packets(host, self.open, self.started)
            answer, extra, unsolicited = pair(host, unit, packets, (hr, ur))
            exp_idx = np.flatnonzero(expecting(host, packets))
            final = w == np.inf and full
            if final:
                cut = k
            else:
                ok = np.flatnonzero(answer[exp_idx[:-1]] >= 0) + 1
                cands = exp_idx[ok]
                cands = cands[ht[1][cands] < wc]
                if len(cands) == 0:
                    if not full:
                        limit *= 2  # no place to cut yet: look further
                        continue
                    return None
                cut = int(cands[-1])
            break
        self.mode = mode
        jc = int((ur < hr[cut]).sum()) if cut < k else j
        hw, uw = host.head(cut), unit.head(jc)
        pk = Packets(packets.member[:cut], packets.packet[:cut], packets.role[:cut])
        uns = unsolicited[unsolicited < jc]
        next_t = float(ht[0][cut]) if cut < len(hl) else np.nan
        ex, _ = build_exchanges(hw, uw, pk, self.baud, next_t_first=next_t,
                                paired=(answer[:cut], extra[:cut], uns))
        check_answer_shapes(ex, uw, ud.data, self.variant)
        c = np.searchsorted(hr[exp_idx], ur[:jc], side="left") - 1
        cmd_row = np.where(c >= 0, exp_idx[np.maximum(c, 0)] + self.rows, -1) \
            if len(exp_idx) else np.full(jc, -1)
        ex["frame"] += self.rows
        a = ex["answer_frame"].to_numpy()
        ex["answer_frame"] = np.where(a >= 0, a + self.ulines, a).astype(np.int32)
        out = Window(hw, uw, ex, uns + self.ulines, cmd_row, self.rows, self.ulines,
                     self.host.base, self.unit.base,
                     hl.bodies[cut].as_py() if cut < len(hl) else None, final)
        if cut < k:
            self.mode = bool(host_mode[cut])
            self.open = bool(packets.open_before[cut])
        self.started = int(packets.started[cut - 1]) if cut else self.started
        self.host.consume(int(hl_all.start[cut]) if cut < len(hl_all) else len(hd.data))
        self.unit.consume(int(ul_all.start[jc]) if jc < len(ul_all) else len(ud.data))
        self.rows += cut
        self.ulines += jc
        self.done = final
        return out
