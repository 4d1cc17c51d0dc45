"""Raw bytes -> frames: lines cut at the terminator, timed, decoded by the spec tables.

Vectorised: lines are found with numpy, checksums are checked with a cumulative sum over
the byte stream, the common motion vectors (C, L) are parsed by one regular expression
built from their table rows and run by Arrow over every line at once, and every other
line is parsed once per distinct text by ``CommandParser`` / ``parse_answer``. The
checksum mode (``%+`` / ``%-`` / ``J``) is tracked as a step function over the lines.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from conform.analysis.rawread import Direction
from conform.families.gve.protocol import Command, CommandParser, Garbled, Rejection, parse_answer
from conform.families.gve.spec.model import Dialect, Variant

CR, LF, COMMA, BANG = 13, 10, 44, 33

# frame kinds
COMMAND, REJECTION, ANSWER, GARBLED, PARTIAL, ECHO = (
    "command", "rejection", "answer", "garbled", "partial", "echo")
# checksum status codes (stored as small ints, named in CHECKSUM_NAMES)
CS_NONE, CS_OK, CS_BAD, CS_MISSING = 0, 1, 2, 3
CHECKSUM_NAMES = np.array(["none", "ok", "bad", "missing"], dtype=object)

_HEXVAL = np.full(256, -1, np.int16)
for _i, _c in enumerate(b"0123456789ABCDEF"):
    _HEXVAL[_c] = _i
for _i, _c in enumerate(b"abcdef"):
    _HEXVAL[_c] = 10 + _i


def byte_times(d: Direction, t_first: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Arrival time of the bytes at ``idx``: spread evenly from the chunk's first to its read."""
    if len(idx) == 0:
        return np.zeros(0)
    k = np.searchsorted(d.start, idx, side="right") - 1
    span = np.maximum(d.length[k] - 1, 1)
    frac = (idx - d.start[k]) / span
    return t_first[k] + (d.t_read[k] - t_first[k]) * frac


@dataclass
class Lines:
    """The lines of one direction: body = data[start:end], terminator at ``end``."""

    start: np.ndarray
    end: np.ndarray
    term: np.ndarray  # bytes of the terminator (0 for a partial line at the end)
    bodies: pa.BinaryArray

    def __len__(self) -> int:
        return len(self.start)

    def head(self, n: int) -> Lines:
        """The first ``n`` lines."""
        return Lines(self.start[:n], self.end[:n], self.term[:n], self.bodies.slice(0, n))


def split_lines(data: np.ndarray, mode: str = "cr", max_lines: int | None = None) -> Lines:
    """Cut the stream into lines (A1: ``cr``, ``cr-or-lf`` or ``crlf``); only the first
    ``max_lines`` when given (a window of a stream needs no more)."""
    if mode == "cr-or-lf":
        ends = np.flatnonzero((data == CR) | (data == LF))
    else:
        ends = np.flatnonzero(data == CR)
    starts = np.concatenate([[0], ends + 1]).astype(np.int64)
    ends_all = np.concatenate([ends, [len(data)]]).astype(np.int64)
    term = np.ones(len(ends_all), np.int64)
    term[-1] = 0
    if mode != "cr-or-lf":
        for _ in range(2):  # an LF after the CR belongs to no line (GVE64 answers end in CR)
            lf = (starts < ends_all) & (data[np.minimum(starts, len(data) - 1)] == LF) \
                if len(data) else np.zeros(len(starts), bool)
            starts = starts + lf
    keep = ends_all > starts
    keep[:-1] |= mode != "cr-or-lf"  # empty lines count in cr mode (the unit answers them)
    if term[-1] == 0 and ends_all[-1] == starts[-1]:
        keep[-1] = False
    starts, ends_all, term = starts[keep], ends_all[keep], term[keep]
    if max_lines is not None:
        starts, ends_all, term = starts[:max_lines], ends_all[:max_lines], term[:max_lines]
    return Lines(starts, ends_all, term, _binary(data, starts, ends_all))


def _binary(data: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> pa.BinaryArray:
    """An Arrow binary array of data[starts[i]:ends[i]] (one copy, in C)."""
    n = len(starts)
    if n == 0:
        return pa.array([], pa.binary())
    offsets = np.empty(2 * n, np.int64)
    offsets[0::2] = starts
    offsets[1::2] = ends
    if (np.diff(offsets) < 0).any():
        raise ValueError("lines overlap")
    buf = pa.py_buffer(data)
    both = pa.LargeBinaryArray.from_buffers(pa.large_binary(), 2 * n - 1,
                                            [None, pa.py_buffer(offsets), buf])
    return pc.take(both, pa.array(np.arange(0, 2 * n, 2))).cast(pa.binary())


def prefix_sums(data: np.ndarray) -> np.ndarray:
    """Byte sums of every prefix of ``data``, modulo 256 (all a checksum needs: one byte
    per position instead of eight)."""
    out = np.empty(len(data) + 1, np.uint8)
    out[0] = 0
    np.cumsum(data, dtype=np.uint8, out=out[1:])
    return out


def checksum_tails(data: np.ndarray, csum: np.ndarray, start: np.ndarray,
                   end: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(has_tail, ok, value) for lines ending in ``,XX`` (GVE64 §13.3.2)."""
    n = len(start)
    has = np.zeros(n, bool)
    ok = np.zeros(n, bool)
    value = np.full(n, -1, np.int64)
    if n == 0 or len(data) < 4:  # no line long enough for a tail (and no byte 4 to point at)
        return has, ok, value
    cand = (end - start) >= 4
    e = np.where(cand, end, 4)
    hi = _HEXVAL[data[e - 2]]
    lo = _HEXVAL[data[e - 1]]
    has = cand & (data[e - 3] == COMMA) & (hi >= 0) & (lo >= 0)
    value = np.where(has, hi.astype(np.int64) * 16 + lo, -1)
    sums = (csum[e - 2] - csum[start]).astype(np.int64) & 0xFF
    ok = has & (sums == value)
    return has, ok, value


@dataclass
class DecodedLines:
    """Decoded frames of one direction (numpy columns, one entry per line)."""

    direction: str
    lines: Lines
    t_first: np.ndarray
    t_last: np.ndarray
    order: np.ndarray  # file order of the chunk holding the terminator
    kind: np.ndarray  # object: COMMAND, REJECTION, ANSWER, GARBLED, PARTIAL
    name: np.ndarray  # object: command id or None
    code: np.ndarray  # int: answer code / rejection code; -1 none (silence)
    inta: np.ndarray  # bool
    checksum: np.ndarray  # int8 CS_*
    checksum_mode: np.ndarray  # bool
    detail: np.ndarray  # object: why rejected / garbled (None if fine)
    vec: np.ndarray  # int64 (n, 4): per-axis pulses of L/C commands (0 otherwise)
    parsed: list[Any] = field(default_factory=list)  # distinct parse results
    parsed_id: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    def __len__(self) -> int:
        return len(self.kind)

    def result(self, i: int) -> Any:
        """The full parse (Command / Rejection / Answer / Garbled) of line ``i``, if kept."""
        j = int(self.parsed_id[i])
        return self.parsed[j] if j >= 0 else None

    def raw(self, i: int) -> bytes:
        return self.lines.bodies[i].as_py()

    def head(self, n: int) -> DecodedLines:
        """The first ``n`` lines (a window of a stream)."""
        return self.take(0, n)

    def take(self, lo: int, hi: int, compact: bool = False) -> DecodedLines:
        """Lines ``lo:hi``; ``compact``: keep only the parse results they use."""
        sl = slice(lo, hi)
        lines = Lines(self.lines.start[sl], self.lines.end[sl], self.lines.term[sl],
                      self.lines.bodies.slice(lo, max(min(hi, len(self)) - lo, 0)))
        parsed, pid = self.parsed, self.parsed_id[sl]
        if compact:
            used = np.unique(pid[pid >= 0])
            parsed = [self.parsed[i] for i in used.tolist()]
            pid = np.where(pid >= 0, np.searchsorted(used, pid), -1).astype(np.int32)
        return DecodedLines(self.direction, lines, self.t_first[sl], self.t_last[sl],
                            self.order[sl], self.kind[sl], self.name[sl], self.code[sl],
                            self.inta[sl], self.checksum[sl], self.checksum_mode[sl],
                            self.detail[sl], self.vec[sl], parsed, pid)

    @classmethod
    def join(cls, parts: list[DecodedLines]) -> DecodedLines:
        """Consecutive windows of one direction as one."""
        if len(parts) == 1:
            return parts[0]
        parsed: list[Any] = []
        ids = []
        for p in parts:
            pid = p.parsed_id.astype(np.int32)
            ids.append(np.where(pid >= 0, pid + len(parsed), -1).astype(np.int32))
            parsed.extend(p.parsed)
        cat = lambda f: np.concatenate([getattr(p, f) for p in parts])  # noqa: E731
        lines = Lines(np.concatenate([p.lines.start for p in parts]),
                      np.concatenate([p.lines.end for p in parts]),
                      np.concatenate([p.lines.term for p in parts]),
                      pa.concat_arrays([p.lines.bodies for p in parts]))
        return cls(parts[0].direction, lines, cat("t_first"), cat("t_last"), cat("order"),
                   cat("kind"), cat("name"), cat("code"), cat("inta"), cat("checksum"),
                   cat("checksum_mode"), cat("detail"), cat("vec"), parsed,
                   np.concatenate(ids))


def _vector_form(variant: Variant, dialect: Dialect, cmd_id: str) -> tuple[str, int, int] | None:
    """The mnemonic, lo and hi of an L/C row whose strict form ``vector_scan`` reads; None
    when the dialect is not strict (the parser takes every line then)."""
    spec = variant.commands.get(cmd_id)
    if spec is None or dialect["A22"] != "strict" or dialect["A21"] != "upper-mnemonics":
        return None
    if len(spec.params) != 1 or not spec.params[0].per_axis or spec.params[0].kind != "int":
        return None
    p = spec.params[0]
    return spec.mnemonic, int(p.lo), int(p.hi)


def decode_host(d: Direction, lines: Lines, times: tuple[np.ndarray, np.ndarray],
                variant: Variant, dialect: Dialect, parser: CommandParser,
                mode_before: np.ndarray) -> DecodedLines:
    """Decode command lines; ``mode_before[i]``: checksums were on when line ``i`` was sent."""
    n = len(lines)
    data = d.data
    csum = prefix_sums(data)
    has, ok, _value = checksum_tails(data, csum, lines.start, lines.end)
    partial = lines.term == 0
    cs = np.zeros(n, np.int8)
    cs[mode_before & has & ok] = CS_OK
    cs[mode_before & has & ~ok] = CS_BAD
    cs[mode_before & ~has] = CS_MISSING
    strip = mode_before & has
    body_end = np.where(strip, lines.end - 3, lines.end)

    kind = np.full(n, COMMAND, object)
    name = np.full(n, None, object)
    code = np.full(n, -1, np.int64)
    detail = np.full(n, None, object)
    vec = np.zeros((n, 4), np.int64)
    parsed_id = np.full(n, -1, np.int32)
    parsed: list[Any] = []
    done = np.zeros(n, bool)

    lenient = dialect["A11"] == "lenient"
    cs_reject = (cs == CS_BAD) | ((cs == CS_MISSING) & (not lenient))
    cs_code = 2 if dialect["A11"] == "watchdog-2" else 4
    kind[cs_reject] = REJECTION
    code[cs_reject] = cs_code
    detail[cs == CS_BAD] = "checksum does not match"
    detail[(cs == CS_MISSING) & cs_reject] = "checksums are on but the line has none"
    done |= cs_reject
    kind[partial] = PARTIAL
    detail[partial] = "line cut off (no terminator)"
    done |= partial

    # fast path: the motion vectors, straight from their table rows
    from conform.families.gve.analysis.vector_scan import scan_vectors  # numba: on first use

    address = variant.interpolator_address
    naxes = len(variant.axes)
    for cid in ("C", "L"):
        form = _vector_form(variant, dialect, cid)
        if form is None or n == 0:
            continue
        mnem, lo, hi = form
        cand = np.flatnonzero(~done)
        ok, arr = scan_vectors(data, lines.start, body_end, cand,
                               np.frombuffer(f"!{address}{mnem}".encode("latin-1"), np.uint8),
                               naxes)
        inr = ok & ((arr >= lo) & (arr <= hi)).all(axis=1)
        rows = cand[inr]
        vec[rows, :naxes] = arr[inr]
        name[rows] = cid
        done[rows] = True

    # everything else: once per distinct body
    rest = np.flatnonzero(~done)
    if len(rest):
        enc = pc.dictionary_encode(_binary(data, lines.start[rest], body_end[rest]))
        idx = enc.indices.to_numpy(zero_copy_only=False).astype(np.int64)
        uniq = enc.dictionary.to_pylist()
        u_kind = np.empty(len(uniq), object)
        u_name = np.empty(len(uniq), object)
        u_code = np.full(len(uniq), -1, np.int64)
        u_detail = np.empty(len(uniq), object)
        u_vec = np.zeros((len(uniq), 4), np.int64)
        base = len(parsed)
        for j, body in enumerate(uniq):
            r = parser.parse(body, False)
            parsed.append(r)
            if isinstance(r, Command):
                u_kind[j], u_name[j], u_detail[j] = COMMAND, r.name, None
                if r.name in ("C", "L"):
                    u_vec[j, : len(r.args)] = r.args[:4]
            else:
                assert isinstance(r, Rejection)
                u_kind[j], u_name[j], u_detail[j] = REJECTION, r.name, r.detail
                u_code[j] = -1 if r.code is None else r.code
        kind[rest] = u_kind[idx]
        name[rest] = u_name[idx]
        code[rest] = u_code[idx]
        detail[rest] = u_detail[idx]
        vec[rest] = u_vec[idx]
        parsed_id[rest] = base + idx

    t_first, t_last = times
    return DecodedLines("host", lines, t_first, t_last, _term_order(d, lines), kind, name,
                        code, np.zeros(n, bool), cs, mode_before.copy(), detail, vec, parsed,
                        parsed_id)


def decode_unit(d: Direction, lines: Lines, times: tuple[np.ndarray, np.ndarray],
                mode: np.ndarray) -> DecodedLines:
    """Decode answer lines; ``mode[i]``: checksums were on for answer ``i``."""
    n = len(lines)
    kind = np.full(n, ANSWER, object)
    name = np.full(n, None, object)
    code = np.full(n, -1, np.int64)
    inta = np.zeros(n, bool)
    cs = np.zeros(n, np.int8)
    detail = np.full(n, None, object)
    parsed_id = np.full(n, -1, np.int32)
    parsed: list[Any] = []
    if n:
        enc = pc.dictionary_encode(pc.binary_join_element_wise(
            lines.bodies, pa.array(np.where(mode, "1", "0")).cast(pa.binary()), b"\x00"))
        idx = enc.indices.to_numpy(zero_copy_only=False).astype(np.int64)
        uniq = enc.dictionary.to_pylist()
        u_kind = np.empty(len(uniq), object)
        u_code = np.full(len(uniq), -1, np.int64)
        u_inta = np.zeros(len(uniq), bool)
        u_cs = np.zeros(len(uniq), np.int8)
        u_detail = np.empty(len(uniq), object)
        for j, key in enumerate(uniq):
            body, on = key[:-2], key[-1:] == b"1"
            if body[:1] == b"!":
                r: Any = Garbled(body, "echo of a command line")
                u_kind[j] = ECHO
                u_detail[j] = "echo of a command line"
            else:
                r = parse_answer(body, on)
                if isinstance(r, Garbled):
                    u_kind[j] = GARBLED
                    u_detail[j] = r.detail
                else:
                    u_kind[j] = ANSWER
                    u_code[j] = r.code
                    u_inta[j] = r.inta
                    if on:
                        u_cs[j] = CS_OK if r.checksum_ok else (
                            CS_MISSING if r.checksum is None else CS_BAD)
                        if not r.checksum_ok:
                            u_detail[j] = "answer checksum " + (
                                "missing" if r.checksum is None else "does not match")
            parsed.append(r)
        kind[:] = u_kind[idx]
        code[:] = u_code[idx]
        inta[:] = u_inta[idx]
        cs[:] = u_cs[idx]
        detail[:] = u_detail[idx]
        parsed_id[:] = idx
        partial = lines.term == 0
        kind[partial] = PARTIAL
        detail[partial] = "line cut off (no terminator)"
    t_first, t_last = times
    return DecodedLines("unit", lines, t_first, t_last, _term_order(d, lines), kind, name,
                        code, inta, cs, mode.copy(), detail, np.zeros((n, 4), np.int64),
                        parsed, parsed_id)


def _term_order(d: Direction, lines: Lines) -> np.ndarray:
    if len(lines) == 0 or d.chunks == 0:
        return np.zeros(len(lines), np.int32)
    idx = np.minimum(lines.end, len(d.data) - 1)
    k = np.searchsorted(d.start, idx, side="right") - 1
    return d.order[np.maximum(k, 0)].astype(np.int32)  # read numbers: int32 is plenty


def line_times(d: Direction, lines: Lines, t_first_chunks: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """(first byte, terminator) time of every line."""
    if len(lines) == 0:
        return np.zeros(0), np.zeros(0)
    last = np.minimum(lines.end, max(len(d.data) - 1, 0))
    return byte_times(d, t_first_chunks, lines.start), byte_times(d, t_first_chunks, last)


def mode_events(data: np.ndarray, lines: Lines) -> tuple[np.ndarray, np.ndarray]:
    """Host lines that switch checksums: (line index, state after: 1 on, 0 off)."""
    n = len(lines)
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int8)
    s = lines.start
    ln = lines.end - s
    at = lambda k: data[np.minimum(s + k, max(len(data) - 1, 0))]  # noqa: E731
    cmd = (ln >= 3) & (at(0) == BANG)
    pct = cmd & (ln >= 4) & (at(2) == ord("%")) & ((at(3) == ord("+")) | (at(3) == ord("-")))
    pct &= (ln == 4) | ((ln == 7) & (at(4) == COMMA))
    jay = cmd & (at(2) == ord("J")) & ((ln == 3) | ((ln == 6) & (at(3) == COMMA)))
    idx = np.flatnonzero(pct | jay)
    state = np.where(pct[idx] & (at(3)[idx] == ord("+")), 1, 0).astype(np.int8)
    return idx, state


def infer_initial_mode(data: np.ndarray, lines: Lines, first_event: int) -> bool:
    """Checksums on at the start? True if most early command lines carry a valid checksum."""
    upto = min(first_event if first_event >= 0 else len(lines), 50)
    if upto <= 0:
        return False
    csum = prefix_sums(data)
    sl = slice(0, upto)
    _has, ok, _ = checksum_tails(data, csum, lines.start[sl], lines.end[sl])
    return bool(ok.mean() > 0.5)


def step_state(ev_pos: np.ndarray, ev_state: np.ndarray, at: np.ndarray, init: bool,
               strict: bool = False) -> np.ndarray:
    """The state set by the last event strictly before each position (``init`` before)."""
    if len(ev_pos) == 0:
        return np.full(len(at), init, bool)
    k = np.searchsorted(ev_pos, at, side="left") - 1
    return np.where(k >= 0, ev_state[np.maximum(k, 0)] == 1, init)


def order_only(d: Direction, lines: Lines, times: tuple) -> DecodedLines:
    """Just enough of a DecodedLines to rank unit lines before they are decoded."""
    n = len(lines)
    z = np.zeros(n, object)
    return DecodedLines("unit", lines, times[0], times[1], _term_order(d, lines), z, z,
                        np.zeros(n, np.int64), np.zeros(n, bool), np.zeros(n, np.int8),
                        np.zeros(n, bool), z, np.zeros((n, 4), np.int64))
