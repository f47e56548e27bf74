"""Error measures, under the names of ../shared/reference/metrics.md.

* ``fold_angle_error_max``, ``fold_angle_error_mean``: over driven creases,
  ``|rho - percent * rho_target|``, radians;
* ``facet_angle_error_max``: over facet creases, ``|rho|``, radians;
* ``strain_max``, ``strain_mean``: over all bars, ``|l / l0 - 1|``;
* ``energy``: total energy at the result, energy units of the model;
* ``grad_norm_rel``: max-abs energy gradient divided by its value at the start of the solve;
* ``shape_error``: RMS vertex distance after optimal rigid alignment (Kabsch) divided by the
  flat sheet's diameter.

Not a metric of metrics.md but reported with them: :func:`collapsed_triangles`, the triangles
a result has squeezed to (nearly) zero area.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax import Array

from origami_jax.energy import FoldParams, Reference, Structure, energy, hinge_goals
from origami_jax.geometry import bar_lengths, fold_angles
from origami_jax.pattern import Mesh, triangle_quality
from origami_jax.solvers.base import COLLAPSED_AREA, doubled_areas

__all__ = [
    "position_metrics",
    "edge_fold_angles",
    "kabsch_align",
    "shape_error",
    "collapsed_triangles",
    "METRIC_NAMES",
]

METRIC_NAMES = (
    "fold_angle_error_max",
    "fold_angle_error_mean",
    "facet_angle_error_max",
    "strain_max",
    "strain_mean",
    "energy",
    "grad_norm_rel",
)


def position_metrics(
    x: Array, s: Structure, p: FoldParams, reference: Reference
) -> dict[str, Array]:
    """The metrics of metrics.md that depend on positions only (radians, dimensionless, energy)."""
    zero = jnp.zeros((), x.dtype)
    strain = jnp.abs(bar_lengths(x, s.bars) / p.rest_length - 1.0)
    out = {"strain_max": jnp.max(strain), "strain_mean": jnp.mean(strain)}
    out["fold_angle_error_max"] = out["fold_angle_error_mean"] = zero
    out["facet_angle_error_max"] = zero
    if s.hinges.shape[0]:
        goal, _ = hinge_goals(s, p)
        err = jnp.abs(fold_angles(x, s.hinges, reference.angles) - goal)
        if s.num_creases:
            out["fold_angle_error_max"] = jnp.max(err[: s.num_creases])
            out["fold_angle_error_mean"] = jnp.mean(err[: s.num_creases])
        if s.num_facets:
            facets = err[s.num_creases : s.num_creases + s.num_facets]
            out["facet_angle_error_max"] = jnp.max(facets)
    out["energy"] = energy(x, s, p, reference)
    return out


def edge_fold_angles(x: Array, s: Structure, reference: Reference, num_edges: int) -> Array:
    """(E,) fold angle of every mesh edge (radians; 0 on borders), unwrapped where tracked."""
    out = jnp.zeros(num_edges, x.dtype)
    if s.hinges.shape[0]:
        out = out.at[s.hinge_bars].set(fold_angles(x, s.hinges, reference.angles))
    if s.free.shape[0]:
        out = out.at[s.free_bars].set(fold_angles(x, s.free))
    return out


def kabsch_align(x: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``x`` (N, 3) moved by the proper rotation and translation that best fits ``reference``."""
    x = np.asarray(x, np.float64)
    reference = np.asarray(reference, np.float64)
    cx, cr = x.mean(0), reference.mean(0)
    h = (x - cx).T @ (reference - cr)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return (x - cx) @ rot.T + cr


def shape_error(x: np.ndarray, reference: np.ndarray, diameter: float) -> float:
    """RMS vertex distance after optimal rigid alignment (Kabsch), divided by ``diameter``."""
    aligned = kabsch_align(x, reference)
    return float(np.sqrt(np.mean(np.sum((aligned - reference) ** 2, axis=1))) / diameter)


def collapsed_triangles(x: np.ndarray, mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of ``mesh`` whose area at positions ``x`` (V, 3) is below ``COLLAPSED_AREA``
    (1e-6) of their flat area: their indices, the smallest area ratio first, and those ratios.

    The bars resist a collapse only by the strain of the triangle's sides, small for a thin
    triangle (its apex reaches the long side at a strain of about half its altitude-to-side
    ratio squared), and a collapsed triangle has no normal: the fold angles of its hinges, and
    so the energy's slope, jump there, and a solver that reaches one stalls on the kink."""
    tris = np.asarray(mesh.triangles)
    flat = doubled_areas(np.asarray(mesh.vertices, np.float64)[tris])
    ratio = doubled_areas(np.asarray(x, np.float64)[tris]) / flat
    found = np.flatnonzero(~(ratio >= COLLAPSED_AREA))
    found = found[np.argsort(ratio[found], kind="stable")]
    return found, ratio[found]


def collapse_note(x: np.ndarray, mesh: Mesh) -> str:
    """``""``, or a sentence naming the worst collapsed triangle of ``x`` and the remedy."""
    found, ratio = collapsed_triangles(x, mesh)
    if not len(found):
        return ""
    t = int(found[0])
    aspect = abs(triangle_quality(np.asarray(mesh.vertices)[mesh.triangles[t], :2]))
    more = f" (and {len(found) - 1} more)" if len(found) > 1 else ""
    return (
        f"triangle {t} (vertices {', '.join(str(int(v)) for v in mesh.triangles[t])}) collapsed "
        f"to {ratio[0]:.1e} of its flat area{more}; its altitude is {aspect:.2g} of its "
        "longest side. Bars resist a collapse only by the strain of the triangle's sides, "
        "small for a thin triangle: a larger axial stiffness keeps it open"
    )
