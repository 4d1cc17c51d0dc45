"""Analysis tables into Parquet, a row group at a time.

A table is written slice by slice (``ROW_GROUP`` rows each) through one
``pyarrow.parquet.ParquetWriter``: only one slice's converted copy is in memory at a time,
and a pandas, polars or DuckDB reader can filter row groups by their statistics instead of
loading the whole table. Repeating text columns (names, kinds, statuses) are categorical
with one category list per table, worked out once, so every row group has the same schema;
text that rarely repeats (command lines) stays plain strings.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

ROW_GROUP = 131_072
Slice = Callable[[int, int], pd.DataFrame]


def text_categories(df: pd.DataFrame) -> dict[str, list[Any] | None]:
    """Per object column: its categories if its values repeat, else None (plain text)."""
    out: dict[str, list[Any] | None] = {}
    for col in df.columns:
        if df[col].dtype == object:
            u = categories_of(df[col].to_numpy())
            out[col] = u if len(u) <= max(1, len(df) // 2) else None
    return out


def categories_of(values: Any) -> list[str]:
    """The distinct values of a text column, sorted, without None/NaN."""
    return sorted(str(x) for x in pd.unique(values) if x is not None and x == x)


def _coded(df: pd.DataFrame, cats: dict[str, list[Any] | None]) -> pd.DataFrame:
    for col, c in cats.items():
        if col not in df:
            continue
        s = df[col].astype("string")
        df[col] = s if c is None else pd.Categorical(s, categories=c)
    return df


def _slices(n: int, rows: int) -> Iterator[tuple[int, int]]:
    for b in range(0, max(n, 1), rows):
        yield b, min(n, b + rows)


def write_table(path: Path, n: int, take: Slice, cats: dict[str, list[Any] | None],
                rows: int = ROW_GROUP) -> Path:
    """Write ``take(lo, hi)`` for every slice of ``n`` rows as one row group each."""
    writer: pq.ParquetWriter | None = None
    try:
        for lo, hi in _slices(n, rows):
            t = pa.Table.from_pandas(_coded(take(lo, hi), cats), preserve_index=False)
            if writer is None:
                writer = pq.ParquetWriter(path, t.schema)
            writer.write_table(t, row_group_size=max(hi - lo, 1))
    finally:
        if writer is not None:
            writer.close()
    return path


def write_frame(path: Path, df: pd.DataFrame, rows: int = ROW_GROUP,
                extra: Callable[[pd.DataFrame, int, int], pd.DataFrame] | None = None
                ) -> Path:
    """A DataFrame in row groups; ``extra(slice, lo, hi)`` may add or change columns."""
    cats = text_categories(df)

    def take(lo: int, hi: int) -> pd.DataFrame:
        part = df.iloc[lo:hi].copy()
        return extra(part, lo, hi) if extra is not None else part

    return write_table(path, len(df), take, cats, rows)


def relative_times(part: pd.DataFrame, t0: float, cols: tuple[str, ...]) -> pd.DataFrame:
    for col in cols:
        if col in part:
            part[col] = part[col].to_numpy() - t0
    return part
