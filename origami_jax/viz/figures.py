"""matplotlib figures: the folded sheet in 3-D (shaded faces, creases, a colour bar, framed)
and the crease pattern in 2-D."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from origami_jax.fold import FoldResult
from origami_jax.pattern import CreasePattern
from origami_jax.viz.colors import (
    ASSIGNMENT_COLORS,
    ASSIGNMENT_NAMES,
    ORDER,
    PAPER,
    color_values,
    crease_segments,
    unpack,
)
from origami_jax.viz.extras import require
from origami_jax.viz.hidden import visible_pieces
from origami_jax.viz.views import camera, view_vector

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["plot_fold", "plot_pattern"]

_WIDTH_3D = {"M": 1.6, "V": 1.6, "F": 0.5, "B": 1.2, "C": 1.6, "U": 1.2, "J": 1.2}
_WIDTH_2D = {"M": 1.4, "V": 1.4, "F": 0.8, "B": 1.8, "C": 1.4, "U": 1.0, "J": 1.0}


def _shade(x: np.ndarray, tri: np.ndarray, base: np.ndarray | None, elev: float, azim: float):
    """(T, 4) RGBA face colours: Lambert shading from a light above-left of the camera.

    ``base`` (T, 4) colours; ``None`` paints the paper's two sides (:data:`PAPER`) by which
    side faces the camera. Data colours are shaded mildly so the colour scale stays readable.
    """
    from matplotlib.colors import to_rgba

    p = x[tri]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    view = view_vector(elev, azim)
    side = np.where(n @ view >= 0, 1.0, -1.0)  # the normal of the side the camera sees
    light = view_vector(elev + 35, azim - 40)
    lambert = np.clip((n * side[:, None]) @ light, 0.0, 1.0)
    if base is None:
        front, back = np.array(to_rgba(PAPER[0])), np.array(to_rgba(PAPER[1]))
        base = np.where(side[:, None] > 0, front, back)
        intensity = 0.45 + 0.55 * lambert
    else:
        intensity = 0.8 + 0.2 * lambert
    out = np.array(base, dtype=np.float64, copy=True)
    out[:, :3] *= intensity[:, None]
    return out


def _axes_fractions(ax, points: np.ndarray) -> np.ndarray:
    """(N, 2) where ``points`` (N, 3) fall in ``ax``'s box (0 to 1 inside), as drawn now."""
    ax.apply_aspect()  # a 3-D axes draws in a square inside its position
    m = np.asarray(ax.get_proj())
    h = m @ np.column_stack([points, np.ones(len(points))]).T
    xy = (h[:2] / h[3]).T  # the 2-D data coordinates mplot3d draws at
    return ax.transAxes.inverted().transform(ax.transData.transform(xy))


def frame(ax, points: np.ndarray, margin: float = 0.04, box: bool = False) -> None:
    """Equal-aspect limits that hold all ``points`` (N, 3), centred and zoomed so that their
    picture from ``ax``'s camera fills its box up to ``margin`` on each side (nothing cut off
    at the edges, nothing drawn over a colour bar beside it); ``box``: the limits' box and its
    labels framed by matplotlib instead (for an axes drawn with its axes)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    span = float(np.max(hi - lo)) or 1.0

    def limits(centre: np.ndarray, zoom: float) -> None:
        # the box holds every point (an axes drawn shows them inside it); a flat sheet's box
        # keeps some depth
        half = np.maximum(np.maximum(hi - centre, centre - lo), 0.02 * span)
        ax.set_xlim(centre[0] - half[0], centre[0] + half[0])
        ax.set_ylim(centre[1] - half[1], centre[1] + half[1])
        ax.set_zlim(centre[2] - half[2], centre[2] + half[2])
        ax.set_box_aspect(tuple(half), zoom=zoom)

    # move the box's centre along the picture's plane (the projection's least-squares inverse)
    # until the points' picture is centred in the axes, and zoom until it fills them
    centre, zoom = (lo + hi) / 2, 1.0
    limits(centre, zoom)
    if box:
        return
    for _ in range(8):  # orthographic: two or three steps
        f = _axes_fractions(ax, np.vstack([points, centre, centre + np.eye(3) * span]))
        f, probe = f[: len(points)], f[len(points) :]
        middle = (f.min(axis=0) + f.max(axis=0)) / 2
        # the picture's size against the room there is
        reach = float(np.max(f.max(axis=0) - f.min(axis=0))) / (1 - 2 * margin)
        done = np.max(np.abs(middle - 0.5)) < 1e-3 and abs(reach - 1) < 1e-3
        if done or reach == 0:  # (0: every point on one spot: nothing to zoom to)
            break
        jac = (probe[1:] - probe[0]).T / span  # (2, 3): axes fractions per unit length
        centre = centre + np.linalg.pinv(jac) @ (middle - 0.5)
        zoom /= reach
        limits(centre, zoom)


def draw_fold(
    ax, pattern, x, values, norm, cmap, show_creases, show_facets, elev, azim, hide_occluded
):
    """Faces (one Poly3DCollection) and creases (a Line3DCollection per letter) on ``ax``."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    tri = pattern.mesh.triangles
    base = None if values is None else cmap(norm(values))
    colours = _shade(x, tri, base, elev, azim)
    # edges in the face colour hide the hairline seams between a face's triangles
    faces = Poly3DCollection(
        x[tri], facecolors=colours, edgecolors=colours, linewidths=0.3, zorder=1
    )
    faces.set_label("faces")
    ax.add_collection3d(faces)
    lines = {}
    if show_creases:
        view = view_vector(elev, azim)
        thin = float(np.clip(np.sqrt(600 / pattern.mesh.num_edges), 0.35, 1.0))  # dense: finer
        for letter, segments in crease_segments(pattern, x, show_facets).items():
            if hide_occluded:
                segments = visible_pieces(segments, x[tri], view)
            if not len(segments):  # every such crease hidden (a flat-folded base from above)
                continue
            lc = Line3DCollection(
                segments,
                colors=ASSIGNMENT_COLORS[letter],
                linewidths=_WIDTH_3D[letter] * thin,
                # over the faces: matplotlib sorts no lines among polygons, so the hidden parts
                # are cut away above instead
                zorder=2,
            )
            lc.set_label(ASSIGNMENT_NAMES[letter])
            ax.add_collection3d(lc)
            lines[letter] = lc
    return faces, lines


def setup_3d(ax, elev: float, azim: float, show_axes: bool, proj_type: str) -> None:
    ax.computed_zorder = False  # keep creases (zorder 2) over faces (zorder 1)
    ax.view_init(elev=elev, azim=azim)
    ax.set_proj_type(proj_type)
    if show_axes:
        ax.set_xlabel("x")
        ax.set_ylabel("y")
        ax.set_zlabel("z")
    else:
        ax.set_axis_off()


def colour_bar(ax, norm, cmap, label: str) -> None:
    """A colour bar in an axes of its own, taken from ``ax``'s right side (before the sheet is
    framed in what is left); its ticks written out (``%.3g``), not with a ``1e-13`` multiplier
    above the bar that would reach over the sheet's axes."""
    from matplotlib.cm import ScalarMappable

    ax.figure.colorbar(
        ScalarMappable(norm, cmap), ax=ax, shrink=0.6, pad=0.02, label=label, format="%.3g"
    )


def plot_fold(
    result_or_positions: FoldResult | np.ndarray,
    pattern: CreasePattern | None = None,
    ax: Axes | None = None,
    color: str | np.ndarray | None = None,
    show_creases: bool = True,
    show_facets: bool = False,
    *,
    percent: float | None = None,
    elev: float | None = None,
    azim: float | None = None,
    cmap: str = "viridis",
    vmax: float | None = None,
    title: str | None = None,
    show_axes: bool = False,
    proj_type: str = "ortho",
    hide_occluded: bool = True,
    figsize: tuple[float, float] = (6.0, 5.0),
) -> Figure:
    """The folded sheet in 3-D: shaded faces and creases in Origami Simulator's colours.

    Args:
      result_or_positions: a :class:`~origami_jax.FoldResult`, or positions (V, 3) of the mesh
        vertices or of the pattern's vertices (then ``pattern`` is needed).
      pattern: the crease pattern (default: the result's).
      ax: a 3-D axes to draw on (default: a new figure).
      color: ``None`` (paper: cream front, blue back, Lambert-shaded from the face normals),
        ``"strain"`` (max ``|l/l0 - 1|`` of each face's bars), ``"fold_angle_error"`` (max
        ``|rho - percent * target|`` of the creases around each face, radians) or (T,) values
        per mesh triangle; with a colour bar.
      show_creases: draw the creases (one ``Line3DCollection`` per assignment).
      show_facets: also draw facet creases and triangulation edges (thin yellow).
      percent: fold percent the fold-angle error is measured against (default: the result's,
        or 1 for positions).
      elev, azim: camera angles in degrees (matplotlib's ``view_init``); default
        :func:`default_view`: matplotlib's (30, -60), or along the sheet's normal when it is
        flat, so that a flat-folded result is not seen edge-on.
      vmax: upper end of the colour scale (default: the largest value).
      proj_type: ``"ortho"`` or ``"persp"``.
      hide_occluded: cut away the parts of creases that faces hide from this camera
        (matplotlib draws lines over polygons; exact for ``"ortho"``; the picture is right for
        this view only). ``False`` keeps every crease whole (one segment per mesh edge).

    Returns:
      The matplotlib figure (its axes holds one ``Poly3DCollection`` with one polygon per mesh
      triangle; equal aspect; the sheet's picture centred, filling the axes up to a margin; a
      colour bar in an axes of its own beside it).

    Example:
      >>> import origami_jax as oj
      >>> fig = plot_fold(oj.fold(oj.patterns.miura_ori(3, 3)), color="strain")  # doctest: +SKIP
      >>> fig.savefig("miura.png", dpi=150)                                     # doctest: +SKIP
    """
    require("matplotlib")
    import matplotlib.pyplot as plt
    from matplotlib import colormaps
    from matplotlib.colors import Normalize

    pattern, x, _, _ = unpack(result_or_positions, pattern)
    values, label = color_values(color, result_or_positions, pattern, percent)
    if ax is None:
        fig = plt.figure(figsize=figsize)
        ax = fig.add_subplot(projection="3d")
        # room on the right for a colour bar's label
        fig.subplots_adjust(left=0, right=1 if color is None else 0.9, bottom=0, top=0.94)
    elif getattr(ax, "name", None) != "3d":
        raise ValueError("ax: plot_fold needs a 3-D axes (add_subplot(projection='3d'))")
    fig = ax.figure
    elev, azim = camera(x, elev, azim)
    setup_3d(ax, elev, azim, show_axes, proj_type)
    cm = colormaps[cmap]
    norm = None
    if values is not None:
        top = float(np.max(values)) if vmax is None else float(vmax)
        norm = Normalize(0.0, top if top > 0 else 1.0)
        colour_bar(ax, norm, cm, label)
    draw_fold(
        ax, pattern, x, values, norm, cm, show_creases, show_facets, elev, azim, hide_occluded
    )
    frame(ax, x, box=show_axes)
    if title is None:
        title = pattern.name
        if isinstance(result_or_positions, FoldResult):
            title += f" ({100 * result_or_positions.percent:.0f} %)"
    if title:
        ax.set_title(title)
    return fig


# -- matplotlib: the crease pattern ------------------------------------------------------------


def plot_pattern(
    pattern: CreasePattern,
    ax: Axes | None = None,
    show_facets: bool = True,
    *,
    title: str | None = None,
    figsize: tuple[float, float] | None = None,
) -> Figure:
    """The crease pattern in 2-D, one ``LineCollection`` per assignment in Origami Simulator's
    colours; a crease's opacity grows with its target ``|rho| / pi`` (as in its SVG files).

    Args:
      pattern: the crease pattern.
      ax: a 2-D axes to draw on (default: a new figure).
      show_facets: draw the pattern's facet (``F``) creases (triangulation edges never).

    Example:
      >>> import origami_jax as oj
      >>> plot_pattern(oj.patterns.seed_waterbomb()).savefig("cp.png")   # doctest: +SKIP
    """
    require("matplotlib")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection
    from matplotlib.colors import to_rgba

    v = pattern.vertices[:, :2]
    if ax is None:
        if figsize is None:  # the pattern's proportions, plus room for the legend
            w, h = np.ptp(v, axis=0)
            figsize = (6.5, float(np.clip(4.5 * h / max(w, 1e-300) + 0.8, 2.0, 6.0)))
        fig, ax = plt.subplots(figsize=figsize)
        fig.set_layout_engine("tight")  # our figure: the caller's keeps its layout
    fig = ax.figure
    letters = pattern.assignments
    driven = np.isin(letters, ["M", "V"]) | ((letters == "U") & (pattern.fold_angles != 0))
    letters = np.where(
        driven & (letters == "U"), np.where(pattern.fold_angles < 0, "M", "V"), letters
    )
    for letter in ORDER:
        mask = letters == letter
        if not mask.any() or (letter == "F" and not show_facets):
            continue
        rgba = np.tile(to_rgba(ASSIGNMENT_COLORS[letter]), (int(mask.sum()), 1))
        if letter in "MV":
            rgba[:, 3] = 0.3 + 0.7 * np.abs(pattern.fold_angles[mask]) / np.pi
        lc = LineCollection(
            v[pattern.edges[mask]],
            colors=rgba,
            linewidths=_WIDTH_2D[letter],
            label=f"{ASSIGNMENT_NAMES[letter]} ({int(mask.sum())})",
            capstyle="round",
        )
        ax.add_collection(lc)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.margins(0.03)
    ax.set_xticks([])
    ax.set_yticks([])
    for spine in ax.spines.values():
        spine.set_visible(False)
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8, frameon=False)
    ax.set_title(pattern.name if title is None else title)
    return fig
