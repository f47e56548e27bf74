"""plotly: an interactive 3-D view of the folded sheet, saved as a self-contained HTML file."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from origami_jax.fold import FoldResult
from origami_jax.io.fold import atomic_path
from origami_jax.pattern import CreasePattern
from origami_jax.viz.colors import (
    ASSIGNMENT_COLORS,
    ASSIGNMENT_NAMES,
    PAPER,
    color_values,
    crease_segments,
    unpack,
)
from origami_jax.viz.extras import require

if TYPE_CHECKING:  # pragma: no cover
    import plotly.graph_objects as go

__all__ = ["plotly_fold", "save_html"]


def plotly_fold(
    result_or_positions: FoldResult | np.ndarray,
    color: str | np.ndarray | None = None,
    pattern: CreasePattern | None = None,
    show_creases: bool = True,
    show_facets: bool = False,
    percent: float | None = None,
) -> go.Figure:
    """An interactive 3-D view: a ``Mesh3d`` of the mesh triangles and a ``Scatter3d`` of crease
    lines per assignment, ``aspectmode="data"`` (true proportions).

    Args: as :func:`plot_fold`. Returns a ``plotly.graph_objects.Figure``.

    Example:
      >>> fig = plotly_fold(result, color="strain")   # doctest: +SKIP
      >>> save_html(fig, "fold.html")                 # doctest: +SKIP
    """
    go = require("plotly")  # the module, imported here: plotly is optional
    pattern, x, _, _ = unpack(result_or_positions, pattern)
    values, label = color_values(color, result_or_positions, pattern, percent)
    tri = pattern.mesh.triangles
    mesh_kw: dict[str, Any] = dict(
        x=x[:, 0],
        y=x[:, 1],
        z=x[:, 2],
        i=tri[:, 0],
        j=tri[:, 1],
        k=tri[:, 2],
        flatshading=True,
        name="faces",
        lighting=dict(ambient=0.45, diffuse=0.6, specular=0.05, roughness=0.9),
    )
    if values is None:
        mesh_kw["color"] = PAPER[0]
    else:
        mesh_kw.update(
            intensity=values,
            intensitymode="cell",
            colorscale="Viridis",
            cmin=0.0,
            colorbar=dict(title=label),
        )
    data = [go.Mesh3d(**mesh_kw)]
    if show_creases:
        for letter, seg in crease_segments(pattern, x, show_facets).items():
            pts = np.concatenate([seg, np.full((len(seg), 1, 3), np.nan)], axis=1).reshape(-1, 3)
            data.append(
                go.Scatter3d(
                    x=pts[:, 0],
                    y=pts[:, 1],
                    z=pts[:, 2],
                    mode="lines",
                    name=ASSIGNMENT_NAMES[letter],
                    line=dict(color=ASSIGNMENT_COLORS[letter], width=4 if letter in "MVC" else 2),
                    hoverinfo="skip",
                )
            )
    fig = go.Figure(data=data)
    hidden = dict(visible=False)
    fig.update_layout(
        title=pattern.name,
        scene=dict(aspectmode="data", xaxis=hidden, yaxis=hidden, zaxis=hidden),
        margin=dict(l=0, r=0, t=40, b=0),
    )
    return fig


def save_html(
    fig_or_result: go.Figure | FoldResult, path: str | os.PathLike, **plotly_kwargs: Any
) -> Path:
    """Write a plotly figure (or :func:`plotly_fold` of a result) to a self-contained HTML file
    that works offline (plotly.js inlined, about 5 MB), atomically. Returns the path.

    Example:
      >>> save_html(result, "fold.html", color="fold_angle_error")   # doctest: +SKIP
    """
    fig = fig_or_result
    if isinstance(fig_or_result, FoldResult):
        fig = plotly_fold(fig_or_result, **plotly_kwargs)
    else:
        require("plotly")
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.write_html(str(tmp), include_plotlyjs=True, full_html=True)
    return path
