"""History plots: error against run time, from a result or a benchmark CSV."""

from __future__ import annotations

import csv
import os
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from origami_jax.fold import FoldResult
from origami_jax.viz.extras import require

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["plot_history"]

HISTORY_METRICS = ("fold_angle_error_max", "strain_max", "grad_norm_rel")


def _read_table(source: Any) -> dict[str, np.ndarray]:
    """Columns of a CSV path, a dict of arrays or a DataFrame-like (``.columns``, ``[name]``)."""
    if isinstance(source, (str, os.PathLike)):
        with open(source, newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
        if not rows:
            raise ValueError(f"{source}: no rows")
        table = {}
        for name in rows[0]:
            col = [r[name] for r in rows]
            try:
                table[name] = np.array([float(c) if c != "" else np.nan for c in col])
            except ValueError:
                table[name] = np.array(col)
        return table
    if hasattr(source, "columns"):
        return {str(c): np.asarray(source[c]) for c in source.columns}
    return {k: np.asarray(v) for k, v in dict(source).items()}


def plot_history(
    source: FoldResult | str | os.PathLike | Any,
    metrics: Sequence[str] = HISTORY_METRICS,
    ax: Axes | None = None,
    pattern: str | None = None,
    solvers: Iterable[str] | None = None,
    *,
    title: str | None = None,
    figsize: tuple[float, float] = (6.0, 4.2),
) -> Figure:
    """Error against run time, log-log: one line per metric (per solver for a table).

    Args:
      source: a :class:`~origami_jax.FoldResult` (its ``history``), a history dict of arrays,
        a benchmark CSV path (``benchmarks/results/history.csv``: columns ``case`` (or
        ``pattern``), ``solver``, ``wall_time`` and the metrics) or a DataFrame-like table.
      metrics: columns to draw (unitless or radians), each in its own line style.
      pattern: keep only the rows of this case/pattern (a table of several must be filtered).
      solvers: keep only these solvers (default: all, one colour each).

    ``wall_time`` is seconds after compilation; its first sample (t = 0, the start) is drawn at
    half the first positive time, and non-positive errors (e.g. zero strain when flat) are left
    out, so both fit the log scale.

    Example:
      >>> plot_history("benchmarks/results/history.csv", pattern="miura_30x30")  # doctest: +SKIP
    """
    require("matplotlib")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    if isinstance(source, FoldResult):
        runs = {source.solver: source.history}
        title = title if title is not None else source.pattern.name
    else:
        table = _read_table(source)
        case_col = "case" if "case" in table else "pattern" if "pattern" in table else None
        if "solver" not in table:
            runs = {"": table}
        else:
            keep = np.ones(len(table["solver"]), bool)
            if pattern is not None:
                if case_col is None:
                    raise ValueError("pattern=: the table has no 'case' or 'pattern' column")
                keep &= table[case_col] == pattern
                if not keep.any():
                    shown = ", ".join(sorted(set(table[case_col].tolist())))
                    raise ValueError(f"pattern {pattern!r} is not in the table (it has {shown})")
            elif case_col is not None and len(set(table[case_col].tolist())) > 1:
                shown = ", ".join(sorted(set(table[case_col].tolist())))
                raise ValueError(
                    f"the table holds several patterns, choose one (pattern=): {shown}"
                )
            runs = {}
            for s in dict.fromkeys(table["solver"][keep].tolist()):
                if solvers is None or s in set(solvers):
                    sel = keep & (table["solver"] == s)
                    runs[s] = {k: v[sel] for k, v in table.items()}
            if title is None:
                title = (
                    pattern
                    if pattern is not None
                    else (str(table[case_col][0]) if case_col else None)
                )
    if ax is None:
        fig, ax = plt.subplots(figsize=figsize)
        fig.set_layout_engine("tight")  # our figure: the caller's keeps its layout
    fig = ax.figure
    styles = ["-", "--", ":", "-."]
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for r, (solver, h) in enumerate(runs.items()):
        if "wall_time" not in h:
            raise ValueError("history: no 'wall_time' column")
        t = np.asarray(h["wall_time"], np.float64)
        positive = t[t > 0]
        t = np.where(t > 0, t, positive.min() / 2 if len(positive) else 1e-6)
        for m, name in enumerate(metrics):
            if name not in h:
                raise ValueError(f"history: no column {name!r} (it has {', '.join(h)})")
            y = np.asarray(h[name], np.float64)
            y = np.where(y > 0, y, np.nan)
            label = f"{solver}: {name}" if solver else name
            ax.plot(t, y, styles[m % 4], color=colours[r % len(colours)], label=label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.xaxis.set_minor_formatter(NullFormatter())  # labelled minor ticks collide on short spans
    ax.set_xlabel("wall time after compilation (s)")
    ax.set_ylabel("error (rad or unitless)")
    if title:
        ax.set_title(f"{title}: error against run time")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    return fig
