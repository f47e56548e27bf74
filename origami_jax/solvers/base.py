"""What every solver shares: the problem pytree, rigid-body gauge, status codes and metrics.

A solver is an object with ``init(problem) -> state`` and ``run(state, problem, steps) -> state``
(both pure and jittable; ``run`` advances at most ``steps`` iterations inside one
``lax.while_loop`` and stops early once the state's status is not RUNNING). Its state has the
fields ``u``, ``reference``, ``iteration``, ``energy``, ``grad_max``, ``grad_max0`` and
``status``. Positions are ``problem.start + gauge(problem, state.u)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Protocol

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from origami_jax.energy import FoldParams, HingeReference, Structure, energy
from origami_jax.pattern import Mesh, find_root

__all__ = ["Status", "Problem", "Solver", "make_problem", "positions", "objective", "gauge"]


class Status(IntEnum):
    """Why a solve stopped (or that it has not)."""

    RUNNING = 0
    CONVERGED = 1
    MAX_ITER = 2
    NONFINITE = 3
    STALLED = 4


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Problem:
    """Everything a solve needs, as arrays: structure, parameters, start and rigid-body gauge.

    ``start`` (V, 3) start positions; ``pinned`` (P,) vertices whose displacement is projected
    by ``projectors`` (P, 3, 3) to remove the 6 rigid-body motions of each piece; ``tol`` the
    ``grad_norm_rel`` at which the solve has converged.
    """

    structure: Structure
    params: FoldParams
    start: Array
    pinned: Array
    projectors: Array
    tol: Array


class Solver(Protocol):
    name: str

    def init(self, problem: Problem): ...

    def run(self, state, problem: Problem, steps: Array): ...


def rigid_gauge(mesh: Mesh, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per connected piece, pin the triangle nearest its centroid: vertex a fixed, b on the line
    ab, c in the plane abc. That removes exactly the 6 rigid motions and nothing else."""
    tris = mesh.triangles
    parent = np.arange(mesh.num_vertices)
    for a, b, c in tris:
        root = find_root(parent, a)
        parent[find_root(parent, b)] = root
        parent[find_root(parent, c)] = root
    piece_of_tri = np.array([find_root(parent, t[0]) for t in tris])
    pinned, projectors = [], []
    for piece in np.unique(piece_of_tri):
        members = np.flatnonzero(piece_of_tri == piece)
        centres = start[tris[members]].mean(axis=1)
        centroid = centres.mean(axis=0)
        t = members[np.argmin(np.linalg.norm(centres - centroid, axis=1))]
        a, b, c = tris[t]
        d = start[b] - start[a]
        d /= np.linalg.norm(d)
        n = np.cross(start[b] - start[a], start[c] - start[a])
        n /= np.linalg.norm(n)
        pinned += [a, b, c]
        projectors += [np.zeros((3, 3)), np.outer(d, d), np.eye(3) - np.outer(n, n)]
    return np.array(pinned, np.int32), np.array(projectors)


def make_problem(
    mesh: Mesh,
    structure: Structure,
    params: FoldParams,
    start: np.ndarray | None = None,
    tol: float = 1e-9,
) -> Problem:
    dtype = params.rest_length.dtype
    start = mesh.vertices if start is None else np.asarray(start, np.float64)
    pinned, projectors = rigid_gauge(mesh, start)
    return Problem(
        structure=structure,
        params=params,
        start=jnp.asarray(start, dtype),
        pinned=jnp.asarray(pinned),
        projectors=jnp.asarray(projectors, dtype),
        tol=jnp.asarray(tol, dtype),
    )


def gauge(problem: Problem, u: Array) -> Array:
    """Displacement with the pinned vertices' motion projected onto what they may do."""
    p = problem.pinned
    return u.at[p].set(jnp.einsum("pij,pj->pi", problem.projectors, u[p]))


def positions(problem: Problem, u: Array) -> Array:
    return problem.start + gauge(problem, u)


def objective(u: Array, problem: Problem, reference: HingeReference) -> Array:
    return energy(positions(problem, u), problem.structure, problem.params, reference)
