"""Hypothesis strategies drawn from the tables: valid arguments for any command of any variant."""

from __future__ import annotations

from typing import Any

from hypothesis import strategies as st

from conform.families.gve.spec.model import CommandSpec, Dialect, ParamSpec, Variant


def _bounds(param: ParamSpec, dialect: Dialect | None) -> tuple[Any, Any]:
    if dialect is not None and param.range_name in dialect.ranges:
        return dialect.ranges[param.range_name]
    return param.lo, param.hi


def param_values(param: ParamSpec, variant: Variant, dialect: Dialect | None = None) -> st.SearchStrategy:
    """Valid values of one parameter (one field; per-axis parameters draw one per axis)."""
    lo, hi = _bounds(param, dialect)
    if param.kind in ("int", "uint", "hex"):
        edges = st.sampled_from([lo, hi, max(lo, min(hi, 0))])
        return st.one_of(edges, st.integers(int(lo), int(hi)))
    if param.kind == "float":
        return st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False).map(lambda x: round(x, 3))
    if param.kind == "axis":
        return st.sampled_from(variant.axes)
    if param.kind == "sign":
        return st.sampled_from(param.choices)
    raise ValueError(f"unknown parameter kind {param.kind!r}")


def command_args(cmd: CommandSpec, variant: Variant, dialect: Dialect | None = None) -> st.SearchStrategy:
    """A flat tuple of valid arguments for ``cmd`` on ``variant``."""
    parts: list[st.SearchStrategy] = []
    for param in cmd.params:
        values = param_values(param, variant, dialect)
        if param.per_axis:
            n = len(variant.axes)
            parts.append(st.integers(param.min_count or n, n).flatmap(
                lambda k, v=values: st.lists(v, min_size=k, max_size=k)))
        else:
            parts.append(values.map(lambda x: [x]))
    if not parts:
        return st.just(())
    return st.tuples(*parts).map(lambda groups: tuple(x for g in groups for x in g))
