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

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

ROW_GROUP = 131_072
Slice = Callable[[int, int], pd.DataFrame]


def text_categories(df: pd.DataFrame) -> dict[str, list[str] | None]:
    """Per object column: its categories if its values repeat, else None (plain text)."""
    out: dict[str, list[str] | None] = {}
    for col in df.columns:
        if df[col].dtype == object:
            u = categories_of(df[col].to_numpy())
            out[col] = u if len(u) <= max(1, len(df) // 2) else None
    return out


def categories_of(values: np.ndarray) -> list[str]:
    """The distinct values of a text column, sorted, without None/NaN."""
    return sorted(str(x) for x in pd.unique(values) if x is not None and x == x)


def _coded(df: pd.DataFrame, cats: dict[str, list[str] | None]) -> pd.DataFrame:
    for col, c in cats.items():
        if col not in df:
            continue
        s = df[col].astype("string")
        df[col] = s if c is None else pd.Categorical(s, categories=c)
    return df


def _slices(n: int, rows: int) -> Iterator[tuple[int, int]]:
    for b in range(0, max(n, 1), rows):
        yield b, min(n, b + rows)


def open_writer(path: Path, schema: pa.Schema) -> pq.ParquetWriter:
    """A Parquet writer with dictionaries only for the dictionary-coded columns, where
    values repeat by design: trying one on every time and count column doubled the time to
    write a table, for a larger file."""
    coded = [f.name for f in schema if pa.types.is_dictionary(f.type)]
    return pq.ParquetWriter(path, schema, use_dictionary=coded)


def write_table(path: Path, n: int, take: Slice, cats: dict[str, list[str] | None],
                rows: int = ROW_GROUP) -> Path:
    """Write ``take(lo, hi)`` for every slice of ``n`` rows as one row group each."""
    writer: pq.ParquetWriter | None = None
    try:
        for lo, hi in _slices(n, rows):
            t = pa.Table.from_pandas(_coded(take(lo, hi), cats), preserve_index=False)
            if writer is None:
                writer = open_writer(path, t.schema)
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


CODED = frozenset({"name", "kind", "status", "answer_kind", "direction", "checksum_status",
                   "detail"})  # text columns written dictionary-encoded (and a family's)
TIMES = {"frames_host": ("t_first", "t_last"), "frames_unit": ("t_first", "t_last")}
"""A table's time columns (seconds from the capture's start): the frames' neutral ones; a
family adds its tables' (``ParquetStream.times``)."""


def escaped(bodies: pa.BinaryArray) -> pa.Array:
    """``escape_bytes`` of every line, as an Arrow string array: lines of printable ASCII
    (nearly all) are taken as they are in one pass, the others escaped one by one."""
    from conform.capture.session import escape_bytes

    plain = pc.match_substring_regex(bodies, r"^[\x20-\x5b\x5d-\x7e]*$").to_numpy(
        zero_copy_only=False)
    text = bodies.cast(pa.string(), safe=False)
    if plain.all():
        return text
    odd = np.flatnonzero(~plain)
    fixed = pa.array([escape_bytes(b) for b in bodies.take(pa.array(odd)).to_pylist()],
                     pa.string())
    return pc.replace_with_mask(text, pa.array(~plain), fixed)


def _arrow(df: pd.DataFrame, coded: frozenset[str] = CODED) -> pa.Table:
    """Text columns as dictionary-encoded strings (names, kinds, statuses) or strings; the
    same schema for every part of a table, whatever values a part holds."""
    cols = {}
    for c in df.columns:
        v = df[c]
        if isinstance(v.dtype, pd.ArrowDtype):
            cols[c] = pa.array(v.array)
        elif not (pd.api.types.is_numeric_dtype(v) or pd.api.types.is_bool_dtype(v)):
            try:  # text and None, straight (a third of the time of going through pandas)
                arr = pa.array(v.to_numpy(), pa.string(), from_pandas=True)
            except (pa.ArrowTypeError, pa.ArrowInvalid):  # anything else, as its text
                arr = pa.array(v.astype("string").to_numpy(na_value=None), pa.string())
            cols[c] = arr.dictionary_encode() if c in coded else arr
        else:
            cols[c] = pa.array(v.to_numpy())
    return pa.table(cols)


class ParquetStream:
    """The tables of a streamed analysis written as their rows come (``--parquet DIR``):
    ``exchanges``, ``frames_host``, ``frames_unit`` and a family's own tables (``rows``) a
    row group per window, ``series`` at the end. Times are seconds from the capture's start; the start is only
    known at the end, so parts are written from the first window's start and, in the rare
    capture whose earliest byte comes later in the file, rewritten a row group at a time."""

    def __init__(self, out_dir: str | Path, only: tuple[str, ...] | None = None,
                 files: dict[str, Path] | None = None, const: dict[str, object] | None = None,
                 part: Path | None = None) -> None:
        """``only``: the tables to write (all by default); ``files``: a path per table
        instead of ``DIR/NAME.parquet``; ``part``: every table as ``DIR/NAME/part`` instead
        (a fleet's ``machine=M/S.parquet``: one file of a dataset per table); ``const``:
        columns of one value put first in every table (a fleet's ``session``), and a ``t0``
        column if it names one. ``coded``: the text columns written dictionary-encoded (a
        family adds its own)."""
        from conform.errors import UserError

        self.only, self.files, self.const = only, files or {}, dict(const or {})
        self.part = part
        self.dir = Path(out_dir)
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise UserError(f"{self.dir}: cannot create the folder: {exc.strerror}") from None
        self.writers: dict[str, pq.ParquetWriter] = {}
        self.t0: float | None = None
        self.coded = CODED
        self.times = dict(TIMES)

    def path(self, name: str) -> Path:
        if self.part is not None:
            return self.files.get(name, self.dir / name / self.part)
        return self.files.get(name, self.dir / f"{name}.parquet")

    def _put(self, name: str, df: pd.DataFrame) -> None:
        assert self.t0 is not None
        if self.only is not None and name not in self.only:
            return
        for c in self.times.get(name, ()):
            df[c] = df[c].to_numpy() - self.t0
        if self.const:
            for k, v in reversed(self.const.items()):
                df.insert(0, k, self.t0 if k == "t0" else v)
        t = _arrow(df, self.coded)
        w = self.writers.get(name)
        if w is None:
            path = self.path(name)
            path.parent.mkdir(parents=True, exist_ok=True)
            w = self.writers[name] = open_writer(path, t.schema)
        w.write_table(t.cast(w.schema), row_group_size=max(len(df), 1))

    def write(self, ex: pd.DataFrame, host: Any, unit: Any, unit_base: int,
              frames_frame: Callable[..., pd.DataFrame],
              host_columns: dict[str, object] | None = None) -> None:
        """Exchange rows with their host lines, and unit lines (numbered from ``unit_base``);
        ``frames_frame(lines, t0, base=, arrow_text=)`` is the family's frames table, and
        ``host_columns`` the columns it adds to the host lines' one."""
        if self.t0 is None:
            t = np.concatenate([host.t_first, unit.t_first])
            t = t[np.isfinite(t)]
            if len(t) == 0 and len(ex) == 0:
                return
            self.t0 = float(t.min()) if len(t) else 0.0
        row0 = int(ex["frame"].iloc[0]) if len(ex) else 0
        part = ex.copy()
        text = pd.Series(pd.arrays.ArrowExtensionArray(escaped(host.lines.bodies)),
                         index=part.index)
        part["command"] = text
        self._put("exchanges", part)
        fh = frames_frame(host, 0.0, base=row0, arrow_text=True)
        for k, v in (host_columns or {}).items():
            fh[k] = v
        self._put("frames_host", fh)
        if len(unit):
            self._put("frames_unit", frames_frame(unit, 0.0, base=unit_base, arrow_text=True))

    def rows(self, name: str, df: pd.DataFrame) -> None:
        """Rows of a family's own table ``name`` (its time columns in ``times``)."""
        if self.t0 is not None and len(df):
            self._put(name, df)

    def finish(self, t0: float, series: pd.DataFrame) -> dict[str, Path]:
        if self.t0 is None:
            self.t0 = t0
        self._put("series", series.copy())
        for w in self.writers.values():
            w.close()
        out = {name: self.path(name) for name in self.writers}
        if t0 != self.t0:
            for name, path in out.items():
                _shift(path, self.times.get(name, ()), self.t0 - t0,
                       t0 if "t0" in self.const else None)
        return out


def _shift(path: Path, cols: tuple[str, ...], by: float, t0: float | None = None) -> None:
    """Add ``by`` to the time columns of a Parquet file, a row group at a time (and set its
    ``t0`` column, if given)."""
    if not cols and t0 is None:
        return
    f = pq.ParquetFile(path)
    tmp = path.with_suffix(".tmp")
    with open_writer(tmp, f.schema_arrow) as w:
        for i in range(f.num_row_groups):
            t = f.read_row_group(i)
            for c in cols:
                j = t.schema.get_field_index(c)
                t = t.set_column(j, c, pc.add(t.column(c), by))
            if t0 is not None:
                j = t.schema.get_field_index("t0")
                t = t.set_column(j, "t0", pa.array(np.full(len(t), t0)))
            w.write_table(t)
    tmp.replace(path)
