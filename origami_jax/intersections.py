"""Faces through faces: pairs of mesh triangles that cross each other.

:func:`intersecting_pairs` reports the pairs of triangles sharing no vertex where an edge of one
passes through the interior of the other deeper than a given depth;
:attr:`origami_jax.fold.FoldResult.intersections` uses it with
``depth = INTERSECTION_DEPTH * diameter``. It only counts: contact (preventing the crossings)
is another matter.

How: host side, NumPy only, vectorised, in two phases.

* Broad phase: a uniform grid over the triangles' axis-aligned bounding boxes (cell size the
  median box size, grown where large triangles would cover too many cells). Two triangles are
  candidates where their boxes overlap; each candidate pair is made once, in the cell whose
  coordinates are the larger of the two boxes' lowest cells' along each axis (so no sort is
  needed to deduplicate), and pairs sharing a vertex are dropped. Candidates are made in
  batches of bounded size, so a pathological input (every triangle in one cell) costs time,
  not memory.
* Narrow phase: the test of :func:`intersecting_pairs`' docstring on each candidate, both ways,
  after a cheap filter on which side of each other's plane the corners lie.

Its cost is linear in the triangles and the candidate pairs: tens of milliseconds for the
5,000 triangles of Origami Simulator's largest example, so every result runs it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["INTERSECTION_DEPTH", "intersecting_pairs"]

#: Depth a crossing must exceed to count, relative to the sheet's diameter: far above float64
#: rounding of a folded state, far below any real penetration.
INTERSECTION_DEPTH = 1e-6

# Candidate pairs per batch (about 100 MB of temporaries); a batch holds more only for one
# entry of the grid with more partners, fewer than the entries: memory stays linear in T.
_CHUNK = 1 << 18
# Grid cells per triangle, on average, before the cells are made larger.
_CELLS_PER_TRIANGLE = 16
# The three edges of a triangle as (start, end) corners; edge k runs from corner k.
_EDGES = ((0, 1), (1, 2), (2, 0))


def intersecting_pairs(positions: np.ndarray, triangles: np.ndarray, depth: float) -> np.ndarray:
    """(K, 2) int64 pairs ``(i, j)``, ``i < j``, sorted, of triangles that cross each other.

    Triangles ``i`` and ``j`` cross when they share no vertex (by index) and an edge ``PQ`` of
    one crosses the other, ``ABC``, deeper than ``depth``: (1) ``P`` and ``Q`` lie on opposite
    sides of ``ABC``'s plane, each farther than ``depth`` from it, and (2) the point where
    ``PQ`` meets that plane lies inside ``ABC`` farther than ``depth`` from each of its three
    edge lines. Why: both are distances in length units that rounding cannot reach, and each
    rejects one kind of harmless contact. (1) rejects edges lying in the plane or grazing it
    (the coplanar layers of an exactly flat fold, a vertex resting on a face) while a real
    crossing counts however shallow its angle, its end points being far from the plane; (2)
    rejects crossings through or just beside the boundary, where a crease folded flat or
    through itself puts them and neighbouring triangles meet. Two triangles whose planes cross
    inside both meet along a segment whose ends are such edge crossings, so testing the six
    edges finds every crossing deeper than ``depth``; a triangle of zero area has no plane to
    cross, and triangles with non-finite corners are skipped.

    Args:
      positions: (V, 3) vertex positions.
      triangles: (T, 3) vertex indices of each triangle.
      depth: the depth to exceed, in the positions' length unit, ``>= 0`` (the project uses
        ``INTERSECTION_DEPTH * diameter``; ``0`` counts any strict crossing).

    Returns:
      (K, 2) int64 triangle indices, each row ``i < j``, rows in lexicographic order.

    Example:
      >>> import numpy as np
      >>> x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0],
      ...               [0.2, 0.2, -1], [0.2, 0.2, 1], [3, 3, 0.5]], float)
      >>> intersecting_pairs(x, np.array([[0, 1, 2], [3, 4, 5]]), 1e-6).tolist()
      [[0, 1]]
    """
    x = np.asarray(positions, dtype=np.float64)
    tri = np.asarray(triangles)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"positions must be (V, 3), got shape {x.shape}")
    if tri.ndim != 2 or tri.shape[1] != 3:
        raise ValueError(f"triangles must be (T, 3), got shape {tri.shape}")
    if tri.size and (not np.issubdtype(tri.dtype, np.integer) or tri.min() < 0):
        raise ValueError("triangles must hold non-negative integer vertex indices")
    if tri.size and tri.max() >= len(x):
        raise ValueError(f"triangles index vertex {tri.max()} of {len(x)}")
    depth = float(depth)
    if not depth >= 0.0 or not np.isfinite(depth):
        raise ValueError(f"depth must be finite and >= 0, got {depth}")
    tri = tri.astype(np.int64)
    empty = np.zeros((0, 2), np.int64)

    p = x[tri]  # (T, 3 corners, 3)
    live = np.flatnonzero(np.isfinite(p).all(axis=(1, 2)))
    if len(live) < 2:
        return empty
    geometry = _planes(p)
    found = [
        _narrow(p, tri, geometry, i, j, depth) for i, j in _candidates(p[live], tri[live], live)
    ]
    if not found:
        return empty
    pairs = np.concatenate(found)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def _planes(p: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per triangle: unit normal ``n`` (T, 3) and offset ``o`` (T,), so that ``n . X - o`` is
    the signed distance from the plane; unit inward edge normals ``m`` (T, 3 edges, 3) and
    offsets ``c`` (T, 3), so that ``m_k . X - c_k`` is the in-plane distance of ``X``'s
    projection inside edge ``k``'s line; and whether the triangle has a plane (area > 0)."""
    e = np.roll(p, -1, axis=1) - p  # edge k: corner k to corner k + 1
    n = np.cross(e[:, 0], -e[:, 2])
    area2 = np.linalg.norm(n, axis=1)
    valid = area2 > 0.0
    with np.errstate(invalid="ignore", divide="ignore"):
        n = n / area2[:, None]
        m = np.cross(n[:, None, :], e)  # counter-clockwise about n: n x edge points inward
        m = m / np.linalg.norm(m, axis=2, keepdims=True)
    o = np.einsum("tc,tc->t", n, p[:, 0])
    c = np.einsum("tkc,tkc->tk", m, p)
    return n, o, m, c, valid


def _narrow(
    p: np.ndarray,
    tri: np.ndarray,
    geometry: tuple[np.ndarray, ...],
    i: np.ndarray,
    j: np.ndarray,
    depth: float,
) -> np.ndarray:
    """The candidate pairs ``(i, j)`` (``i < j``) that cross, as a (k, 2) array."""
    dij, dji = _corner_distances(p, geometry, i, j), _corner_distances(p, geometry, j, i)
    # An edge of i crosses j's interior only if i straddles j's plane deeper than depth and j
    # (which then holds a point of i's plane inside it, off its own boundary) has corners
    # strictly on both sides of i's plane, if i has one: most candidates fail both ways, and
    # half of the rest one way.
    planeless = ~geometry[4]
    hit = np.zeros(len(i), bool)
    for a, b, dab, dba in ((i, j, dij, dji), (j, i, dji, dij)):
        (k,) = np.nonzero(_straddles(dab, depth) & (_straddles(dba, 0.0) | planeless[a]) & ~hit)
        hit[k] = _edge_through(p, geometry, a[k], b[k], dab[k], depth)
    return np.stack([i[hit], j[hit]], axis=1)


def _corner_distances(
    p: np.ndarray, geometry: tuple[np.ndarray, ...], a: np.ndarray, b: np.ndarray
) -> np.ndarray:
    """(K, 3) signed distances of triangle ``a[k]``'s corners from ``b[k]``'s plane (NaN where
    ``b[k]`` has none)."""
    n, o, _, _, _ = geometry
    pa, nb = p[a], n[b]
    # per column: NumPy's einsum and reductions over a short axis are slow
    return sum(pa[:, :, k] * nb[:, k, None] for k in range(3)) - o[b][:, None]


def _straddles(d: np.ndarray, depth: float) -> np.ndarray:
    """Whether corners lie on both sides of the plane, farther than ``depth`` from it."""
    top = np.maximum(np.maximum(d[:, 0], d[:, 1]), d[:, 2])
    bottom = np.minimum(np.minimum(d[:, 0], d[:, 1]), d[:, 2])
    return (top > depth) & (bottom < -depth)


def _edge_through(
    p: np.ndarray,
    geometry: tuple[np.ndarray, ...],
    a: np.ndarray,
    b: np.ndarray,
    d: np.ndarray,
    depth: float,
) -> np.ndarray:
    """Whether an edge of triangle ``a[k]`` crosses triangle ``b[k]`` deeper than ``depth``,
    given the distances ``d`` (K, 3) of ``a[k]``'s corners from ``b[k]``'s plane."""
    _, _, m, c, _ = geometry
    pa, mb = p[a], m[b]  # (K, 3 corners, 3), (K, 3 edges, 3)
    # g[k, v, e]: corner v's (projected) distance inside edge e
    g = sum(pa[:, :, None, k] * mb[:, None, :, k] for k in range(3)) - c[b][:, None, :]
    hit = np.zeros(len(a), bool)
    for s, t in _EDGES:
        ds, dt = d[:, s], d[:, t]
        cross = np.flatnonzero(((ds > depth) & (dt < -depth)) | ((ds < -depth) & (dt > depth)))
        ds, dt = ds[cross, None], dt[cross, None]  # |ds - dt| > 2 depth >= 0
        # in-plane distances of the crossing point, interpolated along the edge
        inside = (ds * g[cross, t] - dt * g[cross, s]) / (ds - dt)
        deep = np.minimum(np.minimum(inside[:, 0], inside[:, 1]), inside[:, 2]) > depth
        hit[cross[deep]] = True
    return hit


def _candidates(p: np.ndarray, tri: np.ndarray, index: np.ndarray):
    """Yield chunks ``(i, j)`` of candidate pairs, ``i < j`` in ``index`` numbering: triangles
    (corners ``p``, vertices ``tri``) whose bounding boxes overlap and that share no vertex;
    each pair once over all chunks."""
    lo, hi = p.min(axis=1), p.max(axis=1)
    size = (hi - lo).max(axis=1)
    if not (size > 0.0).any():
        return  # points only: no edge to cross anything
    origin = lo.min(axis=0)
    # the median size, or larger where the cells' integer coordinates would grow too large
    h = max(float(np.median(size[size > 0.0])), float((hi - origin).max()) / 2.0**40)
    # Cells of the median triangle's size; coarser where a few large triangles would cover
    # too many of them (each doubling divides their count by up to 8).
    while True:
        clo = np.floor((lo - origin) / h).astype(np.int64)
        span = np.floor((hi - origin) / h).astype(np.int64) - clo + 1
        # in floats: a huge triangle among tiny ones can cover more cells than int64 counts
        if span.astype(np.float64).prod(axis=1).sum() <= _CELLS_PER_TRIANGLE * len(p):
            break
        h *= 2.0
    count = span.prod(axis=1)

    # One entry per (triangle, cell it covers).
    owner = np.repeat(np.arange(len(p)), count)
    local = np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)
    sx, sy = span[owner, 0], span[owner, 1]
    cell = clo[owner] + np.stack([local % sx, (local // sx) % sy, local // (sx * sy)], axis=1)
    key = _cell_keys(cell)
    order = np.argsort(key, kind="stable")
    owner, key = owner[order], key[order]
    # bit d: the cell is in the lowest layer of the owner's cells along axis d
    at_lo = ((cell[order] == clo[owner]) * np.array([1, 2, 4], np.int8)).sum(axis=1, dtype=np.int8)

    lo_t, hi_t, tri_t = lo.T.copy(), hi.T.copy(), tri.T.copy()
    # Within each cell, entry e pairs with the entries after it in that cell.
    group = np.concatenate([[0], np.cumsum(np.diff(key) != 0)])
    ends = np.append(np.flatnonzero(np.diff(key)) + 1, len(key))
    partners = ends[group] - np.arange(len(key)) - 1
    total = np.cumsum(partners)
    first = 0
    while first < len(key):
        # entries [first, last) make at most _CHUNK pairs (or one entry's, if more)
        before = total[first] - partners[first]
        last = max(int(np.searchsorted(total, before + _CHUNK, side="right")), first + 1)
        e = np.arange(first, last)
        num = partners[e]
        e1 = np.repeat(e, num)
        e2 = e1 + 1 + np.arange(len(e1)) - np.repeat(np.cumsum(num) - num, num)
        first = last
        # Made once: in the cell at the larger of the two boxes' lower cell corners (both
        # boxes cover it when their cell ranges overlap), where along each axis the cell is
        # the lowest of one of them.
        keep = (at_lo[e1] | at_lo[e2]) == 7
        a, b = owner[e1[keep]], owner[e2[keep]]
        # per column: NumPy's reductions over a short axis are slow
        for d in range(3):
            keep = (lo_t[d][a] <= hi_t[d][b]) & (lo_t[d][b] <= hi_t[d][a])
            a, b = a[keep], b[keep]
        ta, tb = [tri_t[k][a] for k in range(3)], [tri_t[k][b] for k in range(3)]
        shared = np.zeros(len(a), bool)
        for u in ta:
            for w in tb:
                shared |= u == w
        a, b = index[a[~shared]], index[b[~shared]]
        if len(a):
            yield np.minimum(a, b), np.maximum(a, b)


def _cell_keys(cell: np.ndarray) -> np.ndarray:
    """One int64 per distinct cell (N, 3 non-negative ints)."""
    dims = cell.max(axis=0) + 1
    if float(dims[0]) * float(dims[1]) * float(dims[2]) < 2.0**62:
        return (cell[:, 2] * dims[1] + cell[:, 1]) * dims[0] + cell[:, 0]
    return np.unique(cell, axis=0, return_inverse=True)[1].reshape(-1)  # a huge, sparse grid
