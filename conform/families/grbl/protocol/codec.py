"""Sans-I/O framing of grbl traffic.

Host side: realtime bytes (specs/grbl/protocol.toml [realtime], and any byte above 0x7F) are
out of band — they never enter grbl's receive buffer — and everything else forms lines ended by
LF or CR. :class:`HostSplitter` separates the two as bytes come, keeping each byte's offset.
Unit side: lines ended by CR LF, classified by the message table (ok, error:N, ALARM:N, the
status report, the banner, [MSG:...] ...).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from conform.families import Detection
from conform.families.grbl.spec.load import GrblSpec, load_grbl


@dataclass(slots=True)
class HostLine:
    """One line the sender wrote: its bytes (without the terminator), where it began and
    where its terminator was, as stream offsets."""

    data: bytes
    start: int
    end: int              # offset of the terminator
    terminator: bytes = b"\n"

    @property
    def size(self) -> int:
        """Bytes the line takes in grbl's receive buffer, terminator included."""
        return len(self.data) + 1


@dataclass(slots=True)
class RealtimeByte:
    byte: int
    offset: int


@dataclass
class HostSplitter:
    """Feed host bytes; collect lines and realtime bytes in order."""

    spec: GrblSpec = field(default_factory=load_grbl)
    offset: int = 0
    _buf: bytearray = field(default_factory=bytearray)
    _start: int = 0     # offset of the current line's first byte

    def feed(self, data: bytes) -> list[HostLine | RealtimeByte]:
        out: list[HostLine | RealtimeByte] = []
        rt = self.spec.realtime
        for b in data:
            if b in rt or b > 0x7F:
                out.append(RealtimeByte(b, self.offset))
            elif b in (0x0A, 0x0D):
                start = self._start if self._buf else self.offset
                out.append(HostLine(bytes(self._buf), start, self.offset, bytes([b])))
                self._buf.clear()
            else:
                if not self._buf:
                    self._start = self.offset
                self._buf.append(b)
            self.offset += 1
        return out

    @property
    def partial(self) -> bytes:
        return bytes(self._buf)


def split_host(data: bytes, spec: GrblSpec | None = None
               ) -> tuple[list[HostLine], list[RealtimeByte]]:
    """The whole host stream at once (numpy): the same lines and realtime bytes as
    :class:`HostSplitter`, for long captures."""
    import numpy as np

    spec = spec or load_grbl()
    arr = np.frombuffer(data, np.uint8)
    rt_mask = arr > 0x7F
    for b in spec.realtime:
        if b <= 0x7F:
            rt_mask |= arr == b
    rt_at = np.flatnonzero(rt_mask)
    realtime = [RealtimeByte(int(arr[i]), int(i)) for i in rt_at.tolist()]
    orig = np.flatnonzero(~rt_mask)
    kept = arr[orig]
    ends = np.flatnonzero((kept == 0x0A) | (kept == 0x0D))
    starts = np.concatenate([[0], ends[:-1] + 1]) if len(ends) else np.zeros(0, np.int64)
    raw = kept.tobytes()
    lines = []
    for a, e in zip(starts.tolist(), ends.tolist(), strict=True):
        start = int(orig[a]) if a < e else int(orig[e])
        lines.append(HostLine(raw[a:e], start, int(orig[e]), raw[e:e + 1]))
    return lines, realtime


@dataclass(slots=True)
class UnitLine:
    text: str
    kind: str
    code: int | None
    start: int
    end: int


def split_unit(data: bytes, spec: GrblSpec | None = None) -> tuple[list[UnitLine], bytes]:
    """Complete lines from grbl (CR LF, or a lone LF) and the unterminated rest."""
    spec = spec or load_grbl()
    out = []
    pos = 0
    while True:
        nl = data.find(b"\n", pos)
        if nl < 0:
            break
        raw = data[pos:nl].rstrip(b"\r")
        text = raw.decode("latin-1")
        if text == "ok":                 # most lines of a stream: skip the pattern table
            out.append(UnitLine(text, "ok", None, pos, nl))
            pos = nl + 1
            continue
        kind, m = spec.classify(text) if text else ("blank", None)
        code = None
        if kind in ("error", "alarm") and m is not None:
            code = int(m.group(1))
        out.append(UnitLine(text, kind, code, pos, nl))
        pos = nl + 1
    return out, data[pos:]


def detect(host: bytes, unit: bytes, spec: GrblSpec | None = None) -> Detection:
    """How grbl-like the traffic is: the share of grbl-shaped lines from the unit, the banner,
    status reports, '\\n'-ended g-code from the host."""
    spec = spec or load_grbl()
    lines, _ = split_unit(unit[:65536], spec)
    lines = [ln for ln in lines if ln.kind != "blank"]
    if not lines:
        if host and (b"\n" in host[:4096]) and host[:4096].count(b"?") >= 1 and b"!0" not in host[:4096]:
            return Detection("grbl", 0.3, "host traffic looks like g-code but the unit said nothing")
        return Detection("grbl", 0.0, "no lines from the unit")
    known = sum(1 for ln in lines if ln.kind != "unknown")
    share = known / len(lines)
    banner = any(ln.kind == "banner" for ln in lines)
    score = min(1.0, share * 0.9 + (0.1 if banner else 0.0))
    why = f"{known} of {len(lines)} lines from the unit are grbl messages"
    if banner:
        why += " (banner seen)"
    return Detection("grbl", score, why)
