"""Column helpers shared by the analysis steps."""

from __future__ import annotations

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


def _libc_trim() -> Callable[[], object] | None:
    try:
        import ctypes

        return ctypes.CDLL("libc.so.6").malloc_trim  # glibc only
    except (OSError, AttributeError):
        return None


_TRIM = _libc_trim()


def release_memory() -> None:
    """Hand freed heap back to the system between steps: glibc keeps the arrays a step
    freed for reuse, and the next step's peak would stack on top of them."""
    if _TRIM is not None:
        _TRIM(0)
