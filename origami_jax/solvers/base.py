"""What every solver shares: the solver contract, the problem pytree, rigid-body gauge, status
codes and metrics.

**The solver contract** is the abstract class :class:`Solver`. A solver is a (hashable,
immutable: a frozen dataclass, say) subclass that writes two pure, jittable methods:

* ``init(problem) -> state``: the start state;
* ``step(state, problem) -> state``: one iteration; it sets ``state.status`` to a
  :class:`Status` other than ``RUNNING`` once the solve is over (converged, stalled, non-finite).

Everything else has a default, and :func:`~origami_jax.fold` and
:func:`~origami_jax.batch.fold_batch` drive every solver through these methods only:

* ``run(state, problem, steps) -> state``: at most ``steps`` iterations more in one
  ``lax.while_loop`` (:func:`run_steps`: the one loop of every solver), stopping early once the
  status is not ``RUNNING``;
* ``prepare(problem, mesh) -> problem``: attach host-built static data to ``problem.aux``
  before ``jit`` (default: none);
* ``prepare_batch(problem, mesh) -> problem``: the same for one member of a ``fold_batch``,
  whose problem may have more vertices than ``mesh`` (padding: pinned, after the mesh's) and
  has NumPy leaves; its ``aux`` must stack with the other members' of the same shapes
  (default: ``prepare``);
* ``shared_aux(problem, mesh) -> aux | None``: for ``fold_batch`` members of one topology, an
  ``aux`` they all share (one unbatched copy; it may depend on the index arrays of
  ``problem.structure`` only), or ``None`` (default) for each member's own;
* ``check_start(state)``: refuse a start state on the host (raise ``ValueError``), after
  ``init`` (default: accept; ``fold_batch`` runs ``init`` once more on the host only where it
  is overridden);
* ``check_batch(num_vertices)``: refuse to run a ``fold_batch`` of problems padded to
  ``num_vertices`` vertices (raise ``ValueError``; default: accept);
* ``batch_bytes(num_vertices) -> int``: working memory of one ``fold_batch`` slot beyond its
  state (``fold_batch`` keeps its slots' total near 256 MB; default 0);
* ``host_callbacks(problem) -> bool``: whether its solve of ``problem`` (prepared) calls back
  to the host, which an exported program cannot hold (:mod:`origami_jax.exported`; default
  ``False``);
* class attributes: ``follows_path`` (``fold(path="auto")`` follows the fold from flat with
  this solver where a scene needs it; default ``False``), ``supports_contact`` (the solver
  bounds its steps among contact pairs, :func:`contact_limit`, and reports their overflow,
  :func:`with_overflow`: ``fold(contact=...)``; default ``False``); ``name``
  (the result's ``solver``; default the class name, lower case).

**The state** is a ``NamedTuple`` (``fold`` calls ``_replace``) with at least the fields of
:class:`SolverState`: ``u`` (V, 3) the displacement from ``problem.start`` before the gauge
(positions are :func:`positions`), ``reference`` what the energy measures against
(:func:`start_reference` at the start; move it along with the iterates,
:func:`~origami_jax.energy.update_reference`, so a crease is followed through +-pi),
``iteration`` (int32), ``energy``, ``grad_max`` (the largest entry of the gradient),
``grad_max0`` (what ``grad_norm_rel`` divides by: :func:`tolerance_scale`) and ``status``
(int32 :class:`Status`). Any further fields are the solver's own; ``fold_batch`` vmaps them.

**Termination** is written once, here: :func:`has_converged` (the tolerance, or the gradient
down to its rounding floor), :class:`Progress` (best energy and gradient; :meth:`Progress.stalled`
once neither has improved for ``patience`` iterations) and :func:`next_status` (converged, then
non-finite, then stalled). A solver's ``step`` calls them; what a status means is its
:attr:`Status.message`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, replace
from enum import IntEnum
from typing import Any, ClassVar, NamedTuple, Protocol

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from origami_jax.barrier import S_MIN
from origami_jax.contact import step_bound
from origami_jax.energy import (
    FoldParams,
    Reference,
    Structure,
    barrier_distances,
    barrier_rows,
    energy,
    hinge_terms,
    initial_reference,
    springs_only,
    update_reference,
)
from origami_jax.geometry import dihedral_angles, dihedral_gradients
from origami_jax.pattern import Mesh, PatternError

__all__ = [
    "Status",
    "Problem",
    "Progress",
    "Solver",
    "SolverState",
    "check_options",
    "accept",
    "run_steps",
    "make_problem",
    "start_reference",
    "has_barriers",
    "tolerance_scale",
    "stop_closing",
    "element_floor",
    "barrier_limit",
    "prepare",
    "check_start",
    "next_status",
    "positions",
    "objective",
    "gauge",
    "gradient_floor",
    "has_converged",
]


class Status(IntEnum):
    """Why a solve stopped (or that it has not). Each code carries its :attr:`message`, a
    template that :meth:`describe` fills in with the solve's figures."""

    message: str

    def __new__(cls, value: int, message: str):
        member = int.__new__(cls, value)
        member._value_ = value
        member.message = message
        return member

    RUNNING = (
        0,
        "running after {iterations} iterations: grad_norm_rel {grad_norm_rel:.2e} > tol {tol:.1e}",
    )
    CONVERGED = 1, "converged: grad_norm_rel {grad_norm_rel:.2e} <= tol {tol:.1e}"
    MAX_ITER = (
        2,
        "iteration limit {iterations} reached: grad_norm_rel {grad_norm_rel:.2e} > tol {tol:.1e}",
    )
    NONFINITE = 3, "stopped: non-finite energy or gradient; the last finite iterate is returned"
    STALLED = (
        4,
        "stalled at grad_norm_rel {grad_norm_rel:.2e} > tol {tol:.1e}: the line search finds no "
        "decrease (the rounding floor of this dtype, or a kink such as a collapsed triangle)",
    )
    # set on the host, between compiled chunks
    TIME_LIMIT = (
        5,
        "time limit reached after {iterations} iterations: grad_norm_rel {grad_norm_rel:.2e} > "
        "tol {tol:.1e}",
    )
    # more contact pairs than their capacity: gathered again on the host
    CONTACT_OVERFLOW = 6, "stopped: more contact pairs than their capacity"

    def describe(self, grad_norm_rel: float, tol: float, iterations: int) -> str:
        """:attr:`message` with the solve's figures (a convergence above ``tol``, at the
        gradient's rounding floor, says so)."""
        message = self.message
        if self == Status.CONVERGED and grad_norm_rel > tol:
            message = CONVERGED_AT_FLOOR
        return message.format(grad_norm_rel=grad_norm_rel, tol=tol, iterations=iterations)


# what Status.CONVERGED says where the gradient stopped at its rounding floor above tol
CONVERGED_AT_FLOOR = (
    "converged: grad_norm_rel {grad_norm_rel:.2e} > tol {tol:.1e} is this dtype's rounding "
    "floor for these stiffnesses (the gradient is noise there)"
)


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Problem:
    """Everything a solve needs, as arrays: structure, parameters, start and rigid-body gauge.

    ``start`` (V, 3) start positions; ``pinned`` (P,) vertices whose displacement is projected
    by ``projectors`` (P, 3, 3) to remove the 6 rigid-body motions of each piece; ``tol`` the
    ``grad_norm_rel`` at which the solve has converged; ``max_step`` the largest displacement
    of any vertex in one iteration (pattern units), so that no hinge turns by more than about
    a quarter turn per step and the solve follows a folding path instead of jumping across one;
    ``aux`` what a solver attaches in its ``prepare`` (Newton: the Hessian's layout; dynamics:
    the vertex masses), ``None`` for solvers that need nothing; ``reference`` what the start is
    measured against (a continuation carries its last state's), ``None`` for
    :func:`~origami_jax.energy.initial_reference` of the start.
    """

    structure: Structure
    params: FoldParams
    start: Array
    pinned: Array
    projectors: Array
    tol: Array
    max_step: Array
    aux: Any = None
    reference: Reference | None = None


def start_reference(problem: Problem) -> Reference:
    """The :class:`~origami_jax.energy.Reference` a solve starts from (see ``Problem``)."""
    if problem.reference is not None:
        return problem.reference
    return initial_reference(problem.start, problem.structure, problem.params)


class Progress(NamedTuple):
    """Best energy and gradient seen so far, and iterations since either improved."""

    best_grad: Array
    best_energy: Array
    since_best: Array

    @staticmethod
    def start(dtype) -> Progress:
        inf = jnp.full((), jnp.inf, dtype)
        return Progress(inf, inf, jnp.zeros((), jnp.int32))

    def update(self, finite: Array, grad_max: Array, energy: Array, noise=0.0) -> Progress:
        """``noise``: how much the energy can move by rounding alone; a fall within it is no
        progress (a solve creeping along a kink by rounding-sized steps would never stall)."""
        improved = finite & ((grad_max < self.best_grad) | (energy < self.best_energy - noise))
        return Progress(
            best_grad=jnp.where(finite, jnp.minimum(grad_max, self.best_grad), self.best_grad),
            best_energy=jnp.where(finite, jnp.minimum(energy, self.best_energy), self.best_energy),
            since_best=jnp.where(improved, 0, self.since_best + 1),
        )

    def stalled(self, patience: int) -> Array:
        """Neither the energy nor the gradient has improved for ``patience`` iterations."""
        return self.since_best >= patience


def next_status(converged: Array, finite: Array, stalled: Array) -> Array:
    """The status after an iteration: converged first, then non-finite, then stalled."""
    return jnp.where(
        converged,
        Status.CONVERGED,
        jnp.where(~finite, Status.NONFINITE, jnp.where(stalled, Status.STALLED, Status.RUNNING)),
    ).astype(jnp.int32)


def gradient_floor(problem: Problem) -> Array:
    """The size below which a gradient entry is rounding noise: twice eps times the largest sum,
    over a vertex's bars, of their stiffness ``axial / l0`` times the coordinates' size (at
    least ``l0``). Each bar force is computed from ``l - l0``, and ``l`` from differences of
    coordinates, whose rounding is eps times the coordinates' size even at rest: on a sheet of
    many short bars (or one placed far from the origin) that is many times eps ``l0``. With
    stiff bars this lies above ``tol`` times the start gradient, and no solver can go below
    it."""
    params, bars = problem.params, problem.structure.bars
    size = jnp.max(jnp.abs(problem.start))
    l0 = params.rest_length
    force = params.stiffness.axial * jnp.maximum(1.0, size / jnp.where(l0 > 0, l0, size))
    per_vertex = jax.ops.segment_sum(
        jnp.concatenate([force, force]), bars.T.reshape(-1), num_segments=problem.start.shape[0]
    )
    return 2 * jnp.finfo(problem.start.dtype).eps * jnp.max(per_vertex)


def has_converged(
    grad_max: Array,
    grad_max0: Array,
    problem: Problem,
    previous: Array | None = None,
    floor: Array | float = 0.0,
) -> Array:
    """``grad_norm_rel <= tol``, or the gradient is down to its rounding noise (with
    ``previous``, the last iterate's ``grad_max``: there too, for a method whose step still
    gains there, as Newton's does).
    ``floor``: a further rounding floor to add (the hinges' and barriers':
    :func:`element_floor`)."""
    floor = gradient_floor(problem) + floor
    at_floor = grad_max <= floor
    if previous is not None:
        at_floor = at_floor & (previous <= floor)
    return (grad_max <= problem.tol * grad_max0) | at_floor


def run_steps(step, state, steps: Array):
    """``state = step(state)`` in one ``lax.while_loop``, at most ``steps`` times, until the
    state's status is not RUNNING (the ``run`` of every solver)."""
    last = state.iteration + steps

    def cond(s):
        return (s.status == Status.RUNNING) & (s.iteration < last)

    return jax.lax.while_loop(cond, step, state)


class SolverState(Protocol):
    """The fields every solver state has (see the module): a ``NamedTuple`` with these and any
    of the solver's own."""

    u: Array  # (V, 3) displacement from problem.start, before the gauge
    reference: Reference  # what the energy measures against (unwrap, triangle normals)
    iteration: Array  # int32
    energy: Array
    grad_max: Array  # the largest entry of the gradient
    grad_max0: Array  # what grad_norm_rel divides by (tolerance_scale)
    status: Array  # int32 Status

    def _replace(self, **fields: Any) -> SolverState: ...


def check_options(
    solver: Solver,
    at_least: dict[str, float] | None = None,
    above: dict[str, float] | None = None,
    counts: tuple[str, ...] = (),
) -> None:
    """Refuse a solver's option out of its range with a ``ValueError`` naming it: each option in
    ``at_least`` must be a number at or above its bound, each in ``above`` strictly above it
    (NaN is neither), and each in ``counts`` an integer."""
    kind = type(solver).__name__
    for bounds, strict in ((at_least or {}, False), (above or {}, True)):
        for option, bound in bounds.items():
            value = getattr(solver, option)
            number = isinstance(value, (int, float, np.integer, np.floating))
            number = number and not isinstance(value, bool)
            whole = isinstance(value, (int, np.integer)) and not isinstance(value, bool)
            if option in counts and not whole:
                raise ValueError(f"{kind} option {option} must be an integer, got {value!r}")
            if not (number and (value > bound if strict else value >= bound)):
                sign = ">" if strict else ">="
                raise ValueError(f"{kind} option {option} must be {sign} {bound}, got {value!r}")


class Solver(ABC):
    """The solver contract (see the module): write ``init`` and ``step``; the rest has
    defaults. Subclasses are hashable and immutable (compiled solves are cached per solver):
    frozen dataclasses, whose fields are the options."""

    # fold(path="auto") follows the fold from flat with this solver where a scene needs it
    follows_path: ClassVar[bool] = False
    # the solver bounds its steps among contact pairs (fold(contact=...))
    supports_contact: ClassVar[bool] = False

    @property
    def name(self) -> str:
        """The result's ``solver`` (a dataclass field ``name`` overrides it)."""
        return type(self).__name__.lower()

    @abstractmethod
    def init(self, problem: Problem) -> SolverState:
        """The start state (pure, jittable)."""

    @abstractmethod
    def step(self, state: SolverState, problem: Problem) -> SolverState:
        """One iteration (pure, jittable); its status says whether the solve goes on."""

    def run(self, state: SolverState, problem: Problem, steps: Array) -> SolverState:
        """At most ``steps`` iterations of :meth:`step` more, until the status is not
        ``RUNNING`` (:func:`run_steps`)."""
        return run_steps(lambda s: self.step(s, problem), state, steps)

    def prepare(self, problem: Problem, mesh: Mesh) -> Problem:
        """``problem`` with the solver's host-built static data in ``aux`` (before ``jit``)."""
        return problem

    def prepare_batch(self, problem: Problem, mesh: Mesh) -> Problem:
        """:meth:`prepare` of one ``fold_batch`` member: ``problem`` (NumPy leaves) may have
        more vertices than ``mesh``, padding pinned in place after the mesh's own; its ``aux``
        must stack with the other members' of these shapes."""
        return self.prepare(problem, mesh)

    def shared_aux(self, problem: Problem, mesh: Mesh) -> Any:
        """One ``aux`` shared by every ``fold_batch`` member of this problem's topology (built
        from its index arrays only, unbatched), or ``None``: each member its own."""
        return None

    def check_start(self, state: SolverState) -> None:
        """Refuse a start state on the host (raise ``ValueError``); ``state`` may be a batch's
        (a leading axis on every field)."""
        return None  # every start accepted

    @property
    def checks_start(self) -> bool:
        """Whether :meth:`check_start` is the solver's own (``fold_batch`` then runs ``init``
        once more, on the host, to show it the start states)."""
        return type(self).check_start is not Solver.check_start

    def check_batch(self, num_vertices: int) -> None:
        """Refuse a ``fold_batch`` of problems padded to ``num_vertices`` vertices (raise
        ``ValueError``)."""
        return None  # every size accepted

    def batch_bytes(self, num_vertices: int) -> int:
        """Working memory of one ``fold_batch`` slot of ``num_vertices`` vertices beyond its
        state, in bytes (the slots' total is kept near 256 MB)."""
        return 0

    def host_callbacks(self, problem: Problem) -> bool:
        """Whether the solve of ``problem`` (prepared) calls back to the host."""
        return False

    def cost_by_vertices(self) -> bool:
        """Whether an iteration's cost is set by the vertex count (a dense factorization), so
        that padding the elements up to any sheet's counts costs little (``fold``'s buckets)."""
        return False


def check_start(solver: Solver, state) -> None:
    """``solver.check_start(state)`` (kept for callers of the function)."""
    solver.check_start(state)


def prepare(solver: Solver, problem: Problem, mesh: Mesh) -> Problem:
    """``solver.prepare(problem, mesh)`` (kept for callers of the function)."""
    return solver.prepare(problem, mesh)


def accept(take: Array, u: Array, state: SolverState, problem: Problem) -> tuple[Array, Reference]:
    """The end of a step: ``u`` where ``take``, else ``state.u``, and the reference moved along
    to it (:func:`~origami_jax.energy.update_reference`; the state's where not taken)."""
    u = jnp.where(take, u, state.u)
    moved = update_reference(
        positions(problem, u), problem.structure, state.reference, contact_skin(problem)
    )
    return u, jax.tree.map(lambda new, old: jnp.where(take, new, old), moved, state.reference)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` over the last axis of length 3, without its overhead on small arrays."""
    i, j = [1, 2, 0], [2, 0, 1]
    return a[..., i] * b[..., j] - a[..., j] * b[..., i]


# a triangle whose area falls below this fraction of its flat area counts as collapsed: it has
# no normal, so the fold angles of its hinges (and the energy's slope) jump there
COLLAPSED_AREA = 1e-6


def doubled_areas(p: np.ndarray) -> np.ndarray:
    """(..., T) twice the area of triangles ``p`` (..., T, 3, 3) (host side)."""
    n = _cross(p[..., 1, :] - p[..., 0, :], p[..., 2, :] - p[..., 0, :])
    return np.sqrt(np.sum(n * n, axis=-1))


def piece_labels(elements: np.ndarray, num_vertices: int) -> np.ndarray:
    """(V,) the connected piece of each vertex over ``elements`` (n, k) (triangles, bars),
    named by its lowest vertex (a vertex in no element is its own piece): labels spread by
    minimum over elements, with pointer jumping (vectorized; no graph object to build)."""
    label = np.arange(num_vertices)
    while True:
        new = label.copy()
        np.minimum.at(new, elements, label[elements].min(axis=1)[:, None])
        new = new[new]
        if np.array_equal(new, label):
            return label
        label = new


def rigid_gauge(mesh: Mesh, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per connected piece, pin the triangle nearest its centroid: vertex a fixed, b on the line
    ab, c in the plane abc. That removes exactly the 6 rigid motions and nothing else.

    Returns (3 P,) pinned vertices and their (3 P, 3, 3) projectors, P pieces."""
    pinned, projectors = rigid_gauges(mesh.triangles, mesh.vertices[None], np.asarray(start)[None])
    return pinned[0], projectors[0]


def rigid_gauges(
    triangles: np.ndarray, flat: np.ndarray, start: np.ndarray, names: list | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`rigid_gauge` of M problems of one topology at once (fold_batch's variants of one
    pattern): ``triangles`` (T, 3), ``flat`` and ``start`` (M, V, 3); returns (M, 3 P) pinned
    vertices and (M, 3 P, 3, 3) projectors. A problem whose piece has no triangle of nonzero
    area raises :class:`PatternError` naming ``names[m]`` (default: no name)."""
    tris = triangles
    piece_of_tri = piece_labels(tris, flat.shape[1])[tris[:, 0]]
    p = start[:, tris]  # (M, T, 3, 3)
    usable = doubled_areas(p) > COLLAPSED_AREA * doubled_areas(flat[:, tris])
    rows = np.arange(len(start))
    pinned, projectors = [], []
    for piece in np.unique(piece_of_tri):
        members = np.flatnonzero(piece_of_tri == piece)
        centres = p[:, members].mean(axis=2)  # (M, Tp, 3)
        far = np.linalg.norm(centres - centres.mean(axis=1, keepdims=True), axis=2)
        order = members[np.argsort(far, axis=1)]  # (M, Tp) nearest first
        good = usable[rows[:, None], order]
        bad = ~good.any(axis=1)
        if bad.any():
            name = "" if names is None else f" {names[int(np.flatnonzero(bad)[0])]}"
            raise PatternError(
                f"start{name}: every triangle of the piece holding vertex {tris[members[0], 0]} "
                "is collapsed (zero area)"
            )
        a, b, c = tris[order[rows, np.argmax(good, axis=1)]].T  # (M,) each
        d = start[rows, b] - start[rows, a]
        n = _cross(d, start[rows, c] - start[rows, a])
        d = d / np.sqrt(np.sum(d * d, axis=1, keepdims=True))
        n = n / np.sqrt(np.sum(n * n, axis=1, keepdims=True))
        pinned += [a, b, c]
        projectors += pin_projectors(d, n)
    return np.stack(pinned, axis=1).astype(np.int32), np.stack(projectors, axis=1)


def make_problem(
    mesh: Mesh,
    structure: Structure,
    params: FoldParams,
    start: np.ndarray | None = None,
    tol: float = 1e-9,
    max_step: float | None = None,
    reference: Reference | None = None,
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
        max_step=jnp.asarray(default_max_step(mesh) if max_step is None else max_step, dtype),
        reference=reference,
    )


def default_max_step(mesh: Mesh) -> float:
    """Half the median altitude of the triangles: a step turns a typical hinge < ~30 deg."""
    return float(default_max_steps(mesh.triangles, mesh.vertices[None])[0])


def default_max_steps(triangles: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """(M,) :func:`default_max_step` of M meshes of one topology, vertices ``flat`` (M, V, 3)."""
    p = flat[:, triangles]
    edges = p - p[:, :, [2, 0, 1]]
    longest = np.sqrt(np.max(np.sum(edges * edges, axis=3), axis=2))
    return 0.5 * np.median(doubled_areas(p) / longest, axis=1)


def pin_axes(a: Array, b: Array, c: Array) -> tuple[Array, Array]:
    """Unit vectors along ``ab`` and normal to the plane ``abc`` of triangles (..., 3) each:
    the two axes of the rigid gauge. A degenerate triangle gives zeros, not NaN."""

    def unit(w):
        norm = jnp.sqrt(jnp.sum(w * w, axis=-1, keepdims=True))
        return jnp.where(norm > 0, w / jnp.where(norm > 0, norm, 1), 0)

    return unit(b - a), unit(jnp.cross(b - a, c - a))


def pin_projectors(d, n) -> list:
    """The projectors of a pinned triangle's vertices a, b, c: a fixed, b on the line of unit
    ``d``, c in the plane of unit normal ``n`` ((..., 3) each; NumPy or JAX arrays alike)."""
    along = d[..., :, None] * d[..., None, :]
    return [0 * along, along, np.eye(3).astype(n.dtype) - n[..., :, None] * n[..., None, :]]


def gauge(problem: Problem, u: Array) -> Array:
    """Displacement with the pinned vertices' motion projected onto what they may do."""
    p = problem.pinned
    return u.at[p].set(jnp.einsum("pij,pj->pi", problem.projectors, u[p]))


def positions(problem: Problem, u: Array) -> Array:
    return problem.start + gauge(problem, u)


def objective(u: Array, problem: Problem, reference: Array) -> Array:
    return energy(positions(problem, u), problem.structure, problem.params, reference)


def tolerance_scale(problem: Problem, u: Array, reference: Reference, grad_max: Array) -> Array:
    """What ``grad_norm_rel`` divides by: the largest entry of the gauged gradient at the start
    (``grad_max``), of the springs alone where the scene has barriers (a start pushed into a
    barrier's stiff continuation has a gradient that says nothing of the springs' scale)."""
    if not has_barriers(problem.structure):
        return grad_max
    springs = replace(problem, structure=springs_only(problem.structure))
    return jnp.max(jnp.abs(jax.grad(objective)(u, springs, reference)))


def has_barriers(structure: Structure) -> bool:
    """Whether the scene was built with a barrier (a static fact of its structure)."""
    return (structure.barriers.hinge_gap > 0 and structure.hinges.shape[0] > 0) or (
        structure.triangles.shape[0] > 0
    )


# a step may close at most this fraction of any barrier's distance to its wall (to first order)
BARRIER_APPROACH = 0.9


def barrier_limit(x: Array, step: Array, problem: Problem, reference: Reference) -> Array:
    """The largest multiple of ``step`` (at most 1) that closes no barrier's distance to its
    wall by more than :data:`BARRIER_APPROACH`, to first order: the iterates approach a wall
    geometrically instead of landing on it, where its curvature would swamp the Newton system
    (the conservative step of incremental potential contact's line search)."""

    def distances(y):
        return barrier_distances(y, problem.structure, problem.params, reference)

    d, rate = jax.jvp(distances, (x,), (step,))
    # a barrier already in its stiff continuation (pushed there by a step's second-order
    # change) is left to the energy: limiting it would only stop the iterates
    closing = (rate < 0) & (d > S_MIN)
    room = jnp.where(closing, BARRIER_APPROACH * jnp.maximum(d, 0.0), 1.0)
    t = room / jnp.where(closing, -rate, 1.0)
    return jnp.minimum(1.0, jnp.min(t, initial=1.0))


def with_overflow(status: Array, reference: Reference) -> Array:
    """``status``, or ``CONTACT_OVERFLOW`` where the contact pairs of ``reference`` outgrew
    their capacity (the host gathers them again with more room)."""
    if reference.pairs is None:
        return status
    return jnp.where(reference.pairs.did_overflow, Status.CONTACT_OVERFLOW, status)


def contact_skin(problem: Problem) -> Array | None:
    """The contact skin of ``problem`` (see :class:`~origami_jax.energy.ContactParams`), or
    ``None`` in a scene without contact."""
    return None if problem.structure.contact is None else problem.params.contact.skin


def contact_limit(x: Array, step: Array, problem: Problem, reference: Reference) -> Array:
    """The largest multiple of ``step`` (positions, (V, 3); at most 1) that keeps every vertex
    within half the contact skin of where the candidate pairs were gathered (so no pair comes
    within ``dhat`` unseen), and along which no candidate pair closes below a fraction of its
    distance from ``x`` (:func:`~origami_jax.contact.step_bound`, incremental potential
    contact's filter: no face passes through a face). 1 in a scene without contact."""
    pairs = reference.pairs
    if problem.structure.contact is None or pairs is None:
        return jnp.ones((), x.dtype)

    def norms(d):
        return jnp.sqrt(jnp.sum(d * d, axis=-1))

    # each vertex's room: half the skin less how far it has moved since the pairs were gathered
    room = jnp.maximum(0.5 * problem.params.contact.skin - norms(x - pairs.x_built), 0.0)
    speed = norms(step)
    t = jnp.min(jnp.where(speed > 0, room / jnp.where(speed > 0, speed, 1.0), 1.0), initial=1.0)
    return t * step_bound(x, t * step, pairs)


def contact_clear(x: Array, y: Array, problem: Problem, reference: Reference) -> Array:
    """Whether the straight way from ``x`` to ``y`` passes :func:`contact_limit` whole."""
    return contact_limit(x, y - x, problem, reference) >= 1.0


def stop_closing(v: Array, x: Array, problem: Problem, reference: Reference) -> Array:
    """Velocities ``v`` (V, 3) at ``x`` less, for every barrier inside its active zone that
    they would close, their component along that barrier's distance gradient: an inelastic
    stop at the wall, local to the barrier's corners (for explicit dynamics, whose step no
    barrier's unbounded stiffness allows)."""
    out = v
    for rows in barrier_rows(x, problem.structure, problem.params, reference):
        grad = rows.gradient
        rate = jnp.sum(grad * v[rows.corners], axis=(1, 2))
        norm2 = jnp.sum(grad * grad, axis=(1, 2))
        closing = (rows.distance < 1.0) & (rate < 0) & (norm2 > 0)
        scale = jnp.where(closing, rate / jnp.where(norm2 > 0, norm2, 1.0), 0.0)
        out = out.at[rows.corners].add(-scale[:, None, None] * grad)
    return out


def element_floor(x: Array, problem: Problem, reference: Reference) -> Array:
    """Eps times the largest root-sum-square, over a vertex's hinges and barriers, of the
    rounding of their force on it: the force's size, and its change over the rounding of the
    element's angle or distance (its curvature times that rounding: a fold angle's is about
    eps times the coordinates' size over its wing's altitude, large at a sliver; a barrier's
    curvature is large near its wall). Newton counts it in scenes with barriers, where creases
    folded flat and barriers holding them put the gradient's rounding above the bars' alone
    (:func:`gradient_floor`)."""
    eps = jnp.finfo(x.dtype).eps
    force = jnp.zeros(x.shape[:1] + x.shape[2:], x.dtype)
    structure, params = problem.structure, problem.params
    if structure.hinges.shape[0]:
        q = x[structure.hinges]
        g = dihedral_gradients(q)
        _, d1, d2 = hinge_terms(dihedral_angles(q, reference.angles), structure, params)
        size = jnp.sqrt(jnp.sum(g * g, axis=2))
        rounding = jnp.max(jnp.abs(x), axis=(0, 1)) * jnp.max(size, axis=1)
        spread = (jnp.abs(d1) + jnp.abs(d2) * rounding)[:, None] * size
        force = force.at[structure.hinges].add(spread * spread)
    for rows in barrier_rows(x, structure, params, reference):
        if rows.corners.shape[1] == 4:  # the hinges' barriers: in their terms above
            continue
        size = jnp.sqrt(jnp.sum(rows.gradient**2, axis=2))  # (n, 3)
        # an area ratio's rounding is about eps
        spread = jnp.abs(rows.slope) + jnp.abs(rows.curvature)
        force = force.at[rows.corners].add((spread[:, None] * size) ** 2)
    return eps * jnp.sqrt(jnp.max(force, axis=0))
