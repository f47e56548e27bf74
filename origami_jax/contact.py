"""Self-contact: exact distances, the contact barrier, a broad phase and a step bound, which
``fold(..., contact=True)`` uses with Newton's method (see docs/contact.md).

A sheet's layers are kept apart by the barrier of incremental potential contact (Li et al.
2020, "Incremental Potential Contact"; ipc-toolkit), on every pair of primitives that share no
vertex: a vertex and a triangle (point-triangle) and two edges (edge-edge). Everything here is
pure JAX, jit/grad/vmap-friendly, except the host helpers that pick array sizes
(:func:`allocate`, :func:`reallocate`) and the brute-force reference :func:`all_pairs`.

**Distances** (:func:`point_triangle_distance_sq`, :func:`edge_edge_distance_sq`) are exact and
squared, as in ipc-toolkit: the closest features are classified first (vertex-vertex,
vertex-edge, vertex-face, edge-edge lines; parallel edges fall to their vertex cases), then that
case's formula gives the value. The gradient is ``2 w_k r`` in corner ``k``, ``r = sum w_k
x_k`` the vector between the closest points and ``w`` the case's weights of the corners (the
closest points minimise over the features: moving them along the features changes nothing to
first order), and the Hessian is JAX's derivative of that gradient: those of one smooth formula.
The case is the feature pair of least distance among those whose closest points lie inside the
features (the same case ipc-toolkit's classification picks, written so that it vectorises).
Every formula divides only by a guarded denominator: the gradient is finite at every
configuration (coincident points, zero-length edges, collapsed triangles, parallel edges,
touching primitives), never NaN.

**Barrier.** A pair at distance ``d`` has the energy

    kappa * b(d^2 / dhat^2),        b(s) = -(s - 1)^2 ln s  (barrier.ipc),

active only for ``d < dhat``; it is ipc-toolkit's ``kappa_ipc * b(d^2, dhat^2)`` with
``kappa_ipc = kappa / dhat^4``, written in the dimensionless ``s`` so that ``kappa`` is an
energy (force x length, the unit of :class:`origami_jax.energy.Stiffness` times a length), like
the hinge and area barriers' weights: :func:`contact_stiffness` is :data:`KAPPA` (1e-3) times
the mean of the bars' ``axial * l0``, the scale of a bar's energy at a strain of one. The force
at mid-zone, about ``kappa / dhat``, is then some ``l0 / (1000 dhat)`` times a bar's at unit
strain, far above the creases' (1000 times weaker than the bars at the defaults) that press
layers together; and the barrier grows without bound, so nothing pushes one layer through
another. A weight of the bars' own scale would hold the layers at the edge of the barrier's
reach, where its curvature vanishes and Newton's model does not see it (docs/contact.md).
Edge-edge terms can be multiplied by ipc-toolkit's mollifier (:func:`edge_edge_mollifier`),
which turns them off smoothly as the edges become parallel, where the edge-edge distance is not
differentiable (the vertex-face pairs then hold the layers apart).

**dhat.** :data:`DHAT` (1e-3) of the flat sheet's diameter, by :func:`default_dhat`: it is the
gap that folded layers keep (the barrier's reach, so a stand-in for the paper's thickness;
printer paper is 0.1 mm on a 10 to 20 cm sheet, 5e-4 to 1e-3), far above rounding (float64
resolves it to 13 digits, float32 to 4), 1000 times the depth of a crossing that
:mod:`origami_jax.intersections` reports, and far below an element of a flat sheet of up to
some hundred elements across, so that a sheet at rest has no active pair (a crease folded flat
then stops short of ``pi`` by about ``dhat`` over the distance to the nearest vertex off it).
A mesh finer than that needs a smaller one: :func:`contact_report` at rest says so.

**Broad phase.** Uniform grids over the current positions (jax-md's neighbour lists, with
fixed capacities, so that shapes are static under jit), one for the triangles and one for the
edges: cells of the median box's size, doubled while the boxes would cover more than 16 cells
each on average (the rule of :mod:`origami_jax.intersections`' host grid); a vertex goes to
its cell, a triangle's and an edge's boxes, inflated by ``radius = dhat + skin``, to every
cell they cover; cells are keyed exactly, or hashed on a grid too large for 31-bit keys. A
vertex and a triangle are candidates when the vertex lies in the triangle's inflated box; two
edges when their boxes, each inflated by half the radius, overlap (each pair made once, in the
cell at the larger of their boxes' lowest cells). Pairs whose vertices share a group (the same
vertex, or copies of one made by a cut) are left out, and so are those with an inert vertex
(a negative group: a padded problem's padding). Everything is sorts, running sums,
scatters and binary searches: ``O(n log n)`` in the primitives and linear in the candidates,
nothing quadratic. Too small a capacity is reported (:attr:`ContactPairs.did_overflow` and
the capacities it would have needed); :func:`reallocate` builds again on the host with room
for them. The candidates stay valid while no vertex moves more than ``skin / 2`` from where
they were built (:func:`needs_update`).

**Step bound** (:func:`step_bound`): a fraction of a step that keeps every candidate pair at
least a fraction of its distance apart all along it, from the bound of ipc-toolkit's additive
CCD (each primitive's points move at most as far as its farthest vertex, after removing the
pair's mean motion), advanced a few rounds so that pairs moving apart or sliding past each
other are not held back.

Example:
  >>> import jax.numpy as jnp
  >>> from origami_jax import contact
  >>> x = jnp.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.2, 0.2, 0.3]])
  >>> round(float(contact.point_triangle_distance_sq(x[3], x[0], x[1], x[2])), 6)
  0.09
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from origami_jax.barrier import ipc
from origami_jax.pattern import Mesh

if TYPE_CHECKING:  # energy builds on this module
    from origami_jax.energy import FoldParams

__all__ = [
    "DHAT",
    "STEP_KEEP",
    "MOLLIFIER_EPS",
    "POINT_TRIANGLE_CASES",
    "EDGE_EDGE_CASES",
    "point_triangle_distance_type",
    "point_triangle_distance_sq",
    "edge_edge_distance_type",
    "edge_edge_distance_sq",
    "edge_edge_mollifier",
    "default_dhat",
    "contact_stiffness",
    "KAPPA",
    "contact_barrier",
    "ContactMesh",
    "contact_mesh",
    "mesh_edges",
    "Capacity",
    "ContactPairs",
    "pair_energies",
    "contact_energy",
    "pair_hessians",
    "add_pair_hessians",
    "ContactReport",
    "contact_report",
    "build_pairs",
    "allocate",
    "reallocate",
    "update",
    "refreshed",
    "needs_update",
    "all_pairs",
    "step_bound",
]

#: The barrier's reach ``dhat`` as a fraction of the flat sheet's diameter (see the module
#: docstring for why).
DHAT = 1e-3
#: The barrier's weight as a fraction of the bars' work scale (:func:`contact_stiffness`)
KAPPA = 1e-3
#: The fraction of its distance that :func:`step_bound` keeps between any candidate pair (as
#: ipc-toolkit's additive CCD).
STEP_KEEP = 0.1
#: The contact energy, its Hessian and :func:`step_bound` work on the pairs in play packed into
#: ``1 / NARROW`` of the candidates' rows (all of them, where more are in play).
NARROW = 4
#: ... where the candidates have at least this many rows.
NARROW_FROM = 8192
#: ipc-toolkit's mollifier threshold: edge-edge terms fade out where ``|ea x eb|^2`` is below
#: this times ``|ea|^2 |eb|^2`` at rest (edges within about 1.8 degrees of parallel).
MOLLIFIER_EPS = 1e-3

#: The cases of :func:`point_triangle_distance_type`: the point and a corner, an edge (edge
#: ``k`` runs from corner ``k`` to ``k + 1``) or the triangle's plane.
POINT_TRIANGLE_CASES = ("p-t0", "p-t1", "p-t2", "p-e0", "p-e1", "p-e2", "p-plane")
#: The cases of :func:`edge_edge_distance_type`: two end points, an end point and the other
#: edge, or the two lines (edges ``a = a0 a1`` and ``b = b0 b1``).
EDGE_EDGE_CASES = (
    "a0-b0",
    "a0-b1",
    "a1-b0",
    "a1-b1",
    "a0-eb",
    "a1-eb",
    "b0-ea",
    "b1-ea",
    "ea-eb",
)

# boxes cover at most this many grid cells each, on average (as in intersections.py)
_CELLS_PER_BOX = 16
# grid coordinates stay below this along each axis (the cell size grows if need be)
_GRID_LIMIT = 1 << 20
# a key no cell has (cell keys have 31 bits)
_NO_KEY = np.uint32(0xFFFFFFFF)
# capacities stay below this (int32 sums of counts then need no more than 31 bits); counts
# beyond it are reported as it
_COUNT_LIMIT = 1 << 30


# -- distances --------------------------------------------------------------------------------


def _dot(a: Array, b: Array) -> Array:
    return jnp.sum(a * b, axis=-1)


def _safe(den: Array, ok: Array) -> Array:
    """``den`` where it is usable, 1 elsewhere: a division by it has a finite gradient."""
    return jnp.where(ok, den, 1.0)


def _eps(*arrays: Array) -> float:
    return float(jnp.finfo(jnp.result_type(*arrays, float)).eps)


def _point_line(p: Array, e0: Array, e1: Array, eps: float) -> tuple[Array, Array, Array]:
    """Squared distance from ``p`` to the line ``e0 e1``, whether its foot lies strictly inside
    the edge (and the edge is long enough to have a direction), and the foot's place ``s``
    along it (``e0 + s (e1 - e0)``; 0 where the edge has no direction)."""
    e = e1 - e0
    den = _dot(e, e)
    # an edge this short next to the point's distance: its end points give the same distance
    usable = den > eps * (_dot(p - e0, p - e0) + _dot(p - e1, p - e1))
    c = jnp.cross(e0 - p, e1 - p)
    t = _dot(p - e0, e)
    inside = usable & (t > 0.0) & (t < den)
    safe = _safe(den, usable)
    return _dot(c, c) / safe, inside, jnp.where(usable, t / safe, 0.0)


def _weights(dtype, *rows: tuple) -> Array:
    """(..., C, 4) from C rows of 4 weights (arrays or numbers) of a pair's corners."""
    shape = jnp.broadcast_shapes(*(jnp.shape(w) for row in rows for w in row))

    def row_of(ws):
        return jnp.stack([jnp.broadcast_to(jnp.asarray(w, dtype), shape) for w in ws], axis=-1)

    return jnp.stack([row_of(ws) for ws in rows], axis=-2)


def _point_triangle_cases(p: Array, t0: Array, t1: Array, t2: Array) -> tuple[Array, Array, Array]:
    """(..., 7) squared distances of the cases of :data:`POINT_TRIANGLE_CASES`, whether each
    is realised (its closest points lie inside their features), and (..., 7, 4) each case's
    weights ``w`` of the corners ``(p, t0, t1, t2)``: ``sum_k w_k x_k`` is the vector between
    its closest points."""
    eps = _eps(p, t0, t1, t2)
    # the three corners and the three edges (corner k to corner k + 1) side by side on one
    # axis: one copy of each formula in the program, not three
    a = jnp.stack([t0, t1, t2], axis=-2)
    b = jnp.stack([t1, t2, t0], axis=-2)
    q = p[..., None, :]
    corner = _dot(q - a, q - a)
    line, along, s = _point_line(q, a, b, eps)
    u, w = t1 - t0, t2 - t0
    n = jnp.cross(u, w)
    nn = _dot(n, n)
    # a triangle this thin has no plane worth the name: its edges give the same distance
    flat = nn > eps * _dot(u, u) * _dot(w, w)
    inside = flat & jnp.all(_dot(jnp.cross(b - a, q - a), n[..., None, :]) > 0.0, axis=-1)
    h = _dot(p - t0, n)
    # the foot's barycentric coordinates on t1 and t2
    b1 = jnp.where(flat, _dot(jnp.cross(p - t0, w), n) / _safe(nn, flat), 0.0)
    b2 = jnp.where(flat, _dot(jnp.cross(u, p - t0), n) / _safe(nn, flat), 0.0)
    rows = [(1.0, -float(k == 0), -float(k == 1), -float(k == 2)) for k in range(3)]
    for k in range(3):
        row = [1.0, 0.0, 0.0, 0.0]
        row[1 + k], row[1 + (k + 1) % 3] = s[..., k] - 1.0, -s[..., k]
        rows.append(tuple(row))
    rows.append((1.0, b1 + b2 - 1.0, -b1, -b2))
    values = jnp.concatenate([corner, line, (h * h / _safe(nn, flat))[..., None]], axis=-1)
    ok = jnp.concatenate([jnp.ones_like(along), along, inside[..., None]], axis=-1)
    return values, ok, _weights(values.dtype, *rows)


def _edge_edge_cases(a0: Array, a1: Array, b0: Array, b1: Array) -> tuple[Array, Array, Array]:
    """(..., 9) squared distances of the cases of :data:`EDGE_EDGE_CASES`, whether each is
    realised, and (..., 9, 4) each case's weights of the corners ``(a0, a1, b0, b1)`` (as in
    :func:`_point_triangle_cases`)."""
    eps = _eps(a0, a1, b0, b1)
    # end point to end point (a0 b0, a0 b1, a1 b0, a1 b1), then end point to the other edge
    # (a0 and a1 to b, b0 and b1 to a), each set on one axis (one copy of each formula)
    ends = jnp.stack([a0, a0, a1, a1], axis=-2) - jnp.stack([b0, b1, b0, b1], axis=-2)
    corner = _dot(ends, ends)
    q = jnp.stack([a0, a1, b0, b1], axis=-2)
    e0 = jnp.stack([b0, b0, a0, a0], axis=-2)
    e1 = jnp.stack([b1, b1, a1, a1], axis=-2)
    line, along, s = _point_line(q, e0, e1, eps)
    rows = [(1.0, 0.0, -1.0, 0.0), (1.0, 0.0, 0.0, -1.0), (0.0, 1.0, -1.0, 0.0)]
    rows.append((0.0, 1.0, 0.0, -1.0))
    for k in range(4):
        if k < 2:  # an end point of a and the edge b
            rows.append((float(k == 0), float(k == 1), s[..., k] - 1.0, -s[..., k]))
        else:  # the edge a and an end point of b
            rows.append((1.0 - s[..., k], s[..., k], -float(k == 2), -float(k == 3)))
    u, v = a1 - a0, b1 - b0
    n = jnp.cross(u, v)
    nn = _dot(n, n)
    # parallel within rounding: the closest points include an end point (cases above)
    crossing = nn > eps * _dot(u, u) * _dot(v, v)
    w = b0 - a0
    # the lines' closest points a0 + s u and b0 + t v, in the forms accurate near parallel
    sa = _dot(jnp.cross(w, v), n)
    tb = _dot(jnp.cross(w, u), n)
    inside = crossing & (sa > 0.0) & (sa < nn) & (tb > 0.0) & (tb < nn)
    h = _dot(w, n)
    sa, tb = (jnp.where(crossing, z / _safe(nn, crossing), 0.0) for z in (sa, tb))
    rows.append((1.0 - sa, sa, tb - 1.0, -tb))
    values = jnp.concatenate([corner, line, (h * h / _safe(nn, crossing))[..., None]], axis=-1)
    ok = jnp.concatenate([jnp.ones_like(along), along, inside[..., None]], axis=-1)
    return values, ok, _weights(values.dtype, *rows)


def _classify(values: Array, ok: Array) -> Array:
    """The realised case of least distance (a discrete choice: no gradient flows through it)."""
    values, ok = jax.lax.stop_gradient(values), jax.lax.stop_gradient(ok)
    return jnp.argmin(jnp.where(ok, values, jnp.inf), axis=-1)


def _select(values: Array, case: Array) -> Array:
    return jnp.take_along_axis(values, case[..., None], axis=-1)[..., 0]


def _closest_distance(cases: Callable) -> Callable:
    """The squared distance of the realised case of least distance of ``cases`` (a function
    of 4 corners, as :func:`_point_triangle_cases`), differentiated as ``2 w_k r`` in corner
    ``k``: ``r = sum w_k x_k`` joins the closest points, which are a minimum over the
    features' points, so moving them along their features changes nothing to first order.
    The weights are short formulas in the corners (their own derivatives give the Hessian),
    where differentiating every case's distance and selecting one took several times the
    code (and the compile time)."""

    @jax.custom_jvp
    def distance(*corners: Array) -> Array:
        values, ok, _ = cases(*corners)
        return _select(values, _classify(values, ok))

    @distance.defjvp
    def _(corners, tangents):
        d2, g = _closest_gradient(cases, corners)
        return d2, sum(_dot(g[..., k, :], tangents[k]) for k in range(4))

    return distance


def _closest_gradient(cases: Callable, corners: tuple) -> tuple[Array, Array]:
    """``(d2, g)``: the squared distance of the realised case of least distance of ``cases`` at
    ``corners`` (4 arrays (..., 3)) and its gradient ``g`` (..., 4, 3), ``2 w_k r`` in corner
    ``k`` (``w`` the case's weights, ``r = sum_k w_k x_k`` the vector between its closest
    points)."""
    values, ok, weights = cases(*corners)
    case = _classify(values, ok)
    w = jnp.take_along_axis(weights, case[..., None, None], axis=-2)[..., 0, :]
    r = sum(w[..., k, None] * corners[k] for k in range(4))
    return _select(values, case), 2.0 * w[..., :, None] * r[..., None, :]


_point_triangle_distance_sq = _closest_distance(_point_triangle_cases)
_edge_edge_distance_sq = _closest_distance(_edge_edge_cases)


def point_triangle_distance_type(p: Array, t0: Array, t1: Array, t2: Array) -> Array:
    """(...,) int: the index in :data:`POINT_TRIANGLE_CASES` of the closest features of point
    ``p`` and triangle ``t0 t1 t2`` (each (..., 3))."""
    return _classify(*_point_triangle_cases(p, t0, t1, t2)[:2])


def point_triangle_distance_sq(p: Array, t0: Array, t1: Array, t2: Array) -> Array:
    """(...,) squared distance from point ``p`` to triangle ``t0 t1 t2`` (each (..., 3)): that
    of the case :func:`point_triangle_distance_type` picks (its gradient is finite
    everywhere)."""
    return _point_triangle_distance_sq(*jnp.broadcast_arrays(p, t0, t1, t2))


def edge_edge_distance_type(a0: Array, a1: Array, b0: Array, b1: Array) -> Array:
    """(...,) int: the index in :data:`EDGE_EDGE_CASES` of the closest features of edges
    ``a0 a1`` and ``b0 b1`` (each (..., 3)); parallel edges get an end point case."""
    return _classify(*_edge_edge_cases(a0, a1, b0, b1)[:2])


def edge_edge_distance_sq(a0: Array, a1: Array, b0: Array, b1: Array) -> Array:
    """(...,) squared distance between edges ``a0 a1`` and ``b0 b1`` (each (..., 3)), parallel
    ones included: that of the case :func:`edge_edge_distance_type` picks (its gradient is
    finite everywhere)."""
    return _edge_edge_distance_sq(*jnp.broadcast_arrays(a0, a1, b0, b1))


def edge_edge_mollifier(a0: Array, a1: Array, b0: Array, b1: Array, eps_x: Array) -> Array:
    """(...,) ipc-toolkit's edge-edge mollifier ``m(x) = (2 - x / eps_x) x / eps_x`` below
    ``eps_x`` and 1 above, with ``x = |(a1 - a0) x (b1 - b0)|^2``: continuous with its first
    derivative, 0 for parallel edges. ``eps_x`` (...,): :data:`MOLLIFIER_EPS` times the
    product of the edges' squared rest lengths (``<= 0``: no mollifier)."""
    n = jnp.cross(a1 - a0, b1 - b0)
    on = eps_x > 0
    r = _dot(n, n) / _safe(eps_x, on)
    return jnp.where(on & (r < 1.0), (2.0 - r) * r, 1.0)


# -- the barrier ----------------------------------------------------------------------------


def default_dhat(diameter: float) -> float:
    """The barrier's reach for a sheet of this diameter: :data:`DHAT` times it (the module
    docstring says why)."""
    return DHAT * float(diameter)


def contact_stiffness(params: FoldParams) -> Array:
    """``kappa``, the contact barrier's weight: :data:`KAPPA` times the mean over the bars of
    ``axial * l0``, the energy scale of the other barriers' weights (energy units: force x
    length)."""
    l0 = params.rest_length
    return KAPPA * jnp.mean(jnp.broadcast_to(params.stiffness.axial, l0.shape) * l0, axis=0)


def contact_barrier(d2: Array, dhat: Array | float, kappa: Array | float) -> Array:
    """``kappa * b(d2 / dhat^2)`` (energy, ``kappa``'s unit) of pairs at squared distances
    ``d2``: zero with its gradient and Hessian for ``d2 >= dhat^2``; below :data:`barrier.S_MIN`
    of ``dhat^2`` (``d < 0.03 dhat``) barrier.ipc's finite Taylor continuation."""
    return kappa * ipc(d2 / (dhat * dhat))[0]


# -- the scene's structure and the candidate pairs ------------------------------------------------


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=["triangles", "edges", "groups"],
    meta_fields=[],
)
@dataclass(frozen=True)
class ContactMesh:
    """The static structure contact sees: ``triangles`` (T, 3) and ``edges`` (E, 2) vertex
    indices (int32), and ``groups`` (V,) one id per vertex: two primitives with vertices of one
    group share a vertex and are never a pair (a vertex and its copies made by a cut, which sit
    at the same place at rest). A vertex of a negative group is inert: no primitive that has it
    is in any pair (the padding of :mod:`origami_jax.padding`)."""

    triangles: Array
    edges: Array
    groups: Array

    @property
    def num_vertices(self) -> int:
        return int(self.groups.shape[0])


def mesh_edges(triangles: np.ndarray) -> np.ndarray:
    """(E, 2) int32 the distinct sides of ``triangles`` (T, 3), each ``(i, j)`` with ``i < j``,
    sorted."""
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    sides = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    return np.unique(sides, axis=0).astype(np.int32).reshape(-1, 2)


def contact_mesh(
    mesh: Mesh | np.ndarray,
    num_vertices: int | None = None,
    edges: np.ndarray | None = None,
    groups: np.ndarray | None = None,
) -> ContactMesh:
    """A :class:`ContactMesh` (NumPy arrays) from a :class:`~origami_jax.pattern.Mesh` (its
    triangles, edges and, as groups, its ``source_vertex``: copies made by cuts count as one
    vertex) or from triangles (T, 3) with ``num_vertices`` (default: the largest index + 1),
    ``edges`` (default :func:`mesh_edges`) and ``groups`` (default: each vertex its own)."""
    if isinstance(mesh, Mesh):
        return contact_mesh(
            mesh.triangles,
            mesh.num_vertices,
            mesh.edges if edges is None else edges,
            mesh.source_vertex if groups is None else groups,
        )
    triangles = np.asarray(mesh, np.int32).reshape(-1, 3)
    if num_vertices is None:
        num_vertices = int(triangles.max()) + 1 if triangles.size else 0
    edges = mesh_edges(triangles) if edges is None else np.asarray(edges, np.int32).reshape(-1, 2)
    groups = np.arange(num_vertices) if groups is None else np.asarray(groups)
    if groups.shape != (num_vertices,):
        raise ValueError(f"groups must have shape ({num_vertices},), got {groups.shape}")
    return ContactMesh(triangles, edges, groups.astype(np.int32))


class Capacity(NamedTuple):
    """The fixed sizes of a build (static: each new one compiles the build again). ``*_cells``:
    (primitive, grid cell) entries of the triangles and of the edges; ``*_raw``: pairs met in a
    cell, before the exact box test; ``pt`` and ``ee``: the candidate pairs kept."""

    pt_cells: int
    pt_raw: int
    pt: int
    ee_cells: int
    ee_raw: int
    ee: int


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=[
        "pt",
        "pt_ids",
        "pt_mask",
        "ee",
        "ee_ids",
        "ee_mask",
        "x_built",
        "radius",
        "needed",
    ],
    meta_fields=["capacity"],
)
@dataclass(frozen=True)
class ContactPairs:
    """Candidate pairs, padded to a fixed capacity (a pytree; jax-md's neighbour list).

    ``pt`` (P, 4) vertex indices ``(p, t0, t1, t2)`` of the point-triangle pairs and ``pt_ids``
    (P, 2) their ``(vertex, triangle)``; ``ee`` (Q, 4) ``(a0, a1, b0, b1)`` of the edge-edge
    pairs and ``ee_ids`` (Q, 2) their ``(edge a, edge b)``, ``a < b``; ``pt_mask`` and
    ``ee_mask`` which rows are pairs (the others are zeros). ``x_built`` (V, 3) the positions
    and ``radius`` () the ``dhat + skin`` they were built with (``inf`` for :func:`all_pairs`);
    ``needed`` (6,) the capacity each field of :class:`Capacity` needed (a lower bound where an
    earlier field overflowed); ``capacity`` the :class:`Capacity` built with."""

    pt: Array
    pt_ids: Array
    pt_mask: Array
    ee: Array
    ee_ids: Array
    ee_mask: Array
    x_built: Array
    radius: Array
    needed: Array
    capacity: Capacity

    @property
    def did_overflow(self) -> Array:
        """() bool: a capacity was too small, so some candidates may be missing."""
        return jnp.any(self.needed > jnp.asarray(self.capacity, self.needed.dtype))


# -- energy and report -----------------------------------------------------------------------


def _apart(q: Array, split: int) -> Array:
    """Whether the first ``split`` of a pair's 4 vertex indices share none with the rest."""
    shared = q[:, :split, None] == q[:, None, split:]
    return ~jnp.any(shared, axis=(1, 2))


def _pt_rows(q: Array) -> Array:
    return point_triangle_distance_sq(q[:, 0], q[:, 1], q[:, 2], q[:, 3])


def _ee_rows(q: Array) -> Array:
    return edge_edge_distance_sq(q[:, 0], q[:, 1], q[:, 2], q[:, 3])


def _squared_distances(x: Array, pairs: ContactPairs) -> tuple[Array, Array, Array, Array]:
    """(P,) and (Q,) squared distances of the pairs, and which rows are pairs (masked, and
    sharing no vertex index)."""
    pt_on = pairs.pt_mask & _apart(pairs.pt, 1)
    ee_on = pairs.ee_mask & _apart(pairs.ee, 2)
    return _pt_rows(x[pairs.pt]), pt_on, _ee_rows(x[pairs.ee]), ee_on


def pair_energies(
    x: Array,
    pairs: ContactPairs,
    dhat: Array | float,
    kappa: Array | float,
    rest: Array | None = None,
) -> tuple[Array, Array]:
    """(P,) and (Q,) the barrier energy of each point-triangle and edge-edge row (0 for padding
    rows and rows sharing a vertex). With ``rest`` (V, 3), the rest positions, edge-edge terms
    are mollified (:func:`edge_edge_mollifier`)."""
    pt, pt_on, ee, ee_on = _squared_distances(x, pairs)
    far = dhat * dhat
    # padding rows get a distance beyond the barrier's reach: no energy and no gradient
    e_pt = contact_barrier(jnp.where(pt_on, pt, far), dhat, kappa)
    e_ee = contact_barrier(jnp.where(ee_on, ee, far), dhat, kappa)
    if rest is not None:
        e = x[pairs.ee]
        r = jnp.asarray(rest, x.dtype)[pairs.ee]
        la, lb = (_dot(r[:, k + 1] - r[:, k], r[:, k + 1] - r[:, k]) for k in (0, 2))
        e_ee = e_ee * edge_edge_mollifier(
            e[:, 0], e[:, 1], e[:, 2], e[:, 3], MOLLIFIER_EPS * la * lb
        )
    return e_pt, e_ee


def contact_energy(
    x: Array,
    pairs: ContactPairs,
    dhat: Array | float,
    kappa: Array | float,
    rest: Array | None = None,
) -> Array:
    """() the contact energy of positions ``x`` (V, 3) over the candidate ``pairs``:
    ``kappa * sum b(d^2 / dhat^2)`` over the pairs closer than ``dhat`` (``dhat`` in length
    units, ``kappa`` an energy: see :func:`contact_stiffness`). ``rest``: as in
    :func:`pair_energies`. Its value and derivatives (JAX's, in ``x`` only) are taken over the
    pairs that may be in reach, packed where they fit (:func:`_within`): the barrier's terms
    vanish, with their derivatives, beyond ``dhat``."""

    def total(y: Array, few: ContactPairs) -> Array:
        e_pt, e_ee = pair_energies(y, few, dhat, kappa, rest)
        return jnp.sum(e_pt) + jnp.sum(e_ee)

    # the packing is a lax.cond: differentiated as it is, its reverse mode keeps both branches'
    # residuals; its derivative is taken inside each branch instead
    @jax.custom_jvp
    def energy_of(y: Array) -> Array:
        return _within(jax.lax.stop_gradient(y), pairs, dhat, lambda few: total(y, few))

    @energy_of.defjvp
    def _(primals, tangents):
        (y,), (t,) = primals, tangents
        value, grad = _within(
            jax.lax.stop_gradient(y), pairs, dhat, lambda few: jax.value_and_grad(total)(y, few)
        )
        return value, jnp.vdot(grad, t)

    return energy_of(jnp.asarray(x))


def _maybe_within(x: Array, pairs: ContactPairs, dhat: Array | float) -> tuple[Array, Array]:
    """(P,) and (Q,) whether each point-triangle and edge-edge pair may be within ``dhat``: a
    lower bound on its distance (to the centre of the triangle or of the other edge, less the
    primitives' radii about their centres) below it; far cheaper than the exact distance."""

    def bound(q: Array, split: int) -> Array:
        a, b = q[:, :split], q[:, split:]
        ca, cb = jnp.mean(a, axis=1), jnp.mean(b, axis=1)
        ra = jnp.max(jnp.sqrt(_dot(a - ca[:, None], a - ca[:, None])), axis=1)
        rb = jnp.max(jnp.sqrt(_dot(b - cb[:, None], b - cb[:, None])), axis=1)
        return jnp.sqrt(_dot(ca - cb, ca - cb)) - ra - rb

    pt_on = pairs.pt_mask & _apart(pairs.pt, 1)
    ee_on = pairs.ee_mask & _apart(pairs.ee, 2)
    return pt_on & (bound(x[pairs.pt], 1) < dhat), ee_on & (bound(x[pairs.ee], 2) < dhat)


def _within(x: Array, pairs: ContactPairs, dhat: Array | float, fn: Callable) -> Array:
    """``fn(pairs)`` on the pairs that may be within ``dhat`` at ``x`` (:func:`_maybe_within`;
    their masks cleared elsewhere),
    packed where they fit (:func:`_narrow`), else on all of them: the barrier's terms and their
    derivatives are zero beyond ``dhat``."""
    near_pt, near_ee = _maybe_within(x, pairs, dhat)

    def narrow(p, e):
        (ip, vp), (ie, ve) = p, e
        few = ContactPairs(
            pt=pairs.pt[ip],
            pt_ids=pairs.pt_ids[ip],
            pt_mask=vp & near_pt[ip],
            ee=pairs.ee[ie],
            ee_ids=pairs.ee_ids[ie],
            ee_mask=ve & near_ee[ie],
            x_built=pairs.x_built,
            radius=pairs.radius,
            needed=pairs.needed,
            capacity=pairs.capacity,
        )
        return fn(few)

    return _narrow(near_pt, near_ee, narrow, lambda: fn(pairs))


def _pair_hessian(
    q: Array, on: Array, kind: int, dhat: Array, kappa: Array, exact: Array | bool = False
) -> Array:
    """(4, 4, 3, 3) one pair's barrier Hessian in its 4 corners ``q`` (4, 3): its Gauss-Newton
    part ``e''(d2) g g^T`` in the squared distance ``d2`` (``g`` its gradient), positive
    semi-definite (the barrier is convex in ``d2``); with ``exact``, plus the term
    ``e'(d2) hess(d2)``, which the barrier's fall (``e' < 0``) makes indefinite (Newton's exact
    attempts, which fall back to the convex part where it does not factor or its step is
    refused; without it Newton converges only linearly where layers rest on each other). (A
    per-pair eigenvalue clip, as ipc-toolkit's, needs a vmapped ``eigh``, which hangs XLA's CPU
    runtime here.)"""
    cases = _point_triangle_cases if kind == 1 else _edge_edge_cases

    def gradient(f: Array) -> tuple[Array, Array]:
        # the squared distance's gradient, as its derivative rule has it: its Jacobian
        # (forward mode only) is the distance's Hessian
        d2, g = _closest_gradient(cases, tuple(f.reshape(4, 3)))
        return g.reshape(12), d2

    g, d2 = gradient(q.reshape(12))
    scale = 1.0 / (dhat * dhat)
    _, b1, b2 = ipc(jnp.where(on, d2, 1.0 / scale) * scale)
    h = (kappa * b2 * scale * scale) * jnp.outer(g, g)
    if not (isinstance(exact, bool) and not exact):
        curvature = jax.jacfwd(lambda f: gradient(f)[0])(q.reshape(12))
        # (where, not a product: a member without exact attempts keeps its convex part)
        h = h + jnp.where(exact, kappa * b1 * scale * curvature, 0.0)
    h = jnp.where(on & jnp.all(jnp.isfinite(h)), h, 0.0)  # a degenerate pair: no curvature
    return h.reshape(4, 3, 4, 3).transpose(0, 2, 1, 3)


def pair_hessians(
    x: Array, pairs: ContactPairs, dhat: Array, kappa: Array, exact: Array | bool = False
) -> tuple[Array, Array]:
    """``(corners, blocks)``: (P + Q, 4) the vertices of every candidate pair and (P + Q, 4, 4,
    3, 3) the 3 x 3 blocks of their barrier Hessians' positive semi-definite part, or with
    ``exact`` their exact Hessians (see :func:`_pair_hessian`; zero for pairs out of reach and
    padding rows)."""
    pt_on = pairs.pt_mask & _apart(pairs.pt, 1)
    ee_on = pairs.ee_mask & _apart(pairs.ee, 2)
    each = jax.vmap(_pair_hessian, in_axes=(0, 0, None, None, None, None))
    hp = each(x[pairs.pt], pt_on, 1, dhat, kappa, exact)
    he = each(x[pairs.ee], ee_on, 2, dhat, kappa, exact)
    return jnp.concatenate([pairs.pt, pairs.ee]), jnp.concatenate([hp, he])


def add_pair_hessians(
    x: Array,
    pairs: ContactPairs,
    dhat: Array,
    kappa: Array,
    add: Callable[[Array, Array], Array],
    exact: Array | bool = False,
) -> Array:
    """``add(corners, blocks)`` of :func:`pair_hessians` over the pairs within ``dhat`` only
    (:func:`_within`; the others' are zero): what Newton adds to its assembled Hessian. ``add``
    gives an array of one shape whatever the number of rows."""
    x = jnp.asarray(x)
    return _within(x, pairs, dhat, lambda few: add(*pair_hessians(x, few, dhat, kappa, exact)))


def stiffest_pair(x: Array, pairs: ContactPairs, dhat: Array, kappa: Array) -> Array:
    """() the largest eigenvalue of any pair's barrier Hessian (its Gauss-Newton part of
    :func:`pair_hessians`, rank one: its trace), 0 where no pair is within ``dhat``: the
    barrier's stiffness that an explicit time step must resolve."""

    def largest(corners: Array, blocks: Array) -> Array:
        trace = jnp.einsum("riijj->r", blocks)
        return jnp.max(trace, initial=0.0)

    return add_pair_hessians(x, pairs, dhat, kappa, largest)


class ContactReport(NamedTuple):
    """The pairs inside the barrier's reach: ``pt_active`` (P,) and ``ee_active`` (Q,) which
    rows, ``num_active`` () how many, ``min_ratio`` () the least distance over ``dhat`` of any
    pair (``inf`` without pairs)."""

    pt_active: Array
    ee_active: Array
    num_active: Array
    min_ratio: Array


def contact_report(x: Array, pairs: ContactPairs, dhat: Array | float) -> ContactReport:
    """A :class:`ContactReport` of positions ``x`` (V, 3) over ``pairs``."""
    pt, pt_on, ee, ee_on = _squared_distances(x, pairs)
    d2 = jnp.concatenate([jnp.where(pt_on, pt, jnp.inf), jnp.where(ee_on, ee, jnp.inf)])
    dmin = jnp.sqrt(jnp.min(d2, initial=jnp.inf))
    reach = dhat * dhat
    pt_active, ee_active = pt_on & (pt < reach), ee_on & (ee < reach)
    count = jnp.sum(pt_active) + jnp.sum(ee_active)
    return ContactReport(pt_active, ee_active, count, dmin / dhat)


# -- broad phase ------------------------------------------------------------------------------


def _expand(counts: Array, capacity: int) -> tuple[Array, Array, Array, Array]:
    """Slots ``0 .. capacity - 1`` of the concatenation of ``counts[i]`` items per owner ``i``:
    each slot's owner and index within it, whether it is an item, and the total wanted."""
    n = counts.shape[0]
    slot = jnp.arange(capacity, dtype=jnp.int32)
    if n == 0:
        zero = jnp.zeros(capacity, jnp.int32)
        return zero, zero, jnp.zeros(capacity, bool), jnp.int32(0)
    # int32 sums are exact up to the first that passes the capacity (each step adds at most
    # capacity + 1 < 2^30); what follows may wrap around, and no slot needs it
    step = jnp.minimum(counts, capacity + 1)
    ends = jnp.cumsum(step, dtype=jnp.int32)
    over = ends > capacity
    first = jnp.where(jnp.any(over), jnp.argmax(over), n)
    # a slot's owner is the last whose start is at or before it: count the starts (a scatter
    # and a running sum, cheaper than a binary search per slot)
    starts = jnp.where(jnp.arange(n) <= first, ends - step, capacity)
    marks = jnp.zeros(capacity, jnp.int32).at[starts].add(1, mode="drop")
    owner = jnp.clip(jnp.cumsum(marks, dtype=jnp.int32) - 1, 0, n - 1)
    local = slot - (ends[owner] - step[owner])
    # past the capacity: the total in floating point (sizes only), at least capacity + 1
    total = jnp.sum(counts.astype(jnp.result_type(float)))
    wanted = jnp.maximum(jnp.minimum(total, _COUNT_LIMIT).astype(jnp.int32), capacity + 1)
    wanted = jnp.where(first < n, wanted, ends[-1])
    return owner, local, slot < jnp.minimum(wanted, capacity), wanted


def _unravel(local: Array, span: Array) -> Array:
    """(n, 3) the offset of item ``local`` in a block of ``span`` (n, 3) cells, x fastest."""
    sx, sy = span[:, 0], span[:, 1]
    return jnp.stack([local % sx, (local // sx) % sy, local // (sx * sy)], axis=1)


class _Grid(NamedTuple):
    origin: Array
    h: Array
    dims: Array
    linear: Array  # whether the grid's cells fit exact 31-bit keys


def _grid(x: Array, lo: Array, hi: Array) -> _Grid:
    """A grid for boxes ``lo``, ``hi`` (n, 3) and points ``x``: cells of the median box's size,
    doubled while the boxes would cover more than ``_CELLS_PER_BOX`` cells each on average."""
    origin = jnp.minimum(jnp.min(x, axis=0), jnp.min(lo, axis=0))
    top = jnp.maximum(jnp.max(x, axis=0), jnp.max(hi, axis=0))
    extent = jnp.max(top - origin)
    h = jnp.maximum(jnp.median(jnp.max(hi - lo, axis=1)), extent / _GRID_LIMIT)
    h = jnp.where(h > 0, h, 1.0)
    budget = _CELLS_PER_BOX * lo.shape[0]

    def cells(h):
        span = jnp.floor((hi - origin) / h) - jnp.floor((lo - origin) / h) + 1.0
        return jnp.sum(jnp.prod(span, axis=1))

    # ends by h >= extent at the latest: at most 8 cells a box
    h = jax.lax.while_loop(lambda h: (cells(h) > budget) & (h < extent), lambda h: 2.0 * h, h)
    dims = jnp.floor((top - origin) / h).astype(jnp.int32) + 1
    linear = jnp.prod(dims.astype(jnp.float32)) < 2.0**31
    return _Grid(origin, h, dims, linear)


def _cells(grid: _Grid, p: Array) -> Array:
    c = jnp.floor((p - grid.origin) / grid.h)
    return jnp.clip(c, 0, grid.dims - 1).astype(jnp.int32)


def _keys(grid: _Grid, c: Array) -> Array:
    """31-bit keys of cells ``c`` (n, 3): exact where the grid is small enough, else a hash
    (cells that share one are told apart by their coordinates)."""
    u = c.astype(jnp.uint32)
    d = grid.dims.astype(jnp.uint32)
    exact = (u[:, 2] * d[1] + u[:, 1]) * d[0] + u[:, 0]
    mixed = (
        (u[:, 0] * np.uint32(73856093))
        ^ (u[:, 1] * np.uint32(19349663))
        ^ (u[:, 2] * np.uint32(83492791))
    ) >> 1
    return jnp.where(grid.linear, exact, mixed)


def _compact(keep: Array, capacity: int, *columns: Array) -> tuple[Array, list[Array], Array]:
    """The rows ``keep`` selects, packed into ``capacity`` rows (zeros after), their mask and
    how many there were."""
    if keep.shape[0] == 0:  # nothing to gather from
        mask = jnp.zeros(capacity, bool)
        return mask, [jnp.zeros(capacity, c.dtype) for c in columns], jnp.int32(0)
    idx, mask = _rows(keep, capacity)
    return mask, [jnp.where(mask, c[idx], 0) for c in columns], jnp.sum(keep, dtype=jnp.int32)


def _rows(keep: Array, size: int) -> tuple[Array, Array]:
    """The indices of the rows ``keep`` selects, packed into ``size`` (index 0 after them), and
    which of the ``size`` are rows."""
    place = jnp.cumsum(keep, dtype=jnp.int32) - 1  # at most the raw capacity: no overflow
    target = jnp.where(keep & (place < size), place, size)
    n = keep.shape[0]
    idx = jnp.zeros(size, jnp.int32).at[target].set(jnp.arange(n, dtype=jnp.int32), mode="drop")
    return idx, jnp.arange(size) < jnp.sum(keep, dtype=jnp.int32)


def _pairable(ga: Array, gb: Array) -> Array:
    """(n,) whether two primitives, their vertices' groups ``ga`` (n, i) and ``gb`` (n, j), may
    be a pair: no group in common and none negative (inert). NumPy or JAX arrays alike."""
    apart = (ga[:, :, None] != gb[:, None, :]).all(axis=(1, 2))
    return apart & (ga >= 0).all(axis=1) & (gb >= 0).all(axis=1)


def _point_triangle_candidates(x, mesh, grid, t_lo, t_hi, capacity):
    tri = mesh.triangles
    cv = _cells(grid, x)
    kv = _keys(grid, cv)
    order = jnp.argsort(kv).astype(jnp.int32)
    sorted_keys = kv[order]
    clo, chi = _cells(grid, t_lo), _cells(grid, t_hi)
    span = chi - clo + 1
    owner, local, entry, n_entries = _expand(jnp.prod(span, axis=1), capacity.pt_cells)
    cell = clo[owner] + _unravel(local, span[owner])
    key = _keys(grid, cell)
    start = jnp.searchsorted(sorted_keys, key, side="left").astype(jnp.int32)
    end = jnp.searchsorted(sorted_keys, key, side="right").astype(jnp.int32)
    which, j, raw, n_raw = _expand(jnp.where(entry, end - start, 0), capacity.pt_raw)
    v = order[jnp.minimum(start[which] + j, x.shape[0] - 1)]
    t = owner[which]
    # the vertex's own cell (not one sharing its key), inside the inflated box, not a corner
    g = mesh.groups
    keep = (
        raw
        & _same_cells(grid, cv[v], cell[which])
        & jnp.all((t_lo[t] <= x[v]) & (x[v] <= t_hi[t]), axis=1)
        & _pairable(g[v][:, None], g[tri[t]])
    )
    mask, (v, t), count = _compact(keep, capacity.pt, v, t)
    return mask, v, t, jnp.stack([n_entries, n_raw, count])


def _same_cells(grid: _Grid, a: Array, b: Array) -> Array:
    """Whether cells ``a`` and ``b`` (n, 3), which share a key, are one cell: always on an
    exactly keyed grid (the comparison runs only on a hashed one)."""
    return jax.lax.cond(
        grid.linear,
        lambda: jnp.ones(a.shape[0], bool),
        lambda: jnp.all(a == b, axis=1),
    )


def _edge_edge_candidates(x, mesh, half, capacity):
    edges = mesh.edges
    p = x[edges]
    lo, hi = jnp.min(p, axis=1) - half, jnp.max(p, axis=1) + half
    grid = _grid(x, lo, hi)  # its own: edges' boxes are smaller than triangles'
    clo, chi = _cells(grid, lo), _cells(grid, hi)
    span = chi - clo + 1
    owner, local, entry, n_entries = _expand(jnp.prod(span, axis=1), capacity.ee_cells)
    cell = clo[owner] + _unravel(local, span[owner])
    key = jnp.where(entry, _keys(grid, cell), _NO_KEY)
    order = jnp.argsort(key)
    key, owner, cell, entry = key[order], owner[order], cell[order], entry[order]
    # bit d: the cell is the lowest of its box along axis d
    home = jnp.sum(jnp.where(cell == clo[owner], jnp.array([1, 2, 4]), 0), axis=1)
    # entry k pairs with the entries after it that share its key
    ends = jnp.searchsorted(key, key, side="right").astype(jnp.int32)
    k_all = jnp.arange(key.shape[0], dtype=jnp.int32)
    which, j, raw, n_raw = _expand(jnp.where(entry, ends - k_all - 1, 0), capacity.ee_raw)
    other = jnp.minimum(which + 1 + j, key.shape[0] - 1)
    a, b = owner[which], owner[other]
    g = mesh.groups[edges]
    # made once: in the cell at the larger of the two boxes' lowest cells (along each axis the
    # lowest of one of them), which both cover
    keep = (
        raw
        & ((home[which] | home[other]) == 7)
        & _same_cells(grid, cell[which], cell[other])
        & jnp.all((lo[a] <= hi[b]) & (lo[b] <= hi[a]), axis=1)
        & _pairable(g[a], g[b])
    )
    mask, (a, b), count = _compact(keep, capacity.ee, jnp.minimum(a, b), jnp.maximum(a, b))
    return mask, a, b, jnp.stack([n_entries, n_raw, count])


def _assemble(mesh, x, radius, capacity, pt, ee) -> ContactPairs:
    (pt_mask, v, t, pt_needed), (ee_mask, a, b, ee_needed) = pt, ee
    tri, edges = jnp.asarray(mesh.triangles), jnp.asarray(mesh.edges)
    pt_rows = jnp.zeros((pt_mask.shape[0], 4), jnp.int32)
    if tri.shape[0]:  # (none to gather from otherwise)
        pt_rows = jnp.where(pt_mask[:, None], jnp.concatenate([v[:, None], tri[t]], axis=1), 0)
    ee_rows = jnp.zeros((ee_mask.shape[0], 4), jnp.int32)
    if edges.shape[0]:
        ee_rows = jnp.where(ee_mask[:, None], jnp.concatenate([edges[a], edges[b]], axis=1), 0)
    return ContactPairs(
        pt=pt_rows.astype(jnp.int32),
        pt_ids=jnp.stack([v, t], axis=1).astype(jnp.int32),
        pt_mask=pt_mask,
        ee=ee_rows.astype(jnp.int32),
        ee_ids=jnp.stack([a, b], axis=1).astype(jnp.int32),
        ee_mask=ee_mask,
        x_built=x,
        radius=jnp.asarray(radius, x.dtype),
        needed=jnp.concatenate([pt_needed, ee_needed]).astype(jnp.int32),
        capacity=capacity,
    )


def _empty(capacity: int) -> tuple[Array, Array, Array, Array]:
    zero = jnp.zeros(capacity, jnp.int32)
    return jnp.zeros(capacity, bool), zero, zero, jnp.zeros(3, jnp.int32)


@functools.partial(jax.jit, static_argnames=("capacity",))
def build_pairs(
    x: Array, mesh: ContactMesh, radius: Array | float, capacity: Capacity
) -> ContactPairs:
    """The candidate pairs of positions ``x`` (V, 3) within ``radius`` (``dhat + skin``):
    every vertex-triangle pair whose vertex lies in the triangle's box inflated by ``radius``,
    and every edge-edge pair whose boxes inflated by ``radius / 2`` overlap, sharing no vertex
    group. Jittable (``capacity`` static); check :attr:`ContactPairs.did_overflow` (or use
    :func:`allocate`)."""
    if max(capacity) >= _COUNT_LIMIT:
        raise ValueError(f"contact broad phase: a capacity of 2^30 or more ({capacity})")
    x = jnp.asarray(x)
    x = jnp.where(jnp.isfinite(x), x, 0.0)  # a non-finite vertex: somewhere, not a crash
    r = jnp.asarray(radius, x.dtype)
    pt, ee = _empty(capacity.pt), _empty(capacity.ee)
    if mesh.triangles.shape[0]:
        corners = x[mesh.triangles]
        lo, hi = jnp.min(corners, axis=1) - r, jnp.max(corners, axis=1) + r
        pt = _point_triangle_candidates(x, mesh, _grid(x, lo, hi), lo, hi, capacity)
    if mesh.edges.shape[0]:
        ee = _edge_edge_candidates(x, mesh, 0.5 * r, capacity)
    return _assemble(mesh, x, r, capacity, pt, ee)


def update(x: Array, pairs: ContactPairs, mesh: ContactMesh) -> ContactPairs:
    """The pairs built again at ``x`` with ``pairs``' radius and capacity (jittable: for use
    inside a solver's loop when :func:`needs_update`; check ``did_overflow`` after)."""
    return build_pairs(x, mesh, pairs.radius, pairs.capacity)


def refreshed(
    x: Array, pairs: ContactPairs, mesh: ContactMesh, skin: Array | float
) -> ContactPairs:
    """``pairs`` built again at ``x`` where some vertex moved more than a quarter of ``skin``
    since they were built, else ``pairs`` (jittable): a step moves no vertex farther than half
    the skin from where they were built, so every step has at least a quarter of it to go."""
    return jax.lax.cond(
        needs_update(x, pairs.x_built, 0.5 * skin),
        lambda: update(x, pairs, mesh),
        lambda: pairs,
    )


def needs_update(x: Array, x_at_build: Array, skin: Array | float) -> Array:
    """() bool: some vertex moved more than ``skin / 2`` since the pairs were built (two
    primitives may then have come within ``dhat`` unseen)."""
    moved = jnp.sum((x - x_at_build) ** 2, axis=-1)
    return jnp.max(moved, initial=0.0) > 0.25 * skin * skin


def _round_up(n: int) -> int:
    """The least of 16, 24, 32, 48, 64, ... that holds ``n``: few distinct capacities, so few
    compilations."""
    size = 16
    while size < n:
        size = size * 3 // 2 if size & (size - 1) == 0 else size * 4 // 3
    return size


def _initial_capacity(mesh: ContactMesh) -> Capacity:
    t, e = int(mesh.triangles.shape[0]), int(mesh.edges.shape[0])
    return Capacity(*(_round_up(k) for k in (8 * t, 16 * t, 8 * t, 8 * e, 32 * e, 8 * e)))


def _grown(capacity: Capacity, needed: np.ndarray, multiplier: float) -> Capacity:
    return Capacity(
        *(
            c if n <= c else _round_up(math.ceil(n * multiplier))
            for c, n in zip(capacity, needed.tolist(), strict=True)
        )
    )


def allocate(
    x: Array,
    mesh: ContactMesh,
    radius: float,
    capacity: Capacity | None = None,
    multiplier: float = 1.25,
) -> ContactPairs:
    """The candidate pairs of ``x`` within ``radius``, with capacities that hold them (host
    side: builds, and builds again larger, ``multiplier`` times what was needed, until nothing
    overflows; at most a few rounds, each new capacity one compilation). Without ``capacity``
    the capacities end at about ``multiplier`` times what this ``x`` needs (the pairs' are
    what every energy evaluation pays for); with one, they only grow from it."""
    if not (math.isfinite(float(radius)) and float(radius) >= 0):
        raise ValueError(f"radius must be finite and >= 0, got {radius}")
    fit = capacity is None
    capacity = _initial_capacity(mesh) if capacity is None else capacity
    mesh = jax.tree.map(jnp.asarray, mesh)
    for _ in range(8):  # each round fixes at least the first field that overflowed
        pairs = build_pairs(x, mesh, radius, capacity)
        needed = np.asarray(pairs.needed)
        if not (needed > np.asarray(capacity)).any():
            break
        capacity = _grown(capacity, needed, multiplier)
    else:
        raise RuntimeError(f"contact broad phase: capacities still overflow at {capacity}")
    if fit:  # the first guess was generous: trim it to what was needed
        fitted = Capacity(*(_round_up(math.ceil(n * multiplier)) for n in needed.tolist()))
        if fitted != capacity:
            pairs = build_pairs(x, mesh, radius, fitted)
    return pairs


def reallocate(
    x: Array, pairs: ContactPairs, mesh: ContactMesh, multiplier: float = 1.25
) -> ContactPairs:
    """The pairs of ``x`` built again on the host with capacities grown to what ``pairs``
    needed (after an ``update`` that overflowed), and more if that is still too little."""
    needed = np.asarray(pairs.needed)
    capacity = _grown(pairs.capacity, needed, multiplier)
    return allocate(x, mesh, float(pairs.radius), capacity, multiplier)


def all_pairs(mesh: ContactMesh, x: Array | None = None) -> ContactPairs:
    """Every vertex-triangle and edge-edge pair sharing no vertex group: the brute-force
    reference (host side, quadratic: tests and tiny scenes only). ``x``: stored as
    ``x_built`` (zeros if omitted)."""
    tri, edges, g = (np.asarray(a) for a in (mesh.triangles, mesh.edges, mesh.groups))
    v, t = np.meshgrid(np.arange(len(g)), np.arange(len(tri)), indexing="ij")
    v, t = v.ravel(), t.ravel()
    keep = _pairable(g[v][:, None], g[tri[t]])
    v, t = v[keep], t[keep]
    a, b = np.triu_indices(len(edges), k=1)
    keep = _pairable(g[edges[a]], g[edges[b]])
    a, b = a[keep], b[keep]
    x = np.zeros((len(g), 3)) if x is None else np.asarray(x)
    return ContactPairs(
        pt=jnp.asarray(np.concatenate([v[:, None], tri[t]], axis=1).reshape(-1, 4), jnp.int32),
        pt_ids=jnp.asarray(np.stack([v, t], axis=1), jnp.int32),
        pt_mask=jnp.ones(len(v), bool),
        ee=jnp.asarray(np.concatenate([edges[a], edges[b]], axis=1).reshape(-1, 4), jnp.int32),
        ee_ids=jnp.asarray(np.stack([a, b], axis=1), jnp.int32),
        ee_mask=jnp.ones(len(a), bool),
        x_built=jnp.asarray(x),
        radius=jnp.asarray(np.inf, x.dtype),
        needed=jnp.asarray([0, 0, len(v), 0, 0, len(a)], jnp.int32),
        capacity=Capacity(0, 0, len(v), 0, 0, len(a)),
    )


# -- step bound -------------------------------------------------------------------------------


def _closing_speed(dq: Array, split: int) -> Array:
    """Per pair: the most its two primitives' points can approach each other per unit step
    (each point moves at most as far as its primitive's farthest vertex, relative to the pair's
    mean motion, which changes no distance)."""
    rel = dq - jnp.mean(dq, axis=1, keepdims=True)
    speed = jnp.sqrt(jnp.sum(rel * rel, axis=2))
    return jnp.max(speed[:, :split], axis=1) + jnp.max(speed[:, split:], axis=1)


def _narrow(keep_pt: Array, keep_ee: Array, narrow, full, fractions=(NARROW,)):
    """``narrow(pt_rows, ee_rows)`` on the rows each ``keep`` selects, packed into the first
    of ``fractions`` (a fraction ``1/f`` of each kind's rows; ``(idx, valid)`` of
    :func:`_rows`) where they fit; else ``full()``: the pairs in play are a few of the
    candidates (whose capacity is some times their count), and the work on them is what a solve
    repeats."""
    if not fractions or keep_pt.shape[0] + keep_ee.shape[0] < NARROW_FROM:
        return full()  # a few rows: packing them saves less than its compilation costs
    sizes = [min(k.shape[0], max(1, k.shape[0] // fractions[0])) for k in (keep_pt, keep_ee)]
    fits = (jnp.sum(keep_pt) <= sizes[0]) & (jnp.sum(keep_ee) <= sizes[1])
    rows = (_rows(keep_pt, sizes[0]), _rows(keep_ee, sizes[1]))
    rest = functools.partial(_narrow, keep_pt, keep_ee, narrow, full, fractions[1:])
    return jax.lax.cond(fits, lambda: narrow(*rows), rest)


def step_bound(
    x: Array,
    dx: Array,
    pairs: ContactPairs,
    keep: float = STEP_KEEP,
    iterations: int = 16,
) -> Array:
    """() the largest ``t`` in ``[0, 1]`` found such that along ``x + tau dx``,
    ``0 <= tau <= t``, no candidate pair comes closer than ``keep`` times its distance at ``x``
    (0 where a pair already touches).

    Conservative, as ipc-toolkit's additive CCD: a pair at distance ``d(t)`` that approaches at
    most at speed ``l`` (:func:`_closing_speed`) stays above ``keep d(0)`` up to
    ``t + (d(t) - keep d(0)) / l``; each of at most ``iterations`` rounds advances every pair
    so (the first round is the one-shot bound ``(1 - keep) d / l``; the next ones let pairs
    that move apart or slide past each other go further, and run on the pairs the first left
    short of 1 only: :func:`_narrow`). For the candidate pairs only: a step that moves a vertex
    farther than what is left of the skin needs the pairs built again first."""
    x, dx = jax.lax.stop_gradient(x), jax.lax.stop_gradient(dx)
    pt_on, ee_on = pairs.pt_mask & _apart(pairs.pt, 1), pairs.ee_mask & _apart(pairs.ee, 2)
    qp, qe = x[pairs.pt], x[pairs.ee]
    dp, de = dx[pairs.pt], dx[pairs.ee]
    sp, se = _closing_speed(dp, 1), _closing_speed(de, 2)
    d0 = (jnp.sqrt(_pt_rows(qp)), jnp.sqrt(_ee_rows(qe)))
    # the first round, on every pair: the one-shot bound from each pair's distance at x
    first = [
        jnp.where(on & (l > 0), jnp.minimum((1.0 - keep) * d / jnp.where(l > 0, l, 1.0), 1.0), 1.0)
        for on, l, d in ((pt_on, sp, d0[0]), (ee_on, se, d0[1]))
    ]

    def rounds(idx_p, valid_p, idx_e, valid_e):
        # the later rounds on the rows given (padding rows start done, at 1)
        q = (qp[idx_p], dp[idx_p], qe[idx_e], de[idx_e])
        goal = (keep * d0[0][idx_p], keep * d0[1][idx_e])
        t_start = (
            jnp.where(valid_p, first[0][idx_p], 1.0),
            jnp.where(valid_e, first[1][idx_e], 1.0),
        )
        closing = (sp[idx_p], se[idx_e])
        speed = tuple(jnp.where(t < 1.0, c, 1.0) for t, c in zip(t_start, closing, strict=True))

        def distance(t):
            tp, te = t[0][:, None, None], t[1][:, None, None]
            return jnp.sqrt(_pt_rows(q[0] + tp * q[1])), jnp.sqrt(_ee_rows(q[2] + te * q[3]))

        def more(state):
            k, t = state
            return (k < iterations) & (jnp.any(t[0] < 1.0) | jnp.any(t[1] < 1.0))

        def advance(state):
            k, t = state
            now = distance(t)
            t = tuple(
                jnp.where(tk < 1.0, jnp.minimum(tk + jnp.maximum(dk - g, 0.0) / s, 1.0), tk)
                for tk, dk, g, s in zip(t, now, goal, speed, strict=True)
            )
            return k + 1, t

        _, t = jax.lax.while_loop(more, advance, (1, t_start))
        return jnp.minimum(jnp.min(t[0], initial=1.0), jnp.min(t[1], initial=1.0))

    def everything():
        n_p, n_e = first[0].shape[0], first[1].shape[0]
        every = (jnp.arange(n_p), jnp.ones(n_p, bool), jnp.arange(n_e), jnp.ones(n_e, bool))
        return rounds(*every)

    # the pairs a step's first look leaves short are fewer still than those in reach
    short = (first[0] < 1.0, first[1] < 1.0)
    return _narrow(*short, lambda p, e: rounds(*p, *e), everything, (4 * NARROW, NARROW))
