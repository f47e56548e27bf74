"""Newton's method on the same energy, with the exact Hessian assembled from element Hessians.

Each iteration assembles the Hessian of the energy from per-element blocks
(:mod:`origami_jax.solvers.assembly`: bars, torsion hinges and barrier triangles, in closed
form). Far from equilibrium the Hessian can be indefinite, so the method works with two
matrices:

* the **convex part** (always positive semi-definite): the bars' compressive terms and the
  hinges' and barriers' curvature terms dropped (see :mod:`~origami_jax.solvers.assembly`);
* the **exact Hessian**, tried once the previous iteration took the full, unlimited Newton step
  and no longer one (the quadratic region: a step that the line search could double, see
  ``expansions``, shows the convex part still overstating the curvature, where the exact
  Hessian is mostly indefinite), and kept as long as it gives a descent step that the line
  search accepts whole; otherwise the iteration falls back to the convex part. (Measured:
  docs/design-notes/measurements.md.) An
  exact Hessian that does not factor (not positive definite) hands over to the convex part
  within the same iteration when it is factored on the host (sparse, large patterns); dense, the
  failed
  attempt costs the iteration. After the n-th rejected exact attempt in a row the next waits
  for 2^n - 1 full convex steps (at most 15). After ``shift_after`` rejections in a row, exact
  attempts are
  shifted (see there). Far from equilibrium an exact attempt is skipped (the iteration takes the
  convex part, and no rejection is counted) where the compressed bars at some vertex outweigh
  the out-of-plane support of its hinges (``buckling_ratio``): there the exact Hessian is
  mostly indefinite.

A Levenberg-Marquardt shift ``mu * |diag(H)|`` (``mu`` from ``mu_min``, grown 10x, from at least
1e-10, whenever no step is found, and shrunk 10x with every step taken) keeps the system
non-singular on mechanisms and free hinges. Its floor ``mu_min`` is 0: a shift that stays
makes the last iterations converge linearly where the exact step
converges quadratically. Rigid motions are gauged out as in the other solvers
(:func:`~origami_jax.solvers.assembly.gauged_hessian`); but a step
that would turn the sheet (by more than ``free_turn``) is taken free of the gauge: its
infinitesimal rigid motion is removed, the sheet moves, and each piece is then turned rigidly
back so that its pinned triangle lies where the gauge holds it
(:mod:`origami_jax.solvers.reframe`: :func:`rigid_free`, :func:`reframe`). The step is bent by
geodesic acceleration (``acceleration``: a second solve
with the same factor corrects the bar lengths' and fold angles' second-order change along the
step), limited by ``max_turn`` and backtracked (Armijo) on the energy.

The linear system is solved dense (Cholesky, inside ``jit``; vmap-able) for small patterns and
sparse for large ones, on the host through ``jax.pure_callback``
(:mod:`origami_jax.solvers.hostsparse`: MKL's PARDISO or CHOLMOD where installed, else
SuperLU) in a fill-reducing order (:mod:`origami_jax.solvers.hessian_layout`). A batch of one
topology (``fold_batch``'s shared index arrays) factors all its members at once with the
block-sparse Cholesky of :mod:`origami_jax.solvers.blocksparse` instead.

Example:
  >>> from origami_jax import fold, patterns
  >>> r = fold(patterns.miura_ori(3, 3), solver="newton")
  >>> bool(r.converged), r.iterations < 30
  (True, True)
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from origami_jax.barrier import S_MIN
from origami_jax.energy import (
    Reference,
    Structure,
    barrier_distances,
    energy,
    hinge_terms,
    hinge_weights,
    residuals,
    triangle_terms,
    update_reference,
)
from origami_jax.geometry import (
    bar_lengths,
    dihedral_angles,
    dihedral_gradients,
)
from origami_jax.pattern import Mesh
from origami_jax.solvers import blocksparse, hostsparse
from origami_jax.solvers.assembly import (
    assemble,  # noqa: F401
    element_blocks,
    gauge_scale,
    gauged_hessian,
    vertex_projectors,
)
from origami_jax.solvers.base import (
    Problem,
    Progress,
    Solver,
    Status,
    barrier_limit,
    check_options,
    contact_clear,
    contact_limit,
    contact_skin,
    element_floor,
    gauge,
    has_barriers,
    has_converged,
    next_status,
    positions,
    start_reference,
    tolerance_scale,
    with_overflow,
)
from origami_jax.solvers.hessian_layout import (
    UPPER_PAIRS,  # noqa: F401
    HessianLayout,
    hessian_elements,
    hessian_layout,
    layout_arrays,
)
from origami_jax.solvers.innermost import batch_innermost
from origami_jax.solvers.reframe import (
    reframing,
    rigid_fit,
    rigid_free,  # noqa: F401
)

# the Hessian's layout, its assembly and the rigid motions have their own modules
# (hessian_layout, assembly, reframe); the public names they took from this one are still
# imported here (assemble, UPPER_PAIRS and rigid_free only for that: hence the noqa)
__all__ = ["Newton", "NewtonState"]


def energy_noise(x: Array, problem: Problem, reference: Reference, value: Array) -> Array:
    """How much the computed energy can move by rounding alone near ``x``: 16 eps times the
    energy plus each element's force times its length (bars) or moment (hinges). In a strained
    equilibrium the element forces are far larger than the energy's own size suggests; below
    this level an Armijo test compares rounding errors, so it accepts any change within it."""
    work = _element_work(x, problem.structure, problem.params, reference)
    return 16 * jnp.finfo(x.dtype).eps * (jnp.abs(value) + work)


def _element_work(x: Array, structure: Structure, params, reference: Reference) -> Array:
    """The sum of each element's force times its length (bars), moment (hinges) or energy's
    derivative in its area ratio (barrier triangles)."""
    l0 = params.rest_length
    length = bar_lengths(x, structure.bars)
    work = jnp.sum(params.stiffness.axial / l0 * jnp.abs(length - l0) * length, axis=0)
    if structure.hinges.shape[0]:
        rho = dihedral_angles(x[structure.hinges], reference.angles)
        moment = hinge_terms(rho, structure, params)[1]
        work += jnp.sum(jnp.abs(moment), axis=0)
    if structure.triangles.shape[0]:
        _, _, d1, _ = triangle_terms(x, structure, params, reference.normals)
        work += jnp.sum(jnp.abs(d1), axis=0)
    return work


def _vertex_buckling(
    x: Array, structure: Structure, params, reference: Reference
) -> tuple[Array, Array]:
    """(V,) at each vertex, the negative transverse stiffness of its compressed bars,
    ``sum axial / l0 (l0 / l - 1)``, and the stiffness its hinges give it out of their planes,
    ``sum stiffness l0 |grad(rho)|^2`` (the trace of their Gauss-Newton blocks there): where the
    first exceeds the second, the compressed bars buckle the sheet and the exact Hessian is
    indefinite (see ``Newton.buckling_ratio``)."""
    trailing = x.shape[2:]
    bars = structure.bars
    l0 = params.rest_length
    # compression at the level of rounding is none: a vertex without hinge support would
    # otherwise skip every exact attempt
    strain = l0 / bar_lengths(x, bars) - 1.0 - 16 * jnp.finfo(x.dtype).eps
    soft = params.stiffness.axial / l0 * jnp.maximum(strain, 0.0)
    zeros = jnp.zeros((x.shape[0], *trailing), x.dtype)
    softening = zeros.at[bars[:, 0]].add(soft).at[bars[:, 1]].add(soft)
    if not structure.hinges.shape[0]:
        return softening, zeros
    q = x[structure.hinges]
    g = dihedral_gradients(q)
    weight = hinge_weights(structure, params)[1]
    if structure.barriers.hinge_gap > 0:  # a barrier near its wall supports the vertex too
        weight = hinge_terms(dihedral_angles(q, reference.angles), structure, params)[2]
    support = weight[:, None] * jnp.sum(g * g, axis=2)
    return softening, zeros.at[structure.hinges.reshape(-1)].add(support.reshape(-1, *trailing))


def _barrier_distances(x: Array, problem: Problem, reference: Reference) -> Array:
    return barrier_distances(x, problem.structure, problem.params, reference)


def barrier_feasible(y: Array, floor: Array, problem: Problem, reference: Reference) -> Array:
    """Whether no barrier at ``y`` is closer to its wall than ``floor`` (per barrier: the stiff
    continuation's edge, or deeper where the last iterate already was): the filter of the line
    search, as incremental potential contact's, so the iterates stay where the barriers' own
    curvature keeps the Newton system well conditioned."""
    return jnp.all(_barrier_distances(y, problem, reference) >= floor, axis=0)


def _energy_and_gradient(x: Array, structure: Structure, params, reference: Reference):
    value, pullback = jax.vjp(lambda y: energy(y, structure, params, reference), x)
    return value, pullback(jnp.ones_like(value))[0]


# vmapped over problems of one topology (fold_batch), the element kernels of a step run with the
# batch innermost (see innermost.py; also _second_order_pull and _block_factor below)
_element_work = batch_innermost(_element_work, index_args=(1,))
_update_reference = batch_innermost(update_reference, index_args=(1,))
_energy_and_gradient = batch_innermost(_energy_and_gradient, index_args=(1,))
_energy = batch_innermost(energy, index_args=(1,))
_vertex_buckling = batch_innermost(_vertex_buckling, index_args=(1,))


def _value_and_grad(u: Array, problem: Problem, reference: Reference):
    """Energy at displacement ``u``, its gradient in the positions, and the largest entry of
    that gradient gauged (the gradient in ``u``, which the convergence test reads)."""
    value, grad = _energy_and_gradient(
        positions(problem, u), problem.structure, problem.params, reference
    )
    return value, grad, jnp.max(jnp.abs(gauge(problem, grad)))


def _second_order_pull(
    x: Array, velocity: Array, structure: Structure, params, reference: Reference
) -> Array:
    """``J^T W r''[v, v]``: the residuals' second derivative along ``velocity`` at ``x``,
    weighted and pulled back to the positions (the right-hand side of geodesic acceleration)."""

    def res(y):
        return residuals(y, structure, params, reference)

    _, transpose, weights = jax.vjp(res, x, has_aux=True)  # weights: constant in x

    def rate(y):
        return jax.jvp(lambda y: res(y)[0], (y,), (velocity,))[1]

    second = jax.jvp(rate, (x,), (velocity,))[1]
    return transpose(weights * second)[0]


_second_order_pull = batch_innermost(_second_order_pull, index_args=(2,))


def _block_factor(
    plan: blocksparse.BlockPlan,
    structure: Structure,
    x: Array,
    params,
    reference: Reference,
    exact: Array,
    proj: Array,
    scale: Array,
    mu: Array,
) -> blocksparse.Factor:
    """:func:`element_blocks` factored by :func:`blocksparse.factor` (``proj``, ``scale``,
    ``mu`` as there); vmapped, with the batch innermost from the positions to the factor."""
    blocks = element_blocks(x, structure, params, reference, exact)
    return blocksparse.factor(plan, blocks, proj, scale, mu)


_block_factor = batch_innermost(_block_factor, index_args=(0, 1))


def _cholesky_solve(matrix: Array, rhs: Array) -> Array:
    """``matrix^-1 rhs`` by Cholesky (LAPACK), NaN where ``matrix`` is not positive definite."""
    return jax.scipy.linalg.cho_solve((jnp.linalg.cholesky(matrix), True), rhs)


def _one_member_at_a_time(fn):
    """``fn`` as a ``custom_vmap`` whose batched rule loops over the members (``lax.map``):
    jaxlib's batched LAPACK kernels split their batch over XLA's CPU thread pool and wait for
    it from inside the pool, which deadlocks when several CPU devices (fold_batch's shards) run
    at once. Forward-mode differentiable; like Newton's ``while_loop``, not reverse-mode."""
    wrapped = jax.custom_batching.custom_vmap(fn)

    @wrapped.def_vmap
    def _rule(axis_size, in_batched, *args):
        if not any(in_batched):  # only tangents batched (jacfwd): nothing to split
            return fn(*args), False
        args = tuple(
            a if batched else jnp.broadcast_to(a, (axis_size, *a.shape))
            for a, batched in zip(args, in_batched, strict=True)
        )
        return jax.lax.map(lambda pair: fn(*pair), args), True

    return functools.wraps(fn)(wrapped)


_dense_factor = _one_member_at_a_time(jnp.linalg.cholesky)
_dense_solve_factored = _one_member_at_a_time(
    lambda factor, rhs: jax.scipy.linalg.cho_solve((factor, True), rhs)
)


class NewtonState(NamedTuple):
    u: Array  # (V, 3) displacement from problem.start, before the gauge
    grad: Array  # (V, 3) gradient of the energy in the positions at u (not gauged)
    reference: Reference  # what the energy measures against (unwrap, triangle normals)
    iteration: Array
    energy: Array
    grad_max: Array
    grad_max0: Array
    status: Array
    mu: Array  # Levenberg-Marquardt shift, relative to the diagonal
    exact: Array  # ask for the exact Hessian in the next iteration (the buckling check may skip it)
    stalls: Array  # iterations in a row without an accepted step
    failures: Array  # exact-Hessian attempts rejected since the last accepted one
    cooldown: Array  # full convex steps still to take before the next exact attempt
    shift: Array  # Levenberg-Marquardt shift of exact attempts, relative to the diagonal
    progress: Progress


def _shift_of(s: NewtonState, exact: Array | bool) -> Array:
    """The Levenberg-Marquardt shift of a factorization, relative to ``|diag H|``: ``mu``, plus
    ``shift`` for the exact Hessian (see ``Newton.shift_after``)."""
    return s.mu + jnp.where(jnp.asarray(exact), s.shift, 0.0)


@dataclass(frozen=True)
class Newton(Solver):
    """Newton's method with exact element Hessians (``solver="newton"``).

    Attributes:
      linear_solver: ``"auto"`` (dense up to ``dense_max`` vertices, else sparse), ``"dense"``
        or ``"sparse"``.
      dense_max: largest vertex count solved dense under ``"auto"``.
      mu_min: smallest Levenberg-Marquardt shift, relative to the matrix diagonal (a rounding
        sized floor, ``eps`` times the largest diagonal entry, is always added).
      max_turn: largest relative displacement of the two ends of any bar in one step, over its
        rest length (about the largest rotation of any piece of paper per step, radians).
      acceleration: geodesic acceleration (see ``_attempt``): the largest ``2 |a| / |v|`` of the
        second-order correction ``a`` to the step ``v`` that is used; 0 turns it off. It costs
        a second solve with the same factorization.
      expansions: doublings of a step that passed at full length: while the energy falls by
        more than rounding and no bar turns past ``max_turn``, the step is doubled, up to this
        many times (0: never). Far from equilibrium the convex part of the Hessian overstates
        the curvature along a sheet's soft modes, so its full steps fall short; near one, the
        doubled Newton step raises the energy and is not taken. Each doubling tried costs one
        energy evaluation. A doubled step also postpones the next
        exact attempt (see the module docstring).
      free_turn: a step whose rigid part turns a piece by more than this (radians per unit
        step) is taken free of the gauge and the result reframed. Pinned, a step turns the
        whole sheet about one triangle by a linearized rotation, which stretches it: on a
        Miura-ori, whose panels all tilt as it folds, that left a crumpled patch around the
        pinned triangle to smooth out over many iterations. Small steps stay pinned: reframing
        moves every
        vertex by a rotation found from one small triangle, whose rounding would raise the
        gradient's noise floor (float32 Miura-ori 10 x 10 stalled above it). ``inf``: never.
      convex_rate: an iteration that lowers the energy to below this fraction of its value
        keeps the next one on the convex part (exact attempts resume once the energy falls
        more slowly): near a zero-residual solution (rigid-foldable patterns) the convex part
        (Gauss-Newton) converges about as fast as the exact Hessian, without the curvature
        terms' cost. 0 (the default): exact attempts after every unexpanded full step.
      shift_after: after this many exact attempts in a row are rejected (not positive
        definite, or no step accepted), the next ones add a Levenberg-Marquardt shift
        ``shift * |diag(H)|`` to the exact Hessian: ``shift_min`` at first, 10x more with each
        further rejection (at most 1e10), 10x less with each exact step taken (0 once below a
        thousandth of ``shift_min``). A pattern whose exact Hessian stays slightly indefinite
        along a flat valley otherwise crawls there on convex steps. ``10**9`` turns it off (it is
        compared with an int32 count, so
        keep it below 2**31).
      buckling_ratio: an exact attempt is skipped (the iteration takes the convex part and
        counts no rejection) while, at some vertex, the negative transverse stiffness of the
        compressed bars, ``sum axial / l0 (l0 / l - 1)``, exceeds this times the stiffness its
        hinges give it out of their planes, ``sum stiffness l0 |grad(rho)|^2``: such bars
        buckle the sheet there and the exact Hessian is mostly indefinite (on a waterbomb
        2 x 2 every dense attempt in that state failed to factor and cost its iteration).
        ``inf``: never skipped. Only far from equilibrium (``buckling_far``). 1 is the point where
        the compressed bars outweigh the support.
      buckling_far: ``buckling_ratio`` applies while the gradient (its largest gauged entry)
        is above this fraction of its start value. Near equilibrium a folded sheet's other
        bars hold such a vertex and the exact Hessian factors (0.1:
        docs/design-notes/measurements.md).
      shift_min: the first such shift, relative to the diagonal.
      max_linesearch_steps: halvings of the step before an iteration gives up.
      max_stalls: iterations in a row without a step before giving up (STALLED).
      patience: iterations with neither a new lowest energy (lower by more than the energy's
        rounding noise) nor a new smallest gradient before giving up (STALLED).
    """

    linear_solver: str = "auto"
    dense_max: int = 200
    mu_min: float = 0.0
    max_turn: float = 0.5
    acceleration: float = 10.0
    expansions: int = 3
    free_turn: float = 1e-3
    convex_rate: float = 0.0
    shift_after: int = 4
    buckling_ratio: float = 1.0
    buckling_far: float = 0.1
    shift_min: float = 1e-6
    max_linesearch_steps: int = 40
    max_stalls: int = 12
    patience: int = 30
    name: str = "newton"
    # fold() follows the path from flat with this solver where a scene needs it (path="auto")
    follows_path: ClassVar[bool] = True
    # it bounds its steps among contact pairs (fold(contact=...))
    supports_contact: ClassVar[bool] = True

    def __post_init__(self):
        if self.linear_solver not in ("auto", "dense", "sparse"):
            raise ValueError(f"unknown linear solver {self.linear_solver!r} (auto, dense, sparse)")
        counts = ("dense_max", "expansions", "shift_after", "max_linesearch_steps")
        counts += ("max_stalls", "patience")
        at_least = dict.fromkeys(("dense_max", "expansions"), 0)
        at_least.update(dict.fromkeys(("shift_after", "max_linesearch_steps"), 1))
        at_least.update(dict.fromkeys(("max_stalls", "patience"), 1))
        for option in ("mu_min", "acceleration", "free_turn", "convex_rate", "shift_min"):
            at_least[option] = 0.0
        at_least["buckling_far"] = 0.0
        above = dict.fromkeys(("max_turn", "buckling_ratio"), 0.0)
        check_options(self, at_least=at_least, above=above, counts=counts)

    def prepare(self, problem: Problem, mesh: Mesh) -> Problem:
        """Attach the Hessian layout (host side, before ``jit``)."""
        sparse = self.linear_solver == "sparse" or (
            self.linear_solver == "auto" and mesh.num_vertices > self.dense_max
        )
        return replace(problem, aux=hessian_layout(mesh, problem.structure, sparse))

    def init(self, problem: Problem) -> NewtonState:
        u = jnp.zeros_like(problem.start)
        reference = start_reference(problem)
        value, grad, gmax = _value_and_grad(u, problem, reference)
        ok = jnp.isfinite(value) & jnp.isfinite(gmax)
        status = jnp.where(
            ok, jnp.where(gmax == 0, Status.CONVERGED, Status.RUNNING), Status.NONFINITE
        )
        status = with_overflow(status, reference)
        zero = jnp.zeros((), jnp.int32)
        return NewtonState(
            u=u,
            grad=grad,
            reference=reference,
            iteration=zero,
            energy=value,
            grad_max=gmax,
            grad_max0=tolerance_scale(problem, u, reference, gmax),
            status=status.astype(jnp.int32),
            mu=jnp.asarray(self.mu_min, u.dtype),
            exact=jnp.zeros((), bool),
            stalls=zero,
            failures=zero,
            cooldown=zero,
            shift=jnp.zeros((), u.dtype),
            progress=Progress(gmax, value, zero),
        )

    def _factor(self, s: NewtonState, problem: Problem, exact: Array, keep: bool):
        """Factor ``H + mu |diag H|`` (exact or convex ``H``; exact attempts add ``shift`` to
        ``mu``); returns ``(solve, used)``:
        ``solve(rhs) -> (step, ok)`` for (V, 3) right-hand sides (the first call gives the Newton
        step, the second, only with ``keep``, reuses the factorization), and ``used``, a list
        that holds, once the first call has run, whether the exact Hessian was factored.

        On the host (sparse layouts, above ``dense_max`` vertices), an exact Hessian that does
        not factor hands over to the convex part within the same call, so a failed exact
        attempt costs its factorization (which stops at the first pivot that is not positive)
        but not a whole iteration. Dense (small patterns, and every ``fold_batch``), ``used`` is
        ``exact``: there an iteration costs milliseconds while the second branch would add
        0.3 to 0.8 s to every compile, and vmap would run both branches."""
        layout: HessianLayout = problem.aux
        x = positions(problem, s.u)
        if layout.plan is not None:
            proj = vertex_projectors(x.shape[0], problem.pinned, problem.projectors)
            factor = _block_factor(
                layout.plan,
                problem.structure,
                x,
                problem.params,
                s.reference,
                exact,
                proj,
                gauge_scale(problem),
                _shift_of(s, exact),
            )
            return functools.partial(blocksparse.solve_factored, layout.plan, factor), [exact]

        def shifted(hessian_exact):
            values = gauged_hessian(x, problem, s.reference, hessian_exact)
            # the exact Hessian's diagonal can be negative: shifts scale with its magnitude
            diag = jnp.abs(values[layout.diag_blocks[:, jnp.arange(3), jnp.arange(3)]])
            floor = jnp.finfo(x.dtype).eps * jnp.max(diag)
            mu = _shift_of(s, hessian_exact)
            return values.at[layout.diag_blocks[:, jnp.arange(3), jnp.arange(3)]].add(
                mu * diag + floor
            )

        def ordered(rhs):
            return jnp.zeros(layout.size, x.dtype).at[layout.order].set(rhs.reshape(-1))

        def unordered(sol):
            return sol[layout.order].reshape(x.shape)

        if not layout.sparse:
            chol = _dense_factor(shifted(exact).reshape(layout.size, layout.size))

            def dense(rhs):
                sol = unordered(_dense_solve_factored(chol, ordered(rhs)))
                return sol, jnp.all(jnp.isfinite(sol))

            return dense, [exact]

        def first(values, b, active):
            """Factor (kept with ``keep``) and solve on the host: ``(solution, ok, token)``.
            Not ``active``, nothing is factored: a cond branch that vmap runs for every member
            but selects for some."""
            return jax.pure_callback(
                functools.partial(hostsparse.factor_solve, keep=keep),
                (
                    jax.ShapeDtypeStruct(b.shape, b.dtype),
                    jax.ShapeDtypeStruct((), jnp.bool_),
                    jax.ShapeDtypeStruct((), jnp.int32),
                ),
                layout.indptr,
                layout.indices,
                values,
                b,
                active,
                vmap_method="sequential",
            )

        token, used = [], []

        def sparse(rhs):
            b = ordered(rhs)
            if token:
                sol = jax.pure_callback(
                    hostsparse.resolve,
                    jax.ShapeDtypeStruct(b.shape, b.dtype),
                    token[0],
                    b,
                    vmap_method="sequential",
                )
                sol = unordered(sol)
                return sol, jnp.all(jnp.isfinite(sol))
            sol, ok, t = found = first(shifted(exact), b, jnp.asarray(True))
            fail = jnp.asarray(exact) & ~ok
            sol, ok, t = jax.lax.cond(fail, lambda: first(shifted(False), b, fail), lambda: found)
            used.append(jnp.asarray(exact) & ~fail)
            token.append(t)
            return unordered(sol), ok

        return sparse, used

    def _attempt(self, s: NewtonState, problem: Problem, exact: Array):
        """Step, limit, backtracking and expansion: (u, energy, accepted, full step taken,
        the energy's rounding noise at the start, whether an exact attempt was made (``exact``
        unless ``buckling_ratio`` skipped it), whether the exact Hessian was factored (see
        ``_factor``), whether the step was doubled).

        A step that turns the sheet is taken free of the gauge (see ``free_turn``): its
        infinitesimal rigid motion removed (:func:`rigid_free`), the new positions then moved
        rigidly back into the gauge (:func:`reframe`).

        With ``acceleration`` the step follows the curve ``u + t v + t^2 a / 2`` of geodesic
        acceleration (Transtrum & Sethna 2012): ``v`` the Newton step, ``a`` the correction of
        the residuals' (bar lengths', fold angles') second-order change along ``v``, solved with
        the same factorization. On a stiff sheet a straight step stretches every bar it turns
        (to second order); the curve keeps them nearer their length, so longer steps pass the
        line search. ``a`` is dropped when ``2 |a| / |v| > acceleration``.
        """
        accelerate = self.acceleration > 0
        x = positions(problem, s.u)
        if self.buckling_ratio != float("inf"):
            # far from equilibrium, no exact attempt where compressed bars would buckle the sheet
            softening, support = _vertex_buckling(x, problem.structure, problem.params, s.reference)
            far = s.grad_max > self.buckling_far * s.grad_max0
            exact = exact & ~(far & jnp.any(softening > self.buckling_ratio * support))
        solve, used = self._factor(s, problem, exact, keep=accelerate)
        # gauged again: the Levenberg-Marquardt shift does not commute with the projectors, and
        # the line search below evaluates exactly the positions it keeps
        step, ok = solve(-gauge(problem, s.grad))
        used_exact = used[0]
        step = gauge(problem, step)
        remove_rigid = rigid_fit(x, problem)
        free, spin = remove_rigid(step)
        # only a step that turns the sheet by more than ``free_turn`` is taken free (then
        # reframed): reframing moves every vertex, so near a solution it would only add the
        # rounding of a rotation found from one small triangle
        unpin = spin > self.free_turn
        contact = problem.structure.contact is not None
        if contact:
            # reframing turns each piece on its own, past the contact filter: with contact, a
            # step is taken free only where one rigid motion reframes the whole sheet (where the
            # pairs were gathered moves with it, so each vertex keeps its room)
            unpin = unpin & reframing(x, problem)[1]
        step = jnp.where(ok, jnp.where(unpin, free, step), 0.0)
        if accelerate:
            curve = gauge(problem, self._acceleration(s, problem, x, step, solve))
            curve = jnp.where(unpin, remove_rigid(curve)[0], curve)
            curve = jnp.where(ok, curve, 0.0)
        else:
            curve = jnp.zeros_like(step)
        # limit how far any bar turns or stretches in one step (relative displacement of its
        # ends over its length): rigid motion of far-away paper costs nothing, and no hinge
        # turns by enough to jump branches
        bars = problem.structure.bars

        def turn(t):  # the largest relative displacement of a bar's ends at t
            d = t * step + (0.5 * t * t) * curve
            rel = d[bars[:, 1]] - d[bars[:, 0]]
            return jnp.max(jnp.sqrt(jnp.sum(rel * rel, axis=-1)) / problem.params.rest_length)

        limit = jnp.minimum(1.0, self.max_turn / jnp.maximum(turn(1.0), 1e-300))
        barriers = has_barriers(problem.structure)
        if barriers:
            limit = jnp.minimum(limit, barrier_limit(x, step, problem, s.reference))
            feasible = functools.partial(
                barrier_feasible,
                floor=jnp.minimum(S_MIN, _barrier_distances(x, problem, s.reference)),
                problem=problem,
                reference=s.reference,
            )
        if contact:
            # no vertex moves beyond half the skin, no face through a face (base.contact_limit)
            limit = limit * contact_limit(x, limit * step, problem, s.reference)

        slope = limit * jnp.vdot(s.grad, step)
        ok = ok & (slope < 0)

        def point(alpha):  # positions, free of the gauge (which reframe restores)
            t = alpha * limit
            return x + t * step + (0.5 * t * t) * curve

        def value_at(alpha):
            y = point(alpha)
            value = _energy(y, problem.structure, problem.params, s.reference)
            if barriers:  # a point that takes a barrier into its stiff continuation is refused
                value = jnp.where(feasible(y), value, jnp.inf)
            if contact:
                value = jnp.where(contact_clear(x, y, problem, s.reference), value, jnp.inf)
            return value

        noise = energy_noise(x, problem, s.reference, s.energy)

        def sufficient(alpha, value):
            bound = s.energy + 1e-4 * alpha * slope + noise
            return jnp.isfinite(value) & (value <= bound)

        # halvings from alpha = 1 until the energy falls enough, then, where the full step
        # passed, doublings while the energy falls on: one loop, so the energy (and the barrier
        # and contact checks) is compiled once, not once per phase
        grows = self.expansions > 0

        def cond(c):
            alpha, value, k, grow, more = c
            search = (k < 0) | (ok & ~sufficient(alpha, value) & (k < self.max_linesearch_steps))
            return jnp.where(grow, more, search)

        def body(c):
            alpha, value, k, grow, more = c
            t = jnp.where(grow, 2 * alpha, jnp.where(k < 0, 1.0, 0.5 * alpha))
            trial = value_at(t)
            # a doubling past the turn limit is not taken
            trial = jnp.where(grow & ~(turn(t) <= self.max_turn), jnp.inf, trial)
            better = trial < value - noise
            keep = grow & ~better
            alpha, value = jnp.where(keep, alpha, t), jnp.where(keep, value, trial)
            # the full step passed: doublings from here (k counts halvings, then doublings)
            start = ~grow & ok & sufficient(t, trial) & (t == 1) & (limit == 1) & grows
            k = jnp.where(start, 0, k + 1)
            more = jnp.where(grow, better & (k < self.expansions), start)
            return alpha, value, k, grow | start, more

        one = jnp.ones((), s.u.dtype)
        state = (one, jnp.full_like(s.energy, jnp.inf), -1, False, False)
        alpha, value, _, full, _ = jax.lax.while_loop(cond, body, state)
        # a doubled step's energy fell below the full step's, which passed
        accepted = ok & (full | sufficient(alpha, value))
        if not grows:
            full = accepted & (alpha == 1) & (limit == 1)
        end = point(alpha)
        move, _ = reframing(end, problem)
        u = jnp.where(unpin, move(end), end) - problem.start
        reference = s.reference
        if contact and reference.pairs is not None:
            built = reference.pairs.x_built
            pairs = replace(reference.pairs, x_built=jnp.where(unpin, move(built), built))
            reference = reference._replace(pairs=pairs)
        return u, value, accepted, full, noise, exact, used_exact, alpha > 1, reference

    def _acceleration(self, s: NewtonState, problem: Problem, x, velocity: Array, solve) -> Array:
        """``a = -H^-1 J^T W r''[v, v]`` at positions ``x`` (zero when too large or not
        finite)."""
        pull = _second_order_pull(x, velocity, problem.structure, problem.params, s.reference)
        curve, ok = solve(-gauge(problem, pull))
        small = 2 * jnp.linalg.norm(curve) <= self.acceleration * jnp.linalg.norm(velocity)
        return jnp.where(ok & small, curve, 0.0)

    def step(self, s: NewtonState, problem: Problem) -> NewtonState:
        """One Newton iteration (pure)."""
        # one step tried per iteration: a rejected exact attempt costs the iteration and the
        # next one is convex (but on the host an exact Hessian that does not factor hands over
        # within it: see ``_factor``)
        u, value, accepted, full, noise, tried, used_exact, expanded, moved = self._attempt(
            s, problem, s.exact
        )
        exact_ran = tried & used_exact
        retry = exact_ran & ~accepted  # rejected, and no convex step tried yet
        rejected = retry | (tried & ~used_exact)
        new_value, grad, gmax = _value_and_grad(u, problem, s.reference)
        finite = accepted & jnp.isfinite(new_value) & jnp.isfinite(gmax)
        take = finite
        stalls = jnp.where(take, 0, jnp.where(retry, s.stalls, s.stalls + 1))
        # after the n-th rejected exact attempt in a row, wait for 2^n - 1 full convex steps (at
        # most 15) before the next
        failures = jnp.where(rejected, s.failures + 1, jnp.where(take & exact_ran, 0, s.failures))
        cooldown = jnp.where(rejected, 2 ** jnp.minimum(failures, 4) - 1, s.cooldown)
        cooldown = jnp.where(take & full, jnp.maximum(cooldown - 1, 0), cooldown)
        progress = s.progress.update(take, gmax, new_value, noise)
        floor = 0.0
        if has_barriers(problem.structure):  # folded flat, held by barriers: their rounding
            floor = element_floor(positions(problem, u), problem, s.reference)
        converged = take & has_converged(gmax, s.grad_max0, problem, s.grad_max, floor)
        stalled = (stalls >= self.max_stalls) | (progress.since_best >= self.patience)
        nonfinite = accepted & ~finite
        status = next_status(converged, ~nonfinite, stalled)
        # a step (exact or convex) that cut the energy below ``convex_rate`` of its value: near a
        # zero-residual solution, where the convex part converges as fast without the curvature
        # terms, so the next iteration is convex
        fast = new_value < self.convex_rate * s.energy
        keep = lambda new, old: jnp.where(take, new, old)  # noqa: E731
        u = keep(u, s.u)
        reference = jax.tree.map(
            keep,
            _update_reference(
                positions(problem, u), problem.structure, moved, contact_skin(problem)
            ),
            s.reference,
        )
        status = with_overflow(status, reference)
        # exact attempts are shifted once ``shift_after`` of them in a row have failed: 10x more
        # with each further failure, 10x less with each exact step taken
        # (to 0 once below a thousandth of ``shift_min``)
        lower = jnp.where(s.shift > 1e-3 * self.shift_min, 0.1 * s.shift, 0.0)
        shift = jnp.where(
            rejected & (failures >= self.shift_after),
            jnp.minimum(jnp.maximum(10.0 * s.shift, self.shift_min), 1e10),  # as ``mu``
            jnp.where(take & exact_ran, lower, s.shift),
        ).astype(s.shift.dtype)
        mu = jnp.where(
            take,
            jnp.maximum(self.mu_min, 0.1 * s.mu),
            jnp.where(retry, s.mu, jnp.minimum(10.0 * jnp.maximum(s.mu, 1e-10), 1e10)),
        ).astype(s.mu.dtype)
        return NewtonState(
            u=u,
            grad=keep(grad, s.grad),
            reference=reference,
            iteration=s.iteration + 1,
            energy=keep(new_value, s.energy),
            grad_max=keep(gmax, s.grad_max),
            grad_max0=s.grad_max0,
            status=status,
            mu=mu,
            # an exact attempt after an exact step taken, or after a full convex step that was
            # not doubled (a doubled one: far from the quadratic region)
            exact=take & ~fast & (exact_ran | (full & ~expanded & (cooldown == 0))),
            stalls=stalls,
            failures=failures.astype(s.failures.dtype),
            cooldown=cooldown.astype(s.cooldown.dtype),
            shift=shift,
            progress=progress,
        )

    # -- fold_batch: every member solves dense ----------------------------------------------
    def host_callbacks(self, problem: Problem) -> bool:
        """Sparse solves factor on the host (:mod:`~origami_jax.solvers.hostsparse`)."""
        return isinstance(problem.aux, HessianLayout) and problem.aux.sparse

    def cost_by_vertices(self) -> bool:
        """A padded (dense) solve's cost is its Cholesky factorization's: the vertex count's."""
        return True

    def prepare_batch(self, problem: Problem, mesh: Mesh) -> Problem:
        """The dense Hessian layout of the (padded) problem's own elements."""
        elements = [np.asarray(e) for e in hessian_elements(problem.structure)]
        return replace(problem, aux=layout_arrays(elements, problem.start.shape[0], None))

    def shared_aux(self, problem: Problem, mesh: Mesh) -> HessianLayout:
        """The dense layout of one topology with the block plan that factors all its members
        at once (:mod:`~origami_jax.solvers.blocksparse`)."""
        elements = [np.asarray(e) for e in hessian_elements(problem.structure)]
        v = problem.start.shape[0]
        return replace(layout_arrays(elements, v, None), plan=blocksparse.block_plan(elements, v))

    def check_batch(self, num_vertices: int) -> None:
        if self.linear_solver == "sparse":
            raise ValueError("fold_batch(): batched Newton solves dense; use linear_solver='auto'")
        if num_vertices > BATCH_DENSE_MAX:
            raise ValueError(
                f"fold_batch(): a problem of {num_vertices} (padded) vertices is too large for "
                f"batched dense Newton (<= {BATCH_DENSE_MAX}); use fold() or solver='lbfgs'"
            )

    def batch_bytes(self, num_vertices: int) -> int:
        """The slot's dense (3V x 3V) matrix."""
        return (3 * num_vertices) ** 2 * 8


# the largest padded vertex count that fold_batch's Newton solves (dense)
BATCH_DENSE_MAX = 512
