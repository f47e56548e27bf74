"""The Hessian of the energy, assembled from element Hessians, and its gauge.

The Hessian is assembled from per-element blocks (:func:`element_blocks`): bars (6 x 6, in
closed form), torsion hinges (12 x 12, from the closed-form gradient and Hessian of the atan2
dihedral: :func:`~origami_jax.geometry.dihedral_hessians`) and, where the scene has area
barriers, triangles (9 x 9), scattered into the layout of
:mod:`origami_jax.solvers.hessian_layout` (:func:`assemble`). Far from equilibrium the exact
Hessian can be indefinite; its **convex part** is always positive semi-definite: each bar's
Hessian with its compressive (negative) transverse term dropped, and each hinge's Gauss-Newton
term ``k l0 grad(rho) grad(rho)^T``, which drops ``k l0 (rho - goal) hess(rho)`` (a barrier's
curvature term likewise). Newton's method (:mod:`origami_jax.solvers.newton`) chooses between
the two.

Rigid motions are gauged out as in the other solvers: the pinned vertices' blocks are projected
(``P H P``, projecting every element block), and :func:`gauged_hessian` sets their complement
to a stiffness-sized identity, the matrix that Newton's step and the implicit derivatives of
:mod:`origami_jax.design` factor.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import Array

from origami_jax.barrier import rest_areas
from origami_jax.contact import add_pair_hessians
from origami_jax.energy import (
    Reference,
    Structure,
    hinge_terms,
    hinge_weights,
    triangle_terms,
)
from origami_jax.geometry import (
    dihedral_angles,
    dihedral_gradients,
    dihedral_hessians,
)
from origami_jax.solvers.base import Problem
from origami_jax.solvers.hessian_layout import UPPER_PAIRS, HessianLayout, hessian_elements

__all__ = ["element_blocks", "assemble", "gauged_hessian"]


def element_blocks(
    x: Array,
    structure: Structure,
    params,
    reference: Reference,
    exact: Array | bool,
    upper: bool = False,
) -> list[Array]:
    """The element Hessians as 3 x 3 blocks of vertex pairs, in the order of
    :func:`hessian_elements`: bars (E, 2, 2, 3, 3), then hinges (H, 4, 4, 3, 3) and barrier
    triangles (T, 3, 3, 3, 3) if any (``[e, a, b]`` the block of rows of corner ``a``, columns
    of ``b``); with ``upper`` only the pairs ``a <= b`` of :data:`UPPER_PAIRS`: (E, 3, 3, 3),
    (H, 10, 3, 3), (T, 6, 3, 3).

    A hinge's energy ``e(rho)`` (spring and barrier) has the Hessian
    ``e'' grad(rho) grad(rho)^T + e' hess(rho)``, a triangle's barrier ``e(r)`` of its area
    ratio ``r`` likewise. ``exact`` selects the exact Hessian; otherwise its convex part (the
    bars' compressive term and the ``e' hess`` terms dropped; ``e'' >= 0`` for every term),
    positive semi-definite.

    With a trailing batch axis (``x`` (V, 3, B), see :mod:`origami_jax.solvers.innermost`), the
    blocks have it last.
    """
    dtype = x.dtype
    trailing = x.shape[2:]  # a batch innermost (batch_innermost), elementwise
    ones = (None,) * len(trailing)
    p = x[structure.bars]
    l0 = params.rest_length
    d = p[:, 1] - p[:, 0]
    length = jnp.sqrt(jnp.sum(d * d, axis=1))
    dh = d / jnp.maximum(length, jnp.finfo(dtype).tiny)[:, None]
    transverse = 1.0 - l0 / jnp.maximum(length, jnp.finfo(dtype).tiny)
    transverse = jnp.where(exact, transverse, jnp.maximum(transverse, 0.0))
    k = params.stiffness.axial / l0
    outer = dh[:, :, None] * dh[:, None, :]
    eye = jnp.eye(3, dtype=dtype)[(..., *ones)]
    a = k[:, None, None] * (outer + transverse[:, None, None] * (eye - outer))
    sign = jnp.array([[1.0, -1.0], [-1.0, 1.0]], dtype)
    if upper:
        out = [sign[UPPER_PAIRS[2]][(None, slice(None), None, None, *ones)] * a[:, None]]
    else:
        out = [sign[(None, slice(None), slice(None), None, None, *ones)] * a[:, None, None]]
    if structure.hinges.shape[0]:
        kl = hinge_weights(structure, params)[1]
        q = x[structure.hinges]
        g = dihedral_gradients(q)
        pairs = list(zip(*UPPER_PAIRS[4], strict=True)) if upper else None
        pad = (slice(None),) + (None,) * (3 if upper else 4)
        barrier = structure.barriers.hinge_gap > 0
        # a barrier's curvature depends on the angle, a spring's does not: the angle (and its
        # dihedral) only where needed
        rho = dihedral_angles(q, reference.angles) if barrier else None
        d2 = hinge_terms(rho, structure, params)[2] if barrier else kl

        def gauss_newton():  # in each branch: computed once, where it is used
            full = g[:, :, None, :, None] * g[:, None, :, None, :]
            if upper:
                # all 16 outer products and then the 10: a gather of the corners first made
                # XLA read them strided, several times slower
                full = full[(slice(None), *UPPER_PAIRS[4])]
            return d2[pad] * full

        def with_curvature(weight=1.0):
            # the angle's own Hessian is most of an iteration's work on small patterns: only
            # when asked
            angle = rho if barrier else dihedral_angles(q, reference.angles)
            d1 = hinge_terms(angle, structure, params)[1]
            h = dihedral_hessians(q, pairs)
            return gauss_newton() + (weight * d1)[pad] * h

        if isinstance(exact, bool):
            out.append(with_curvature() if exact else gauss_newton())
        else:
            # vmapped (fold_batch), a cond on each member's flag would run both branches; on
            # whether any member wants the curvature it runs one, and the members that do not
            # get a zero weight
            # (upper: the branches give flat blocks, which the scatter then reads in place; their
            # (H, 10, 3, 3) result was copied whole first)
            shape = (-1, 3, 3, *trailing) if upper else (-1, 4, 4, 3, 3, *trailing)
            blocks = jax.lax.cond(
                _any_member(jnp.any(exact)),
                lambda: with_curvature(exact.astype(dtype)).reshape(shape),
                lambda: gauss_newton().reshape(shape),
            )
            out.append(blocks.reshape(-1, 10, 3, 3, *trailing) if upper else blocks)
    if structure.triangles.shape[0]:
        out.append(_triangle_blocks(x, structure, params, reference, exact, upper))
    return out


def _skew(v: Array) -> Array:
    """(T, 3, 3, ...) the matrices ``[v]`` with ``[v] w = v x w`` of vectors ``v`` (T, 3, ...)."""
    z = jnp.zeros_like(v[:, 0])
    v0, v1, v2 = v[:, 0], v[:, 1], v[:, 2]
    rows = ([z, -v2, v1], [v2, z, -v0], [-v1, v0, z])
    return jnp.stack([jnp.stack(r, axis=1) for r in rows], axis=1)


def _triangle_blocks(x, structure, params, reference, exact, upper):
    """The area barrier's element Hessians: (T, 3, 3, 3, 3), or (T, 6, 3, 3) with ``upper``.

    With ``n = (p1 - p0) x (p2 - p0)`` and ``J_k = dn / dp_k`` (``[p2 - p1]``, ``-[p2 - p0]``,
    ``[p1 - p0]`` as cross-product matrices), the area ``|n| / 2`` has the gradient
    ``J_k^T n^ / 2`` and the Hessian ``(J_j^T (I - n^ n^T) J_k / |n| + K_jk) / 2``, ``K`` the
    constant second derivative of ``n^ . n`` (``-[n^]`` for the pairs (0, 1), (1, 2), (2, 0))."""
    trailing = x.shape[2:]
    ones = (None,) * len(trailing)
    ratio, _, d1, d2 = triangle_terms(x, structure, params, reference.normals)
    p = x[structure.triangles]  # (T, 3, 3, ...)
    p0, p1, p2 = p[:, 0], p[:, 1], p[:, 2]
    jac = [_skew(p2 - p1), -_skew(p2 - p0), _skew(p1 - p0)]
    n = jnp.einsum("tij...,tj...->ti...", jac[2], p2 - p0)  # (p1 - p0) x (p2 - p0)
    norm = jnp.sqrt(jnp.sum(n * n, axis=1))
    safe = jnp.where(norm > 0, norm, 1.0)
    unit = n / safe[:, None]
    l0 = params.rest_length[structure.triangle_bars]
    area0 = rest_areas(l0)
    # d(ratio)/d(area): the sign of the area (turned over: negative) over the rest area
    scale = jnp.sign(ratio) / jnp.where(area0 > 0, area0, 1.0)
    grads = [0.5 * jnp.einsum("tji...,tj...->ti...", j, unit) for j in jac]
    eye = jnp.eye(3, dtype=x.dtype)[(..., *ones)]
    proj = (eye - unit[:, :, None] * unit[:, None, :]) / safe[:, None, None]
    k_skew = -_skew(unit)
    corner_pairs = (
        list(zip(*UPPER_PAIRS[3], strict=True))
        if upper
        else [(a, b) for a in range(3) for b in range(3)]
    )

    def block(a, b):
        outer = (d2 * scale * scale)[:, None, None] * (grads[a][:, :, None] * grads[b][:, None, :])
        if isinstance(exact, bool) and not exact:
            return outer
        curvature = jnp.einsum("tki...,tkl...,tlj...->tij...", jac[a], proj, jac[b])
        if (a, b) in ((0, 1), (1, 2), (2, 0)):
            curvature = curvature + k_skew
        elif (b, a) in ((0, 1), (1, 2), (2, 0)):
            curvature = curvature - k_skew
        weight = (0.5 * d1 * scale * jnp.asarray(exact, x.dtype))[:, None, None]
        return outer + weight * curvature

    blocks = jnp.stack([block(a, b) for a, b in corner_pairs], axis=1)
    return blocks if upper else blocks.reshape(-1, 3, 3, 3, 3, *trailing)


@jax.custom_batching.custom_vmap
def _any_member(flag: Array) -> Array:
    """``flag`` itself; vmapped, whether any member's is set (unbatched), so that a
    ``lax.cond`` on it stays a branch instead of becoming a select of both."""
    return flag


@_any_member.def_vmap
def _any_member_vmap(axis_size, in_batched, flag):
    return (jnp.any(flag), False) if in_batched[0] else (flag, False)


def vertex_projectors(v: int, pinned: Array, projectors: Array) -> Array:
    """(V, 3, 3) each vertex's gauge projector: ``projectors`` at ``pinned``, else identity."""
    eye = jnp.eye(3, dtype=projectors.dtype)
    return jnp.broadcast_to(eye, (v, 3, 3)).at[pinned].set(projectors)


def _project_pinned(matrix: Array, pinned: Array, projectors: Array) -> Array:
    """``P matrix P`` for a (V, 3, V, 3) matrix and P block-diagonal: ``projectors`` (P, 3, 3)
    at the ``pinned`` vertices (a vertex repeated carries the same projector: batch padding),
    identity elsewhere; only their rows and columns change (broadcast sums: XLA's CPU einsum
    of such small dims is several times slower)."""
    v = matrix.shape[0]
    if pinned.shape[0] >= v:  # batch padding pins every padding vertex: project all at once
        proj = vertex_projectors(v, pinned, projectors)
        matrix = jnp.sum(proj[:, :, :, None, None] * matrix[:, None], axis=2)
        return jnp.sum(matrix[..., None] * proj[None, None], axis=3)
    rows = jnp.sum(projectors[:, :, :, None, None] * matrix[pinned][:, None], axis=2)
    matrix = matrix.at[pinned].set(rows)
    cols = matrix[:, :, pinned]
    cols = jnp.sum(cols[..., None] * projectors[None, None], axis=3)
    return matrix.at[:, :, pinned].set(cols)


def assemble(x: Array, problem: Problem, reference: Reference, exact: Array | bool) -> Array:
    """Storage values of the gauged Hessian (exact or its convex part) in ``problem.aux``'s
    layout, before the pinned directions' identity.

    ``P (sum H_e) P`` with P block-diagonal (the pinned vertices' projectors, else identity)
    equals projecting every element block, at a fraction of the cost."""
    layout: HessianLayout = problem.aux
    structure = problem.structure
    blocks = element_blocks(x, structure, problem.params, reference, exact, upper=layout.sparse)
    contact = None
    if structure.contact is not None and reference.pairs is not None:
        c = problem.params.contact
        contact = functools.partial(add_pair_hessians, x, reference.pairs, c.dhat, c.kappa)
    v = problem.start.shape[0]
    elements = hessian_elements(structure)
    if layout.sparse:
        proj = vertex_projectors(v, problem.pinned, problem.projectors)
        num = layout.block_vertices.shape[0]
        matrix, start = jnp.zeros((2 * num, 3, 3), x.dtype), 0
        for part in blocks:  # each part on its own: a concatenation would copy them all
            part = part.reshape(-1, 3, 3)
            index = layout.blocks[start : start + part.shape[0]]
            matrix = matrix.at[index].add(part, mode="promise_in_bounds")
            start += part.shape[0]
        # only the pinned vertices' rows and columns change (a block of two pinned vertices
        # is listed twice and set twice to the same value), set in the values (an update of
        # the blocks copied all of them)
        touched = layout.vertex_blocks[problem.pinned].reshape(-1)
        ends = layout.block_vertices.at[touched].get(mode="fill", fill_value=0)
        rows, cols = proj[ends[:, 0]], proj[ends[:, 1]]
        part = matrix.at[touched].get(mode="fill", fill_value=0.0)
        part += jnp.swapaxes(matrix.at[touched + num].get(mode="fill", fill_value=0.0), 1, 2)
        part = jnp.sum(rows[:, :, :, None] * part[:, None], axis=2)
        part = jnp.sum(part[:, :, :, None] * cols[:, None], axis=2)
        values = jnp.sum(matrix.reshape(-1)[layout.block_entries], axis=1)
        slots = layout.block_slots.at[touched].get(mode="fill", fill_value=values.shape[0])
        values = values.at[slots].set(part.reshape(-1, 9), mode="drop")
        if contact is not None:
            # the sparse pattern is the sheet's: each pair's curvature on its corners' diagonal
            # blocks only (a principal part of a positive semi-definite block stays one), its
            # convex part even in exact attempts (with the whole pair Hessian, over every pair
            # in reach, cuts.svg took 252 iterations in 60 s against 510: docs/contact.md)
            def diagonal(corners, pair_blocks):
                diag = pair_blocks[:, jnp.arange(4), jnp.arange(4)]
                return jnp.zeros((v, 3, 3), x.dtype).at[corners].add(diag)

            own = jnp.einsum("vij,vjk,vlk->vil", proj, contact(diagonal), proj)
            values = values.at[layout.diag_blocks].add(own, mode="drop")
        return values
    matrix = jnp.zeros((v, v, 3, 3), x.dtype)
    for part, e in zip(blocks, elements, strict=True):
        matrix = matrix.at[e[:, :, None], e[:, None, :]].add(part, mode="promise_in_bounds")
    if contact is not None:

        def with_pairs(corners, pair_blocks):
            return matrix.at[corners[:, :, None], corners[:, None, :]].add(pair_blocks)

        if isinstance(exact, bool):
            matrix = contact(with_pairs, exact=exact)
        else:
            # the pairs' own curvature (a Hessian of each pair's distance) only in the
            # iterations that take it, as the elements' (a traced flag computed it always)
            matrix = jax.lax.cond(
                _any_member(jnp.any(exact)),
                lambda: contact(with_pairs, exact=exact),
                lambda: contact(with_pairs, exact=False),
            )
    matrix = jnp.swapaxes(matrix, 1, 2)  # (V, 3, V, 3)
    return _project_pinned(matrix, problem.pinned, problem.projectors).reshape(-1)


def gauged_hessian(x: Array, problem: Problem, reference: Reference, exact: Array | bool) -> Array:
    """:func:`assemble` plus a stiffness-sized identity on the pinned (gauged-out) directions, so
    the system stays well scaled: the matrix Newton's step and the implicit derivatives of
    :mod:`origami_jax.design` factor."""
    layout: HessianLayout = problem.aux
    values = assemble(x, problem, reference, exact)
    eye = jnp.eye(3, dtype=x.dtype)
    return values.at[layout.diag_blocks[problem.pinned]].add(
        gauge_scale(problem) * (eye - problem.projectors), mode="drop"
    )


def gauge_scale(problem: Problem) -> Array:
    """The stiffness put on the pinned-out directions: the mean bar stiffness."""
    return jnp.mean(problem.params.stiffness.axial / problem.params.rest_length)
