"""Exact rigid folding: place every triangle of a pattern by rotations about its creases.

This is a pure-numpy *reference*, not a simulation kernel: it builds the folded state that a
set of fold angles describes when every triangle is a rigid plate, so that tests (and users)
can check that an angle set is consistent (rigid-foldable) and compare solver results against
an exact state.

Conventions are those of :mod:`origami_jax.pattern` and :func:`origami_jax.geometry.fold_angles`:
fold angles in **radians**, valley positive, mountain negative, flat 0; lengths in the
pattern's units. A valley lifts both wings toward +z when the root triangle lies flat.

Example:
  >>> import numpy as np
  >>> from origami_jax.patterns import single_crease
  >>> from origami_jax.kinematics import rigid_fold, check_rigid
  >>> cp = single_crease(fold_angle=np.pi / 2)
  >>> x = rigid_fold(cp)
  >>> strain, angle_error = check_rigid(cp, x)
  >>> bool(strain < 1e-12 and angle_error < 1e-12)
  True
"""

from __future__ import annotations

from collections import deque

import numpy as np

from origami_jax.pattern import CreasePattern, PatternError

__all__ = ["rigid_fold", "check_rigid", "fold_angles_np", "triangle_tree"]


def fold_angles_np(x: np.ndarray, hinges: np.ndarray) -> np.ndarray:
    """(H,) fold angles in radians of the hinges ``(i, j, k, l)`` at positions ``x`` (V, 3).

    The numpy twin of :func:`origami_jax.geometry.fold_angles` (same formula, same sign
    convention, result in (-pi, pi]); hinges with ``k`` or ``l`` equal to -1 (borders) give 0.
    """
    x = np.asarray(x, dtype=np.float64)
    hinges = np.asarray(hinges, dtype=np.int64)
    out = np.zeros(len(hinges))
    ok = (hinges[:, 2] >= 0) & (hinges[:, 3] >= 0)
    if not ok.any():
        return out
    i, j, k, l = hinges[ok].T
    e = x[j] - x[i]
    e_hat = e / np.linalg.norm(e, axis=1)[:, None]
    n_left = np.cross(e_hat, x[k] - x[i])
    n_right = np.cross(x[l] - x[i], e_hat)
    s = np.einsum("ij,ij->i", np.cross(n_right, n_left), e_hat)
    c = np.einsum("ij,ij->i", n_left, n_right)
    out[ok] = np.arctan2(s, c)
    return out


def triangle_tree(pattern: CreasePattern) -> tuple[int, list[tuple[int, int, int]]]:
    """Breadth-first spanning tree of the mesh triangles, adjacent across non-border edges.

    Returns ``(root, steps)``: the root triangle (the one whose centroid is nearest the pattern's
    vertex centroid) and, in tree order, ``(parent, child, edge)`` with ``edge`` the mesh edge the
    two triangles share.

    Raises:
      PatternError: if the triangles are not all connected (the pattern has several pieces).
    """
    mesh = pattern.mesh
    tris = mesh.triangles
    owner: dict[tuple[int, int], int] = {}
    for t, (a, b, c) in enumerate(tris):
        for u, w in ((a, b), (b, c), (c, a)):
            owner[(int(u), int(w))] = t
    neighbours: list[list[tuple[int, int]]] = [[] for _ in range(len(tris))]
    for e, (i, j, k, l) in enumerate(mesh.hinges):
        if k < 0 or l < 0:
            continue
        left, right = owner[(int(i), int(j))], owner[(int(j), int(i))]
        neighbours[left].append((right, e))
        neighbours[right].append((left, e))
    centre = mesh.vertices[: pattern.num_vertices].mean(axis=0)
    centroids = mesh.vertices[tris].mean(axis=1)
    root = int(np.argmin(np.linalg.norm(centroids - centre, axis=1)))
    seen = np.zeros(len(tris), dtype=bool)
    seen[root] = True
    steps: list[tuple[int, int, int]] = []
    queue = deque([root])
    while queue:
        t = queue.popleft()
        for s, e in neighbours[t]:
            if not seen[s]:
                seen[s] = True
                steps.append((t, s, e))
                queue.append(s)
    if not seen.all():
        raise PatternError(
            f"rigid_fold: the pattern falls apart into pieces (triangle {int(np.argmin(seen))} "
            f"is not connected to triangle {root} across creases)"
        )
    return root, steps


def _hinge_rotation(p0: np.ndarray, p1: np.ndarray, q: np.ndarray, rho: float) -> np.ndarray:
    """3x3 rotation (in the flat frame) of the half plane on ``q``'s side of the line p0-p1.

    The half plane turns about the line by ``rho`` toward +z: ``s -> cos(rho) s + sin(rho) z``
    with ``s`` the in-plane unit normal of the line pointing toward ``q``.
    """
    d = p1 - p0
    d = d / np.linalg.norm(d)
    s = (q - p0) - np.dot(q - p0, d) * d
    s = s / np.linalg.norm(s)
    z = np.array([0.0, 0.0, 1.0])
    c, n = np.cos(rho), np.sin(rho)
    # the rotation fixes d and turns the (s, z) plane: s -> c s + n z, z -> -n s + c z
    return np.outer(d, d) + np.outer(c * s + n * z, s) + np.outer(-n * s + c * z, z)


def rigid_fold(pattern: CreasePattern, fold_angles: np.ndarray | None = None) -> np.ndarray:
    """(V_mesh, 3) float64 positions of the pattern folded rigidly to the given fold angles.

    Walks a spanning tree of the mesh triangles (adjacent across non-border edges, see
    :func:`triangle_tree`): the root triangle (nearest the pattern's centroid) stays at its flat
    position, and each child triangle is turned relative to its parent about their shared edge by
    that edge's fold angle (radians; valley +, mountain -, the convention of
    :func:`origami_jax.geometry.fold_angles`, so a valley lifts both wings toward +z).

    Each vertex takes the position given by the first triangle (in tree order) that holds it.
    Only tree edges are guaranteed to have their fold angle; for a rigid-foldable angle set
    every other edge keeps its length and angle too, which :func:`check_rigid` measures.

    Args:
      pattern: the crease pattern; its ``mesh`` (triangles, edges, hinges) is used.
      fold_angles: (num_edges of ``pattern.mesh``,) fold angles in radians, one per mesh edge;
        default ``pattern.mesh.target`` (pattern targets, 0 on facet creases and borders).

    Returns:
      (``pattern.mesh.num_vertices``, 3) positions in the pattern's length unit.

    Example:
      >>> import numpy as np
      >>> from origami_jax.patterns import single_crease
      >>> cp = single_crease(fold_angle=np.pi / 2, width=2.0)
      >>> x = rigid_fold(cp)
      >>> round(float(np.ptp(x[:, 2])), 12)  # one wing stands up by half the width
      1.0
    """
    mesh = pattern.mesh
    if fold_angles is None:
        rho = np.asarray(mesh.target, dtype=np.float64)
    else:
        rho = np.asarray(fold_angles, dtype=np.float64)
        if rho.shape != (mesh.num_edges,):
            raise PatternError(
                f"rigid_fold: fold_angles must have shape ({mesh.num_edges},) (one per mesh edge),"
                f" got {rho.shape}"
            )
        if not np.isfinite(rho).all():
            raise PatternError("rigid_fold: fold_angles must be finite")
    flat = mesh.vertices
    tris = mesh.triangles
    root, steps = triangle_tree(pattern)
    rot = np.zeros((len(tris), 3, 3))
    shift = np.zeros((len(tris), 3))
    rot[root] = np.eye(3)
    for parent, child, e in steps:
        i, j = mesh.edges[e]
        p0, p1 = flat[i], flat[j]
        q = flat[[v for v in tris[child] if v != i and v != j][0]]
        m = _hinge_rotation(p0, p1, q, float(rho[e]))
        # x = R_parent (M (p - p0) + p0) + t_parent
        rot[child] = rot[parent] @ m
        shift[child] = rot[parent] @ (p0 - m @ p0) + shift[parent]
    out = np.full((mesh.num_vertices, 3), np.nan)
    placed = np.zeros(mesh.num_vertices, dtype=bool)
    for t in [root] + [child for _, child, _ in steps]:
        for v in tris[t]:
            if not placed[v]:
                out[v] = rot[t] @ flat[v] + shift[t]
                placed[v] = True
    if not placed.all():  # vertices in no triangle: leave them flat
        out[~placed] = flat[~placed]
    return out


def check_rigid(
    pattern: CreasePattern, positions: np.ndarray, fold_angles: np.ndarray | None = None
) -> tuple[float, float]:
    """How far ``positions`` are from the rigid, exactly folded state: ``(strain, angle_error)``.

    Args:
      pattern: the crease pattern.
      positions: (``pattern.mesh.num_vertices``, 3) positions.
      fold_angles: (num mesh edges,) expected fold angles in radians; default the mesh targets.

    Returns:
      ``strain``: max over all mesh edges of ``|l / l0 - 1|`` (dimensionless);
      ``angle_error``: max over non-border mesh edges of ``|rho - expected|`` in radians, the
      difference wrapped to [-pi, pi] (so +pi and -pi agree).

    For an angle set that is rigid-foldable, ``check_rigid(cp, rigid_fold(cp, rho), rho)`` gives
    values at round-off level (~1e-13); an inconsistent set shows up as strain on the edges
    that close loops of the triangle tree.
    """
    mesh = pattern.mesh
    x = np.asarray(positions, dtype=np.float64)
    if x.shape != (mesh.num_vertices, 3):
        raise PatternError(
            f"check_rigid: positions must have shape ({mesh.num_vertices}, 3), got {x.shape}"
        )
    rho = mesh.target if fold_angles is None else np.asarray(fold_angles, dtype=np.float64)
    edges = mesh.edges
    l0 = np.linalg.norm(mesh.vertices[edges[:, 1]] - mesh.vertices[edges[:, 0]], axis=1)
    length = np.linalg.norm(x[edges[:, 1]] - x[edges[:, 0]], axis=1)
    strain = float(np.max(np.abs(length / l0 - 1.0)))
    inner = (mesh.hinges[:, 2] >= 0) & (mesh.hinges[:, 3] >= 0)
    if not inner.any():
        return strain, 0.0
    diff = fold_angles_np(x, mesh.hinges)[inner] - rho[inner]
    diff = (diff + np.pi) % (2 * np.pi) - np.pi
    return strain, float(np.max(np.abs(diff)))
