"""Exporting the triangle mesh, flat or folded, through meshio: .obj, .ply, .stl, .vtu.

The geometry is ``pattern.mesh``: its triangles (counterclockwise in the flat pattern) on the
folded positions of a result, or on the flat positions of a pattern. Cut copies of vertices are
separate points (STL has no shared points: readers may merge coincident ones).

``.obj``, ``.ply`` and ``.stl`` get the triangles only (PLY and STL in binary, meshio's
default for PLY). ``.vtu`` also carries data, in two cell
blocks, ``triangle`` (the T triangles) then ``line`` (the E mesh edges, in mesh edge order).
meshio needs every cell-data array on every block, so each array has a value on both:

=====================  ==========================================  ================================
array                  ``triangle`` block                           ``line`` block
=====================  ==========================================  ================================
``strain``             mean of ``|l / l0 - 1|`` over its 3 sides    ``|l / l0 - 1|`` of the edge
``fold_angle``         NaN (not meaningful)                         simulated fold angle, radians,
                                                                    0 on border edges (and 0 for a
                                                                    flat pattern)
``target_fold_angle``  NaN (not meaningful)                         ``pattern.mesh.target``, radians
``assignment``         -1 (not meaningful)                          index into ``"BMVFUCJ"`` of the
                                                                    source pattern edge's letter
                                                                    (both sides of a cut: ``C``,
                                                                    5); triangulation edges: ``F``
                                                                    (3)
=====================  ==========================================  ================================

``l`` is the length in the exported positions and ``l0`` in ``pattern.mesh.vertices`` (the flat
rest state), so a flat pattern has strain 0. The NaN and -1 placeholders appear only in VTU files.

Files are written atomically: meshio writes a temporary file with the same suffix in the same
folder, which then replaces the target.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import meshio
import numpy as np

from origami_jax.io.fold import atomic_path, pattern_and_state
from origami_jax.pattern import ASSIGNMENTS

__all__ = ["save_mesh", "mesh_of", "MESH_FORMATS"]

#: suffix -> meshio format name
MESH_FORMATS = {".obj": "obj", ".ply": "ply", ".stl": "stl", ".vtu": "vtu"}


def _format(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in MESH_FORMATS:
        shown = f"'{path.suffix}'" if path.suffix else "(no suffix)"
        raise ValueError(
            f"{path}: unsupported mesh format {shown} (supported: {', '.join(MESH_FORMATS)})"
        )
    return MESH_FORMATS[suffix]


def _edge_strain(positions: np.ndarray, rest: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(positions[pairs[..., 0]] - positions[pairs[..., 1]], axis=-1)
    rest_length = np.linalg.norm(rest[pairs[..., 0]] - rest[pairs[..., 1]], axis=-1)
    return np.abs(length / rest_length - 1.0)


def mesh_of(result_or_pattern: Any, with_data: bool = True) -> meshio.Mesh:
    """The :class:`meshio.Mesh` that :func:`save_mesh` writes (with the VTU data if asked)."""
    pattern, positions, fold_angles = pattern_and_state(result_or_pattern)
    mesh = pattern.mesh
    rest = np.asarray(mesh.vertices, dtype=np.float64)
    if positions is None:
        positions = rest.copy()
        fold_angles = np.zeros(mesh.num_edges)
    triangles = np.asarray(mesh.triangles, dtype=np.int64)
    if not with_data:
        return meshio.Mesh(positions, [("triangle", triangles)])

    edges = np.asarray(mesh.edges, dtype=np.int64)
    sides = np.stack([triangles, np.roll(triangles, -1, axis=1)], axis=-1)  # (T, 3, 2)
    triangle_strain = _edge_strain(positions, rest, sides).mean(axis=1)
    edge_strain = _edge_strain(positions, rest, edges)
    angles = np.where(mesh.role == "border", 0.0, fold_angles)
    codes = np.array(
        [
            ASSIGNMENTS.index("F") if src < 0 else ASSIGNMENTS.index(pattern.assignments[src])
            for src in mesh.source_edge
        ],
        dtype=np.int64,
    )
    nan_t = np.full(len(triangles), np.nan)
    return meshio.Mesh(
        positions,
        [("triangle", triangles), ("line", edges)],
        cell_data={
            "strain": [triangle_strain, edge_strain],
            "fold_angle": [nan_t, angles.astype(np.float64)],
            "target_fold_angle": [nan_t.copy(), np.asarray(mesh.target, dtype=np.float64)],
            "assignment": [np.full(len(triangles), -1, dtype=np.int64), codes],
        },
    )


def save_mesh(path: str | os.PathLike, result_or_pattern: Any) -> None:
    """Write the triangle mesh of a result (folded) or a pattern (flat), atomically.

    The format follows the suffix: ``.obj``, ``.ply``, ``.stl`` (triangles only) or ``.vtu``
    (triangles and edges with strain, fold-angle, target and assignment data; see the module
    docstring).

    Raises:
      ValueError: an unsupported suffix (the message lists the supported ones), or a result
        whose arrays have the wrong shape.
      TypeError: not a CreasePattern nor a result.
      OSError: the file cannot be written (nothing is left behind).
    """
    path = Path(path)
    file_format = _format(path)
    mesh = mesh_of(result_or_pattern, with_data=file_format == "vtu")
    with atomic_path(path) as tmp:
        if file_format == "stl":
            meshio.write(tmp, mesh, file_format=file_format, binary=True)
        else:
            meshio.write(tmp, mesh, file_format=file_format)
