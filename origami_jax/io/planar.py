"""A crease pattern from loose line segments: the planar arrangement of a drawing.

Used by the SVG reader and by FOLD files without ``faces_vertices``. The input is a list of
segments, each with a FOLD assignment letter, a target fold angle and a name for messages; the
output is a validated :class:`~origami_jax.CreasePattern`. Geometry is done by shapely (GEOS):

1. segments shorter than the tolerance are dropped; the rest are noded with
   ``shapely.unary_union(..., grid_size=tol)`` (snap rounding: crossing segments are split at
   their crossing, endpoints closer than the tolerance merge, overlapping pieces dissolve);
   a vertex keeps the exact coordinates of the input endpoint it came from, so snapping moves
   only new crossing points;
2. each noded piece takes the assignment of the input segments it lies on; pieces covered by
   segments with different assignments or angles are an error naming both;
3. faces are the polygons of ``shapely.polygonize`` on the pieces (holes and separate pieces
   included); a face bounded only by border (``B``) pieces that lies inside another face is a
   hole, not paper;
4. pieces with paper on one side only become borders, a border with paper on both sides
   becomes a cut (``C``), and pieces with no paper beside them (dangling lines, lines outside
   the paper) are dropped; each such change is reported as a :class:`PatternWarning`;
5. faces with holes are triangulated (``shapely.constrained_delaunay_triangles``), their new
   sides becoming ``J`` (join) edges; other faces stay polygons.

The tolerance is relative to the drawing's size (its bounding-box diagonal), 1e-6 by default.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
import shapely

from origami_jax.pattern import (
    MAX_COORDINATE,
    CreasePattern,
    PatternError,
    PatternWarning,
    find_root,
)

__all__ = ["pattern_from_segments"]

DEFAULT_TOLERANCE = 1e-6
# a line end that touches nothing is joined to a line within this many tolerances
GAP_FACTOR = 10.0


def _warn(message: str) -> None:
    warnings.warn(message, PatternWarning, stacklevel=3)


def pattern_from_segments(
    starts: np.ndarray,
    ends: np.ndarray,
    assignments: Sequence[str],
    fold_angles: Sequence[float],
    names: Sequence[str],
    *,
    tolerance: float = DEFAULT_TOLERANCE,
    name: str = "pattern",
    vertex_order: np.ndarray | None = None,
) -> CreasePattern:
    """The crease pattern drawn by line segments (see the module docstring).

    Args:
      starts, ends: (S, 2) segment end points.
      assignments: (S,) FOLD letters (``B M V F U C J``).
      fold_angles: (S,) target fold angles in radians (used for ``M``, ``V``, ``U``).
      names: (S,) how messages name each segment, e.g. ``"<line> 3"``.
      tolerance: end points closer than ``tolerance`` times the drawing's diagonal merge.
      name: the pattern's name.
      vertex_order: optional (N, 2) points: vertices at these points come first, in this
        order (a FOLD file's vertices keep their numbers); the others follow in order of
        first use by an edge.

    Raises:
      PatternError: no segments, non-finite coordinates, overlapping segments with different
        assignments, or no face at all.
    """
    p0 = np.asarray(starts, np.float64).reshape(-1, 2)
    p1 = np.asarray(ends, np.float64).reshape(-1, 2)
    letters = list(assignments)
    angles = np.asarray(fold_angles, np.float64).reshape(-1)
    if not len(p0) == len(p1) == len(letters) == len(angles) == len(names):
        raise PatternError("segments: starts, ends, assignments, angles and names differ in length")
    if len(p0) == 0:
        raise PatternError(f"{name}: no line segments to build a pattern from")
    # squares of lengths must stay finite: |coordinates| up to 1e150
    bad = ~(np.abs(np.concatenate([p0, p1], axis=1)) <= MAX_COORDINATE).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise PatternError(
            f"{names[k]}: coordinate {[*p0[k].tolist(), *p1[k].tolist()]} is not finite "
            f"or beyond {MAX_COORDINATE:g}"
        )
    points = np.concatenate([p0, p1])
    diagonal = float(np.linalg.norm(points.max(0) - points.min(0)))
    if diagonal == 0.0:
        raise PatternError(f"{name}: every segment has zero length")
    tol = tolerance * diagonal
    lengths = np.linalg.norm(p1 - p0, axis=1)
    keep = np.flatnonzero(lengths > tol)
    if len(keep) == 0:
        raise PatternError(f"{name}: every segment is shorter than the tolerance")
    p0, p1, angles = p0[keep], p1[keep], angles[keep]
    letters = [letters[k] for k in keep]
    names = [names[k] for k in keep]

    # 1. node (snap rounding on a grid of the tolerance)
    origin = points.min(0)
    ends = np.concatenate([p0, p1]) - origin
    ends = ends[_clusters(ends, tol)]  # end points closer than tol become one
    p0, p1 = ends[: len(p0)] + origin, ends[len(p0) :] + origin
    lines = shapely.linestrings(np.stack([p0 - origin, p1 - origin], axis=1))
    # a grid finer than tol, so snapping moves points by much less than the merge distance
    noded = shapely.unary_union(lines, grid_size=tol / 64)
    coords, pieces = _pieces(noded)
    root = _clusters(coords, tol)
    used, new = np.unique(root, return_inverse=True)
    coords, pieces = _unique_pieces(coords[used], new.reshape(-1)[pieces])
    coords = _restore(coords, ends, tol)

    # 2. assignment of each piece from the input segments it lies on
    sources = _sources(coords, pieces, lines, tol)
    pieces, sources = _join_dangles(coords, pieces, sources, GAP_FACTOR * tol)
    piece_letter, piece_angle = _label(sources, letters, angles, names)
    # pieces in the order of the input segments they come from, then along each segment
    along = np.einsum(
        "pi,pi->p",
        coords[pieces].mean(axis=1) - (p0 - origin)[[s[0] for s in sources]],
        (p1 - p0)[[s[0] for s in sources]],
    )
    order = sorted(range(len(pieces)), key=lambda p: (sources[p][0], along[p]))

    # 3. faces
    piece_lines = shapely.linestrings(coords[pieces])
    polygons = list(shapely.get_parts(shapely.polygonize(piece_lines)))
    # faces thinner than the tolerance are slivers of the noding, not paper
    polygons = [poly for poly in polygons if poly.area > tol * tol]
    if not polygons:
        raise PatternError(f"{name}: the lines enclose no face (is the border closed?)")
    index = {(float(x), float(y)): i for i, (x, y) in enumerate(coords)}
    key_of = {_key(a, b): p for p, (a, b) in enumerate(pieces)}

    def ring_vertices(ring) -> list[int]:
        xy = shapely.get_coordinates(ring)[:-1]
        return [index[(float(x), float(y))] for x, y in xy]

    faces_rings = [
        [ring_vertices(poly.exterior)] + [ring_vertices(r) for r in poly.interiors]
        for poly in polygons
    ]
    paper = _paper_faces(polygons, faces_rings, key_of, piece_letter)
    if not paper:
        raise PatternError(f"{name}: no face of paper (every face is a hole)")

    # 4. faces beside each piece, and the assignments that follow from them
    sides: dict[int, list[int]] = {}
    for f in paper:
        for ring in faces_rings[f]:
            for s in range(len(ring)):
                sides.setdefault(key_of[_key(ring[s], ring[s - 1])], []).append(f)
    kept: list[int] = []
    for p in order:
        fs = sides.get(p, [])
        a, b = coords[pieces[p]] + origin
        where = (
            f"{names[sources[p][0]]}: the piece from ({a[0]:.6g}, {a[1]:.6g}) "
            f"to ({b[0]:.6g}, {b[1]:.6g})"
        )
        if not fs:
            _warn(f"{where}: has no paper beside it (dangling or outside the paper); dropped")
            continue
        if len(fs) == 1 and piece_letter[p] != "B":
            _warn(f"{where}: is assigned {piece_letter[p]} but lies on the paper's edge; made B")
            piece_letter[p], piece_angle[p] = "B", 0.0
        elif len(fs) == 2 and piece_letter[p] == "B":
            piece_letter[p] = "C"  # paper on both sides of an edge of the paper: a cut
        kept.append(p)

    # 5. faces: polygons, or triangles (plus J edges) for faces with holes
    edges = [tuple(pieces[p]) for p in kept]
    edge_letter = [piece_letter[p] for p in kept]
    edge_angle = [float(piece_angle[p]) for p in kept]
    edge_keys = {_key(a, b) for a, b in edges}
    faces: list[list[int]] = []
    for f in paper:
        if len(faces_rings[f]) == 1:
            faces.append(faces_rings[f][0])
            continue
        for tri in shapely.get_parts(shapely.constrained_delaunay_triangles(polygons[f])):
            t = ring_vertices(tri.exterior)
            faces.append(t)
            for s in range(3):
                k = _key(t[s], t[s - 1])
                if k not in edge_keys:
                    edge_keys.add(k)
                    edges.append(k)
                    edge_letter.append("J")
                    edge_angle.append(0.0)

    # renumber the vertices in use, in order of first use by an edge
    used = np.unique(np.asarray(edges).ravel(), return_index=True)
    order = used[0][np.argsort(used[1])]
    if vertex_order is not None:
        hint = {(float(x), float(y)): i for i, (x, y) in enumerate(vertex_order - origin)}
        rank = [hint.get((float(coords[v, 0]), float(coords[v, 1])), len(hint)) for v in order]
        order = order[np.argsort(rank, kind="stable")]
    new = np.full(len(coords), -1, dtype=np.int64)
    new[order] = np.arange(len(order))
    return CreasePattern(
        vertices=coords[order] + origin,
        edges=new[np.asarray(edges)],
        faces=[[int(new[v]) for v in face] for face in faces],
        assignments=edge_letter,
        fold_angles=edge_angle,
        name=name,
    )


def _key(a: int, b: int) -> tuple[int, int]:
    return (int(a), int(b)) if a < b else (int(b), int(a))


def _pieces(noded) -> tuple[np.ndarray, np.ndarray]:
    """Unique vertex coordinates and (P, 2) two-point pieces of a noded line geometry."""
    parts = shapely.get_parts(noded)
    parts = parts[shapely.get_type_id(parts) == 1]  # LineStrings
    xy, owner = shapely.get_coordinates(parts, return_index=True)
    coords, inverse = np.unique(xy, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    same = owner[1:] == owner[:-1]
    return _unique_pieces(coords, np.stack([inverse[:-1][same], inverse[1:][same]], axis=1))


def _clusters(points: np.ndarray, tol: float) -> np.ndarray:
    """For each point, the first point of its cluster (points chained by distances <= tol)."""
    tree = shapely.STRtree(shapely.points(points))
    i, j = tree.query(shapely.points(points), predicate="dwithin", distance=tol)
    parent = np.arange(len(points))
    for a, b in zip(i[i < j].tolist(), j[i < j].tolist(), strict=True):
        ra, rb = find_root(parent, a), find_root(parent, b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    return np.array([find_root(parent, v) for v in range(len(points))], dtype=np.int64)


def _unique_pieces(coords: np.ndarray, pieces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pieces = pieces[pieces[:, 0] != pieces[:, 1]]
    _, first = np.unique(np.sort(pieces, axis=1), axis=0, return_index=True)
    return coords, pieces[np.sort(first)]


def _restore(coords: np.ndarray, endpoints: np.ndarray, tol: float) -> np.ndarray:
    """Give each snapped vertex the exact coordinates of the nearest input end point within
    ``tol`` (each end point to one vertex only, so vertices stay distinct)."""
    tree = shapely.STRtree(shapely.points(endpoints))
    vi, ei = tree.query(shapely.points(coords), predicate="dwithin", distance=tol)
    out = coords.copy()
    if len(vi):
        d = np.linalg.norm(coords[vi] - endpoints[ei], axis=1)
        taken: set[tuple[float, float]] = set()
        done: set[int] = set()
        for j in np.argsort(d, kind="stable").tolist():
            v, e = int(vi[j]), int(ei[j])
            xy = (float(endpoints[e, 0]), float(endpoints[e, 1]))
            if v in done or xy in taken:
                continue
            out[v] = endpoints[e]
            done.add(v)
            taken.add(xy)
    return out


def _join_dangles(coords, pieces, sources, gap: float):
    """Join each line end that touches no other line to the nearest line within ``gap``.

    A crease must end on another line, so a free end near a line is a drawing slip: it is
    merged into that line's nearest end point, or splits the line where it is nearest.
    """
    degree = np.bincount(pieces.ravel(), minlength=len(coords))
    free = np.flatnonzero(degree == 1)
    if not len(free):
        return pieces, sources
    tree = shapely.STRtree(shapely.linestrings(coords[pieces]))
    vi, pi = tree.query(shapely.points(coords[free]), predicate="dwithin", distance=gap)
    rename = np.arange(len(coords))
    splits: dict[int, list[tuple[float, int]]] = {}
    best: dict[int, tuple[float, int, float]] = {}
    for j, p in zip(vi.tolist(), pi.tolist(), strict=True):
        v = int(free[j])
        if v in pieces[p]:
            continue
        a, b = coords[pieces[p, 0]], coords[pieces[p, 1]]
        d = b - a
        t = float(np.clip(np.dot(coords[v] - a, d) / np.dot(d, d), 0.0, 1.0))
        dist = float(np.linalg.norm(a + t * d - coords[v]))
        if v not in best or dist < best[v][0]:
            best[v] = (dist, p, t)
    for v, (_, p, t) in best.items():
        a, b = pieces[p]
        length = float(np.linalg.norm(coords[b] - coords[a]))
        if t * length <= gap:
            rename[v] = a
        elif (1 - t) * length <= gap:
            rename[v] = b
        else:
            splits.setdefault(p, []).append((t, v))
    out_pieces, out_sources = [], []
    for p, (a, b) in enumerate(pieces.tolist()):
        chain = [a] + [v for _, v in sorted(splits.get(p, []))] + [b]
        for u, w in zip(chain[:-1], chain[1:], strict=True):
            out_pieces.append((int(rename[u]), int(rename[w])))
            out_sources.append(sources[p])
    merged: dict[tuple[int, int], int] = {}
    pieces_, sources_ = [], []
    for (u, w), src in zip(out_pieces, out_sources, strict=True):
        if u == w:
            continue
        k = merged.setdefault(_key(u, w), len(pieces_))
        if k == len(pieces_):
            pieces_.append((u, w))
            sources_.append(list(src))
        else:
            sources_[k] += [s for s in src if s not in sources_[k]]
    return np.array(pieces_, dtype=np.int64), sources_


def _sources(coords, pieces, lines, tol) -> list[list[int]]:
    """For each piece, the input segments it lies on."""
    a, b = coords[pieces[:, 0]], coords[pieces[:, 1]]
    tree = shapely.STRtree(lines)
    pi, si = tree.query(shapely.points(0.5 * (a + b)), predicate="dwithin", distance=2 * tol)
    out: list[list[int]] = [[] for _ in range(len(pieces))]
    # both ends of the piece on the segment: it lies along it, not across it
    along = (shapely.distance(shapely.points(a[pi]), lines[si]) <= 2 * tol) & (
        shapely.distance(shapely.points(b[pi]), lines[si]) <= 2 * tol
    )
    for p, s in zip(pi[along].tolist(), si[along].tolist(), strict=True):
        out[p].append(s)
    # a piece shorter than the tolerance can touch a crossing segment at both ends: where
    # candidates disagree, keep those along the piece (angle below about 6 degrees)
    seg = shapely.get_coordinates(lines).reshape(-1, 2, 2)
    for p, src in enumerate(out):
        if len(src) > 1:
            u = (b[p] - a[p]) / np.linalg.norm(b[p] - a[p])
            d = seg[src, 1] - seg[src, 0]
            sin = np.abs(u[0] * d[:, 1] - u[1] * d[:, 0]) / np.linalg.norm(d, axis=1)
            along = [s for s, x in zip(src, sin.tolist(), strict=True) if x <= 0.1]
            out[p] = along or src
    return out


def _label(sources, letters, angles, names):
    """Each piece's letter and angle from the segments it lies on: they must agree, except that
    a border line drawn over a crease or cut wins (with a warning)."""
    piece_letter: list[str] = []
    piece_angle = np.zeros(len(sources))
    warned: set[tuple[int, int]] = set()
    for p, src in enumerate(sources):
        if not src:  # cannot happen for a noded piece, but never guess
            raise PatternError(f"piece {p}: lies on no input segment (noding failed)")
        borders = [s for s in src if letters[s] == "B"]
        if borders and len(borders) < len(src):
            pair = (borders[0], next(s for s in src if letters[s] != "B"))
            if pair not in warned:
                warned.add(pair)
                _warn(
                    f"{names[pair[1]]}: runs along the border line {names[pair[0]]}; "
                    "taken as border"
                )
            src = borders
        s0 = src[0]
        for s in src[1:]:
            if letters[s] != letters[s0] or abs(angles[s] - angles[s0]) > 1e-9:
                raise PatternError(
                    f"{names[s0]} and {names[s]}: overlap with different assignments "
                    f"({letters[s0]} {np.degrees(angles[s0]):.6g} deg and "
                    f"{letters[s]} {np.degrees(angles[s]):.6g} deg)"
                )
        piece_letter.append(letters[s0])
        piece_angle[p] = angles[s0]
    return piece_letter, piece_angle


def _paper_faces(polygons, faces_rings, key_of, piece_letter) -> list[int]:
    """Faces of paper: all but those bounded by border pieces only that lie inside another face."""
    shells = shapely.polygons([shapely.get_exterior_ring(p) for p in polygons])
    tree = shapely.STRtree(shells)
    paper = []
    for f, rings in enumerate(faces_rings):
        outer = rings[0]
        all_border = all(
            piece_letter[key_of[_key(outer[s], outer[s - 1])]] == "B" for s in range(len(outer))
        )
        if all_border:
            with np.errstate(all="ignore"):  # denormal coordinates overflow inside GEOS
                point = shapely.point_on_surface(polygons[f])
            inside = tree.query(point, predicate="within")
            if any(int(g) != f for g in inside):
                continue  # a hole in another face
        paper.append(f)
    return paper
