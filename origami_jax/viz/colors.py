"""What is drawn in which colour: the assignments' colours and names, each mesh edge's
letter, a value per face (strain, fold-angle error) and the positions they are read from."""

from __future__ import annotations

from typing import Any

import numpy as np

from origami_jax.fold import FoldResult
from origami_jax.pattern import CreasePattern

__all__ = ["ASSIGNMENT_COLORS", "ASSIGNMENT_NAMES", "edge_assignments", "face_values"]

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
ORDER = "FJUBCVM"


# paper seen from above (front) and from below (back) in the flat pattern's orientation
PAPER = ("#f1e9d2", "#a9c1df")
COLOR_LABELS = {
    "strain": "strain |l/l0 - 1|",
    "fold_angle_error": "fold-angle error (rad)",
    "contact_force": "contact force",
}


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


def mesh_positions(x: Any, pattern: CreasePattern) -> np.ndarray:
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


def unpack(result_or_positions: Any, pattern: CreasePattern | None):
    """(pattern, mesh positions, fold angles or None, percent)."""
    if isinstance(result_or_positions, FoldResult):
        r = result_or_positions
        pattern = pattern or r.pattern
        return pattern, mesh_positions(r.positions, pattern), r.fold_angles, r.percent
    if pattern is None:
        raise ValueError("plotting positions needs their pattern: pass pattern=...")
    return pattern, mesh_positions(result_or_positions, pattern), None, 1.0


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
    (radians) of the driven creases around the face (0 for a face without one);
    ``"contact_force"`` (a :class:`FoldResult` folded with contact only), per triangle, the
    largest self-contact force on its corners (:attr:`FoldResult.contact_forces`).

    Example:
      >>> import origami_jax as oj
      >>> cp = oj.patterns.single_crease()
      >>> face_values(cp.mesh.vertices, "fold_angle_error", cp).round(3)   # flat: error pi/2
      array([1.571, 1.571, 1.571, 1.571])
    """
    if quantity == "contact_force":
        if not isinstance(result_or_positions, FoldResult):
            raise ValueError("color='contact_force' needs a FoldResult (fold(..., contact=True))")
        force = np.linalg.norm(result_or_positions.contact_forces, axis=1)
        return force[result_or_positions.pattern.mesh.triangles].max(axis=1)
    pattern, x, angles, pct = unpack(result_or_positions, pattern)
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
        raise ValueError(
            f"color: expected 'strain', 'fold_angle_error' or 'contact_force', got {quantity!r}"
        )
    per_triangle = per_edge[tri_edges].max(axis=1)
    per_face = np.zeros(pattern.num_faces)
    np.maximum.at(per_face, mesh.triangle_face, per_triangle)
    return per_face[mesh.triangle_face]


def crease_segments(pattern: CreasePattern, x: np.ndarray, show_facets: bool):
    """{letter: (n, 2, 3) segments} in drawing order."""
    letters = edge_assignments(pattern)
    edges = pattern.mesh.edges
    out = {}
    for letter in ORDER:
        if letter == "F" and not show_facets:
            continue
        mask = letters == letter
        if mask.any():
            out[letter] = x[edges[mask]]
    return out


def color_values(color, result_or_positions, pattern, percent):
    if color is None:
        return None, None
    if isinstance(color, str):
        return face_values(result_or_positions, color, pattern, percent), COLOR_LABELS[color]
    values = np.asarray(color, np.float64)
    if values.shape != (len(pattern.mesh.triangles),):
        raise ValueError(
            "color: expected 'strain', 'fold_angle_error', 'contact_force' or "
            f"({len(pattern.mesh.triangles)},) "
            f"values per mesh triangle, got shape {values.shape}"
        )
    return values, "value"
