"""Rigid motions of the sheet, piece by piece: removing them from a step and turning the
pieces back into the gauge.

The solvers gauge rigid motions out by pinning one triangle per piece
(:func:`~origami_jax.solvers.base.rigid_gauges`); but a Newton step that would turn the sheet
is taken free of the gauge (see ``Newton.free_turn``): its infinitesimal rigid motion is removed
(:func:`rigid_free`, :func:`rigid_fit`), the sheet moves, and each piece is then turned rigidly
back so that its pinned triangle lies where the gauge holds it (:func:`reframe`). The pieces are
the Hessian layout's (``HessianLayout.piece``, in ``problem.aux``).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
from jax import Array

from origami_jax.solvers.base import Problem, pin_axes

__all__ = ["reframe", "reframing", "rigid_free", "rigid_fit"]


def _pinned_frames(x: Array, problem: Problem) -> tuple[Array, Array, Array]:
    """Of every third pinned vertex's triangle (a, b, c) (the gauge's pinned triangles, one
    per piece; in a batch, padding rows after them): (K, 3, 3) frames at ``x`` (rows: along
    ab, in the plane, normal), the (K, 3) positions of a, and (K,) which are real pinned
    triangles (c's projector has rank 2) that ``x`` does not collapse."""
    k = problem.pinned.shape[0] // 3
    a, b, c = (x[problem.pinned[i : 3 * k : 3]] for i in range(3))
    d, n = pin_axes(a, b, c)
    frame = jnp.stack([d, jnp.cross(n, d), n], axis=1)
    pinned = jnp.trace(problem.projectors[2 : 3 * k : 3], axis1=1, axis2=2) > 1.5
    return frame, a, pinned & (jnp.sum(n * n, axis=-1) > 0.5)


def _piece_index(problem: Problem, usable: Array) -> tuple[Array, Array]:
    """(V,) each vertex's pinned triangle (clipped) and whether it has a usable one."""
    piece = problem.aux.piece
    k = jnp.clip(piece, 0, usable.shape[0] - 1)
    return k, (piece >= 0) & (piece < usable.shape[0]) & usable[k]


def reframe(x: Array, problem: Problem) -> Array:
    """``x`` moved rigidly, piece by piece, so that each pinned triangle is back where the
    gauge holds it (a at its start, b on the start's line ab, c in the start's plane abc):
    the displacement ``x - start`` then satisfies the gauge exactly, so :func:`positions`
    gives ``x`` back."""
    return reframing(x, problem)[0](x)


def reframing(x: Array, problem: Problem) -> tuple[Callable[[Array], Array], Array]:
    """The rigid motions :func:`reframe` applies at ``x``, as a function of any (V, 3) points
    (each vertex's moved by its piece's motion), and () whether one motion moves every vertex:
    then distances between any two points are kept, such as those of contact pairs."""
    frame, a, usable = _pinned_frames(x, problem)
    frame0, a0, usable0 = _pinned_frames(problem.start, problem)
    usable = usable & usable0  # a start that collapses a pinned triangle has no frame to keep
    rotation = jnp.einsum("kji,kjl->kil", frame0, frame)  # frame0^T frame
    k, ok = _piece_index(problem, usable)

    def move(y: Array) -> Array:
        moved = jnp.einsum("vij,vj->vi", rotation[k], y - a[k]) + a0[k]
        return jnp.where(ok[:, None], moved, y)

    one = (jnp.sum(usable) == 1) & jnp.all(ok | (problem.aux.piece < 0))  # (< 0: on no bar)
    return move, one


def rigid_free(w: Array, x: Array, problem: Problem) -> tuple[Array, Array]:
    """``w`` (V, 3) less its least-squares infinitesimal rigid motion at ``x``, piece by
    piece (the shortest displacement equivalent to ``w`` up to a rigid motion), and the
    largest rotation removed (radians per unit of ``w``). :func:`rigid_fit` once for several
    ``w`` at the same ``x``."""
    return rigid_fit(x, problem)(w)


def rigid_fit(x: Array, problem: Problem):
    """:func:`rigid_free` at ``x`` as a function of ``w``, the pieces' centroids and inertia
    tensors computed once.

    About each piece's centroid the fit splits: the translation is the mean of ``w``, the
    rotation ``J^-1 sum r x w`` with ``J`` the piece's inertia tensor (3 x 3, inverted in
    closed form: LAPACK's batched kernels deadlock under several CPU devices)."""
    _, _, usable = _pinned_frames(x, problem)
    k, ok = _piece_index(problem, usable)
    num = usable.shape[0]
    weight = ok.astype(x.dtype)[:, None]
    count = jnp.maximum(jax.ops.segment_sum(weight, k, num), 1)
    centre = jax.ops.segment_sum(weight * x, k, num) / count
    r = (x - centre[k]) * weight
    outer = jax.ops.segment_sum(r[:, :, None] * r[:, None, :], k, num)
    inertia = jnp.trace(outer, axis1=1, axis2=2)[:, None, None] * jnp.eye(3, dtype=x.dtype) - outer
    # inverse by cofactors (the inertia tensor is symmetric): rows are cross products of columns
    c0, c1, c2 = inertia[:, :, 0], inertia[:, :, 1], inertia[:, :, 2]
    adjugate = jnp.stack([jnp.cross(c1, c2), jnp.cross(c2, c0), jnp.cross(c0, c1)], axis=1)
    det = jnp.sum(c0 * jnp.cross(c1, c2), axis=-1)
    solid = det > 1e-12 * jnp.max(jnp.abs(inertia), axis=(1, 2)) ** 3
    inverse = (
        jnp.where(solid[:, None, None], adjugate, 0.0) / jnp.where(solid, det, 1.0)[:, None, None]
    )

    def remove(w: Array) -> tuple[Array, Array]:
        shift = jax.ops.segment_sum(weight * w, k, num) / count
        omega = jnp.einsum("kij,kj->ki", inverse, jax.ops.segment_sum(jnp.cross(r, w), k, num))
        spin = jnp.max(jnp.sqrt(jnp.sum(omega * omega, axis=-1)))
        return w - (shift[k] + jnp.cross(omega[k], r)) * weight, spin

    return remove
