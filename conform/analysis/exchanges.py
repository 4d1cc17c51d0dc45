"""Frames -> exchanges: every command line paired with the answer the unit gave it.

The protocol is simplex (GVE64 §13.3): one command, one answer. Pairing is done in the
order the tap saw the lines (terminator time, then file order): an answer belongs to the
last command that expects one and was complete before it. When a sender broke the simplex
rule and two commands were out before their answers, the answers are handed out first in,
first out. Packet members (``*S`` … ``*E<n>``, §13.3.3) expect no answer of their own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from conform.analysis.frames import (
    ANSWER,
    BITS_PER_BYTE,
    COMMAND,
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


def find_packets(host: DecodedLines) -> Packets:
    n = len(host)
    name = host.name
    is_s = (name == "*S") & (host.kind == COMMAND)
    is_e = (name == "*E") & (host.kind != PARTIAL)
    ev = np.flatnonzero(is_s | is_e)
    open_before = np.zeros(n, bool)
    if len(ev):
        pos = np.searchsorted(ev, np.arange(n), side="left") - 1
        has = pos >= 0
        open_before[has] = is_s[ev[pos[has]]]
    pid = np.cumsum(is_s) - 1
    member = open_before & ~is_s & ~is_e
    role = np.full(n, None, object)
    role[is_s] = "start"
    role[member] = "member"
    role[is_e & open_before] = "end"
    packet = np.where(is_s | member | (is_e & open_before), pid, -1).astype(np.int32)
    return Packets(member, packet, role)


def pair(host: DecodedLines, unit: DecodedLines, packets: Packets,
         ranks: tuple[np.ndarray, np.ndarray] | None = None
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(answer line per host line or -1, extra answer lines per host line, unsolicited lines).

    ``extra`` counts further non-echo lines that came for the same command.
    """
    n = len(host)
    expects = ((host.kind == COMMAND) | ((host.kind == REJECTION) & (host.code >= 0)))
    expects &= ~packets.member & (packets.role != "start")
    exp_idx = np.flatnonzero(expects)
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
                    ranks: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> tuple[pd.DataFrame, np.ndarray]:
    """One row per host line (the exchange it opened) and the unsolicited unit lines;
    ``ranks``: ``merged_rank(host, unit)`` if the caller has it already."""
    answer, extra, unsolicited = pair(host, unit, packets, ranks)
    n = len(host)
    has = answer >= 0
    a = np.where(has, answer, 0)

    def pick(col: np.ndarray, fill: object) -> np.ndarray:
        if len(unit) == 0:
            return np.full(n, fill)
        return np.where(has, col[a], fill)

    expects = ((host.kind == COMMAND) | ((host.kind == REJECTION) & (host.code >= 0)))
    expects &= ~packets.member & (packets.role != "start")
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
    nxt = np.concatenate([host.t_first[1:], [np.nan]])
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
