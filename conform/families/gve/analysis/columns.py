"""Column helpers shared by the analysis steps."""

from __future__ import annotations

import ctypes
from collections.abc import Callable, Iterable

import numpy as np
import pandas as pd


def isin(values: np.ndarray, choices: Iterable[object]) -> np.ndarray:
    """``np.isin`` that hashes text columns instead of sorting them (object arrays of a
    million names took a third of a second each way)."""
    if values.dtype != object:
        return np.isin(values, list(choices))
    return pd.Series(values, dtype=object, copy=False).isin(list(choices)).to_numpy()


AXES = ("dx", "dy", "dz", "da")


def packet_numbers(ex: pd.DataFrame) -> np.ndarray:
    """The packet column numbered from 0 within the table (a window of a long capture
    numbers its packets from wherever the capture had got to), -1 outside packets."""
    packet = ex["packet"].to_numpy()
    inside = packet >= 0
    if not inside.any():
        return packet
    return np.where(inside, packet - packet[inside].min(), -1)


def vectors(ex: pd.DataFrame, rows: np.ndarray | None = None) -> np.ndarray:
    """The (rows, 4) pulses of the exchange table, taken column by column (no copy of the
    whole table's four columns when only some rows are wanted)."""
    cols = [ex[c].to_numpy() for c in AXES]
    if rows is not None:
        cols = [c[rows] for c in cols]
    return np.stack(cols, axis=1).astype(np.int64, copy=False)


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
        "fordblks", "keepcost")]


def _libc() -> tuple[Callable[[int], object] | None, Callable[[], _MallInfo2] | None]:
    """glibc's ``malloc_trim`` and ``mallinfo2`` (2.33+), or None where there is none."""
    try:
        libc = ctypes.CDLL("libc.so.6")
        trim = libc.malloc_trim
    except (OSError, AttributeError):
        return None, None
    try:
        info = libc.mallinfo2
        info.restype = _MallInfo2
    except AttributeError:
        info = None
    return trim, info


_TRIM, _INFO = _libc()
# Free heap kept for reuse before it goes back to the system. Trimming after every window
# keeps the peak lowest but makes the next window fault every page in again (~0.25 M page
# faults, ~0.5 s of system time per million exchanges); a few windows' worth of free heap
# costs a few tens of MB and almost none of that.
KEEP_FREE = 96 << 20


def release_memory() -> None:
    """Hand freed heap back to the system between steps once more than ``KEEP_FREE`` is
    held: glibc keeps the arrays a step freed for reuse, fragmented, and without a trim a
    long capture's resident memory creeps up by tens of MB per million exchanges."""
    if _TRIM is None:
        return
    if _INFO is None or _INFO().fordblks > KEEP_FREE:
        _TRIM(0)


TIMES = {"exchanges": ("t_cmd_first", "t_cmd_last", "t_ans_first", "t_ans_last"),
         "queue_depth": ("t",)}  # its tables' time columns (conform.analysis.tables)
