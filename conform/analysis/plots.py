"""Plots of an analysis, as base64 PNG for a self-contained HTML report (matplotlib, Agg).

The engine's plotting pieces: a figure, its PNG, a legend beside the axes, decimation and
the report's time range; a family draws its own plots with them (``draw`` runs a family's
list, so one failing plot is a note, not a lost report). Large sessions are decimated for
drawing only (never for the numbers): at most ``MAX_POINTS`` points per line. The plots over
time are drawn for the analysis's ``time_range`` (seconds from the start) when one is set
(``conform analyze --time-range``), so a stutter can be looked at closely; legends sit
beside the axes, not over the curves.
"""

from __future__ import annotations

import base64
import io
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Protocol, TypeVar

import numpy as np

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from conform.analysis.result import Reported

MAX_POINTS = 20_000

R = TypeVar("R", bound="Reported")   # a family's analysis: its plots read its own records


class Plotted(Protocol):
    def plots(self) -> dict[str, str]:
        """Its plots: key -> base64 PNG."""


def use_agg() -> None:
    import matplotlib

    matplotlib.use("Agg")


def new_figure(w: float = 7.5, h: float = 3.2) -> tuple[Figure, Axes]:
    use_agg()
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(w, h), dpi=100)
    return fig, ax


def to_png(fig: Figure) -> str:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def legend_beside(ax: Axes, handles: list[Artist] | None = None,
                  labels: list[str] | None = None) -> None:
    """A legend beside the axes, never over the curves."""
    if handles is None:
        handles, labels = ax.get_legend_handles_labels()
    if handles:
        if labels is None:
            labels = [str(h.get_label()) for h in handles]
        ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.01, 1.0),
                  borderaxespad=0.0, fontsize=8, frameon=False)


def window(a: object, t: np.ndarray) -> np.ndarray:
    """Mask of times (seconds from the start) inside the report's time range."""
    lo, hi = getattr(a, "time_range", None) or (-np.inf, np.inf)
    return (t >= lo) & (t <= hi)


def limit(ax: Axes, a: object) -> None:
    rng = getattr(a, "time_range", None)
    if rng:
        lo, hi = rng
        ax.set_xlim(left=lo if np.isfinite(lo) else None, right=hi if np.isfinite(hi) else None)


def over_time(fig: Figure, ax: Axes, a: object, ylabel: str, title: str, legend: bool = True) -> str:
    """Labels, the report's time range and the legend of a plot over time (``legend``
    False: the caller placed it, e.g. for twin axes); its PNG."""
    ax.set_xlabel("s from the start")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    limit(ax, a)
    if legend:
        legend_beside(ax)
    return to_png(fig)


def thin_points(*arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """Every ``step``-th point of long arrays (at most ``MAX_POINTS`` and one), the last
    point always kept: a line ends where its data ends, and the largest value of a sorted
    series (a CDF's tail) is not cut off the axis."""
    n = len(arrays[0])
    if n <= MAX_POINTS:
        return arrays
    step = int(np.ceil(n / MAX_POINTS))
    idx = np.arange(0, n, step)
    if idx[-1] != n - 1:
        idx = np.append(idx, n - 1)
    return tuple(np.asarray(a)[idx] for a in arrays)


def draw(a: R, makers: Iterable[tuple[str, Callable[[R], str | None]]]) -> dict[str, str]:
    """Every plot ``makers`` draws of analysis ``a`` (key -> base64 PNG); one that fails
    becomes a note of ``a`` instead of sinking the report."""
    out = {}
    for key, fn in makers:
        try:
            img = fn(a)
        except Exception as exc:  # noqa: BLE001 - a plot must not sink the report
            a.notes.append(f"plot {key} failed: {type(exc).__name__}: {exc}")
            img = None
        if img:
            out[key] = img
    return out


def all_plots(a: Plotted) -> dict[str, str]:
    """The plots of a family's analysis (its ``plots()``)."""
    return a.plots()
