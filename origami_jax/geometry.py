"""Geometric kernels: bar lengths and atan2 fold angles, with gradients finite everywhere.

Shapes: ``x`` is (V, 3) positions; ``bars`` (E, 2) and ``hinges`` (H, 4) are vertex indices.
A hinge ``(i, j, k, l)`` is the edge ``i -> j`` with ``k`` the third vertex of the triangle on
its left and ``l`` of the one on its right (in the flat, counterclockwise pattern).

Every kernel also takes trailing axes after those shapes (``x`` (V, 3, B), results (E, B),
(H, B), (H, 4, 3, B), ...), elementwise over them: the batch-innermost layout in which
:mod:`origami_jax.batch` evaluates many problems of one topology at once (the coordinate axis
is always axis 1, so a batch axis after it is contiguous).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

__all__ = [
    "safe_norm",
    "bar_lengths",
    "fold_angles",
    "dihedral_angles",
    "atan2_dihedral",
    "dihedral_gradients",
    "dihedral_hessians",
    "wrap_angle",
]


def safe_norm(v: Array, axis: int = 1) -> Array:
    """Euclidean norm whose gradient is 0 (not NaN) at the zero vector."""
    sq = jnp.sum(v * v, axis=axis)
    positive = sq > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, sq, 1.0)), 0.0)


def bar_lengths(x: Array, bars: Array) -> Array:
    """(E,) current lengths of the bars."""
    p = x[bars]  # one gather: (E, 2, 3)
    return safe_norm(p[:, 1] - p[:, 0], axis=1)


def _cross(a: Array, b: Array) -> Array:
    # written out: fewer XLA ops than jnp.cross, which matters for compile time
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
    return jnp.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=1)


def _dot(a: Array, b: Array) -> Array:
    return jnp.sum(a * b, axis=1)


def wrap_angle(a: Array) -> Array:
    """Map angles to (-pi, pi]."""
    return a - 2 * jnp.pi * jnp.ceil((a - jnp.pi) / (2 * jnp.pi))


def fold_angles(x: Array, hinges: Array, reference: Array | None = None) -> Array:
    """(H,) fold angles in radians: valley positive, mountain negative, flat 0.

    ``rho = atan2(((n_r x n_l) . e_hat), n_l . n_r)`` with ``n_l``, ``n_r`` the normals of the
    triangles left and right of the edge: the seed's atan2 dihedral, ``rho = pi - theta``.

    Without ``reference`` the result lies in (-pi, pi]. With a (H,) ``reference`` the result is
    the branch closest to it, ``reference + angle in (-pi, pi]``, so a crease can be followed
    continuously through +-pi (unwrapping against a previous iterate); the gradient does not
    depend on the reference.
    """
    return dihedral_angles(x[hinges], reference)  # one gather: (H, 4, 3)


def dihedral_angles(p: Array, reference: Array | None = None) -> Array:
    """:func:`fold_angles` of hinges given by their gathered corners ``p`` (H, 4, 3).

    Its derivatives are those of :func:`dihedral_gradients` (a ``jax.custom_jvp``): the same
    values as differentiating the atan2 formula, with a fraction of the operations, so every
    gradient of the energy compiles and runs faster. The reference has no effect on them.
    """
    if reference is None:
        reference = jnp.zeros(p.shape[:1] + p.shape[3:], p.dtype)
    return _dihedral(p, reference)


def atan2_dihedral(p: Array, reference: Array | None = None) -> Array:
    """The atan2 formula of :func:`dihedral_angles`, differentiated by JAX as written (the
    reference against which the closed-form derivatives are tested)."""
    xi = p[:, 0]
    e = p[:, 1] - xi
    e_hat = e / jnp.maximum(safe_norm(e), jnp.finfo(p.dtype).tiny)[:, None]
    n_left = _cross(e_hat, p[:, 2] - xi)
    n_right = _cross(p[:, 3] - xi, e_hat)
    sin_part = _dot(_cross(n_right, n_left), e_hat)
    cos_part = _dot(n_left, n_right)
    if reference is not None:
        c, s = jnp.cos(reference), jnp.sin(reference)
        sin_part, cos_part = sin_part * c - cos_part * s, cos_part * c + sin_part * s
    # atan2(0, 0) has a NaN gradient: only for a collapsed triangle, where any finite value will do
    degenerate = (sin_part == 0) & (cos_part == 0)
    angle = jnp.arctan2(sin_part, jnp.where(degenerate, 1.0, cos_part))
    return angle if reference is None else reference + angle


@jax.custom_jvp
def _dihedral(p: Array, reference: Array) -> Array:
    return atan2_dihedral(p, reference)


@_dihedral.defjvp
def _dihedral_jvp(primals, tangents):
    p, reference = primals
    dp, _ = tangents  # the unwrapped angle does not move with its reference
    return _dihedral(p, reference), jnp.sum(dihedral_gradients(p) * dp, axis=(1, 2))


def dihedral_gradients(p: Array) -> Array:
    """(H, 4, 3) gradient of each hinge's fold angle with respect to its corners ``p`` (H, 4, 3),
    in closed form (Bridson, Marino and Fedkiw 2003): the wings move along their triangles'
    normals, ``|e| n / |n|^2``; the axis ends share the rest so that translations cost nothing.

    It equals ``jax.grad`` of :func:`atan2_dihedral` (to rounding) at a tenth of the cost, and
    it is the derivative of :func:`dihedral_angles`; :func:`dihedral_hessians` is its
    Jacobian. A nearly collapsed wing gives large but finite values; one exactly on the axis
    (zero normal) moves along the other wing's normal.
    """
    return _gradients(_Hinge.of(p))


class _Hinge(NamedTuple):
    """What a hinge's derivatives share: axis ``e``, wing offsets ``a``, ``b`` (from corner 0),
    ``|e|^2`` (floored at ``tiny``) and ``|e|``, the wings' normals and their squared norms, and
    the wings' projections ``t = offset . e / |e|^2`` on the axis; (H,) or (H, 3) each."""

    e: Array
    a: Array
    b: Array
    e2: Array
    length: Array
    n_left: Array
    n_right: Array
    nl2: Array
    nr2: Array
    t2: Array
    t3: Array

    @staticmethod
    def of(p: Array) -> _Hinge:
        e, a, b = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
        e2 = jnp.maximum(_dot(e, e), jnp.finfo(p.dtype).tiny)
        n_left, n_right = _cross(e, a), _cross(b, e)
        return _Hinge(
            e=e,
            a=a,
            b=b,
            e2=e2,
            length=jnp.sqrt(e2),
            n_left=n_left,
            n_right=n_right,
            nl2=_dot(n_left, n_left),
            nr2=_dot(n_right, n_right),
            t2=_dot(a, e) / e2,
            t3=_dot(b, e) / e2,
        )


def _gradients(h: _Hinge) -> Array:
    """:func:`dihedral_gradients` from the hinge's shared quantities."""
    tiny = jnp.finfo(h.e.dtype).tiny
    length, nl2, nr2 = h.length[:, None], h.nl2[:, None], h.nr2[:, None]
    g2 = length * h.n_left / jnp.maximum(nl2, tiny)
    g3 = length * h.n_right / jnp.maximum(nr2, tiny)
    # a wing collapsed onto the axis has no normal: move it along the other wing's normal, at
    # the rate of a wing as wide as the axis is long, so a collapsed start unfolds (0 would
    # leave it at a stationary point of the bars alone)
    g2 = jnp.where(nl2 > 0, g2, h.n_right / jnp.maximum(jnp.sqrt(nr2) * length, tiny))
    g3 = jnp.where(nr2 > 0, g3, h.n_left / jnp.maximum(jnp.sqrt(nl2) * length, tiny))
    g1 = -(h.t2[:, None] * g2 + h.t3[:, None] * g3)
    g0 = -(g1 + g2 + g3)
    return jnp.stack([g0, g1, g2, g3], axis=1)


def _outer(u: Array, v: Array) -> Array:
    return u[:, :, None] * v[:, None, :]


def _skew(v: Array) -> Array:
    """(H, 3, 3) the matrices ``[v]`` with ``[v] w = v x w``."""
    z = jnp.zeros_like(v[:, 0])
    v0, v1, v2 = v[:, 0], v[:, 1], v[:, 2]
    rows = ([z, -v2, v1], [v2, z, -v0], [-v1, v0, z])
    return jnp.stack([jnp.stack(r, axis=1) for r in rows], axis=1)


def dihedral_hessians(p: Array, pairs: Sequence[tuple[int, int]] | None = None) -> Array:
    """(H, 4, 4, 3, 3) Hessian of each hinge's fold angle with respect to its corners ``p``
    (H, 4, 3), as 3 x 3 blocks of corner pairs: entry ``[h, a, b, i, j]`` is the derivative of
    coordinate ``i`` of corner ``a``'s :func:`dihedral_gradients` along coordinate ``j`` of
    corner ``b``, in closed form. Block-major, so that assembling a sparse Hessian moves whole
    contiguous blocks (XLA's CPU transposes of such small dimensions cost several times the
    assembly itself). With ``pairs`` (P corner pairs ``(a, b)``), only those blocks, (H, P, 3,
    3): the upper triangle of a symmetric assembly computes 10 of the 16.

    The wings' gradients ``|e| n / |n|^2`` change with the axis length and with the normal,
    ``d n = [v] d x`` (``[v]`` the cross-product matrix of an edge of the wing); the axis
    ends' gradients follow by the product rule from the wings' and from their projections
    ``t = (x_wing - x_0) . e / |e|^2`` on the axis. It equals ``jax.jacfwd`` of
    :func:`dihedral_gradients` to rounding (tested) in a fraction of the operations, and
    compiles in a fraction of the time. A collapsed wing (zero normal), whose gradient is a
    fallback, contributes no curvature.
    """
    h = _Hinge.of(p)
    e, a, b, e2, length = h.e, h.a, h.b, h.e2, h.length
    nl2, nr2, t2, t3 = h.nl2, h.nr2, h.t2, h.t3
    x1, x2, x3 = p[:, 1], p[:, 2], p[:, 3]
    tiny = jnp.finfo(p.dtype).tiny
    g = _gradients(h)
    zero = jnp.zeros_like(e)
    unit = e / length[:, None]
    d_length = [-unit, unit, zero, zero]

    def wing(n, n2, sides):
        """d(|e| n / |n|^2) / d x_k for each corner k, ``sides`` {k: v} with d n = [v] d x_k."""
        n2 = jnp.maximum(n2, tiny)[:, None, None]
        out = [_outer(n, d) / n2 for d in d_length]
        for k, v in sides.items():
            turn = _skew(v) - 2.0 / n2 * _outer(n, _cross(n, v))
            out[k] = out[k] + length[:, None, None] / n2 * turn
        return out

    left = wing(h.n_left, nl2, {0: x2 - x1, 1: -a, 2: e})
    right = wing(h.n_right, nr2, {0: x1 - x3, 1: b, 3: -e})
    left = [jnp.where((nl2 > 0)[:, None, None], d, 0.0) for d in left]
    right = [jnp.where((nr2 > 0)[:, None, None], d, 0.0) for d in right]
    # d t / d x_k: t2 = a . e / |e|^2 moves with x2 (along e) and with x1 (a - 2 t2 e)
    dt2_1 = (a - 2 * t2[:, None] * e) / e2[:, None]
    dt3_1 = (b - 2 * t3[:, None] * e) / e2[:, None]
    axis = e / e2[:, None]
    dt2 = [-(dt2_1 + axis), dt2_1, axis, zero]
    dt3 = [-(dt3_1 + axis), dt3_1, zero, axis]
    # g1 = -(t2 g2 + t3 g3), g0 = -(g1 + g2 + g3)
    s2, s3 = t2[:, None, None], t3[:, None, None]
    end = [
        -(_outer(g[:, 2], dt2[k]) + s2 * left[k] + _outer(g[:, 3], dt3[k]) + s3 * right[k])
        for k in range(4)
    ]
    start = [-(end[k] + left[k] + right[k]) for k in range(4)]
    rows = (start, end, left, right)
    if pairs is not None:
        return jnp.stack([rows[a][b] for a, b in pairs], axis=1)
    return jnp.stack([jnp.stack(r, axis=1) for r in rows], axis=1)
