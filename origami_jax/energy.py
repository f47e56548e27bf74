"""The bar-and-hinge energy of the seed (section 3): pure, jit/grad/vmap-friendly functions.

Energy terms (lengths in the pattern's unit ``u``, angles in radians):

* bar on every edge: ``axial / (2 l0) * (l - l0)**2``;
* torsion on every driven crease: ``crease * l0 / 2 * (rho - percent * rho_target)**2``;
* torsion on every facet crease (``F``, ``J`` and triangulation edges): ``facet * l0 / 2 * rho**2``
  (the two torsion kinds share one vectorised kernel, creases first).

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

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from origami_jax.geometry import bar_lengths, fold_angles
from origami_jax.pattern import CreasePattern, Mesh

__all__ = [
    "Stiffness",
    "Structure",
    "FoldParams",
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


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=["bars", "hinges", "hinge_bars", "free", "free_bars"],
    meta_fields=["num_creases"],
)
@dataclass(frozen=True)
class Structure:
    """The static structure of a scene: index arrays only (their shapes fix the compilation).

    ``bars`` (E, 2); ``hinges`` (H, 4) torsion hinges ``(i, j, k, l)``, the ``num_creases``
    driven creases first, then the facet creases; ``hinge_bars`` (H,) the bar of each hinge;
    ``free`` (Hu, 4) hinges without a spring and their ``free_bars``, kept only to report their
    fold angles.
    """

    bars: Array
    hinges: Array
    hinge_bars: Array
    free: Array
    free_bars: Array
    num_creases: int

    @property
    def num_facets(self) -> int:
        return int(self.hinges.shape[0]) - self.num_creases


class FoldParams(NamedTuple):
    """Differentiable parameters of the energy (a pytree).

    Attributes:
      target: (Hc,) target fold angles of the driven creases, radians.
      percent: () fold percent as a fraction (1.0 = fully to the targets); the target used is
        ``percent * target``, as in Origami Simulator.
      rest_length: (E,) rest lengths of the bars, pattern units.
      stiffness: a :class:`Stiffness`.
    """

    target: Array
    percent: Array
    rest_length: Array
    stiffness: Stiffness


def structure_arrays(mesh: Mesh) -> Structure:
    """The index arrays of :func:`make_structure` as NumPy arrays (host side, no device copy)."""
    driven, facet, free = (mesh.edges_with_role(r) for r in ("driven", "facet", "free"))
    torsion = np.concatenate([driven, facet])
    return Structure(
        bars=np.asarray(mesh.edges, np.int32),
        hinges=np.asarray(mesh.hinges[torsion].reshape(-1, 4), np.int32),
        hinge_bars=np.asarray(torsion, np.int32),
        free=np.asarray(mesh.hinges[free].reshape(-1, 4), np.int32),
        free_bars=np.asarray(free, np.int32),
        num_creases=len(driven),
    )


def make_structure(mesh: Mesh) -> Structure:
    """Index arrays of the scene from a triangulated :class:`Mesh`."""
    return jax.tree.map(jnp.asarray, structure_arrays(mesh))


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
    nc, nf = structure.num_creases, structure.num_facets
    s, dtype = params.stiffness, params.rest_length.dtype
    trailing = params.rest_length.shape[1:]
    goals, stiffness = [], []
    if nc:
        goals.append(jnp.broadcast_to(params.percent * params.target, (nc, *trailing)))
        stiffness.append(jnp.broadcast_to(s.crease, (nc, *trailing)))
    if nf:
        goals.append(jnp.zeros((nf, *trailing), dtype))
        stiffness.append(jnp.broadcast_to(s.facet, (nf, *trailing)))
    return jnp.concatenate(goals), jnp.concatenate(stiffness)


def residuals(
    x: Array, structure: Structure, params: FoldParams, reference: Array | None = None
) -> tuple[Array, Array]:
    """The energy as weighted squares, ``energy = 1/2 sum(w r^2)``: (E + H,) residuals ``r``
    (bar length minus rest length, then fold angle minus goal, radians) and their weights ``w``
    (``axial / l0``, then ``stiffness * l0``). ``reference`` as in :func:`energy`."""
    l0 = params.rest_length
    r = [bar_lengths(x, structure.bars) - l0]
    w = [jnp.broadcast_to(params.stiffness.axial / l0, l0.shape)]
    if structure.hinges.shape[0]:
        goal, stiffness = hinge_goals(structure, params)
        if reference is None:
            reference = 0.5 * goal
        r.append(fold_angles(x, structure.hinges, reference) - goal)
        w.append(stiffness * l0[structure.hinge_bars])
    return jnp.concatenate(r), jnp.concatenate(w)


def energy(
    x: Array, structure: Structure, params: FoldParams, reference: Array | None = None
) -> Array:
    """Total energy of positions ``x`` (V, 3); a scalar in energy units (force x length).
    With trailing batch axes (``x`` (V, 3, B), the parameters' arrays (n, B)), one per member.

    ``reference`` (H,) unwraps each hinge's fold angle to the branch nearest it (see
    :func:`origami_jax.geometry.fold_angles`); it changes no gradient. ``None`` uses the half-way
    reference of :func:`initial_reference`, continuous on the whole way from flat to target.
    """
    r, w = residuals(x, structure, params, reference)
    return 0.5 * jnp.sum(w * r * r, axis=0)


def initial_reference(x: Array, structure: Structure, params: FoldParams) -> Array:
    """(H,) unwrapped fold angles of ``x``, measured against half way to each goal: the branch
    cut lies opposite, far from both flat and the target."""
    goal, _ = hinge_goals(structure, params)
    return fold_angles(x, structure.hinges, 0.5 * goal)


def build_energy(
    pattern: CreasePattern, percent: float = 1.0, stiffness: Stiffness | dict | None = None
) -> tuple[Callable[[Array, FoldParams], Array], FoldParams]:
    """Close over a pattern's structure: returns ``(energy_fn(x, params), default_params)``."""
    structure = make_structure(pattern.mesh)
    params = make_params(pattern, percent, stiffness)

    def energy_fn(x: Array, params: FoldParams, reference: Array | None = None) -> Array:
        return energy(jnp.asarray(x, params.rest_length.dtype), structure, params, reference)

    return energy_fn, params
