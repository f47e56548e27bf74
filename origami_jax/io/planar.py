"""A crease pattern from loose line segments: the planar arrangement of a drawing.

Used by the SVG reader and by FOLD files without ``faces_vertices``. The input is a list of
segments, each with a FOLD assignment letter, a target fold angle and a name for messages; the
output is a validated :class:`~origami_jax.CreasePattern`. ``tol`` below is the tolerance times
the drawing's size (its bounding-box diagonal); the tolerance is 1e-6 by default.

1. segments not longer than ``tol`` are dropped, their two ends being one point; when that
   drops most lines, because one point lies far from the rest (a coordinate such as 1e20 among
   others of about 100), the error names that point;
2. the segments are noded by snapping, each piece keeping the list of segments it comes from:
   end points within ``tol`` merge (at the first one's exact coordinates); a vertex within
   ``tol`` of a piece splits it there, except that a line end touching nothing else joins that
   piece's nearer end when within ``GAP_FACTOR * tol`` of it; pieces that cross are split at
   their crossing (a crossing within ``tol`` of a vertex is that vertex). This repeats until no
   vertex lies within ``tol`` of a piece it is not an end of and no two pieces cross
   (``shapely.STRtree`` finds the candidates, GEOS's robust predicates decide). Then:

   * a piece that lines crossing at an angle share (snapping ran both through two points of
     their crossing zone, where they are within ``tol`` of each other) is contracted;
   * a line end touching nothing that overshoots a junction by at most ``GAP_FACTOR * tol`` is
     trimmed back to it; one that stops short of a line within that distance is joined to
     it, at its nearer end point if within that distance, else where it is nearest; not to a
     line its own piece already meets (that would fold the piece onto it);
   * a piece at most ``2 tol`` long at a junction of three or more pieces is contracted:
     snapping moves a vertex by up to ``tol``, so two vertices of one point of the drawing
     (four creases meeting, two of them drawn to a point a little off) can be ``2 tol`` apart;

   each followed by the same snapping. Since every piece knows its segments, a short piece
   between two vertices is credited to its own segments only, never to the lines near it;
3. each piece takes the assignment of the segments it comes from; where segments with different
   assignments or angles overlap, ``precedence`` decides (the SVG reader passes Origami
   Simulator's order), with a :class:`PatternWarning` per pair naming both and the rule (a
   crease along a border line on the paper's edge is a border either way, and is said so);
   without ``precedence`` a border line wins over a crease or cut (a warning) and any other
   disagreement is an error naming both;
4. faces are the polygons of ``shapely.polygonize`` on the pieces (holes and separate pieces
   included); a face bounded only by border (``B``) pieces that lies inside another face is a
   hole, not paper;
5. pieces with paper on one side only become borders, a border with paper on both sides
   becomes a cut (``C``), and pieces with no paper beside them (dangling lines, lines outside
   the paper) are dropped; a cut whose two ends are inside the paper and meet no other cut (a
   slit) cannot open, and is loaded as Origami Simulator loads it, as a free hinge (``U``,
   angle 0: its two sides stay joined at both ends and nothing drives it); each such change is
   reported as a :class:`PatternWarning` naming the element;
6. faces with holes are triangulated (``shapely.constrained_delaunay_triangles``), their new
   sides becoming ``J`` (join) edges; other faces stay polygons.
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
# snapping settles in 2 to 4 rounds on real drawings; this bounds pathological input
MAX_SNAP_ROUNDS = 100


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
    precedence: Sequence[float] | None = None,
    precedence_rule: str = "the segment of higher precedence is kept",
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
      precedence: optional (S,) numbers: where segments with different assignments or angles
        overlap, the piece takes the one with the highest number (a :class:`PatternWarning`
        names both and ``precedence_rule``). Without it, a border wins over a crease or cut
        (a warning) and any other disagreement is an error.
      precedence_rule: the rule behind ``precedence``, in words, for the warning.

    Raises:
      PatternError: no segments, non-finite coordinates, a point so far out that the other
        lines fall under the tolerance, overlapping segments with different assignments
        (without ``precedence``), or no face at all.
    """
    p0 = np.asarray(starts, np.float64).reshape(-1, 2)
    p1 = np.asarray(ends, np.float64).reshape(-1, 2)
    letters = list(assignments)
    angles = np.asarray(fold_angles, np.float64).reshape(-1)
    rank = None if precedence is None else np.asarray(precedence, np.float64).reshape(-1)
    if not len(p0) == len(p1) == len(letters) == len(angles) == len(names):
        raise PatternError("segments: starts, ends, assignments, angles and names differ in length")
    if rank is not None and len(rank) != len(p0):
        raise PatternError("segments: precedence and starts differ in length")
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
    # 1. segments not longer than tol are points
    keep = np.flatnonzero(lengths > tol)
    _check_short(p0, p1, lengths, keep, names, tol, tolerance, diagonal, name)
    p0, p1, angles = p0[keep], p1[keep], angles[keep]
    letters = [letters[k] for k in keep]
    names = [names[k] for k in keep]
    rank = None if rank is None else rank[keep]

    # 2. node by snapping, each piece with the segments it comes from
    origin = points.min(0)
    coords, pieces, sources = _node(p0 - origin, p1 - origin, tol, GAP_FACTOR * tol, names)
    where_of = _where(coords, pieces, origin)

    # 3. assignment of each piece from its segments
    piece_letter, piece_angle, piece_source, overlaps = _label(
        sources, letters, angles, names, rank, where_of
    )
    overlapped = {p for ps in overlaps.values() for p in ps}

    # 4. faces
    piece_lines = shapely.linestrings(coords[pieces])
    polygons = list(shapely.get_parts(shapely.polygonize(piece_lines)))
    # faces thinner than the tolerance are slivers of the noding, not paper
    polygons = [poly for poly in polygons if poly.area > tol * tol]
    if not polygons:
        raise PatternError(f"{name}: the lines enclose no face (is the border closed?)")
    in_use = np.unique(pieces)
    index = {(float(coords[v, 0]), float(coords[v, 1])): int(v) for v in in_use}
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

    # 5. faces beside each piece, and the assignments that follow from them
    sides: dict[int, list[int]] = {}
    for f in paper:
        for ring in faces_rings[f]:
            for s in range(len(ring)):
                sides.setdefault(key_of[_key(ring[s], ring[s - 1])], []).append(f)
    kept: list[int] = []
    on_edge: set[int] = set()
    for p in range(len(pieces)):
        fs = sides.get(p, [])
        where = f"{names[piece_source[p]]}: {where_of(p)}"
        if not fs:
            _warn(f"{where}: has no paper beside it (dangling or outside the paper); dropped")
            continue
        if len(fs) == 1:
            on_edge.add(p)
        border_too = p in overlapped and any(letters[s] == "B" for s in sources[p])
        if len(fs) == 1 and piece_letter[p] != "B":
            if not border_too:  # else said once for the pair of lines, below
                _warn(
                    f"{where}: is assigned {piece_letter[p]} but lies on the paper's edge; made B"
                )
            piece_letter[p], piece_angle[p] = "B", 0.0
        elif len(fs) == 2 and piece_letter[p] == "B":
            piece_letter[p] = "C"  # paper on both sides of an edge of the paper: a cut
        kept.append(p)
    _warn_overlaps(overlaps, on_edge, letters, angles, names, precedence_rule, where_of)
    for p in slit_edges([tuple(pieces[p]) for p in kept], [piece_letter[p] for p in kept]):
        p = kept[p]
        _warn(
            f"{names[piece_source[p]]}: {where_of(p)}: is a cut whose ends are both inside the "
            "paper and meet no other cut (a slit), which cannot open; loaded as a free hinge "
            "(U, angle 0), as Origami Simulator does"
        )
        piece_letter[p], piece_angle[p] = "U", 0.0

    # 6. faces: polygons, or triangles (plus J edges) for faces with holes
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
        rank_ = [hint.get((float(coords[v, 0]), float(coords[v, 1])), len(hint)) for v in order]
        order = order[np.argsort(rank_, kind="stable")]
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


def slit_edges(edges: Sequence[Sequence[int]], assignments: Sequence[str]) -> list[int]:
    """The cut (``C``) edges that cannot open: both ends inside the paper, neither on another cut.

    A vertex is on the paper's edge when it is an end of an edge that has one face; here, where
    faces are not known, the ``B`` edges stand for those. Origami Simulator loads such a slit
    as two border bars between the same two vertices, which splits no vertex: the two sides
    stay joined at both ends with no torsion spring, that is a free hinge (``U``, angle 0).
    """
    border = {
        int(v) for (a, b), x in zip(edges, assignments, strict=True) if x == "B" for v in (a, b)
    }
    cuts_at: dict[int, int] = {}
    for (a, b), x in zip(edges, assignments, strict=True):
        if x == "C":
            cuts_at[int(a)] = cuts_at.get(int(a), 0) + 1
            cuts_at[int(b)] = cuts_at.get(int(b), 0) + 1
    return [
        k
        for k, ((a, b), x) in enumerate(zip(edges, assignments, strict=True))
        if x == "C" and all(int(v) not in border and cuts_at[int(v)] == 1 for v in (a, b))
    ]


def _key(a: int, b: int) -> tuple[int, int]:
    return (int(a), int(b)) if a < b else (int(b), int(a))


def _where(coords: np.ndarray, pieces: np.ndarray, origin: np.ndarray):
    """A function giving the words for piece ``p``: ``"the piece from (x, y) to (x, y)"``."""

    def where(p: int) -> str:
        a, b = coords[pieces[p]] + origin
        return f"the piece from ({a[0]:.6g}, {a[1]:.6g}) to ({b[0]:.6g}, {b[1]:.6g})"

    return where


def _check_short(p0, p1, lengths, keep, names, tol, tolerance, diagonal, name) -> None:
    """Refuse a drawing whose lines are mostly shorter than the tolerance, naming the point that
    makes it so large (a coordinate such as 1e20 among others of about 100); segments shorter
    than the tolerance are otherwise dropped, their two ends being one point."""
    if len(keep) == len(p0):
        return
    # a zero-length segment is a dot, not a line: lengths below rounding of its coordinates
    scale = np.maximum(np.abs(p0).max(axis=1), np.abs(p1).max(axis=1))
    lines = lengths > 1e-12 * np.maximum(scale, 1e-300)
    short = np.flatnonzero(lines & (lengths <= tol))
    if len(short) >= 2 and 2 * len(short) >= int(lines.sum()):
        pts = np.concatenate([p0, p1])
        far = int(np.argmax(np.linalg.norm(pts - np.median(pts, axis=0), axis=1)))
        x, y = pts[far]
        raise PatternError(
            f"{names[far % len(p0)]}: its point ({x:.6g}, {y:.6g}) spreads the lines over "
            f"{diagonal:.3g}, so {len(short)} of the {int(lines.sum())} lines are shorter than "
            f"the merge tolerance {tol:.3g} ({tolerance:g} of that) and vanish; is that point "
            "a mistake?"
        )
    if len(keep) == 0:
        raise PatternError(f"{name}: every segment is shorter than the tolerance {tol:.3g}")


def _node(p0: np.ndarray, p1: np.ndarray, tol: float, gap: float, names):
    """Node segments by snapping (see the module docstring, step 2).

    Returns the vertex coordinates (V, 2) (unused ones included), the pieces (P, 2), in the
    order of the segments they come from and then along each, and for each piece the list of
    segments it comes from (several where segments overlap).
    """
    n = len(p0)
    pts = np.concatenate([p0, p1])
    # end points closer than tol become one vertex, at the first end point's coordinates
    root = _clusters(pts, tol)
    first, vid = np.unique(root, return_inverse=True)
    coords = pts[first]
    # the chain of each segment: (segment, position along it, vertex) entries
    seg = np.concatenate([np.arange(n), np.arange(n)])
    t = np.concatenate([np.zeros(n), np.ones(n)])
    vert = vid.reshape(-1).astype(np.int64)
    direction = (p1 - p0) / np.linalg.norm(p1 - p0, axis=1)[:, None]

    def settle(seg, t, vert, coords):
        for _ in range(MAX_SNAP_ROUNDS):
            chains = _chains(seg, t, vert)
            changed = False
            for find in (_near, _crossings):  # crossings only once no vertex is near a piece
                found = find(coords, chains, tol, gap)
                if found is None:
                    continue
                rename, extra = found
                if rename is not None:
                    vert, changed = rename[vert], True
                if extra is not None:
                    seg, t, vert, coords, added = _add(seg, t, vert, coords, *extra)
                    changed = changed or added > 0
                if changed:
                    break
            if not changed:
                return seg, t, vert, coords, chains
        raise PatternError(
            f"{names[int(chains[0][0])]}: the lines near it do not settle into a planar "
            f"arrangement after {MAX_SNAP_ROUNDS} rounds of snapping"
        )

    seg, t, vert, coords, chains = settle(seg, t, vert, coords)
    # then the clean-ups, each followed by snapping again (see the module docstring, step 2);
    # (step, rounds): junctions once, so that a chain of short pieces is not eaten piece by piece
    steps = ((_contract, MAX_SNAP_ROUNDS), (_join_dangles, MAX_SNAP_ROUNDS))
    steps += ((_contract_junctions, 1), (_contract, MAX_SNAP_ROUNDS))
    for step, rounds in steps:
        for _ in range(rounds):
            found = step(coords, chains, tol, gap, direction)
            if found is None:
                break
            rename, extra = found
            added = 0
            if extra is not None:
                seg, t, vert, coords, added = _add(seg, t, rename[vert], coords, *extra)
            if not added and (rename == np.arange(len(rename))).all():
                break  # nothing changed: the next round would find the same
            vert = rename[vert] if extra is None else vert
            seg, t, vert, coords, chains = settle(seg, t, vert, coords)
    ps, _, _, u, w = chains
    keys = np.sort(np.stack([u, w], axis=1), axis=1)
    _, first_of, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(first_of, kind="stable")  # pieces in chain order
    slot = np.empty(len(order), dtype=np.int64)
    slot[order] = np.arange(len(order))
    pieces = np.stack([u, w], axis=1)[first_of[order]]
    sources: list[list[int]] = [[] for _ in range(len(order))]
    for k, s in zip(slot[inverse].tolist(), ps.tolist(), strict=True):
        if s not in sources[k]:
            sources[k].append(s)
    return coords, pieces, sources


def _chains(seg, t, vert):
    """The pieces of the current chains: (segment, t at start, t at end, start, end) arrays,
    in the order of the segments and along each; repeated vertices in a row are one."""
    order = np.lexsort((t, seg))
    s, tt, v = seg[order], t[order], vert[order]
    same = (s[1:] == s[:-1]) & (v[1:] != v[:-1])
    return s[:-1][same], tt[:-1][same], tt[1:][same], v[:-1][same], v[1:][same]


def _add(seg, t, vert, coords, s_new, t_new, v_new, xy_new):
    """The entries with new (segment, t, vertex) entries, less those that put a vertex on a
    segment twice, the coordinates with new vertices, and the number of entries added."""
    coords = np.concatenate([coords, xy_new]) if len(xy_new) else coords
    have = set(zip(seg.tolist(), vert.tolist(), strict=True))
    keep = []
    for k, pair in enumerate(zip(s_new.tolist(), v_new.tolist(), strict=True)):
        if pair not in have:
            have.add(pair)
            keep.append(k)
    keep = np.asarray(keep, dtype=np.int64)
    return (
        np.concatenate([seg, s_new[keep]]),
        np.concatenate([t, t_new[keep]]),
        np.concatenate([vert, v_new[keep]]),
        coords,
        len(keep),
    )


def _on_piece(coords, chains, p, xy):
    """Position along the segment of points ``xy`` on pieces ``p``, between the pieces' ends,
    and how far along each piece (0 to 1)."""
    _, ta, tb, u, w = chains
    a, b = coords[u[p]], coords[w[p]]
    d = b - a
    # pieces join distinct vertices, more than tol apart; the floor only keeps this finite
    dd = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    lam = np.clip(np.einsum("ij,ij->i", xy - a, d) / dd, 0.0, 1.0)
    return ta[p] + lam * (tb[p] - ta[p]), lam


def _degree(chains, n: int) -> np.ndarray:
    """How many distinct pieces meet at each of ``n`` vertices."""
    _, _, _, u, w = chains
    keys = np.unique(np.sort(np.stack([u, w], axis=1), axis=1), axis=0)
    return np.bincount(keys.ravel(), minlength=n)


def _near(coords, chains, tol: float, gap: float):
    """Vertices within ``tol`` of a piece they are not an end of: split the piece there; but a
    line end that touches nothing else is merged into that piece's nearer end when it is
    within ``gap`` of it (a line drawn to a vertex, a little short of it or beside it)."""
    ps, _, _, u, w = chains
    if not len(ps):
        return None
    active = np.unique(np.concatenate([u, w]))
    tree = shapely.STRtree(shapely.linestrings(np.stack([coords[u], coords[w]], axis=1)))
    vi, p = tree.query(shapely.points(coords[active]), predicate="dwithin", distance=tol)
    v = active[vi]
    mask = (v != u[p]) & (v != w[p])
    if not mask.any():
        return None
    v, p = v[mask], p[mask]
    degree = _degree(chains, len(coords))
    rename = np.arange(len(coords))
    free = np.flatnonzero(degree[v] == 1)
    if len(free):
        # the other end of each free end's own piece: a piece meeting it is not joined
        own = {int(a): int(b) for a, b in zip(u.tolist(), w.tolist(), strict=True)}
        own.update({int(b): int(a) for a, b in zip(u.tolist(), w.tolist(), strict=True)})
        da = np.linalg.norm(coords[v[free]] - coords[u[p[free]]], axis=1)
        db = np.linalg.norm(coords[v[free]] - coords[w[p[free]]], axis=1)
        target = np.where(da <= db, u[p[free]], w[p[free]])
        dist = np.minimum(da, db)
        for k in np.argsort(dist, kind="stable").tolist():
            vv, tt = int(v[free[k]]), int(target[k])
            x = own[vv]
            if (
                dist[k] > gap
                or rename[vv] != vv
                or rename[tt] != tt
                or x in (u[p[free[k]]], w[p[free[k]]])
            ):
                continue
            rename[vv] = tt
        if (rename != np.arange(len(coords))).any():
            while (rename[rename] != rename).any():  # a -> b -> c: a -> c
                rename = rename[rename]
            return rename, None
    t_new, _ = _on_piece(coords, chains, p, coords[v])
    return None, (ps[p], t_new, v, np.empty((0, 2)))


def _crossings(coords, chains, tol: float, gap: float):
    """Pieces that cross: both split at the crossing, a new vertex (crossings closer than
    ``tol`` to each other are one)."""
    ps, _, _, u, w = chains
    if not len(ps):
        return None
    # overlapping segments repeat pieces: test each piece once, then split every copy
    keys = np.sort(np.stack([u, w], axis=1), axis=1)
    _, once, copy = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    lines = shapely.linestrings(np.stack([coords[u[once]], coords[w[once]]], axis=1))
    i, j = shapely.STRtree(lines).query(lines, predicate="crosses")
    i, j = once[i], once[j]
    mask = (i < j) & (u[i] != u[j]) & (u[i] != w[j]) & (w[i] != u[j]) & (w[i] != w[j])
    i, j = i[mask], j[mask]
    if not len(i):
        return None
    a, da = coords[u[i]], coords[w[i]] - coords[u[i]]
    c, dc = coords[u[j]], coords[w[j]] - coords[u[j]]
    denom = da[:, 0] * dc[:, 1] - da[:, 1] * dc[:, 0]
    with np.errstate(all="ignore"):  # pieces that cross are not parallel, but keep it finite
        lam = ((c - a)[:, 0] * dc[:, 1] - (c - a)[:, 1] * dc[:, 0]) / denom
    lam = np.nan_to_num(lam, nan=0.5)
    xy = a + np.clip(lam, 0.0, 1.0)[:, None] * da
    # a crossing within tol of a vertex (one a piece passes beside) is that vertex
    active = np.unique(np.concatenate([u, w]))
    xi, vi = shapely.STRtree(shapely.points(coords[active])).query_nearest(
        shapely.points(xy), max_distance=tol, all_matches=False
    )
    vid = np.full(len(xy), -1, dtype=np.int64)
    vid[xi] = active[vi]
    new = np.flatnonzero(vid < 0)
    root = _clusters(xy[new], tol)
    first, inverse = np.unique(root, return_inverse=True)
    vid[new] = len(coords) + inverse.reshape(-1)
    # split every copy of each crossing piece: (piece, row of its crossing) pairs
    copies: dict[int, list[int]] = {}
    for piece, key in enumerate(copy.reshape(-1).tolist()):
        copies.setdefault(key, []).append(piece)
    key_of = copy.reshape(-1)
    pairs = [
        (piece, row)
        for row, crossing in enumerate(np.concatenate([i, j]).tolist())
        for piece in copies[key_of[crossing]]
    ]
    piece = np.array([pair[0] for pair in pairs], dtype=np.int64)
    row = np.array([pair[1] for pair in pairs], dtype=np.int64)
    t_new, _ = _on_piece(coords, chains, piece, np.concatenate([xy, xy])[row])
    return None, (ps[piece], t_new, np.concatenate([vid, vid])[row], xy[new][first])


def _contract(coords, chains, tol: float, gap: float, direction: np.ndarray):
    """Merge the two ends of each piece that lines crossing at an angle share: snapping ran
    both through two vertices of their crossing zone (where they are within ``tol`` of each
    other), which are one point of the drawing.

    Lines crossing at angle ``a`` are within ``tol`` of each other along ``2 tol / sin(a / 2)``:
    a piece they share lies in that zone when its length times ``sin(a / 2)`` is at most
    ``2 tol``; longer shared pieces (lines that truly overlap), and any longer than
    ``gap``, are kept. Returns None when nothing merges, else the renaming of vertices.
    """
    ps, _, _, u, w = chains
    keys = np.sort(np.stack([u, w], axis=1), axis=1)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    shared = np.flatnonzero(counts[inverse] > 1)
    by_key: dict[int, list[int]] = {}
    for q in shared.tolist():
        by_key.setdefault(int(inverse[q]), []).append(q)
    parent = np.arange(len(coords))
    merged = False
    for qs in by_key.values():
        a, b = keys[qs[0]]
        length = float(np.linalg.norm(coords[a] - coords[b]))
        d = direction[np.unique(ps[qs])]
        if length > gap or len(d) < 2:
            continue
        # sin of half the widest angle between the lines (directions taken either way)
        cos = np.abs(d @ d.T).min()
        if length * np.sqrt(max(0.0, (1.0 - cos) / 2.0)) <= 2.0 * tol:
            ra, rb = find_root(parent, int(a)), find_root(parent, int(b))
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
                merged = True
    if not merged:
        return None
    return np.array([find_root(parent, v) for v in range(len(coords))], dtype=np.int64), None


def _contract_junctions(coords, chains, tol: float, gap: float, direction: np.ndarray):
    """Merge the two ends of each piece at most ``2 tol`` long that has a junction (three or more
    pieces) at an end: snapping moves a vertex by up to ``tol``, so two vertices of one point of
    the drawing, such as four creases meeting with two of them drawn to a point a little off,
    can be up to ``2 tol`` apart. Returns None when nothing merges, else the renaming."""
    _, _, _, u, w = chains
    keys = np.unique(np.sort(np.stack([u, w], axis=1), axis=1), axis=0)
    degree = np.bincount(keys.ravel(), minlength=len(coords))
    length = np.linalg.norm(coords[keys[:, 0]] - coords[keys[:, 1]], axis=1)
    short = (length <= 2.0 * tol) & (np.maximum(degree[keys[:, 0]], degree[keys[:, 1]]) >= 3)
    if not short.any():
        return None
    parent = np.arange(len(coords))
    for a, b in keys[short].tolist():
        ra, rb = find_root(parent, a), find_root(parent, b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    return np.array([find_root(parent, v) for v in range(len(coords))], dtype=np.int64), None


def _join_dangles(coords, chains, tol: float, gap: float, direction: np.ndarray):
    """Trim each line end that touches no other line and overshoots a line by at most ``gap``;
    join the others to the nearest line within ``gap``.

    A crease must end on another line, so a free end near a line is a drawing slip: a piece
    from a junction to a free end at most ``gap`` long is an overshoot, and its free end is
    merged into the junction; another free end is merged into the nearest line's nearest end
    point, or splits that line where it is nearest. A line that the free end's own piece already
    meets is left alone: joining would fold the piece onto it (two lines crossing at a small
    angle, one ending just past the other).

    Returns None when no end is joined, else the renaming of vertices and new entries.
    """
    ps, _, _, u, w = chains
    keys = np.unique(np.sort(np.stack([u, w], axis=1), axis=1), axis=0)
    degree = np.bincount(keys.ravel(), minlength=len(coords))
    rename = np.arange(len(coords))
    other = {}  # free vertex -> the other end of its piece
    for a, b in keys.tolist():
        for v, x in ((a, b), (b, a)):
            if degree[v] != 1:
                continue
            if degree[x] >= 3 and np.linalg.norm(coords[v] - coords[x]) <= gap:
                rename[v] = x  # an overshoot past a junction
            else:
                other[v] = x
    free = np.array(sorted(other), dtype=np.int64)
    if not len(free):
        return (rename, None) if (rename != np.arange(len(coords))).any() else None
    tree = shapely.STRtree(shapely.linestrings(np.stack([coords[u], coords[w]], axis=1)))
    fi, p = tree.query(shapely.points(coords[free]), predicate="dwithin", distance=gap)
    v = free[fi]
    x = np.array([other[int(k)] for k in v.tolist()], dtype=np.int64)
    mask = (u[p] != v) & (w[p] != v) & (u[p] != x) & (w[p] != x)
    v, p = v[mask], p[mask]
    if not len(v):
        return (rename, None) if (rename != np.arange(len(coords))).any() else None
    _, lam = _on_piece(coords, chains, p, coords[v])
    a, b = coords[u[p]], coords[w[p]]
    dist = np.linalg.norm(a + lam[:, None] * (b - a) - coords[v], axis=1)
    best: dict[int, int] = {}
    for k in np.argsort(dist, kind="stable").tolist():
        best.setdefault(int(v[k]), k)
    split = []
    for vv, k in best.items():
        length = float(np.linalg.norm(b[k] - a[k]))
        if lam[k] * length <= gap:
            rename[vv] = u[p[k]]
        elif (1 - lam[k]) * length <= gap:
            rename[vv] = w[p[k]]
        else:
            split.append(k)
    # a free end merged into another free end that is itself merged: follow the chain
    for vv in best:
        r = int(rename[vv])
        seen = {vv}
        while rename[r] != r and r not in seen:
            seen.add(r)
            r = int(rename[r])
        rename[vv] = r
    if not split:
        return rename, None
    # the piece is split at the free end, on every segment it comes from
    by_key: dict[tuple[int, int], list[tuple[int, float]]] = {}
    for k in split:
        by_key.setdefault((int(u[p[k]]), int(w[p[k]])), []).append((int(v[k]), float(lam[k])))
    _, ta, tb, _, _ = chains
    s_new, t_new, v_new = [], [], []
    for q in range(len(ps)):
        for key, flip in (((int(u[q]), int(w[q])), False), ((int(w[q]), int(u[q])), True)):
            for vv, lm in by_key.get(key, []):
                lm = 1.0 - lm if flip else lm
                s_new.append(int(ps[q]))
                t_new.append(float(ta[q] + lm * (tb[q] - ta[q])))
                v_new.append(int(rename[vv]))
    return rename, (
        np.asarray(s_new, dtype=np.int64),
        np.asarray(t_new),
        np.asarray(v_new, dtype=np.int64),
        np.empty((0, 2)),
    )


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


def _describe(letter: str, angle: float) -> str:
    return f"{letter} {np.degrees(angle):.6g} deg"


def _label(sources, letters, angles, names, rank, where_of):
    """Each piece's letter, angle and deciding segment, from the segments it comes from, and
    the overlaps that ``rank`` decided: {(kept segment, other segment): [pieces]}.

    Without ``rank`` a border wins over a crease or cut (a warning) and any other disagreement
    is an error.
    """
    piece_letter: list[str] = []
    piece_angle = np.zeros(len(sources))
    piece_source: list[int] = []
    overlaps: dict[tuple[int, int], list[int]] = {}
    warned: set[tuple[int, int]] = set()
    for p, src in enumerate(sources):
        if not src:  # cannot happen: every piece is made from a segment's chain
            raise PatternError(f"piece {p}: lies on no input segment (noding failed)")
        if rank is not None:
            s0 = max(src, key=lambda s: (rank[s], s))
            for s in src:
                if letters[s] != letters[s0] or abs(angles[s] - angles[s0]) > 1e-9:
                    overlaps.setdefault((s0, s), []).append(p)
        else:
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
                        f"({_describe(letters[s0], angles[s0])} and "
                        f"{_describe(letters[s], angles[s])}), {where_of(p)}"
                    )
        piece_letter.append(letters[s0])
        piece_angle[p] = angles[s0]
        piece_source.append(s0)
    return piece_letter, piece_angle, piece_source, overlaps


def _warn_overlaps(overlaps, on_edge, letters, angles, names, rule, where_of) -> None:
    """One warning per pair of overlapping segments that ``precedence`` decided; a crease or cut
    along a border line on the paper's edge is a border either way, and is said so."""
    for (s0, s), ps in overlaps.items():
        if "B" in (letters[s0], letters[s]) and all(p in on_edge for p in ps):
            crease, border = (s, s0) if letters[s0] == "B" else (s0, s)
            _warn(f"{names[crease]}: runs along the border line {names[border]}; taken as border")
            continue
        p = next((p for p in ps if p not in on_edge), ps[0])
        _warn(
            f"{names[s]} ({_describe(letters[s], angles[s])}) and {names[s0]} "
            f"({_describe(letters[s0], angles[s0])}): overlap with different assignments at "
            f"{where_of(p)}{'' if len(ps) == 1 else f' and {len(ps) - 1} more'}; "
            f"{names[s0]}'s {letters[s0]} is kept ({rule})"
        )


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
