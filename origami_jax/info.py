"""What a crease pattern holds, before folding it: counts, pieces, holes, flat-foldability.

:func:`describe` returns a :class:`PatternInfo`; ``origami-jax info INPUT`` prints its
:meth:`~PatternInfo.summary`. Flat-foldability is checked at every interior vertex whose creases
are all mountains and valleys folded fully (``|target| = pi``; facet creases, targets 0, are
not folds and are skipped): **Kawasaki** (the alternating sum of the sector angles between
consecutive creases is 0, here to 1e-3 rad, about 0.06 degrees) and **Maekawa**
(``|M - V| = 2``). A vertex that breaks either cannot fold flat, so a full fold of it strains
the paper.

Example:
  >>> from origami_jax import patterns
  >>> from origami_jax.info import describe
  >>> info = describe(patterns.miura_ori(2, 2))
  >>> info.pieces, info.holes, info.kawasaki, info.maekawa
  (1, 0, [], [])
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from origami_jax.pattern import ASSIGNMENTS, CreasePattern, find_root

__all__ = ["PatternInfo", "describe", "KAWASAKI_TOL"]

# rad: drawings are rounded (Origami Simulator's miura-ori.svg is off by up to 5e-5 rad)
KAWASAKI_TOL = 1e-3


@dataclass(frozen=True)
class PatternInfo:
    """Counts and checks of a pattern (see the module docstring).

    ``kawasaki``: ``(vertex, alternating angle sum in rad)`` where it is not 0;
    ``maekawa``: ``(vertex, M count, V count)`` where ``|M - V| != 2``; ``warnings``: messages
    given while reading the file.
    """

    name: str
    vertices: int
    edges: int
    faces: int
    triangles: int
    assignments: dict[str, int]
    pieces: int
    holes: int
    kawasaki: list[tuple[int, float]] = field(default_factory=list)
    maekawa: list[tuple[int, int, int]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    def summary(self) -> str:
        """A readable table, one fact per line, warnings last."""
        hist = " ".join(f"{a}={n}" for a, n in self.assignments.items())
        rows = [
            ("pattern", self.name),
            ("vertices", str(self.vertices)),
            ("edges", f"{self.edges} ({hist})"),
            ("faces", f"{self.faces} ({self.triangles} triangles once triangulated)"),
            ("pieces", str(self.pieces)),
            ("holes", str(self.holes)),
        ]
        lines = [f"{k:<20}  {v}" for k, v in rows]
        lines += [f"warning: {w}" for w in self.warnings]
        lines += [
            f"warning: vertex {v}: breaks Kawasaki's condition (alternating angle sum "
            f"{math.degrees(s):.4g} deg, not 0): not flat-foldable"
            for v, s in self.kawasaki
        ]
        lines += [
            f"warning: vertex {v}: breaks Maekawa's condition ({m} M, {vv} V; |M - V| must "
            "be 2): not flat-foldable"
            for v, m, vv in self.maekawa
        ]
        return "\n".join(lines)


def describe(pattern: CreasePattern, warnings: list[str] | None = None) -> PatternInfo:
    """Counts, pieces, holes and flat-foldability of ``pattern`` (see the module docstring)."""
    counts = Counter(pattern.assignments.tolist())
    hist = {a: counts[a] for a in ASSIGNMENTS if counts[a]}
    pieces = _pieces(pattern)
    loops = _border_loops(pattern)
    kawasaki, maekawa = _flat_foldability(pattern)
    return PatternInfo(
        name=pattern.name,
        vertices=pattern.num_vertices,
        edges=pattern.num_edges,
        faces=pattern.num_faces,
        triangles=len(pattern.mesh.triangles),
        assignments=hist,
        pieces=pieces,
        holes=max(loops - pieces, 0),
        kawasaki=kawasaki,
        maekawa=maekawa,
        warnings=list(warnings or []),
    )


def _pieces(cp: CreasePattern) -> int:
    """Pieces of paper: faces joined across edges that are not cuts."""
    parent = np.arange(cp.num_faces)
    owner: dict[tuple[int, int], int] = {}
    cut = {tuple(sorted(e)) for e in cp.edges[cp.assignments == "C"].tolist()}
    for f, face in enumerate(cp.faces):
        for a, b in zip(face, face[1:] + face[:1], strict=True):
            key = (min(a, b), max(a, b))
            if key in cut:
                continue
            g = owner.setdefault(key, f)
            if g != f:
                parent[find_root(parent, f)] = find_root(parent, g)
    return len({find_root(parent, f) for f in range(cp.num_faces)})


def _border_loops(cp: CreasePattern) -> int:
    """Closed border (``B``) curves, counted as components of the border edges' graph; slits
    cut in the paper (``C``) are not holes."""
    edges = cp.edges[cp.assignments == "B"]
    if len(edges) == 0:
        return 0
    parent = {int(v): int(v) for v in edges.ravel()}
    for a, b in edges.tolist():
        parent[find_root(parent, a)] = find_root(parent, b)
    return len({find_root(parent, v) for v in parent})


def _flat_foldability(cp: CreasePattern):
    xy = cp.vertices[:, :2]
    border = set(cp.edges[np.isin(cp.assignments, ["B", "C"])].ravel().tolist())
    full = np.isin(cp.assignments, ["M", "V"]) & np.isclose(np.abs(cp.fold_angles), np.pi)
    folded = np.isin(cp.assignments, ["M", "V"]) & (cp.fold_angles != 0)
    around: dict[int, list[int]] = {}
    for k in np.flatnonzero(folded):
        for v in cp.edges[k].tolist():
            around.setdefault(v, []).append(int(k))
    kawasaki, maekawa = [], []
    for v, ks in sorted(around.items()):
        if v in border or not all(full[k] for k in ks):
            continue
        other = [int(cp.edges[k, 1] if cp.edges[k, 0] == v else cp.edges[k, 0]) for k in ks]
        d = xy[other] - xy[v]
        order = np.argsort(np.arctan2(d[:, 1], d[:, 0]))
        angles = np.arctan2(d[order, 1], d[order, 0])
        sectors = np.diff(np.append(angles, angles[0] + 2 * np.pi))
        if len(sectors) % 2 == 1:
            alternating = float("nan")  # an odd number of folds never folds flat
        else:
            alternating = float(sectors[0::2].sum() - sectors[1::2].sum())
        if not abs(alternating) <= KAWASAKI_TOL:
            kawasaki.append((v, alternating))
        m = int(sum(cp.assignments[k] == "M" for k in ks))
        n_v = len(ks) - m
        if abs(m - n_v) != 2:
            maekawa.append((v, m, n_v))
    return kawasaki, maekawa
