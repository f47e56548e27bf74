"""Pictures of crease patterns and folded states: matplotlib figures, plotly HTML, animations.

matplotlib, plotly and pillow are optional (``pip install "origami-jax[viz]"``): they are
imported inside the functions, so ``import origami_jax.viz`` works without them and a function
that needs a missing one raises :class:`ImportError` naming the extra.

Colours are Origami Simulator's, by FOLD assignment: mountain red ``#ff0000``, valley blue
``#0000ff``, facet yellow ``#ffff00`` (hidden in 3-D unless ``show_facets``), border black, cut
green ``#00ff00``, unassigned / join (an undriven hinge) magenta ``#ff00ff``. An unassigned
crease with a non-zero target folds like a mountain or valley and is drawn as one.

* :func:`plot_fold`: the folded sheet in 3-D (shaded faces, creases), optionally coloured per
  face by ``"strain"`` or ``"fold_angle_error"``;
* :func:`plot_pattern`: the crease pattern in 2-D;
* :func:`plotly_fold`, :func:`save_html`: an interactive 3-D view, as a self-contained HTML file;
* :func:`plot_history`: error against run time, from a result or a benchmark CSV;
* :func:`animate_fold`: the fold from flat to folded as a GIF or MP4.

Example:
  >>> import origami_jax as oj
  >>> from origami_jax import viz
  >>> result = oj.fold(oj.patterns.miura_ori(3, 3))                  # doctest: +SKIP
  >>> viz.plot_fold(result, color="strain").savefig("miura.png")    # doctest: +SKIP
  >>> viz.save_html(result, "miura.html")                           # doctest: +SKIP
  >>> viz.animate_fold(oj.patterns.miura_ori(3, 3), "miura.gif")    # doctest: +SKIP
"""

from __future__ import annotations

import contextlib
import csv
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from origami_jax.fold import FoldResult
from origami_jax.io.fold import atomic_path
from origami_jax.pattern import CreasePattern

if TYPE_CHECKING:  # pragma: no cover
    import plotly.graph_objects as go
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "ASSIGNMENT_COLORS",
    "ASSIGNMENT_NAMES",
    "edge_assignments",
    "face_values",
    "default_view",
    "plot_fold",
    "plot_pattern",
    "plotly_fold",
    "save_html",
    "plot_history",
    "fold_frames",
    "animate_fold",
]

ASSIGNMENT_COLORS = {
    "M": "#ff0000",
    "V": "#0000ff",
    "F": "#ffff00",
    "B": "#000000",
    "C": "#00ff00",
    "U": "#ff00ff",
    "J": "#ff00ff",
}
ASSIGNMENT_NAMES = {
    "M": "mountain",
    "V": "valley",
    "F": "facet",
    "B": "border",
    "C": "cut",
    "U": "unassigned",
    "J": "join",
}
# drawing order: facets under everything, mountains and valleys on top
_ORDER = "FJUBCVM"
_WIDTH_3D = {"M": 1.6, "V": 1.6, "F": 0.5, "B": 1.2, "C": 1.6, "U": 1.2, "J": 1.2}
_WIDTH_2D = {"M": 1.4, "V": 1.4, "F": 0.8, "B": 1.8, "C": 1.4, "U": 1.0, "J": 1.0}
# paper seen from above (front) and from below (back) in the flat pattern's orientation
PAPER = ("#f1e9d2", "#a9c1df")
COLOR_LABELS = {"strain": "strain |l/l0 - 1|", "fold_angle_error": "fold-angle error (rad)"}
HISTORY_METRICS = ("fold_angle_error_max", "strain_max", "grad_norm_rel")
_EXTRA = 'pip install "origami-jax[viz]"'


# -- optional imports -------------------------------------------------------------------------


def _matplotlib():
    try:
        import matplotlib
        import matplotlib.pyplot  # noqa: F401  (the figure manager, for plt.figure)
    except ImportError as exc:
        raise ImportError(f"this plot needs matplotlib: {_EXTRA}") from exc
    return matplotlib


def _plotly():
    try:
        import plotly.graph_objects as go
    except ImportError as exc:
        raise ImportError(f"this figure needs plotly: {_EXTRA}") from exc
    return go


# -- data: per-edge letters, per-face values --------------------------------------------------


def edge_assignments(pattern: CreasePattern) -> np.ndarray:
    """(E_mesh,) the letter each mesh edge is drawn as.

    The pattern edge's assignment; ``"F"`` for triangulation edges; an unassigned (``U``) crease
    with a non-zero target becomes ``"M"`` or ``"V"`` by the target's sign; both sides of a cut
    are ``"C"``.
    """
    mesh = pattern.mesh
    src = mesh.source_edge
    letters = np.where(src >= 0, pattern.assignments[np.maximum(src, 0)], "F")
    driven_u = (letters == "U") & (mesh.role == "driven")
    return np.where(driven_u, np.where(mesh.target < 0, "M", "V"), letters)


def _mesh_positions(x: Any, pattern: CreasePattern) -> np.ndarray:
    """(V_mesh, 3) positions from mesh positions or pattern positions (copied across cuts)."""
    x = np.asarray(x, np.float64)
    mesh = pattern.mesh
    if x.ndim != 2 or x.shape[1] not in (2, 3):
        raise ValueError(f"positions: expected shape (V, 3), got {x.shape}")
    if x.shape[1] == 2:
        x = np.concatenate([x, np.zeros((len(x), 1))], axis=1)
    if len(x) == mesh.num_vertices:
        return x
    if len(x) == pattern.num_vertices:
        return x[mesh.source_vertex]
    raise ValueError(
        f"positions: {len(x)} rows, but the pattern has {pattern.num_vertices} vertices "
        f"({mesh.num_vertices} in its mesh)"
    )


def _unpack(result_or_positions: Any, pattern: CreasePattern | None):
    """(pattern, mesh positions, fold angles or None, percent)."""
    if isinstance(result_or_positions, FoldResult):
        r = result_or_positions
        pattern = pattern or r.pattern
        return pattern, _mesh_positions(r.positions, pattern), r.fold_angles, r.percent
    if pattern is None:
        raise ValueError("plotting positions needs their pattern: pass pattern=...")
    return pattern, _mesh_positions(result_or_positions, pattern), None, 1.0


def _triangle_edges(mesh) -> np.ndarray:
    """(T, 3) mesh edge index of each triangle side."""
    n = mesh.num_vertices
    e = np.sort(mesh.edges, axis=1)
    keys = e[:, 0] * n + e[:, 1]
    order = np.argsort(keys)
    tri = mesh.triangles
    sides = np.stack([tri, np.roll(tri, -1, axis=1)], axis=-1)  # (T, 3, 2)
    sides = np.sort(sides, axis=-1)
    pos = np.searchsorted(keys[order], sides[..., 0] * n + sides[..., 1])
    return order[pos]


def _dihedrals(x: np.ndarray, hinges: np.ndarray) -> np.ndarray:
    """(E,) fold angles in (-pi, pi], valley positive (numpy twin of geometry.fold_angles)."""
    p = x[np.maximum(hinges, 0)]
    e = p[:, 1] - p[:, 0]
    e = e / np.maximum(np.linalg.norm(e, axis=1, keepdims=True), 1e-300)
    n_left = np.cross(e, p[:, 2] - p[:, 0])
    n_right = np.cross(p[:, 3] - p[:, 0], e)
    sin_part = np.sum(np.cross(n_right, n_left) * e, axis=1)
    cos_part = np.sum(n_left * n_right, axis=1)
    angle = np.arctan2(sin_part, cos_part)
    return np.where((hinges[:, 2] < 0) | (hinges[:, 3] < 0), 0.0, angle)


def face_values(
    result_or_positions: Any,
    quantity: str,
    pattern: CreasePattern | None = None,
    percent: float | None = None,
) -> np.ndarray:
    """(T,) a value per mesh triangle, the same for all triangles of one pattern face.

    ``quantity``: ``"strain"``, the face's largest bar strain ``max |l / l0 - 1|`` (its sides and
    its triangulation edges); ``"fold_angle_error"``, the largest ``|rho - percent * target|``
    (radians) of the driven creases around the face (0 for a face without one).

    Example:
      >>> import origami_jax as oj
      >>> cp = oj.patterns.single_crease()
      >>> face_values(cp.mesh.vertices, "fold_angle_error", cp).round(3)   # flat: error pi/2
      array([1.571, 1.571, 1.571, 1.571])
    """
    pattern, x, angles, pct = _unpack(result_or_positions, pattern)
    pct = pct if percent is None else float(percent)
    mesh = pattern.mesh
    tri_edges = _triangle_edges(mesh)
    if quantity == "strain":
        l0 = np.linalg.norm(np.diff(mesh.vertices[mesh.edges], axis=1)[:, 0], axis=1)
        length = np.linalg.norm(np.diff(x[mesh.edges], axis=1)[:, 0], axis=1)
        per_edge = np.abs(length / l0 - 1.0)
    elif quantity == "fold_angle_error":
        goal = pct * mesh.target
        if angles is None:  # the branch nearest the goal, as the energy unwraps it
            raw = _dihedrals(x, mesh.hinges)
            angles = goal / 2 + (raw - goal / 2 + np.pi) % (2 * np.pi) - np.pi
        per_edge = np.where(mesh.role == "driven", np.abs(np.asarray(angles) - goal), 0.0)
    else:
        raise ValueError(f"color: expected 'strain' or 'fold_angle_error', got {quantity!r}")
    per_triangle = per_edge[tri_edges].max(axis=1)
    per_face = np.zeros(pattern.num_faces)
    np.maximum.at(per_face, mesh.triangle_face, per_triangle)
    return per_face[mesh.triangle_face]


# -- matplotlib: the folded sheet --------------------------------------------------------------


def _view_vector(elev: float, azim: float) -> np.ndarray:
    """Unit vector from the scene towards the camera of a 3-D axes (degrees)."""
    e, a = np.radians(elev), np.radians(azim)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def _shade(x: np.ndarray, tri: np.ndarray, base: np.ndarray | None, elev: float, azim: float):
    """(T, 4) RGBA face colours: Lambert shading from a light above-left of the camera.

    ``base`` (T, 4) colours; ``None`` paints the paper's two sides (:data:`PAPER`) by which
    side faces the camera. Data colours are shaded mildly so the colour scale stays readable.
    """
    from matplotlib.colors import to_rgba

    p = x[tri]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    view = _view_vector(elev, azim)
    side = np.where(n @ view >= 0, 1.0, -1.0)  # the normal of the side the camera sees
    light = _view_vector(elev + 35, azim - 40)
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


# the default camera (matplotlib's) for a sheet that is not flat
DEFAULT_VIEW = (30.0, -60.0)
# a sheet whose RMS thickness off its best-fit plane is under this fraction of its smaller RMS
# size in that plane counts as flat: the default camera may see it edge-on, as a line
_FLAT = 0.02


def default_view(points: np.ndarray) -> tuple[float, float]:
    """The camera ``(elev, azim)`` (degrees) for a sheet at ``points`` (N, 3): along the normal
    of its best-fit plane when it is (nearly) flat (a flat-folded base, the unfolded sheet),
    from the side :data:`DEFAULT_VIEW` sees; else :data:`DEFAULT_VIEW`.

    Example:
      >>> import origami_jax as oj
      >>> default_view(oj.patterns.miura_ori(2, 2).mesh.vertices)   # flat: seen from above
      (90.0, -90.0)
    """
    x = np.asarray(points, np.float64)
    if x.shape[1] == 2:  # a flat pattern's 2-D coordinates
        return (90.0, -90.0)
    _, sv, vt = np.linalg.svd(x - x.mean(axis=0), full_matrices=False)
    if len(sv) < 3 or sv[2] > _FLAT * sv[1]:
        return DEFAULT_VIEW
    normal = vt[2] if vt[2] @ _view_vector(*DEFAULT_VIEW) >= 0 else -vt[2]
    elev = float(np.degrees(np.arcsin(np.clip(normal[2], -1.0, 1.0))))
    if abs(normal[2]) > np.cos(np.radians(1.0)):  # from above: x to the right, y up, as in 2-D
        return (90.0 if normal[2] > 0 else -90.0, -90.0)
    return (elev, float(np.degrees(np.arctan2(normal[1], normal[0]))))


def _view(points: np.ndarray, elev: float | None, azim: float | None) -> tuple[float, float]:
    """The camera: as given; :func:`default_view` when neither angle is given."""
    if elev is None and azim is None:
        return default_view(points)
    return (DEFAULT_VIEW[0] if elev is None else elev, DEFAULT_VIEW[1] if azim is None else azim)


def _axes_fractions(ax, points: np.ndarray) -> np.ndarray:
    """(N, 2) where ``points`` (N, 3) fall in ``ax``'s box (0 to 1 inside), as drawn now."""
    ax.apply_aspect()  # a 3-D axes draws in a square inside its position
    m = np.asarray(ax.get_proj())
    h = m @ np.column_stack([points, np.ones(len(points))]).T
    xy = (h[:2] / h[3]).T  # the 2-D data coordinates mplot3d draws at
    return ax.transAxes.inverted().transform(ax.transData.transform(xy))


def _frame(ax, points: np.ndarray, margin: float = 0.04, box: bool = False) -> None:
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


def _crease_segments(pattern: CreasePattern, x: np.ndarray, show_facets: bool):
    """{letter: (n, 2, 3) segments} in drawing order."""
    letters = edge_assignments(pattern)
    edges = pattern.mesh.edges
    out = {}
    for letter in _ORDER:
        if letter == "F" and not show_facets:
            continue
        mask = letters == letter
        if mask.any():
            out[letter] = x[edges[mask]]
    return out


def _occluded(points: np.ndarray, corners: np.ndarray, view: np.ndarray) -> np.ndarray:
    """(N,) whether the ray from each point (N, 3) towards the camera (direction ``view``) hits
    one of the triangles ``corners`` (T, 3, 3).

    The rays are parallel, so points and triangles are projected on the image plane and binned
    in a grid of cells about a triangle wide; each point is tested (Moller-Trumbore) only
    against the triangles whose image box overlaps its cell: O(N) tests, not O(N T).
    """
    helper = np.array([0.0, 0.0, 1.0]) if abs(view[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e_u = np.cross(view, helper)
    e_u /= np.linalg.norm(e_u)
    basis = np.stack([e_u, np.cross(view, e_u)], axis=1)  # (3, 2): image-plane coordinates
    p2, c2 = points @ basis, corners @ basis
    lo, hi = c2.min(axis=1), c2.max(axis=1)
    origin = np.minimum(lo.min(axis=0), p2.min(axis=0))
    extent = np.maximum(hi.max(axis=0), p2.max(axis=0)) - origin
    cell = max(float(np.median((hi - lo).max(axis=1))), float(extent.max()) / 2000, 1e-300)
    ny = int(extent[1] // cell) + 1
    first, last = ((lo - origin) // cell).astype(np.int64), ((hi - origin) // cell).astype(np.int64)
    span = last - first + 1  # (T, 2) cells each triangle's box covers
    count = span[:, 0] * span[:, 1]
    tri = np.repeat(np.arange(len(corners)), count)
    local = np.arange(len(tri)) - np.repeat(np.cumsum(count) - count, count)
    cx = first[tri, 0] + local % span[tri, 0]
    cy = first[tri, 1] + local // span[tri, 0]
    order = np.argsort(cx * ny + cy, kind="stable")
    cell_ids, tri = (cx * ny + cy)[order], tri[order]
    # Moller-Trumbore pieces that depend on the triangle only (the direction is shared)
    a = corners[:, 0]
    e1, e2 = corners[:, 1] - a, corners[:, 2] - a
    pvec = np.cross(view, e2)
    det = np.sum(e1 * pvec, axis=1)
    ok = np.abs(det) > 1e-300
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    out = np.zeros(len(points), bool)
    pc = ((p2 - origin) // cell).astype(np.int64)
    pid = pc[:, 0] * ny + pc[:, 1]
    start = np.searchsorted(cell_ids, pid, side="left")
    n_cand = np.searchsorted(cell_ids, pid, side="right") - start
    chunk = 200_000
    for s in range(0, len(points), chunk):
        idx = np.arange(s, min(s + chunk, len(points)))
        k = n_cand[idx]
        pt = np.repeat(idx, k)
        t_ = tri[np.repeat(start[idx], k) + np.arange(len(pt)) - np.repeat(np.cumsum(k) - k, k)]
        tvec = points[pt] - a[t_]
        qvec = np.cross(tvec, e1[t_])
        u = np.sum(tvec * pvec[t_], axis=1) * inv[t_]
        w = (qvec @ view) * inv[t_]
        t = np.sum(qvec * e2[t_], axis=1) * inv[t_]
        hit = ok[t_] & (u > 1e-9) & (w > 1e-9) & (u + w < 1 - 1e-9) & (t > 0)
        out[pt[hit]] = True
    return out


def _visible_pieces(segments: np.ndarray, corners: np.ndarray, view: np.ndarray) -> np.ndarray:
    """The parts of ``segments`` (n, 2, 3) that no triangle hides from an orthographic camera
    looking along ``-view``, as (m, 2, 3) segments (sampled at 16 points a segment, 8 on large
    meshes: a part shorter than that spacing may be missed)."""
    n = len(segments)
    if n == 0:
        return segments
    samples = 16 if n * len(corners) < 1e7 else 8
    size = float(np.ptp(corners.reshape(-1, 3), axis=0).max()) or 1.0
    s = (np.arange(samples) + 0.5) / samples
    start, step = segments[:, :1], segments[:, 1:2] - segments[:, :1]
    # lifted a hair towards the camera: the segment's own triangles are then behind it
    points = (start + s[None, :, None] * step).reshape(-1, 3) + 1e-7 * size * view
    visible = ~_occluded(points, corners, view).reshape(n, samples)
    if visible.all():
        return segments
    padded = np.pad(visible, ((0, 0), (1, 1)))
    change = np.diff(padded.astype(np.int8), axis=1)  # +1 where a visible run starts, -1 ends
    rows, begin = np.nonzero(change == 1)
    _, end = np.nonzero(change == -1)  # row-major order: the k-th end closes the k-th start
    a = start[rows, 0] + (begin / samples)[:, None] * step[rows, 0]
    b = start[rows, 0] + (end / samples)[:, None] * step[rows, 0]
    return np.stack([a, b], axis=1)


def _draw_fold(
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
        view = _view_vector(elev, azim)
        thin = float(np.clip(np.sqrt(600 / pattern.mesh.num_edges), 0.35, 1.0))  # dense: finer
        for letter, segments in _crease_segments(pattern, x, show_facets).items():
            if hide_occluded:
                segments = _visible_pieces(segments, x[tri], view)
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


def _setup_3d(ax, elev: float, azim: float, show_axes: bool, proj_type: str) -> None:
    ax.computed_zorder = False  # keep creases (zorder 2) over faces (zorder 1)
    ax.view_init(elev=elev, azim=azim)
    ax.set_proj_type(proj_type)
    if show_axes:
        ax.set_xlabel("x")
        ax.set_ylabel("y")
        ax.set_zlabel("z")
    else:
        ax.set_axis_off()


def _colour_bar(ax, norm, cmap, label: str) -> None:
    """A colour bar in an axes of its own, taken from ``ax``'s right side (before the sheet is
    framed in what is left); its ticks written out (``%.3g``), not with a ``1e-13`` multiplier
    above the bar that would reach over the sheet's axes."""
    from matplotlib.cm import ScalarMappable

    ax.figure.colorbar(
        ScalarMappable(norm, cmap), ax=ax, shrink=0.6, pad=0.02, label=label, format="%.3g"
    )


def _color_values(color, result_or_positions, pattern, percent):
    if color is None:
        return None, None
    if isinstance(color, str):
        return face_values(result_or_positions, color, pattern, percent), COLOR_LABELS[color]
    values = np.asarray(color, np.float64)
    if values.shape != (len(pattern.mesh.triangles),):
        raise ValueError(
            f"color: expected 'strain', 'fold_angle_error' or ({len(pattern.mesh.triangles)},) "
            f"values per mesh triangle, got shape {values.shape}"
        )
    return values, "value"


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
    _matplotlib()
    import matplotlib.pyplot as plt
    from matplotlib import colormaps
    from matplotlib.colors import Normalize

    pattern, x, _, _ = _unpack(result_or_positions, pattern)
    values, label = _color_values(color, result_or_positions, pattern, percent)
    if ax is None:
        fig = plt.figure(figsize=figsize)
        ax = fig.add_subplot(projection="3d")
        # room on the right for a colour bar's label
        fig.subplots_adjust(left=0, right=1 if color is None else 0.9, bottom=0, top=0.94)
    elif getattr(ax, "name", None) != "3d":
        raise ValueError("ax: plot_fold needs a 3-D axes (add_subplot(projection='3d'))")
    fig = ax.figure
    elev, azim = _view(x, elev, azim)
    _setup_3d(ax, elev, azim, show_axes, proj_type)
    cm = colormaps[cmap]
    norm = None
    if values is not None:
        top = float(np.max(values)) if vmax is None else float(vmax)
        norm = Normalize(0.0, top if top > 0 else 1.0)
        _colour_bar(ax, norm, cm, label)
    _draw_fold(
        ax, pattern, x, values, norm, cm, show_creases, show_facets, elev, azim, hide_occluded
    )
    _frame(ax, x, box=show_axes)
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
    _matplotlib()
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
    for letter in _ORDER:
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


# -- plotly ------------------------------------------------------------------------------------


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
    go = _plotly()  # the module, imported here: plotly is optional
    pattern, x, _, _ = _unpack(result_or_positions, pattern)
    values, label = _color_values(color, result_or_positions, pattern, percent)
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
        for letter, seg in _crease_segments(pattern, x, show_facets).items():
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
        _plotly()
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.write_html(str(tmp), include_plotlyjs=True, full_html=True)
    return path


# -- history -----------------------------------------------------------------------------------


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
    _matplotlib()
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


# -- animation ---------------------------------------------------------------------------------


def fold_frames(
    pattern: CreasePattern,
    frames: int = 30,
    solver: str = "newton",
    percent: float = 1.0,
    **fold_kwargs: Any,
) -> list[FoldResult]:
    """The fold at percents ``linspace(0, percent, frames)`` by continuation: each frame is
    ``fold(pattern, percent=p, start=previous positions)`` (the first from flat), so every frame
    reuses one compiled solver and starts near its answer.

    Returns:
      One :class:`~origami_jax.FoldResult` per frame (the first is the flat sheet).

    Example:
      >>> results = fold_frames(oj.patterns.miura_ori(3, 3), frames=10)   # doctest: +SKIP
      >>> [r.converged for r in results]                                  # doctest: +SKIP
    """
    from origami_jax.fold import fold

    if int(frames) < 2:
        raise ValueError(f"frames: need at least 2, got {frames}")
    out: list[FoldResult] = []
    start = pattern.mesh.vertices
    for p in np.linspace(0.0, percent, int(frames)):
        out.append(fold(pattern, percent=float(p), solver=solver, start=start, **fold_kwargs))
        start = out[-1].positions
    return out


def _movie_rc(path: Path) -> dict[str, str]:
    """matplotlib settings that let a movie writer write ``path`` (.gif: none; .mp4: where
    ffmpeg is), or a clear error before any work is done."""
    from matplotlib import animation

    suffix = path.suffix.lower()
    if suffix == ".gif":
        return {}
    if suffix != ".mp4":
        raise ValueError(f"{path}: unsupported animation format {path.suffix!r} (use .gif or .mp4)")
    if animation.writers.is_available("ffmpeg"):
        return {}
    try:
        import imageio_ffmpeg
    except ImportError:
        raise RuntimeError(
            f"{path}: writing MP4 needs ffmpeg: install it (e.g. apt install ffmpeg) or "
            "pip install imageio-ffmpeg; or write a .gif"
        ) from None
    return {"animation.ffmpeg_path": imageio_ffmpeg.get_ffmpeg_exe()}


@contextlib.contextmanager
def _writer(path: Path, fps: int):
    """A matplotlib movie writer for ``path``'s suffix (.gif: pillow, .mp4: ffmpeg)."""
    from matplotlib import animation, rc_context

    rc = _movie_rc(path)
    if path.suffix.lower() == ".gif":
        yield animation.PillowWriter(fps=fps)
        return
    with rc_context(rc):  # the ffmpeg path for this save only
        # yuv420p (what players expect) needs even sizes: pad by a pixel where odd
        pad = ["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-pix_fmt", "yuv420p"]
        yield animation.FFMpegWriter(fps=fps, codec="h264", extra_args=pad)


def animate_fold(
    pattern: CreasePattern,
    path: str | os.PathLike,
    frames: int | Sequence[np.ndarray] = 30,
    fps: int = 15,
    solver: str = "newton",
    *,
    percent: float = 1.0,
    color: str | None = None,
    show_facets: bool = False,
    elev: float | None = None,
    azim: float | None = None,
    cmap: str = "viridis",
    dpi: int = 100,
    figsize: tuple[float, float] = (6.0, 5.0),
    proj_type: str = "ortho",
    hide_occluded: bool = True,
    **fold_kwargs: Any,
) -> list[np.ndarray]:
    """Animate the fold from flat to ``percent`` and write it to ``path`` (.gif or .mp4).

    Args:
      pattern: the crease pattern.
      path: ``.gif`` (pillow) or ``.mp4`` (ffmpeg: a system ``ffmpeg`` or the
        ``imageio-ffmpeg`` package); written atomically.
      frames: a number of frames, folded by continuation in fold percent (see
        :func:`fold_frames`, ``solver`` and ``fold_kwargs`` go to :func:`~origami_jax.fold`),
        or precomputed frames: results of :func:`fold_frames`, a fold's path
        (``fold(...).frames``, the states it followed from flat) or (V, 3) position arrays
        (e.g. a dynamics trajectory).
      fps: frames per second.
      color: ``None``, ``"strain"`` or ``"fold_angle_error"`` (against each frame's percent,
        one colour scale for all frames).
      elev, azim: camera angles in degrees; default: :func:`default_view` of the last frame.

    The camera frames the union of all frames (fixed limits), so the sheet never leaves it.

    Returns:
      The frames' mesh positions, a list of (V_mesh, 3) arrays.

    Example:
      >>> animate_fold(oj.patterns.miura_ori(4, 4), "miura.gif", frames=24)  # doctest: +SKIP
    """
    _matplotlib()
    from matplotlib import colormaps
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    path = Path(path)
    if color is not None and color not in COLOR_LABELS:
        raise ValueError(f"color: expected 'strain' or 'fold_angle_error', got {color!r}")
    # the writer first: a missing ffmpeg fails before any folding
    with _writer(path, fps) as writer:
        if isinstance(frames, (int, np.integer)):
            frames = fold_frames(pattern, int(frames), solver, percent, **fold_kwargs)
        frames = list(frames)
        if not frames:
            raise ValueError("frames: empty")
        # results and a fold's path frames (``result.frames``) carry positions and a percent
        positions = [_mesh_positions(getattr(f, "positions", f), pattern) for f in frames]
        percents = None  # known for results and path frames: titled by percent, else by number
        if all(hasattr(f, "percent") for f in frames):
            percents = np.array([f.percent for f in frames])
        values = None
        cm = colormaps[cmap]
        norm = None
        # a bare Figure (no pyplot): nothing to close, no window, any backend
        fig = Figure(figsize=figsize)
        ax = fig.add_subplot(projection="3d")
        fig.subplots_adjust(left=0, right=1 if color is None else 0.9, bottom=0, top=0.94)
        if color is not None:  # one colour scale for all frames
            pcts = percents if percents is not None else np.full(len(positions), percent)
            values = [
                face_values(x, color, pattern, p) for x, p in zip(positions, pcts, strict=True)
            ]
            top = max(float(np.max(v)) for v in values)
            norm = Normalize(0.0, top if top > 0 else 1.0)
            _colour_bar(ax, norm, cm, COLOR_LABELS[color])
        everything = np.concatenate(positions)
        elev, azim = _view(positions[-1], elev, azim)
        with atomic_path(path) as tmp, writer.saving(fig, str(tmp), dpi):
            for k, x in enumerate(positions):
                ax.clear()
                _setup_3d(ax, elev, azim, False, proj_type)
                v = None if values is None else values[k]
                _draw_fold(
                    ax, pattern, x, v, norm, cm, True, show_facets, elev, azim, hide_occluded
                )
                _frame(ax, everything)
                if percents is None:
                    ax.set_title(f"{pattern.name}  frame {k + 1}/{len(positions)}")
                else:
                    ax.set_title(f"{pattern.name}  {100 * percents[k]:.0f} %")
                writer.grab_frame()
    return positions
