"""The crease pattern: flat vertices, edges with FOLD assignments and target fold angles, faces.

Conventions (the FOLD 1.2 conventions, see docs/concepts.md):

* coordinates are in any length unit; the model is scale invariant;
* fold angles are in **radians**, valley positive, mountain negative, flat 0, fully folded +-pi;
* assignments are FOLD letters: ``B`` border, ``M`` mountain, ``V`` valley, ``F`` flat crease,
  ``U`` unassigned, ``C`` cut, ``J`` join;
* faces are polygons; they are re-oriented counterclockwise (seen from +z) and triangulated,
  the added edges being facet creases (target 0): by ear clipping, the best-shaped ear first,
  or, where that leaves a sliver (altitude under 1e-2 of the longest side, which the bars
  hardly keep from collapsing), by the triangulation whose worst triangle is best.

How each assignment enters the model:

===========  ===============================================================
``M``, ``V``  driven crease: torsion spring with ``crease`` stiffness, target given or -pi / +pi
``F``, ``J``  facet crease: torsion spring with ``facet`` stiffness, target 0
``U``         driven crease if it has a non-zero target, else a free hinge (no torsion spring)
``B``         border: a bar only, exactly one face
``C``         cut: the paper is split along it, each side becomes a border
===========  ===============================================================

Every edge, whatever its assignment, is a bar (an axial spring).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["PatternError", "PatternWarning", "CreasePattern", "Mesh", "ASSIGNMENTS"]

ASSIGNMENTS = "BMVFUCJ"
# squares of lengths must stay finite in float64: coordinates up to 1e150
MAX_COORDINATE = 1e150
_DRIVEN, _FACET, _FREE, _BORDER = "driven", "facet", "free", "border"


class PatternError(ValueError):
    """A crease pattern (array, file or generator argument) is invalid.

    The message names the offending vertex, edge or face and the problem, for example
    ``"edge 7 (vertices 3, 9): names vertex 9, but there are only 9 vertices"``.
    """


class PatternWarning(UserWarning):
    """An input was read, but something in it was changed or ignored.

    For example a line of an unknown colour in an SVG, a crease on the paper's edge made a
    border, or a FOLD file with no ``file_spec``. The message names the element.
    """


def _edge_name(k: int, edge: Sequence[int]) -> str:
    return f"edge {k} (vertices {int(edge[0])}, {int(edge[1])})"


@dataclass(frozen=True, eq=False)
class Mesh:
    """The triangulated pattern the energy is built on (derived from a :class:`CreasePattern`).

    Arrays (``V`` vertices, ``E`` edges, ``T`` triangles):

    * ``vertices`` (V, 3) float64: rest (flat) positions; the pattern's own vertices first, then
      copies made by cuts; ``source_vertex`` (V,) int: the pattern vertex each one copies;
    * ``edges`` (E, 2) int: the pattern's edges first (a cut edge stands for its first side),
      then the second sides of cut edges, then triangulation edges;
    * ``source_edge`` (E,) int: the pattern edge each edge comes from (-1 for triangulation edges);
    * ``triangles`` (T, 3) int, counterclockwise; ``triangle_face`` (T,) their pattern face;
    * ``role`` (E,) str: ``"driven"``, ``"facet"``, ``"free"`` or ``"border"``;
    * ``target`` (E,) float64: target fold angle in radians (0 for facets, free hinges, borders);
    * ``hinges`` (E, 4) int: for each edge ``(i, j, k, l)``, the edge ``i -> j``, ``k`` the third
      vertex of the triangle on its left and ``l`` of the one on its right (-1 on borders).
    """

    vertices: np.ndarray
    source_vertex: np.ndarray
    edges: np.ndarray
    source_edge: np.ndarray
    triangles: np.ndarray
    triangle_face: np.ndarray
    role: np.ndarray
    target: np.ndarray
    hinges: np.ndarray

    @property
    def num_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def num_edges(self) -> int:
        return int(self.edges.shape[0])

    def edges_with_role(self, role: str) -> np.ndarray:
        """Indices of the edges with the given role."""
        return np.flatnonzero(self.role == role)


@dataclass(frozen=True, eq=False)
class CreasePattern:
    """A validated crease pattern.

    Args:
      vertices: (V, 2) or (V, 3) flat coordinates (z must be 0).
      edges: (E, 2) vertex indices.
      faces: polygons as sequences of vertex indices (any orientation).
      assignments: one FOLD letter per edge (a string or a sequence); default ``B`` for edges
        with one face, ``U`` for the others.
      fold_angles: (E,) target fold angles in radians; default -pi for ``M``, +pi for ``V``,
        0 otherwise.
      name: a label used in reports.
      start: optional (V, 3) positions of a folded state of these vertices (a pre-folded
        input, e.g. a FOLD folded form): :func:`~origami_jax.fold` starts from it by default.

    Raises:
      PatternError: naming the vertex, edge or face at fault.

    Example:
      >>> from origami_jax import CreasePattern
      >>> cp = CreasePattern(
      ...     vertices=[[0, 0], [1, 0], [1, 1], [0, 1]],
      ...     edges=[[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]],
      ...     faces=[[0, 1, 2], [0, 2, 3]],
      ...     assignments="BBBBV",
      ...     fold_angles=[0, 0, 0, 0, 1.0],
      ... )
      >>> cp.num_vertices, cp.num_edges, cp.mesh.triangles.shape
      (4, 5, (2, 3))
    """

    vertices: np.ndarray
    edges: np.ndarray
    faces: tuple[tuple[int, ...], ...]
    assignments: np.ndarray = field(default=None)  # type: ignore[assignment]
    fold_angles: np.ndarray = field(default=None)  # type: ignore[assignment]
    name: str = "pattern"
    start: np.ndarray | None = None

    def __post_init__(self) -> None:
        vertices = _check_vertices(self.vertices)
        edges = _check_edges(self.edges, len(vertices))
        faces = _check_faces(self.faces, len(vertices))
        edge_faces = _edge_faces(edges, faces)
        assignments = _check_assignments(self.assignments, edge_faces)
        fold_angles = _check_fold_angles(self.fold_angles, assignments)
        _check_edge_geometry(vertices, edges)
        _check_face_edges(edges, faces, edge_faces, assignments)
        faces = tuple(_counterclockwise(vertices, f, k) for k, f in enumerate(faces))
        start = None if self.start is None else _check_start(self.start, len(vertices))
        for name, value in [
            ("start", start),
            ("vertices", vertices),
            ("edges", edges),
            ("faces", faces),
            ("assignments", assignments),
            ("fold_angles", fold_angles),
        ]:
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    # -- sizes -----------------------------------------------------------------------------
    @property
    def num_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def num_edges(self) -> int:
        return int(self.edges.shape[0])

    @property
    def num_faces(self) -> int:
        return len(self.faces)

    @property
    def diameter(self) -> float:
        """Largest distance between two vertices (the flat sheet's diameter)."""
        v = self.vertices
        if len(v) > 2000:  # bounding-box diagonal: an upper bound within sqrt(2), cheap
            return float(np.linalg.norm(v.max(0) - v.min(0)))
        d = v[:, None, :] - v[None, :, :]
        return float(np.sqrt((d * d).sum(-1).max()))

    def with_fold_angles(self, fold_angles: Sequence[float] | np.ndarray) -> CreasePattern:
        """A copy with other target fold angles (radians), validated again."""
        return CreasePattern(
            self.vertices,
            self.edges,
            self.faces,
            self.assignments,
            fold_angles,
            self.name,
            self.start,
        )

    # -- the triangulated mesh the energy is built on ----------------------------------------
    @functools.cached_property
    def mesh(self) -> Mesh:
        return _build_mesh(self)

    def __repr__(self) -> str:
        counts = {a: int((self.assignments == a).sum()) for a in ASSIGNMENTS}
        hist = " ".join(f"{a}={n}" for a, n in counts.items() if n)
        return (
            f"CreasePattern({self.name!r}: {self.num_vertices} vertices, {self.num_edges} edges"
            f" [{hist}], {self.num_faces} faces)"
        )


# ---------------------------------------------------------------------------------------------
# validation


def _as_array(value, dtype, what: str) -> np.ndarray:
    try:
        return np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise PatternError(f"{what}: cannot be read as an array of numbers ({exc})") from None


def _check_vertices(vertices) -> np.ndarray:
    v = _as_array(vertices, np.float64, "vertices")
    if v.ndim != 2 or v.shape[1] not in (2, 3):
        raise PatternError(f"vertices: expected shape (V, 2) or (V, 3), got {v.shape}")
    if len(v) < 3:
        raise PatternError(f"vertices: a pattern needs at least 3 vertices, got {len(v)}")
    bad = ~(np.abs(v) <= MAX_COORDINATE).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        what = "non-finite" if not np.isfinite(v[k]).all() else f"beyond {MAX_COORDINATE:g}"
        raise PatternError(f"vertex {k}: {what} coordinate {v[k].tolist()}")
    if v.shape[1] == 2:
        v = np.concatenate([v, np.zeros((len(v), 1))], axis=1)
    else:
        scale = max(float(np.abs(v[:, :2]).max()), 1e-300)
        off = np.abs(v[:, 2]) > 1e-12 * scale
        if off.any():
            k = int(np.flatnonzero(off)[0])
            raise PatternError(
                f"vertex {k}: z = {v[k, 2]:g}, but a crease pattern must be flat (z = 0)"
            )
        v = v.copy()
        v[:, 2] = 0.0
    return v


def _check_start(start, num_vertices: int) -> np.ndarray:
    x = _as_array(start, np.float64, "start")
    if x.shape != (num_vertices, 3):
        raise PatternError(f"start: expected shape ({num_vertices}, 3), got {x.shape}")
    bad = ~np.isfinite(x).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise PatternError(f"start: vertex {k} has non-finite position {x[k].tolist()}")
    return x


def _check_edges(edges, num_vertices: int) -> np.ndarray:
    e = _as_array(edges, None, "edges")
    if e.ndim != 2 or e.shape[1] != 2 or len(e) == 0:
        raise PatternError(f"edges: expected shape (E, 2) with E > 0, got {e.shape}")
    if not np.issubdtype(e.dtype, np.integer):
        ef = _as_array(e, np.float64, "edges")
        if not (np.isfinite(ef).all() and (ef == np.round(ef)).all()):
            k = int(np.flatnonzero(~(np.isfinite(ef) & (ef == np.round(ef))).all(1))[0])
            raise PatternError(f"edge {k}: vertex indices must be integers, got {ef[k].tolist()}")
        e = ef.astype(np.int64)
    e = e.astype(np.int64)
    for k, (a, b) in enumerate(e):
        for v in (a, b):
            if v < 0 or v >= num_vertices:
                raise PatternError(
                    f"{_edge_name(k, (a, b))}: names vertex {v}, "
                    f"but there are only {num_vertices} vertices"
                )
        if a == b:
            raise PatternError(f"{_edge_name(k, (a, b))}: joins a vertex to itself")
    key = np.sort(e, axis=1)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    dup = np.flatnonzero(first[inverse] != np.arange(len(e)))
    if len(dup):
        k = int(dup[0])
        raise PatternError(f"{_edge_name(k, e[k])}: duplicates edge {int(first[inverse[k]])}")
    return e


def _check_faces(faces, num_vertices: int) -> tuple[tuple[int, ...], ...]:
    if faces is None:
        raise PatternError("faces: missing (a pattern needs its faces)")
    try:
        faces = list(faces)
    except TypeError:
        raise PatternError(f"faces: expected a sequence of polygons, got {faces!r}") from None
    out = []
    for k, face in enumerate(faces):
        try:
            f = [int(v) for v in face]
            if any(float(v) != int(v) for v in face):
                raise ValueError
        except (TypeError, ValueError):
            raise PatternError(f"face {k}: vertex indices must be integers, got {face!r}") from None
        if len(f) < 3:
            raise PatternError(f"face {k}: has {len(f)} vertices, needs at least 3")
        for v in f:
            if v < 0 or v >= num_vertices:
                raise PatternError(
                    f"face {k}: names vertex {v}, but there are only {num_vertices} vertices"
                )
        if len(set(f)) != len(f):
            raise PatternError(f"face {k}: repeats a vertex {f}")
        out.append(tuple(f))
    if not out:
        raise PatternError("faces: the pattern has no faces")
    return tuple(out)


def _edge_faces(edges: np.ndarray, faces) -> list[list[int]]:
    index = {(int(min(a, b)), int(max(a, b))): k for k, (a, b) in enumerate(edges)}
    edge_faces: list[list[int]] = [[] for _ in range(len(edges))]
    for fk, face in enumerate(faces):
        n = len(face)
        for s in range(n):
            a, b = face[s], face[(s + 1) % n]
            k = index.get((min(a, b), max(a, b)))
            if k is None:
                raise PatternError(f"face {fk}: side ({a}, {b}) is not an edge of the pattern")
            edge_faces[k].append(fk)
    return edge_faces


def _check_assignments(assignments, edge_faces) -> np.ndarray:
    n = len(edge_faces)
    if assignments is None:
        return np.array(["B" if len(f) == 1 else "U" for f in edge_faces])
    try:
        letters = list(assignments)
    except TypeError:
        raise PatternError(
            f"assignments: expected one letter per edge, got {assignments!r}"
        ) from None
    if len(letters) != n:
        raise PatternError(f"assignments: expected {n} letters (one per edge), got {len(letters)}")
    out = np.empty(n, dtype="<U1")
    for k, a in enumerate(letters):
        a = str(a).upper()
        if len(a) != 1 or a not in ASSIGNMENTS:
            raise PatternError(f"edge {k}: unknown assignment {a!r} (expected one of BMVFUCJ)")
        out[k] = a
    return out


def _check_fold_angles(fold_angles, assignments: np.ndarray) -> np.ndarray:
    n = len(assignments)
    if fold_angles is None:
        return np.where(assignments == "M", -np.pi, np.where(assignments == "V", np.pi, 0.0))
    rho = _as_array(fold_angles, np.float64, "fold_angles")
    if rho.shape != (n,):
        raise PatternError(f"fold_angles: expected shape ({n},), got {rho.shape}")
    for k in range(n):
        r, a = rho[k], assignments[k]
        if not np.isfinite(r):
            raise PatternError(f"edge {k}: fold angle is {r}")
        if abs(r) > np.pi * (1 + 1e-12):
            raise PatternError(f"edge {k}: fold angle {r:.6g} rad is outside [-pi, pi]")
        if (a == "M" and r > 0) or (a == "V" and r < 0):
            raise PatternError(
                f"edge {k}: assignment {a} but fold angle {r:.6g} rad "
                "(mountains are negative, valleys positive)"
            )
        if a in "FJBC" and r != 0:
            raise PatternError(f"edge {k}: assignment {a} takes no fold angle, got {r:.6g} rad")
    return np.clip(rho, -np.pi, np.pi)


def _check_edge_geometry(vertices: np.ndarray, edges: np.ndarray) -> None:
    lengths = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    scale = float(lengths.max())
    short = np.flatnonzero(lengths <= 1e-12 * scale)
    if len(short):
        k = int(short[0])
        name = _edge_name(k, edges[k])
        if lengths[k] == 0.0:
            raise PatternError(f"{name}: has zero length")
        what = f"{name}: is {lengths[k]:.3g} long, under 1e-12 of the longest edge ({scale:.3g})"
        # not zero: its ends nearly coincide, or a vertex far out makes the pattern that large
        r = np.linalg.norm(vertices - np.median(vertices, axis=0), axis=1)
        far = int(np.argmax(r))
        if r[far] <= 1e6 * float(np.median(r)):
            raise PatternError(f"{what}: its two vertices nearly coincide")
        where = ", ".join(f"{x:.6g}" for x in vertices[far])
        raise PatternError(
            f"{what}: vertex {far} at ({where}) lies that far from the others; is its "
            "coordinate a mistake?"
        )


def _check_face_edges(edges, faces, edge_faces, assignments) -> None:
    for k, fs in enumerate(edge_faces):
        a = assignments[k]
        name = _edge_name(k, edges[k])
        if len(fs) == 0:
            raise PatternError(f"{name}: belongs to no face")
        if len(fs) > 2:
            raise PatternError(f"{name}: belongs to {len(fs)} faces {fs}, at most 2 allowed")
        if a == "B" and len(fs) != 1:
            raise PatternError(f"{name}: is a border (B) but lies between faces {fs}")
        if a != "B" and len(fs) == 1:
            raise PatternError(f"{name}: is assigned {a} but lies on the border (one face)")
        if len(fs) == 2 and fs[0] == fs[1]:
            raise PatternError(f"{name}: has face {fs[0]} on both sides")
    # a cut opens only at a vertex that can be split in two: on the border or on a second cut
    on_border = {int(v) for k, fs in enumerate(edge_faces) if len(fs) == 1 for v in edges[k]}
    cuts_at = np.bincount(edges[assignments == "C"].ravel(), minlength=int(edges.max()) + 1)
    for k in np.flatnonzero(assignments == "C"):
        if all(int(v) not in on_border and cuts_at[v] == 1 for v in edges[k]):
            raise PatternError(
                f"{_edge_name(k, edges[k])}: is a cut (C) that cannot open "
                "(both its ends are inside the paper and meet no other cut)"
            )


def signed_area(points: np.ndarray) -> float:
    """Signed area of a polygon (N, 2), positive when counterclockwise."""
    # relative to its first vertex: a small face far from the origin keeps its digits
    points = points[:, :2] - points[:1, :2]
    x, y = points[:, 0], points[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def _counterclockwise(vertices, face, k) -> tuple[int, ...]:
    pts = vertices[list(face), :2]
    area = signed_area(pts)
    span = np.ptp(pts, axis=0).max()
    if abs(area) <= 1e-12 * span * span:
        raise PatternError(f"face {k}: has zero area (vertices {list(face)})")
    return tuple(face) if area > 0 else tuple(reversed(face))


# ---------------------------------------------------------------------------------------------
# triangulation


# a triangle whose altitude is below this fraction of its longest side is a sliver: the bars
# hardly keep it from collapsing (see origami_jax.metrics.collapsed_triangles)
SLIVER = 1e-2


def _orient(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Twice the signed area of the 2-D triangles ``(o, a, b)`` (..., 2) each: > 0 when ``b``
    lies left of ``o -> a``."""
    return (a[..., 0] - o[..., 0]) * (b[..., 1] - o[..., 1]) - (a[..., 1] - o[..., 1]) * (
        b[..., 0] - o[..., 0]
    )


def triangle_quality(p: np.ndarray) -> np.ndarray:
    """(...,) twice the area over the longest side squared of 2-D triangles ``p`` (..., 3, 2):
    the altitude on the longest side over its length; larger is rounder (equilateral 0.87)."""
    area2 = _orient(p[..., 0, :], p[..., 1, :], p[..., 2, :])
    longest = np.max(np.sum((p - np.roll(p, 1, axis=-2)) ** 2, axis=-1), axis=-1)
    return area2 / np.maximum(longest, np.finfo(float).tiny)


def _triangulate(points: np.ndarray, face: tuple[int, ...], k: int) -> list[tuple[int, int, int]]:
    """Triangles of a simple counterclockwise polygon: ear clipping, the best-shaped ear first;
    where that leaves a sliver, the triangulation whose worst triangle is best, if better."""
    tris = _clip_ears(points, k)
    worst = np.min(triangle_quality(points[np.array(tris)]))
    if worst < SLIVER and len(face) <= 200:  # the search holds (n, n, n) arrays
        found = _max_min_triangulation(points)
        if found is not None and np.min(triangle_quality(points[np.array(found)])) > worst:
            tris = found
    return [(face[a], face[b], face[c]) for a, b, c in tris]


def _diagonals(points: np.ndarray) -> np.ndarray:
    """(n, n) whether the segment between polygon vertices i and j is a side or an inner
    diagonal of the simple counterclockwise polygon ``points`` (touching no other vertex)."""
    n = len(points)
    nxt = np.roll(points, -1, axis=0)
    prv = np.roll(points, 1, axis=0)
    cross = _orient
    pi, pj = points[:, None, :], points[None, :, :]
    # leaves i into the polygon's interior: inside the angle at i (convex or reflex)
    convex = cross(prv, points, nxt) > 0
    a = cross(pi, nxt[:, None, :], pj) > 0  # j left of i -> i+1
    b = cross(pi, pj, prv[:, None, :]) > 0  # i-1 left of i -> j
    inside = np.where(convex[:, None], a & b, a | b)
    # crossing or touching any side (e, e+1) that does not end at i or j; 16 rows of (n, n, n)
    # at a time, so a 200-vertex face needs megabytes, not hundreds of them
    span = float(np.ptp(points, axis=0).max())
    eps = 1e-12 * span * span
    idx = np.arange(n)
    blocked = np.zeros((n, n), bool)
    e0, e1 = points[None, None, :, :], nxt[None, None, :, :]
    for rows in np.array_split(idx, max(1, n // 16)):
        s0, s1 = pi[rows, :, None, :], pj[:, :, None, :]
        d1, d2 = cross(s0, s1, e0), cross(s0, s1, e1)
        d3, d4 = cross(e0, e1, s0), cross(e0, e1, s1)
        hits = (np.minimum(d1, d2) <= eps) & (np.maximum(d1, d2) >= -eps)
        hits &= (np.minimum(d3, d4) <= eps) & (np.maximum(d3, d4) >= -eps)
        # on one line the four signs all vanish: a hit only where the side overlaps the diagonal
        collinear = (np.abs(d1) <= eps) & (np.abs(d2) <= eps)
        axis = s1 - s0
        t0, t1 = np.sum((e0 - s0) * axis, axis=-1), np.sum((e1 - s0) * axis, axis=-1)
        length2 = np.sum(axis * axis, axis=-1)
        hits &= ~collinear | ((np.maximum(t0, t1) >= -eps) & (np.minimum(t0, t1) <= length2 + eps))
        e, i, j = idx[None, None, :], rows[:, None, None], idx[None, :, None]
        ends = (e == i) | (e == j) | ((e + 1) % n == i) | ((e + 1) % n == j)
        blocked[rows] = np.any(hits & ~ends, axis=2)
    ok = inside & ~blocked
    side = (idx[:, None] - idx[None, :]) % n
    ok |= (side == 1) | (side == n - 1)
    np.fill_diagonal(ok, False)
    return ok


def _max_min_triangulation(points: np.ndarray) -> list[tuple[int, int, int]] | None:
    """The triangulation of a simple counterclockwise polygon that maximizes its worst
    triangle's :func:`triangle_quality` (dynamic programming over the polygon's diagonals,
    vectorized over the chains of each length); ``None`` if it finds none."""
    n = len(points)
    ok = _diagonals(points)
    best = np.full((n, n), -np.inf)
    split = np.full((n, n), -1)
    best[np.arange(n - 1), np.arange(1, n)] = np.inf
    for length in range(2, n):
        i = np.arange(n - length)
        j = i + length
        k = i[:, None] + np.arange(1, length)[None, :]
        ii, jj = np.broadcast_to(i[:, None], k.shape), np.broadcast_to(j[:, None], k.shape)
        q = triangle_quality(points[np.stack([ii, k, jj], axis=-1)])
        value = np.minimum(np.minimum(best[ii, k], best[k, jj]), q)
        value[~(ok[ii, k] & ok[k, jj])] = -np.inf
        m = np.argmax(value, axis=1)  # the first of equals: deterministic
        v = value[np.arange(len(i)), m]
        good = ok[i, j] & (v > -np.inf)
        best[i[good], j[good]] = v[good]
        split[i[good], j[good]] = k[np.arange(len(i)), m][good]
    if split[0, n - 1] < 0:
        return None
    out, stack = [], [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j - i >= 2:
            k = int(split[i, j])
            out.append((i, k, j))
            stack += [(i, k), (k, j)]
    return out


def _clip_ears(points: np.ndarray, k: int) -> list[tuple[int, int, int]]:
    """Ear clipping of a simple counterclockwise polygon (face ``k``), taking the best-shaped
    ear first (each round tests every ear against every vertex at once); triangles of indices
    into ``points``."""
    idx = np.arange(len(points))
    out: list[tuple[int, int, int]] = []
    span = float(np.ptp(points, axis=0).max())
    eps = 1e-12 * span * span
    cross = _orient
    while len(idx) > 3:
        a, b, c = np.roll(idx, 1), idx, np.roll(idx, -1)
        pa, pb, pc = points[a], points[b], points[c]
        area2 = cross(pa, pb, pc)
        pv = points[idx][None]
        inside = cross(pa[:, None], pb[:, None], pv) >= -eps
        inside &= cross(pb[:, None], pc[:, None], pv) >= -eps
        inside &= cross(pc[:, None], pa[:, None], pv) >= -eps
        own = (idx[None] == a[:, None]) | (idx[None] == b[:, None]) | (idx[None] == c[:, None])
        usable = (area2 > eps) & ~np.any(inside & ~own, axis=1)
        longest = np.max(
            [np.linalg.norm(pb - pa, axis=1), np.linalg.norm(pc - pb, axis=1),
             np.linalg.norm(pa - pc, axis=1)],
            axis=0,
        )  # fmt: skip
        # as triangle_quality, but through the sides' norms, as ever: ties resolve as before
        quality = area2 / longest**2  # larger is rounder
        best, best_q = -1, -np.inf
        for s in np.flatnonzero(usable):
            # ties (a parallelogram's two ears) go to the first ear, not to rounding, so
            # variants of one pattern keep one triangulation (where no other ear overtakes)
            if quality[s] > best_q * (1 + 1e-9) + 1e-300:
                best, best_q = int(s), quality[s]
        if best < 0:
            raise PatternError(f"face {k}: is not a simple polygon (cannot be triangulated)")
        out.append((int(a[best]), int(b[best]), int(c[best])))
        idx = np.delete(idx, best)
    out.append((int(idx[0]), int(idx[1]), int(idx[2])))
    return out


def find_root(parent, v):
    """Root of ``v`` in a union-find forest (``parent`` a dict or array), compressing the path."""
    while parent[v] != v:
        parent[v] = parent[parent[v]]
        v = parent[v]
    return v


def _split_cuts(vertices, triangles, cut_keys) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Give each fan of triangles around a vertex, separated by cut edges, its own vertex copy.

    Returns the vertices, the triangles and the source vertex of each vertex."""
    if not cut_keys:
        return vertices, triangles, np.arange(len(vertices))
    out = triangles.copy()
    around: dict[int, list[int]] = {}
    for t, tri in enumerate(triangles):
        for v in tri:
            around.setdefault(int(v), []).append(t)
    cut_vertices = sorted({v for key in cut_keys for v in key})
    new_vertices = [vertices]
    source = list(range(len(vertices)))
    count = len(vertices)
    for v in cut_vertices:
        tris = around[v]
        parent = {t: t for t in tris}
        by_edge: dict[tuple[int, int], list[int]] = {}
        for t in tris:
            for w in triangles[t]:
                if w != v:
                    key = (min(v, int(w)), max(v, int(w)))
                    by_edge.setdefault(key, []).append(t)
        for key, ts in by_edge.items():
            if key in cut_keys or len(ts) != 2:
                continue
            parent[find_root(parent, ts[0])] = find_root(parent, ts[1])
        groups: dict[int, list[int]] = {}
        for t in tris:
            groups.setdefault(find_root(parent, t), []).append(t)
        for group in list(groups.values())[1:]:
            for t in group:
                out[t][triangles[t] == v] = count
            new_vertices.append(vertices[v][None])
            source.append(v)
            count += 1
    return np.concatenate(new_vertices), out, np.array(source, dtype=np.int64)


def _build_mesh(cp: CreasePattern) -> Mesh:
    vertices = cp.vertices
    triangles: list[tuple[int, int, int]] = []
    triangle_face: list[int] = []
    for k, face in enumerate(cp.faces):
        tris = [face] if len(face) == 3 else _triangulate(vertices[list(face), :2], face, k)
        triangles.extend(tris)
        triangle_face.extend([k] * len(tris))
    tri = np.array(triangles, dtype=np.int64)

    pattern_key = {(int(min(a, b)), int(max(a, b))): k for k, (a, b) in enumerate(cp.edges)}
    cut_keys = {key for key, k in pattern_key.items() if cp.assignments[k] == "C"}
    # triangulation edges: sides of triangles that are not pattern edges
    extra: dict[tuple[int, int], None] = {}  # insertion-ordered set
    for a, b, c in tri:
        for u, w in ((a, b), (b, c), (c, a)):
            key = (int(min(u, w)), int(max(u, w)))
            if key not in pattern_key:
                extra[key] = None

    split_vertices, split_tri, source_vertex = _split_cuts(vertices, tri, cut_keys)

    # map each (directed) triangle side to its triangle, in the split mesh
    side_owner: dict[tuple[int, int], int] = {}
    for t, (a, b, c) in enumerate(split_tri):
        for u, w in ((a, b), (b, c), (c, a)):
            side_owner[(int(u), int(w))] = t
    # each original undirected key -> list of split sides (u, w) with the triangle on the left
    sides_of_key: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for t in range(len(tri)):
        for s in range(3):
            u0, w0 = int(tri[t][s]), int(tri[t][(s + 1) % 3])
            u1, w1 = int(split_tri[t][s]), int(split_tri[t][(s + 1) % 3])
            key = (min(u0, w0), max(u0, w0))
            sides_of_key.setdefault(key, []).append((u1, w1))

    edges, source, role, target, hinges = [], [], [], [], []
    second_sides = []

    def add(u, w, src, rl, tg):
        left = side_owner.get((u, w))
        right = side_owner.get((w, u))
        k_ = -1 if left is None else _third(split_tri[left], u, w)
        l_ = -1 if right is None else _third(split_tri[right], u, w)
        if rl != _BORDER and (k_ < 0 or l_ < 0):
            rl, tg = _BORDER, 0.0
        edges.append((u, w))
        source.append(src)
        role.append(rl)
        target.append(tg)
        hinges.append((u, w, k_, l_))

    for k, (a, b) in enumerate(cp.edges):
        key = (int(min(a, b)), int(max(a, b)))
        asg, rho = cp.assignments[k], float(cp.fold_angles[k])
        sides = sides_of_key[key]
        if asg == "C":
            u, w = sides[0]
            add(u, w, k, _BORDER, 0.0)
            if len(sides) > 1:
                second_sides.append((sides[1], k))
            continue
        u, w = sides[0]
        if asg in "MV" or (asg == "U" and rho != 0.0):
            add(u, w, k, _DRIVEN, rho)
        elif asg in "FJ":
            add(u, w, k, _FACET, 0.0)
        elif asg == "U":
            add(u, w, k, _FREE, 0.0)
        else:
            add(u, w, k, _BORDER, 0.0)
    for (u, w), k in second_sides:
        add(u, w, k, _BORDER, 0.0)
    for key in extra:
        u, w = sides_of_key[key][0]
        add(u, w, -1, _FACET, 0.0)

    hinge_arr = np.array(hinges, dtype=np.int64)
    mesh = Mesh(
        vertices=split_vertices,
        source_vertex=source_vertex,
        edges=hinge_arr[:, :2].copy(),
        source_edge=np.array(source, dtype=np.int64),
        triangles=split_tri,
        triangle_face=np.array(triangle_face, dtype=np.int64),
        role=np.array(role),
        target=np.array(target, dtype=np.float64),
        hinges=hinge_arr,
    )
    for arr in (
        mesh.vertices,
        mesh.source_vertex,
        mesh.edges,
        mesh.source_edge,
        mesh.triangles,
        mesh.triangle_face,
        mesh.role,
        mesh.target,
        mesh.hinges,
    ):
        arr.setflags(write=False)
    return mesh


def _third(tri, u, w) -> int:
    for v in tri:
        if v != u and v != w:
            return int(v)
    raise AssertionError("degenerate triangle")
