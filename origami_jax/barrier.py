"""Barriers that keep a folded sheet physical: no crease through itself, no collapsed triangle.

Both use the barrier of incremental potential contact (Li et al. 2020, "Incremental Potential
Contact", eq. 6), in a dimensionless distance ``s`` (1 at the edge of the active zone, 0 at
the wall):

    b(s) = -(s - 1)^2 ln(s)   for 0 < s < 1,        b(s) = 0   for s >= 1,

which is zero with its first and second derivatives at ``s = 1`` (so an inactive barrier
changes no energy, force or Hessian), convex, and grows without bound as ``s -> 0``. Below
:data:`S_MIN` it is continued by its second-order Taylor polynomial, so the energy stays finite
(a step that jumps past a wall is rejected by a line search on a finite, huge energy, never
by a NaN).

* **Hinge barrier.** A crease's fold angle ``rho`` (unwrapped, so ``|rho| > pi`` means the
  paper passed through itself) has ``s = (pi + gap - |rho|) / gap``: the active zone is
  ``pi <= |rho| < pi + gap``, beyond full folding, so every state with ``|rho| <= pi`` (a
  fully folded crease at its target included) keeps its energy exactly, and no crease gets
  more than ``gap`` past ``pi``. Energy ``w gap b(s)`` with ``w`` its bar's ``axial * l0``
  (what pushes a crease through itself is the sheet's bars, up to their own stiffness): its
  moment ``w |b'(s)|`` grows as ``w gap / (pi + gap - |rho|)`` towards the wall. This replaces
  MERLIN2's "enhanced linear" spring (Liu and Paulino 2017), which stiffens from 135 degrees on
  and so stops a lone crease driven to 180 degrees near 164 degrees: fully folded targets
  would be unreachable.
* **Area barrier.** A triangle's area ``A`` (signed: negative once its normal has turned over
  against the reference normal, that is once it passed through a collapse) over its rest area
  ``A0`` has ``s = A / (A0 floor)``: active below ``floor`` (a fraction) of its rest area.
  Energy ``w b(s)`` with ``w`` the mean over its sides of ``axial * l0``, the scale of a bar's
  energy at a strain of one.

The derivatives are written out (``b'`` and ``b''``) so that Newton's element Hessians use
them directly; the energy itself is differentiated by JAX like every other term.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array

__all__ = [
    "S_MIN",
    "HINGE_GAP",
    "AREA_FLOOR",
    "ipc",
    "hinge_barrier",
    "area_barrier",
    "rest_areas",
    "signed_areas",
    "triangle_normals",
]

# below this the barrier is continued by its Taylor polynomial: a finite, stiff wall (its
# curvature there, 1e6 times the zone's scale, keeps a Newton system that meets it solvable)
S_MIN = 1e-3
# how far past pi (radians) a crease's barrier reaches its wall: a crease ends at most this far
# through itself (1e-5 rad over a wing of a tenth of the sheet is a depth of 1e-6 of it)
HINGE_GAP = 1e-5
# the fraction of its rest area below which a triangle's barrier is active
AREA_FLOOR = 0.25


def ipc(s: Array) -> tuple[Array, Array, Array]:
    """``(b, b', b'')`` of the barrier at ``s`` (any real; see the module docstring)."""
    active = s < 1.0
    c = jnp.clip(s, S_MIN, 1.0)
    ln = jnp.log(c)
    d = c - 1.0
    b = -d * d * ln
    b1 = -2.0 * d * ln - d * d / c
    b2 = -2.0 * ln - 4.0 * d / c + d * d / (c * c)
    t = s - c  # negative only below S_MIN: the Taylor continuation
    below = s < S_MIN
    b = jnp.where(below, b + t * (b1 + 0.5 * t * b2), b)
    b1 = jnp.where(below, b1 + t * b2, b1)
    zero = jnp.zeros_like(s)
    return jnp.where(active, b, zero), jnp.where(active, b1, zero), jnp.where(active, b2, zero)


def hinge_barrier(rho: Array, weight: Array, gap: float) -> tuple[Array, Array, Array]:
    """Per hinge: the barrier's energy and its first and second derivatives in ``rho``."""
    # (gap - (|rho| - pi)): exact at |rho| = pi, where the barrier is exactly inactive
    b, b1, b2 = ipc((gap - (jnp.abs(rho) - jnp.pi)) / gap)
    return weight * gap * b, -weight * b1 * jnp.sign(rho), weight * b2 / gap


def area_barrier(ratio: Array, weight: Array, floor: float) -> tuple[Array, Array, Array]:
    """Per triangle: the barrier's energy and its first and second derivatives in the area
    ratio ``A / A0``."""
    b, b1, b2 = ipc(ratio / floor)
    return weight * b, weight * b1 / floor, weight * b2 / (floor * floor)


def rest_areas(sides: Array) -> Array:
    """(T,) areas of triangles with side lengths ``sides`` (T, 3) (Heron's formula, in the
    stable form of Kahan; 0 for a degenerate or padding triangle)."""
    s = -jnp.sort(-sides, axis=1)  # a >= b >= c
    a, b, c = s[:, 0], s[:, 1], s[:, 2]
    q = (a + (b + c)) * (c - (a - b)) * (c + (a - b)) * (a + (b - c))
    return 0.25 * jnp.sqrt(jnp.maximum(q, 0.0))


def _normals(p: Array) -> Array:
    u, v = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    return jnp.stack(
        [
            u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1],
            u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2],
            u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0],
        ],
        axis=1,
    )


def triangle_normals(x: Array, triangles: Array) -> Array:
    """(T, 3) unit normals of ``triangles`` (T, 3) at positions ``x`` (0 for a collapsed one)."""
    n = _normals(x[triangles])
    norm = jnp.sqrt(jnp.sum(n * n, axis=1, keepdims=True))
    return n / jnp.where(norm > 0, norm, 1.0)


def signed_areas(x: Array, triangles: Array, normals: Array) -> Array:
    """(T,) areas of ``triangles`` at ``x``, negative where the triangle's normal points against
    ``normals`` (the reference: it turned over since)."""
    n = _normals(x[triangles])
    sq = jnp.sum(n * n, axis=1)
    positive = sq > 0
    area = 0.5 * jnp.where(positive, jnp.sqrt(jnp.where(positive, sq, 1.0)), 0.0)
    return jnp.where(jnp.sum(n * normals, axis=1) >= 0, area, -area)
