"""The compiled reading of C and L lines decides exactly as the command parser would.

``decode_host`` reads the strict vector form straight from the bytes (``vector_scan``) and
hands every other line to ``CommandParser``; with the fast path switched off the parser sees
every line. Both must give the same kind, name, code, detail and axis values for any line,
well-formed or not: near misses (signs, lengths, commas, fields, ranges) are drawn on purpose.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conform.analysis.rawread import Direction
from conform.families.gve.analysis import frames
from conform.families.gve.spec import load_spec

SPEC = load_spec()

digits = st.text("0123456789", min_size=0, max_size=22)
number = st.one_of(
    st.integers(-(2**40), 2**40).map(str),
    st.builds(lambda s, d: s + d, st.sampled_from(["", "-", "+", "--", " "]), digits),
)
field_list = st.lists(number, min_size=0, max_size=6).map(",".join)
line = st.one_of(
    st.builds(lambda a, m, f, t: f"!{a}{m}{f}{t}", st.sampled_from(["0", "1", ""]),
              st.sampled_from(["C", "L", "c", "l", "CL", "M", "W", "N"]), field_list,
              st.sampled_from(["", ",", " ", ",,", "\n"])),
    st.text("!0CL-,0123456789 +", max_size=30),
)


def _tail(line: str) -> str:
    """The line with its checksum (GVE64 §13.3.2: the byte sum up to and with the comma)."""
    return f"{line},{sum((line + ',').encode('latin-1')) & 0xFF:02X}"


def _decode(lines: list[str], variant_id: str, fast: bool,
            checksums: bool = False) -> frames.DecodedLines:
    variant, dialect = SPEC.variant(variant_id), SPEC.dialect({})
    if checksums:
        lines = [_tail(s) for s in lines]
    data = np.frombuffer("".join(s + "\r" for s in lines).encode("latin-1"), np.uint8).copy()
    d = Direction("host", data, np.array([0]), np.array([len(data)]), np.array([0]),
                  np.array([1.0]), np.array([0.5]), np.array([0]))
    cut = frames.split_lines(data)
    with pytest.MonkeyPatch.context() as m:
        if not fast:
            m.setattr(frames, "_vector_form", lambda *_a: None)
        return frames.decode_host(d, cut, (np.zeros(len(cut)), np.zeros(len(cut))), variant,
                                  dialect, frames.CommandParser(variant, dialect),
                                  np.full(len(cut), checksums))


@pytest.mark.parametrize("variant_id", ["gve64-v10", "gve124"])
@settings(max_examples=60, deadline=None)
@given(lines=st.lists(line, min_size=1, max_size=40), checksums=st.booleans())
def test_fast_path_decides_like_the_parser(variant_id: str, lines: list[str],
                                           checksums: bool) -> None:
    fast = _decode(lines, variant_id, True, checksums)
    slow = _decode(lines, variant_id, False, checksums)
    assert len(fast) == len(slow)
    for col in ("kind", "name", "code", "detail", "vec"):
        assert np.array_equal(getattr(fast, col), getattr(slow, col)), col


def test_fast_path_reads_the_common_vectors() -> None:
    lines = ["!0L1000,0,0", "!0C-5,7,0,3", "!0C1,2", "!0L+1,0,0", "!0L1,2,3,"]
    out = _decode(lines, "gve64-v10", True)
    assert list(out.name[:2]) == ["L", "C"]
    assert out.vec[0].tolist() == [1000, 0, 0, 0] and out.vec[1].tolist() == [-5, 7, 0, 3]
    assert all(k == frames.REJECTION for k in out.kind[2:])  # too few fields, '+', empty field
    tailed = _decode(lines[:2], "gve64-v10", True, checksums=True)
    assert list(tailed.name) == ["L", "C"] and np.array_equal(tailed.vec, out.vec[:2])
