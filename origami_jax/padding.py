"""Problems padded to shared size buckets, so that patterns of similar size share compiled code.

A problem's arrays are padded up to the sizes of its bucket (:func:`bucket`). Padding is inert
by construction, with no mask in any kernel:

* padded vertices are pinned (they never move) and padded bars join two of them at their rest
  length (the sheet's mean bar) with zero stiffness: no energy, no force, no strain;
* padded hinges lie on four padded vertices folded flat, with target 0 and zero stiffness: no
  energy, no force, no fold-angle error;
* padded triangles lie on three padded vertices, their sides the padding bar (of zero
  stiffness: no barrier weight);
* with self-contact, padded contact triangles and edges lie on padded vertices, and those are
  inert to contact (a negative group): they are in no pair;

so every energy, gradient, Hessian and maximum over a padded problem equals that of the
problem alone, and means are rescaled to the real counts (:func:`unpad_metrics`).
``fold_batch`` stacks padded problems of one bucket; ``fold`` pads a single problem so that
its compiled solve serves the next pattern of that bucket.
"""

from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np

from origami_jax.contact import ContactMesh
from origami_jax.energy import NO_BARRIERS, Barriers, Reference, Stiffness
from origami_jax.pattern import CreasePattern
from origami_jax.solvers.base import Problem, rigid_gauge

__all__ = [
    "PAD_VERTICES",
    "Sizes",
    "Floors",
    "BATCH_FLOORS",
    "PLANAR_FLOORS",
    "bucket",
    "floor_sizes",
    "round_up",
    "problem_sizes",
    "sizes_of",
    "pad_problem",
    "pad_reference",
    "unpad_metrics",
]

# four padding vertices carry every padded bar and hinge: a bar 0-1 and a flat hinge (scaled to
# the sheet's mean bar: a solve's rounding floors, which scale with the positions, see a sheet
# 1e-6 wide as they see it alone)
PAD_VERTICES = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
# a padded triangle's normal (it lies on the first three padding vertices)
_PAD_NORMAL = (0.0, 0.0, 1.0)


class Sizes(NamedTuple):
    """The array sizes of a problem: vertices, bars, driven creases, facet creases, free
    hinges, pinned vertices and barrier triangles, and the barriers built (the static shapes
    and settings a compiled solve depends on); with self-contact, the contact mesh's triangles
    and edges (0 without)."""

    vertices: int
    bars: int
    creases: int
    facets: int
    free: int
    pinned: int
    triangles: int = 0
    barriers: Barriers = NO_BARRIERS
    contact_triangles: int = 0
    contact_edges: int = 0


def round_up(n: int, per_octave: int = 1) -> int:
    """The least of ``round(2 ** (k / per_octave))`` (k = 0, 1, ...) at least ``n``; 0 for 0."""
    if n <= 0:
        return 0
    k = int(np.ceil(per_octave * np.log2(n))) - 1
    while round(2.0 ** (k / per_octave)) < n:
        k += 1
    return round(2.0 ** (k / per_octave))


class Floors(NamedTuple):
    """The least element counts of a bucket, as multiples of its padded vertex count."""

    bars: int = 2
    creases: int = 1
    facets: int = 1
    triangles: int = 2


# fold_batch's floors: most sheets of one size share a bucket, at little padding
BATCH_FLOORS = Floors()
# every triangulated sheet of V vertices fits these (Euler: at most 3 V - 6 edges, of which the
# creases and facet creases are some, and 2 V - 5 triangles), so it pads to its vertex bucket
PLANAR_FLOORS = Floors(bars=3, creases=3, facets=3, triangles=2)


def bucket(sizes: Sizes, per_octave: int = 1, floors: Floors = BATCH_FLOORS) -> Sizes:
    """The padded sizes of a problem: each count rounded up to a power of two (``per_octave``
    steps per doubling: 4 rounds up by at most 19 %), with room for the four padding vertices
    and one padding bar (which padded hinges point to), and at least ``floors`` times the
    padded vertex count of each kind of element.

    The floors tie the element counts to the vertex bucket, so patterns of one size share a
    compiled solve whatever their mix of creases and facets (a stream of 100 random Miura-ori
    and waterbomb sheets makes 7 buckets instead of 17 at :data:`BATCH_FLOORS`); dense
    Newton's cost is set by the vertex count, and the extra padded elements cost little."""

    def up(n: int) -> int:
        return round_up(n, per_octave)

    vertices = up(sizes.vertices + len(PAD_VERTICES))
    least = floor_sizes(vertices, floors, sizes.barriers)
    return Sizes(
        vertices=vertices,
        bars=max(up(sizes.bars + 1), least.bars),
        creases=max(up(sizes.creases), least.creases),
        facets=max(up(sizes.facets), least.facets),
        free=up(sizes.free),
        pinned=up(sizes.pinned),
        triangles=max(up(sizes.triangles), floors.triangles * vertices) if sizes.triangles else 0,
        barriers=sizes.barriers,
        contact_triangles=up(sizes.contact_triangles),
        contact_edges=up(sizes.contact_edges),
    )


def floor_sizes(vertices: int, floors: Floors, barriers: Barriers = NO_BARRIERS) -> Sizes:
    """The least :class:`Sizes` of the bucket of ``vertices`` padded vertices: its floors, the
    pinned triangle of one piece, and barrier triangles where the area barrier is built."""
    return Sizes(
        vertices=vertices,
        bars=floors.bars * vertices,
        creases=floors.creases * vertices,
        facets=floors.facets * vertices,
        free=0,
        pinned=3,
        triangles=floors.triangles * vertices if barriers.area_floor > 0 else 0,
        barriers=barriers,
    )


def problem_sizes(pattern: CreasePattern) -> Sizes:
    """The unpadded :class:`Sizes` of a pattern's folding problem (``fold_batch``'s)."""
    from origami_jax.energy import structure_arrays

    mesh = pattern.mesh
    s = structure_arrays(mesh, free_barriers=False)
    pieces = len(rigid_gauge(mesh, mesh.vertices)[0])
    return Sizes(
        mesh.num_vertices,
        len(s.bars),
        s.num_creases,
        s.num_facets,
        len(s.free),
        pieces,
        len(s.triangles),
        s.barriers,
    )


def sizes_of(problem: Problem) -> Sizes:
    """The :class:`Sizes` of a (not yet padded) problem."""
    s = problem.structure
    contact = s.contact
    return Sizes(
        problem.start.shape[0],
        s.bars.shape[0],
        s.num_creases,
        s.hinges.shape[0] - s.num_creases,
        s.free.shape[0],
        problem.pinned.shape[0],
        s.triangles.shape[0],
        s.barriers,
        0 if contact is None else contact.triangles.shape[0],
        0 if contact is None else contact.edges.shape[0],
    )


def _pad_rows(a, n: int, fill) -> np.ndarray:
    """``a`` with rows appended up to ``n``, each equal to ``fill``."""
    a = np.asarray(a)
    extra = n - a.shape[0]
    if extra <= 0:
        return a
    pad = np.broadcast_to(np.asarray(fill, a.dtype), (extra, *a.shape[1:]))
    return np.concatenate([a, pad])


def per_element(k: Stiffness, sizes: Sizes) -> Stiffness:
    """Stiffnesses as one value per element (scalars broadcast), so problems stack."""
    return Stiffness(
        axial=np.broadcast_to(k.axial, (sizes.bars,)),
        facet=np.broadcast_to(k.facet, (sizes.facets,)),
        crease=np.broadcast_to(k.crease, (sizes.creases,)),
    )


def _pad_hinge_rows(a, s: Sizes, to: Sizes, fill) -> np.ndarray:
    """Per-hinge rows (creases, then facets) padded: creases to ``to.creases``, then facets."""
    a = np.asarray(a)
    nc = s.creases
    return np.concatenate([_pad_rows(a[:nc], to.creases, fill), _pad_rows(a[nc:], to.facets, fill)])


def pad_reference(reference: Reference, s: Sizes, to: Sizes) -> Reference:
    """A :class:`~origami_jax.energy.Reference` of the problem of sizes ``s``, padded to ``to``
    (padded hinges flat, padded triangles facing up); one already padded is returned as is."""
    if reference.pairs is not None:
        raise ValueError("pad_reference: contact pairs are not padded")
    angles, normals = reference.angles, reference.normals
    if angles.shape[0] != to.creases + to.facets:
        angles = _pad_hinge_rows(angles, s, to, 0.0)
    if normals.shape[0] != to.triangles:
        normals = _pad_rows(normals, to.triangles, _PAD_NORMAL)
    return Reference(angles, normals, None)


def pad_problem(problem: Problem, s: Sizes, to: Sizes) -> Problem:
    """``problem`` (of sizes ``s``) padded to the sizes ``to`` (NumPy leaves), not yet
    prepared by a solver (``solver.prepare_batch`` does that)."""
    st, prm = problem.structure, problem.params
    v = s.vertices
    rest = np.asarray(prm.rest_length)
    length = float(np.mean(rest)) if rest.size else 1.0
    pad_bar = [v, v + 1]
    pad_hinge = [v, v + 1, v + 2, v + 3]
    structure = replace(
        st,
        bars=_pad_rows(st.bars, to.bars, pad_bar).astype(np.int32),
        hinges=_pad_hinge_rows(st.hinges, s, to, pad_hinge).astype(np.int32),
        hinge_bars=_pad_hinge_rows(st.hinge_bars, s, to, s.bars).astype(np.int32),
        free=_pad_rows(st.free, to.free, pad_hinge).astype(np.int32),
        free_bars=_pad_rows(st.free_bars, to.free, s.bars).astype(np.int32),
        triangles=_pad_rows(st.triangles, to.triangles, pad_hinge[:3]).astype(np.int32),
        triangle_bars=_pad_rows(st.triangle_bars, to.triangles, [s.bars] * 3).astype(np.int32),
        num_creases=to.creases,
    )
    if st.contact is not None:
        # padded contact primitives lie on the padding vertices, whose negative group makes
        # them inert: no pair has one (origami_jax.contact.ContactMesh)
        c = st.contact
        structure = replace(
            structure,
            contact=ContactMesh(
                triangles=_pad_rows(c.triangles, to.contact_triangles, pad_hinge[:3]).astype(
                    np.int32
                ),
                edges=_pad_rows(c.edges, to.contact_edges, pad_bar).astype(np.int32),
                groups=_pad_rows(c.groups, to.vertices, -1).astype(np.int32),
            ),
        )
    k = per_element(prm.stiffness, s)
    stiffness = Stiffness(
        axial=_pad_rows(k.axial, to.bars, 0.0),
        facet=_pad_rows(k.facet, to.facets, 0.0),
        crease=_pad_rows(k.crease, to.creases, 0.0),
    )
    params = prm._replace(
        target=_pad_rows(prm.target, to.creases, 0.0),
        rest_length=_pad_rows(prm.rest_length, to.bars, length),
        stiffness=stiffness,
    )
    start = np.asarray(problem.start)
    corners = length * PAD_VERTICES  # about the origin: the padding bar is exactly ``length``
    start = np.concatenate([start, _pad_rows(corners, to.vertices - v, corners[0])])
    # every padding vertex is pinned in place (its rows repeat the first one): the gauge's
    # pins, then the padding vertices, then fill, to a length that fits every member of a bucket
    pinned = np.concatenate([problem.pinned, np.arange(v, to.vertices)])
    projectors = np.concatenate([problem.projectors, np.zeros((to.vertices - v, 3, 3))])
    rows = to.pinned + to.vertices
    reference = problem.reference
    if reference is not None:
        reference = pad_reference(reference, s, to)
    return replace(
        problem,
        structure=structure,
        params=params,
        start=start,
        pinned=_pad_rows(pinned, rows, v).astype(np.int32),
        projectors=_pad_rows(projectors, rows, np.zeros((3, 3))),
        reference=reference,
    )


def unpad_metrics(m: dict, s: Sizes, to: Sizes) -> dict:
    """A padded solve's metrics (host values) for the real problem: padding adds exact zeros,
    so the means are rescaled to the real elements' counts."""
    m = dict(m)
    m["strain_mean"] = m["strain_mean"] * (to.bars / s.bars)
    m["fold_angle_error_mean"] = m["fold_angle_error_mean"] * (
        to.creases / s.creases if s.creases else 0.0
    )
    return m
