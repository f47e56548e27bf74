"""The bar-and-hinge energy of the seed (section 3): pure, jit/grad/vmap-friendly functions.

Energy terms (lengths in the pattern's unit ``u``, angles in radians):

* bar on every edge: ``axial / (2 l0) * (l - l0)**2``;
* torsion on every driven crease: ``crease * l0 / 2 * (rho - percent * rho_target)**2``;
* torsion on every facet crease (``F``, ``J`` and triangulation edges): ``facet * l0 / 2 * rho**2``
  (the two torsion kinds share one vectorised kernel, creases first);
* where a scene needs them (see :func:`needs_barriers`), the barriers of
  :mod:`origami_jax.barrier`: on every torsion hinge, one that keeps the crease from folding
  through itself (active only past ``pi``), and on every triangle, one that keeps it from
  collapsing (active only below a quarter of its rest area). Inactive, they change nothing.

All three stiffnesses are forces (energy per unit length), so their ratios are dimensionless and
a pattern's folded shape does not depend on its scale. Defaults follow the seed's order
``axial > facet > crease``: ``axial = 1``, ``facet = 0.02``, ``crease = 0.001`` (facet 20x the
crease, as in the seed; axial 1000x the crease, so that the sheet stays stiff in its plane: at
400x a degree-4 vertex folded to 3 rad collapsed one of its thin triangles).

A scene builds only the terms it has: a pattern without facet creases has no facet term, no
array for it and no cost for it. Forces are ``-jax.grad`` of :func:`energy`; nothing is
hand-written.

Example:
  >>> import jax
  >>> from origami_jax import patterns
  >>> from origami_jax.energy import build_energy
  >>> cp = patterns.single_crease(fold_angle=1.0)
  >>> energy_fn, params = build_energy(cp)
  >>> x = cp.mesh.vertices
  >>> float(energy_fn(x, params)) > 0, jax.grad(energy_fn)(x, params).shape
  (True, (6, 3))
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from origami_jax.barrier import (
    AREA_FLOOR,
    HINGE_GAP,
    area_barrier,
    hinge_barrier,
    ipc,
    rest_areas,
    signed_areas,
    triangle_normals,
)
from origami_jax.contact import (
    Capacity,
    ContactMesh,
    ContactPairs,
    build_pairs,
    contact_energy,
    refreshed,
)
from origami_jax.geometry import (
    bar_lengths,
    dihedral_angles,
    dihedral_gradients,
    fold_angles,
)
from origami_jax.pattern import CreasePattern, Mesh

__all__ = [
    "Stiffness",
    "Structure",
    "FoldParams",
    "Reference",
    "Barriers",
    "ContactParams",
    "needs_barriers",
    "hinge_terms",
    "triangle_terms",
    "update_reference",
    "barrier_distances",
    "BarrierRows",
    "barrier_rows",
    "springs_only",
    "hinge_goals",
    "make_structure",
    "structure_arrays",
    "make_params",
    "param_arrays",
    "stiffness_arrays",
    "rest_lengths",
    "energy",
    "residuals",
    "build_energy",
    "initial_reference",
]


class Stiffness(NamedTuple):
    """Spring constants (force units: energy per unit length). Scalars or per-element arrays.

    Attributes:
      axial: ``lambda_l``, bars on every edge.
      facet: ``lambda_T``, torsion of facet creases (target flat).
      crease: ``lambda_t``, torsion of driven creases.
    """

    axial: float | Array = 1.0
    facet: float | Array = 0.02
    crease: float | Array = 0.001


# Origami Simulator's default springs (axial 20, facet and crease 0.7; the same per-length
# forms as here), for side-by-side folds; its face (corner-angle) stiffness has no term here
ORIGAMI_SIMULATOR_STIFFNESS = Stiffness(axial=20.0, facet=0.7, crease=0.7)


class Barriers(NamedTuple):
    """Which barriers of :mod:`origami_jax.barrier` a scene has, and their sizes (static).

    Attributes:
      hinge_gap: how far past ``pi`` a crease's barrier reaches its wall (radians); 0: no
        hinge barrier.
      area_floor: the fraction of its rest area below which a triangle's barrier is active;
        0: no area barrier.
    """

    hinge_gap: float = HINGE_GAP
    area_floor: float = AREA_FLOOR


NO_BARRIERS = Barriers(0.0, 0.0)


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=[
        "bars",
        "hinges",
        "hinge_bars",
        "free",
        "free_bars",
        "triangles",
        "triangle_bars",
        "contact",
    ],
    meta_fields=["num_creases", "barriers", "num_free", "contact_capacity"],
)
@dataclass(frozen=True)
class Structure:
    """The static structure of a scene: index arrays only (their shapes fix the compilation).

    ``bars`` (E, 2); ``hinges`` (H, 4) torsion hinges ``(i, j, k, l)``, the ``num_creases``
    driven creases first, then the facet creases, then (with a hinge barrier) the ``num_free``
    hinges without a spring, which have only their barrier; ``hinge_bars`` (H,) the bar of
    each hinge; ``free`` (Hu, 4) hinges without a spring or barrier and their ``free_bars``,
    kept only to report their fold angles; ``triangles`` (T, 3) and their sides' bars
    ``triangle_bars`` (T, 3), only with an area barrier (else (0, 3)); ``barriers`` the
    :class:`Barriers` built; ``contact`` the :class:`~origami_jax.contact.ContactMesh` of a
    scene with self-contact (``None``: none) and ``contact_capacity`` the fixed sizes of its
    candidate pairs (see :func:`with_contact`).
    """

    bars: Array
    hinges: Array
    hinge_bars: Array
    free: Array
    free_bars: Array
    triangles: Array
    triangle_bars: Array
    num_creases: int
    barriers: Barriers = NO_BARRIERS
    num_free: int = 0
    contact: ContactMesh | None = None
    contact_capacity: Capacity | None = None

    @property
    def num_facets(self) -> int:
        return int(self.hinges.shape[0]) - self.num_creases - self.num_free


class Reference(NamedTuple):
    """What the energy measures the current state against (no effect on its value or
    gradient at positions reachable from it without passing through a wall).

    Attributes:
      angles: (H,) each torsion hinge's unwrap reference: its fold angle is the branch nearest
        it (see :func:`origami_jax.geometry.fold_angles`), radians.
      normals: (T, 3) each barrier triangle's unit normal at the last accepted iterate: a
        triangle turned over against it has a negative area ((0, 3) without area barrier).
      pairs: with self-contact, the candidate pairs built at the last accepted iterate
        (:class:`~origami_jax.contact.ContactPairs`; ``None`` without contact).
    """

    angles: Array
    normals: Array
    pairs: ContactPairs | None = None


class ContactParams(NamedTuple):
    """The self-contact barrier's parameters (differentiable).

    Attributes:
      dhat: () the barrier's reach, the gap folded layers keep (the paper's thickness),
        pattern units.
      kappa: () its weight, an energy (:func:`~origami_jax.contact.contact_stiffness`).
      skin: () how much farther than ``dhat`` candidate pairs are gathered (pattern units): a
        step moves no vertex more than half of it, so no pair comes within ``dhat`` unseen.
    """

    dhat: Array
    kappa: Array
    skin: Array


class FoldParams(NamedTuple):
    """Differentiable parameters of the energy (a pytree).

    Attributes:
      target: (Hc,) target fold angles of the driven creases, radians.
      percent: () fold percent as a fraction (1.0 = fully to the targets); the target used is
        ``percent * target``, as in Origami Simulator.
      rest_length: (E,) rest lengths of the bars, pattern units.
      stiffness: a :class:`Stiffness`.
      gap_scale: () a multiple of the structure's hinge gap (``None``: 1). Continuation in fold
        percent widens the gap on its way (a narrow one makes every step that turns a crease
        held at its wall tiny) and narrows it back at full percent.
      contact: the self-contact barrier's :class:`ContactParams` (``None``: no contact).
    """

    target: Array
    percent: Array
    rest_length: Array
    stiffness: Stiffness
    gap_scale: Array | None = None
    contact: ContactParams | None = None


# a driven crease whose target reaches this far (radians) is folded nearly flat: such scenes get
# the barriers by default (a fold that far can pass a crease through itself, or crush a triangle)
FULL_FOLD = 0.9 * np.pi


def needs_barriers(mesh: Mesh) -> bool:
    """Whether a scene gets the barriers by default: a driven crease whose target is at least
    :data:`FULL_FOLD` (0.9 pi). Rigid-foldable tessellations folded part way never come near
    either wall, so they are built without them (no term, no array, no cost)."""
    driven = mesh.edges_with_role("driven")
    return bool(len(driven)) and bool(np.max(np.abs(mesh.target[driven])) >= FULL_FOLD)


def _barriers(mesh: Mesh, barriers: Barriers | bool | None) -> Barriers:
    if barriers is None:
        barriers = needs_barriers(mesh)
    if barriers is True:
        return Barriers()
    if barriers is False:
        return NO_BARRIERS
    if not isinstance(barriers, Barriers):
        raise TypeError(f"barriers: expected None, a bool or Barriers, got {barriers!r}")
    return barriers


def triangle_bars(mesh: Mesh) -> np.ndarray:
    """(T, 3) the bar of each triangle's sides ``(0, 1)``, ``(1, 2)``, ``(2, 0)``."""
    e = np.sort(np.asarray(mesh.edges), axis=1)
    v = mesh.num_vertices
    keys = e[:, 0].astype(np.int64) * v + e[:, 1]
    order = np.argsort(keys)
    t = np.asarray(mesh.triangles)
    sides = np.stack([t, np.roll(t, -1, axis=1)], axis=2)  # (T, 3, 2)
    side_keys = sides.min(axis=2).astype(np.int64) * v + sides.max(axis=2)
    return order[np.searchsorted(keys[order], side_keys)]


def structure_arrays(
    mesh: Mesh, barriers: Barriers | bool | None = None, free_barriers: bool = True
) -> Structure:
    """The index arrays of :func:`make_structure` as NumPy arrays (host side, no device copy).
    With a hinge barrier, free hinges join the torsion hinges for it (unless ``free_barriers``
    is off: ``fold_batch`` keeps them apart)."""
    barriers = _barriers(mesh, barriers)
    driven, facet, free = (mesh.edges_with_role(r) for r in ("driven", "facet", "free"))
    barred = free if barriers.hinge_gap > 0 and free_barriers else free[:0]
    free = free[len(barred) :]
    torsion = np.concatenate([driven, facet, barred])
    if barriers.area_floor > 0:
        triangles = np.asarray(mesh.triangles, np.int32).reshape(-1, 3)
        sides = triangle_bars(mesh).astype(np.int32).reshape(-1, 3)
    else:
        triangles = sides = np.zeros((0, 3), np.int32)
    return Structure(
        bars=np.asarray(mesh.edges, np.int32),
        hinges=np.asarray(mesh.hinges[torsion].reshape(-1, 4), np.int32),
        hinge_bars=np.asarray(torsion, np.int32),
        free=np.asarray(mesh.hinges[free].reshape(-1, 4), np.int32),
        free_bars=np.asarray(free, np.int32),
        triangles=triangles,
        triangle_bars=sides,
        num_creases=len(driven),
        barriers=barriers,
        num_free=len(barred),
    )


def make_structure(mesh: Mesh, barriers: Barriers | bool | None = None) -> Structure:
    """Index arrays of the scene from a triangulated :class:`Mesh`; ``barriers``: ``None`` as
    :func:`needs_barriers` says, ``True`` both at their defaults, ``False`` none, or a
    :class:`Barriers`."""
    return jax.tree.map(jnp.asarray, structure_arrays(mesh, barriers))


def param_arrays(
    pattern: CreasePattern, percent: float = 1.0, stiffness: Stiffness | dict | None = None
) -> FoldParams:
    """The parameters of :func:`make_params` as float64 NumPy arrays (host side)."""
    mesh = pattern.mesh
    return FoldParams(
        target=np.asarray(mesh.target[mesh.edges_with_role("driven")], np.float64),
        percent=np.asarray(percent, np.float64),
        rest_length=rest_lengths(mesh.vertices, mesh.edges),
        stiffness=stiffness_arrays(stiffness),
    )


def rest_lengths(vertices: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(..., E) lengths of the bars ``edges`` (E, 2) at ``vertices`` (..., V, 3) (host side;
    leading axes: several sheets of one mesh topology at once)."""
    return np.linalg.norm(vertices[..., edges[:, 1], :] - vertices[..., edges[:, 0], :], axis=-1)


def stiffness_arrays(stiffness: Stiffness | dict | None = None) -> Stiffness:
    """A :class:`Stiffness` (default ``Stiffness()``; a dict of its fields) with float64 NumPy
    leaves; a traced stiffness (inside jit or grad) stays a JAX value."""
    if stiffness is None:
        stiffness = Stiffness()
    elif isinstance(stiffness, dict):
        stiffness = Stiffness(**stiffness)
    return Stiffness(
        *(k if isinstance(k, jax.Array) else np.asarray(k, np.float64) for k in stiffness)
    )


def make_params(
    pattern: CreasePattern,
    percent: float = 1.0,
    stiffness: Stiffness | dict | None = None,
    dtype=None,
) -> FoldParams:
    """Default parameters of a pattern: its targets, rest lengths and the given stiffness."""
    dtype = dtype or jnp.result_type(float)
    return jax.tree.map(lambda a: jnp.asarray(a, dtype), param_arrays(pattern, percent, stiffness))


def hinge_goals(structure: Structure, params: FoldParams) -> tuple[Array, Array]:
    """(H,) goal angle ``percent * target`` (0 for facets) and (H,) torsion stiffness (with the
    rest lengths' trailing batch axes, if any: see :mod:`origami_jax.geometry`)."""
    nc, nf, nu = structure.num_creases, structure.num_facets, structure.num_free
    s, dtype = params.stiffness, params.rest_length.dtype
    trailing = params.rest_length.shape[1:]
    goals, stiffness = [], []
    if nc:
        goals.append(jnp.broadcast_to(params.percent * params.target, (nc, *trailing)))
        stiffness.append(jnp.broadcast_to(s.crease, (nc, *trailing)))
    if nf:
        goals.append(jnp.zeros((nf, *trailing), dtype))
        stiffness.append(jnp.broadcast_to(s.facet, (nf, *trailing)))
    if nu:  # free hinges: no spring (only a barrier)
        goals.append(jnp.zeros((nu, *trailing), dtype))
        stiffness.append(jnp.zeros((nu, *trailing), dtype))
    return jnp.concatenate(goals), jnp.concatenate(stiffness)


def _reference(
    x: Array, structure: Structure, params: FoldParams, reference: Reference | Array | None
) -> Reference:
    """A :class:`Reference` from ``reference`` (``None``: :func:`initial_reference` at ``x``;
    an array: the hinges' angles, the triangles' normals those of ``x``)."""
    if reference is None:  # the branches of initial_reference, without measuring twice
        return Reference(_toward(structure, params), triangle_normals(x, structure.triangles))
    if isinstance(reference, Reference):
        return reference
    return Reference(reference, triangle_normals(x, structure.triangles))


def hinge_weights(structure: Structure, params: FoldParams) -> tuple[Array, Array]:
    """(H,) goal angle of each torsion hinge and its weight ``stiffness * l0`` (the torsion
    spring's energy is ``weight / 2 (rho - goal)^2``)."""
    goal, stiffness = hinge_goals(structure, params)
    return goal, stiffness * params.rest_length[structure.hinge_bars]


def residuals(
    x: Array, structure: Structure, params: FoldParams, reference: Reference | Array | None = None
) -> tuple[Array, Array]:
    """The energy's residuals and its curvature in each: bar lengths minus rest lengths, then
    fold angles minus goals (radians), then barrier triangles' area ratios; weights ``w`` the
    energy's second derivative in each (``axial / l0``; ``stiffness * l0`` plus a hinge
    barrier's; a triangle barrier's), evaluated at ``x``. Without barriers the energy is
    exactly ``1/2 sum(w r^2)``; with them, ``w`` is what geodesic acceleration weighs each
    residual's second-order change by. ``reference`` as in :func:`energy`."""
    l0 = params.rest_length
    r = [bar_lengths(x, structure.bars) - l0]
    w = [jnp.broadcast_to(params.stiffness.axial / l0, l0.shape)]
    if structure.hinges.shape[0] or structure.triangles.shape[0]:
        reference = _reference(x, structure, params, reference)
    if structure.hinges.shape[0]:
        goal, weight = hinge_weights(structure, params)
        rho = fold_angles(x, structure.hinges, reference.angles)
        r.append(rho - goal)
        gap = structure.barriers.hinge_gap
        w.append(jax.lax.stop_gradient(hinge_terms(rho, structure, params)[2]) if gap else weight)
    if structure.triangles.shape[0]:
        ratio, _, _, d2 = triangle_terms(x, structure, params, reference.normals)
        r.append(ratio)
        w.append(jax.lax.stop_gradient(d2))
    return jnp.concatenate(r), jnp.concatenate(w)


def barrier_weights(structure: Structure, params: FoldParams) -> tuple[Array, Array]:
    """The barriers' weights: (H,) each hinge's bar's ``axial * l0`` and (T,) each barrier
    triangle's mean over its sides (the scale of a bar's energy at a strain of one: what pushes
    a crease through itself or crushes a triangle is the sheet's bars)."""
    l0 = params.rest_length
    work = jnp.broadcast_to(params.stiffness.axial, l0.shape) * l0
    return work[structure.hinge_bars], jnp.mean(work[structure.triangle_bars], axis=1)


def hinge_gap(structure: Structure, params: FoldParams) -> Array | float:
    """How far past ``pi`` the hinge barriers reach their wall (radians): the structure's gap
    times ``params.gap_scale``."""
    gap = structure.barriers.hinge_gap
    return gap if params.gap_scale is None else gap * params.gap_scale


def hinge_terms(rho: Array, structure: Structure, params: FoldParams) -> tuple[Array, Array, Array]:
    """Per torsion hinge: its energy (spring and, if built, barrier) and that energy's first and
    second derivatives in the fold angle ``rho`` (radians). The barrier's weight is its bar's
    ``axial * l0``, the scale of what can push a crease through itself (the sheet's bars),
    whatever the crease's own stiffness."""
    goal, weight = hinge_weights(structure, params)
    diff = rho - goal
    e, d1, d2 = 0.5 * weight * diff * diff, weight * diff, weight
    if structure.barriers.hinge_gap > 0:
        gap = hinge_gap(structure, params)
        b, b1, b2 = hinge_barrier(rho, barrier_weights(structure, params)[0], gap)
        e, d1, d2 = e + b, d1 + b1, d2 + b2
    return e, d1, d2


def triangle_terms(
    x: Array, structure: Structure, params: FoldParams, normals: Array
) -> tuple[Array, Array, Array, Array]:
    """Per barrier triangle: the area ratio ``A / A0`` (signed against ``normals``), the area
    barrier's energy, and its first and second derivatives in that ratio."""
    l0 = params.rest_length
    sides = l0[structure.triangle_bars]  # (T, 3)
    area0 = rest_areas(sides)
    real = area0 > 0  # a triangle with no rest area (degenerate) gets no barrier
    ratio = signed_areas(x, structure.triangles, normals) / jnp.where(real, area0, 1.0)
    ratio = jnp.where(real, ratio, 1.0)
    weight = barrier_weights(structure, params)[1]
    e, d1, d2 = area_barrier(ratio, weight, structure.barriers.area_floor)
    return ratio, e, d1, d2


def springs_only(structure: Structure) -> Structure:
    """The structure without its barriers: the bars' and hinges' springs alone."""
    none = structure.triangles[:0]
    return dataclasses.replace(
        structure,
        barriers=NO_BARRIERS,
        triangles=none,
        triangle_bars=none,
        contact=None,
        contact_capacity=None,
    )


def energy(
    x: Array, structure: Structure, params: FoldParams, reference: Reference | Array | None = None
) -> Array:
    """Total energy of positions ``x`` (V, 3); a scalar in energy units (force x length).
    With trailing batch axes (``x`` (V, 3, B), the parameters' arrays (n, B)), one per member.

    ``reference``, a :class:`Reference`, unwraps each hinge's fold angle to the branch nearest
    its angle (see :func:`origami_jax.geometry.fold_angles`) and signs each barrier triangle's
    area against its normal; neither changes a gradient. ``None`` uses
    :func:`initial_reference` of ``x``; an array is taken as the hinges' angles.
    """
    l0 = params.rest_length
    stretch = bar_lengths(x, structure.bars) - l0
    total = 0.5 * jnp.sum(params.stiffness.axial / l0 * stretch * stretch, axis=0)
    if structure.hinges.shape[0] or structure.triangles.shape[0]:
        reference = _reference(x, structure, params, reference)
    if structure.hinges.shape[0]:
        rho = fold_angles(x, structure.hinges, reference.angles)
        total = total + jnp.sum(hinge_terms(rho, structure, params)[0], axis=0)
    if structure.triangles.shape[0]:
        total = total + jnp.sum(triangle_terms(x, structure, params, reference.normals)[1], axis=0)
    if structure.contact is not None:
        total = total + contact_term(x, structure, params, reference)
    return total


def contact_term(
    x: Array, structure: Structure, params: FoldParams, reference: Reference | Array | None
) -> Array:
    """() the self-contact barrier's energy at ``x`` over the reference's candidate pairs (built
    at ``x`` within ``dhat`` where the reference has none)."""
    c = params.contact
    pairs = reference.pairs if isinstance(reference, Reference) else None
    if pairs is None:
        pairs = contact_pairs(jax.lax.stop_gradient(x), structure, c.dhat)
    return contact_energy(x, pairs, c.dhat, c.kappa)


def contact_pairs(x: Array, structure: Structure, radius: Array) -> ContactPairs:
    """The candidate pairs of ``x`` within ``radius``, at the structure's capacity."""
    return build_pairs(x, structure.contact, radius, structure.contact_capacity)


def barrier_distances(
    x: Array, structure: Structure, params: FoldParams, reference: Reference
) -> Array:
    """(H + T,) how far each barrier is from its wall, as a fraction of its active zone
    (``pi + gap - |rho|`` over ``gap`` for the hinges, ``A / (A0 floor)`` for the triangles;
    empty without barriers): what a solver's step limit keeps positive."""
    out = []
    if structure.barriers.hinge_gap > 0 and structure.hinges.shape[0]:
        gap = hinge_gap(structure, params)
        rho = fold_angles(x, structure.hinges, reference.angles)
        out.append((gap - (jnp.abs(rho) - jnp.pi)) / gap)
    if structure.triangles.shape[0]:
        ratio = triangle_terms(x, structure, params, reference.normals)[0]
        out.append(ratio / structure.barriers.area_floor)
    if not out:
        return jnp.zeros((0, *x.shape[2:]), x.dtype)
    return jnp.concatenate(out)


class BarrierRows(NamedTuple):
    """The barriers of one kind at a state: their ``corners`` (n, k), ``distance`` (n,) to the
    wall as a fraction of the active zone, the energy's ``slope`` and ``curvature`` (n,) in that
    distance, and the distance's ``gradient`` (n, k, 3) in the corners' positions."""

    corners: Array
    distance: Array
    slope: Array
    curvature: Array
    gradient: Array


def barrier_rows(
    x: Array, structure: Structure, params: FoldParams, reference: Reference
) -> list[BarrierRows]:
    """:class:`BarrierRows` of the hinge barriers and of the area barriers a scene has (what
    explicit dynamics stops at a wall, and what sets the rounding floor of a gradient that
    barriers hold)."""
    out = []
    l0 = params.rest_length
    if structure.barriers.hinge_gap > 0 and structure.hinges.shape[0]:
        gap = hinge_gap(structure, params)
        q = x[structure.hinges]
        rho = dihedral_angles(q, reference.angles)
        d = (gap - (jnp.abs(rho) - jnp.pi)) / gap
        weight = barrier_weights(structure, params)[0]
        grad = -(jnp.sign(rho) / gap)[:, None, None] * dihedral_gradients(q)
        _, b1, b2 = ipc(d)
        out.append(BarrierRows(structure.hinges, d, weight * gap * b1, weight * gap * b2, grad))
    if structure.triangles.shape[0]:
        floor = structure.barriers.area_floor
        sides = l0[structure.triangle_bars]
        area0 = rest_areas(sides)
        real = area0 > 0

        def distance(p, n, a0):
            return signed_areas(p, jnp.array([[0, 1, 2]]), n[None])[0] / (a0 * floor)

        d, grad = jax.vmap(jax.value_and_grad(distance))(
            x[structure.triangles], reference.normals, jnp.where(real, area0, 1.0)
        )
        d = jnp.where(real, d, 2.0)  # a padding triangle: never near a wall
        weight = barrier_weights(structure, params)[1]
        _, b1, b2 = ipc(d)
        out.append(BarrierRows(structure.triangles, d, weight * b1, weight * b2, grad))
    return out


def initial_reference(x: Array, structure: Structure, params: FoldParams) -> Reference:
    """The :class:`Reference` of a start ``x``: its fold angles measured against half way to
    each goal (the branch cut lies opposite, far from both flat and the target: a start folded
    through itself is seen as such, and brought back by the hinge barrier or the spring), and
    the triangles' normals at ``x``."""
    pairs = None
    if structure.contact is not None:
        c = params.contact
        pairs = contact_pairs(x, structure, c.dhat + c.skin)
    return Reference(
        fold_angles(x, structure.hinges, _toward(structure, params)),
        triangle_normals(x, structure.triangles),
        pairs,
    )


def _toward(structure: Structure, params: FoldParams) -> Array:
    """(H,) what a start's fold angles are measured against (see :func:`initial_reference`)."""
    return 0.5 * hinge_goals(structure, params)[0]


def update_reference(
    x: Array, structure: Structure, reference: Reference, skin: Array | None = None
) -> Reference:
    """The :class:`Reference` at an accepted iterate ``x``, from the last one: each hinge's
    angle followed continuously, each triangle's current normal turned to the side of its last
    (a triangle turned over stays turned over, and its barrier keeps pushing it back). The
    contact pairs are gathered again where a vertex moved more than a quarter of ``skin``
    since they were (:func:`~origami_jax.contact.refreshed`), or at every iterate without
    ``skin``."""
    normals = triangle_normals(x, structure.triangles)
    side = jnp.sum(normals * reference.normals, axis=1, keepdims=True)
    pairs = reference.pairs
    if pairs is not None and skin is None:
        pairs = contact_pairs(x, structure, pairs.radius)
    elif pairs is not None:
        pairs = refreshed(x, pairs, structure.contact, skin)
    return Reference(
        fold_angles(x, structure.hinges, reference.angles),
        jnp.where(side < 0, -normals, normals),
        pairs,
    )


def build_energy(
    pattern: CreasePattern,
    percent: float = 1.0,
    stiffness: Stiffness | dict | None = None,
    barriers: Barriers | bool | None = None,
) -> tuple[Callable[[Array, FoldParams], Array], FoldParams]:
    """Close over a pattern's structure: returns ``(energy_fn(x, params), default_params)``
    (``barriers`` as in :func:`make_structure`)."""
    structure = make_structure(pattern.mesh, barriers)
    params = make_params(pattern, percent, stiffness)

    def energy_fn(x: Array, params: FoldParams, reference: Reference | None = None) -> Array:
        return energy(jnp.asarray(x, params.rest_length.dtype), structure, params, reference)

    return energy_fn, params
