"""The bar-and-hinge energy of the seed (section 3): pure, jit/grad/vmap-friendly functions.

Energy terms (lengths in the pattern's unit ``u``, angles in radians):

* bar on every edge: ``axial / (2 l0) * (l - l0)**2``;
* torsion on every driven crease: ``crease * l0 / 2 * (rho - percent * rho_target)**2``;
* torsion on every facet crease (``F``, ``J`` and triangulation edges): ``facet * l0 / 2 * rho**2``.

All three stiffnesses are forces (energy per unit length), so their ratios are dimensionless and
a pattern's folded shape does not depend on its scale. Defaults follow the seed's order
``axial > facet > crease``, about 20x apart: ``axial = 1``, ``facet = 0.05``, ``crease = 0.0025``.

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
    "HingeReference",
    "make_structure",
    "make_params",
    "energy",
    "build_energy",
    "initial_reference",
    "update_reference",
]


class Stiffness(NamedTuple):
    """Spring constants (force units: energy per unit length). Scalars or per-element arrays.

    Attributes:
      axial: ``lambda_l``, bars on every edge.
      facet: ``lambda_T``, torsion of facet creases (target flat).
      crease: ``lambda_t``, torsion of driven creases.
    """

    axial: float | Array = 1.0
    facet: float | Array = 0.05
    crease: float | Array = 0.0025


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Structure:
    """The static structure of a scene: index arrays only (their shapes fix the compilation).

    ``bars`` (E, 2); ``creases`` (Hc, 4) and ``facets`` (Hf, 4) hinges ``(i, j, k, l)``;
    ``crease_bars`` (Hc,) and ``facet_bars`` (Hf,) the bar of each hinge; ``free`` (Hu, 4)
    hinges without a spring and their ``free_bars``, kept only to report their fold angles.
    """

    bars: Array
    creases: Array
    crease_bars: Array
    facets: Array
    facet_bars: Array
    free: Array
    free_bars: Array


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


class HingeReference(NamedTuple):
    """Per-hinge reference angles (radians) to unwrap fold angles against (see fold_angles)."""

    creases: Array
    facets: Array


def make_structure(mesh: Mesh) -> Structure:
    """Index arrays of the scene from a triangulated :class:`Mesh`."""
    def pick(role):
        idx = mesh.edges_with_role(role)
        return jnp.asarray(mesh.hinges[idx], jnp.int32), jnp.asarray(idx, jnp.int32)

    creases, crease_bars = pick("driven")
    facets, facet_bars = pick("facet")
    free, free_bars = pick("free")
    return Structure(
        bars=jnp.asarray(mesh.edges, jnp.int32),
        creases=creases,
        crease_bars=crease_bars,
        facets=facets,
        facet_bars=facet_bars,
        free=free,
        free_bars=free_bars,
    )


def make_params(
    pattern: CreasePattern,
    percent: float = 1.0,
    stiffness: Stiffness | dict | None = None,
    dtype=None,
) -> FoldParams:
    """Default parameters of a pattern: its targets, rest lengths and the given stiffness."""
    mesh = pattern.mesh
    dtype = dtype or jnp.result_type(float)
    if stiffness is None:
        stiffness = Stiffness()
    elif isinstance(stiffness, dict):
        stiffness = Stiffness(**stiffness)
    rest = np.linalg.norm(mesh.vertices[mesh.edges[:, 1]] - mesh.vertices[mesh.edges[:, 0]], axis=1)
    target = mesh.target[mesh.edges_with_role("driven")]
    return FoldParams(
        target=jnp.asarray(target, dtype),
        percent=jnp.asarray(percent, dtype),
        rest_length=jnp.asarray(rest, dtype),
        stiffness=Stiffness(*(jnp.asarray(s, dtype) for s in stiffness)),
    )


def _torsion(x, hinges, length, stiffness, target, reference):
    rho = fold_angles(x, hinges, reference)
    return 0.5 * jnp.sum(stiffness * length * (rho - target) ** 2)


def energy(
    x: Array, structure: Structure, params: FoldParams, reference: HingeReference | None = None
) -> Array:
    """Total energy of positions ``x`` (V, 3); a scalar in energy units (force x length).

    ``reference`` unwraps each fold angle to the branch nearest it (see
    :func:`origami_jax.geometry.fold_angles`); it changes no gradient. ``None`` uses
    :func:`initial_reference` of the flat state, continuous on the whole way from flat to target.
    """
    s = params.stiffness
    l0 = params.rest_length
    l = bar_lengths(x, structure.bars)
    total = 0.5 * jnp.sum(s.axial / l0 * (l - l0) ** 2)
    if reference is None:
        reference = _midway(structure, params)
    if structure.creases.shape[0]:
        goal = params.percent * params.target
        total += _torsion(
            x, structure.creases, l0[structure.crease_bars], s.crease, goal, reference.creases
        )
    if structure.facets.shape[0]:
        total += _torsion(
            x, structure.facets, l0[structure.facet_bars], s.facet, 0.0, reference.facets
        )
    return total


def _midway(structure: Structure, params: FoldParams) -> HingeReference:
    """Half way to each crease's target: the branch cut lies opposite, far from flat and target."""
    return HingeReference(
        creases=0.5 * params.percent * params.target,
        facets=jnp.zeros(structure.facets.shape[0], params.rest_length.dtype),
    )


def initial_reference(x: Array, structure: Structure, params: FoldParams) -> HingeReference:
    """Unwrapped fold angles of ``x`` measured against the half-way reference."""
    return update_reference(x, structure, _midway(structure, params))


def update_reference(x: Array, structure: Structure, reference: HingeReference) -> HingeReference:
    """Fold angles of ``x`` on the branches nearest ``reference`` (continuity through +-pi)."""
    return HingeReference(
        creases=fold_angles(x, structure.creases, reference.creases),
        facets=fold_angles(x, structure.facets, reference.facets),
    )


def build_energy(
    pattern: CreasePattern, percent: float = 1.0, stiffness: Stiffness | dict | None = None
) -> tuple[Callable[[Array, FoldParams], Array], FoldParams]:
    """Close over a pattern's structure: returns ``(energy_fn(x, params), default_params)``."""
    structure = make_structure(pattern.mesh)
    params = make_params(pattern, percent, stiffness)

    def energy_fn(x: Array, params: FoldParams, reference: HingeReference | None = None) -> Array:
        return energy(jnp.asarray(x, params.rest_length.dtype), structure, params, reference)

    return energy_fn, params
