"""Inverse design: the folded state as a differentiable function of the fold parameters.

:func:`equilibrium_fn` closes over a pattern and returns ``solve(params, start=None) ->
(positions, info)``: the equilibrium ``x*(p)`` of the bar-and-hinge energy for the parameters
``p`` (a :class:`~origami_jax.energy.FoldParams`: targets, percent, rest lengths, stiffnesses).
The forward pass runs the Newton solver (pure, inside ``jit``); derivatives come from the
**implicit function theorem** at the equilibrium, not from the solver's iterations. With
``u`` the gauged displacement (``x = start + gauge(u)``, rigid motions pinned) the equilibrium
is ``F(u, p) = dE/du = 0``, so

    du*/dp = -H^-1 dF/dp,    H = d^2E/du^2 (+ identity on the pinned directions),

one solve with the Hessian per tangent (forward mode) or per cotangent (reverse mode). ``H`` is
assembled from the solver's exact element Hessians and Cholesky-factored once, in the forward
pass (dense, for patterns up to the Newton solver's ``dense_max`` vertices), or, sparse,
checked by SuperLU's pivots and solved by the host backend of
:mod:`origami_jax.solvers.hostsparse` (PARDISO, CHOLMOD or SuperLU). The factorization also
tells whether the equilibrium is stable (``H`` positive definite): when it is not, or the
solve has not converged, **every derivative is NaN** and ``info`` says why: never a silent
wrong gradient.

On top of it: residual builders for design goals (:func:`target_positions`,
:func:`target_shape`, :func:`target_height`, :func:`target_span`, :func:`target_surface`) and a
loop, :func:`design`, that optimises crease targets with an optax optimizer or with
Levenberg-Marquardt (Gauss-Newton) steps, warm-starting each solve from the last equilibrium.

Example:
  >>> import jax, jax.numpy as jnp
  >>> from origami_jax import patterns
  >>> from origami_jax.design import equilibrium_fn, make_params
  >>> cp = patterns.miura_ori(2, 2, fold_angle=1.0)
  >>> solve = equilibrium_fn(cp)
  >>> params = make_params(cp)
  >>> x, info = jax.jit(solve)(params)
  >>> bool(info.ok), x.shape
  (True, (9, 3))
  >>> g = jax.grad(lambda p: solve(p)[0][:, 2].sum())(params)
  >>> g.target.shape, bool(jnp.all(jnp.isfinite(g.target)))
  ((4,), True)
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.tree_util import Partial

from origami_jax.energy import (
    Barriers,
    ContactParams,
    FoldParams,
    Reference,
    make_params,
    make_structure,
)
from origami_jax.fold import checked_start, contact_reach, default_tol, with_contact
from origami_jax.pattern import CreasePattern
from origami_jax.solvers import Solver, Status, get_solver, hostsparse
from origami_jax.solvers.assembly import gauged_hessian
from origami_jax.solvers.base import (
    Problem,
    default_max_step,
    objective,
    pin_axes,
    pin_projectors,
    positions,
    prepare,
    rigid_gauge,
)
from origami_jax.solvers.hessian_layout import HessianLayout
from origami_jax.solvers.newton import Newton

__all__ = [
    "Equilibrium",
    "EquilibriumInfo",
    "equilibrium_fn",
    "make_params",
    "target_positions",
    "target_shape",
    "target_height",
    "target_span",
    "target_distance",
    "target_surface",
    "kabsch",
    "not_ok_reason",
    "DesignResult",
    "design",
]


class EquilibriumInfo(NamedTuple):
    """How a solve of :func:`equilibrium_fn` ended (scalars, or (B,) under ``vmap``).

    Attributes:
      converged: the solver reached ``grad_norm_rel <= tol``.
      status: the solver's :class:`~origami_jax.solvers.Status` code (int).
      iterations: solver iterations taken.
      grad_norm_rel: max-abs gradient of the energy at the result over its value on the flat
        sheet (the force scale of the targets), as in :func:`origami_jax.fold`.
      energy: energy at the result.
      stable: the gauged Hessian is positive definite there (a strict local minimum), so the
        implicit derivative exists.
      pivot_rel: smallest over largest pivot of the Hessian's factorization (about the
        reciprocal condition number; tiny means nearly singular, derivatives inaccurate).

    ``ok = converged & stable``; derivatives through a solve that is not ``ok`` are NaN.
    """

    converged: Array
    status: Array
    iterations: Array
    grad_norm_rel: Array
    energy: Array
    stable: Array
    pivot_rel: Array

    @property
    def ok(self) -> Array:
        return self.converged & self.stable


# -- the equilibrium and its implicit derivative --------------------------------------------------


def _hessian_values(problem: Problem, u: Array, reference: Reference) -> Array:
    """Storage values of the gauged exact Hessian d^2E/du^2 in the solver's layout, with a
    stiffness-sized identity on the pinned (gauged-out) directions."""
    return gauged_hessian(positions(problem, u), problem, reference, True)


def _host_factor_check(indptr, indices, data):
    """Sparse LU without pivoting of the symmetric matrix (``U``'s diagonal is ``D`` of
    ``L D L^T``): (positive definite, smallest over largest |pivot|); never raises."""
    found = hostsparse.superlu(indptr, indices, data)
    d = None if found is None else found[1]
    ok = d is not None and bool(np.all(np.isfinite(d)) and np.all(d > 0))
    rel = float(np.min(np.abs(d)) / np.max(np.abs(d))) if ok else 0.0
    return np.asarray(ok), np.asarray(rel, data.dtype)


def _factorize(problem: Problem, values: Array) -> tuple[Array, Array, Array]:
    """(factor, stable, pivot_rel): the Cholesky factor (dense) or the values (sparse)."""
    layout: HessianLayout = problem.aux
    eps = jnp.finfo(values.dtype).eps
    if layout.sparse:
        stable, rel = jax.pure_callback(
            _host_factor_check,
            (
                jax.ShapeDtypeStruct((), jnp.bool_),
                jax.ShapeDtypeStruct((), values.dtype),
            ),
            layout.indptr,
            layout.indices,
            values,
            vmap_method="sequential",
        )
        return values, stable & (rel > eps), rel
    n = layout.size
    chol = jnp.linalg.cholesky(values.reshape(n, n))
    d = jnp.diagonal(chol)
    finite = jnp.all(jnp.isfinite(chol))
    rel = jnp.where(finite, (jnp.min(d) / jnp.max(d)) ** 2, 0.0)
    return chol, finite & (rel > eps), rel


def _linear_solve(problem: Problem, factor: Array, rhs: Array) -> Array:
    """``H^-1 rhs`` for a (V, 3) right-hand side, with the factor of :func:`_factorize`."""
    layout: HessianLayout = problem.aux
    b = jnp.zeros(layout.size, rhs.dtype).at[layout.order].set(rhs.reshape(-1))
    if layout.sparse:
        sol, _ = jax.pure_callback(
            hostsparse.solve,
            (jax.ShapeDtypeStruct(b.shape, b.dtype), jax.ShapeDtypeStruct((), jnp.bool_)),
            layout.indptr,
            layout.indices,
            factor,
            b,
            vmap_method="sequential",
        )
    else:
        sol = jax.scipy.linalg.cho_solve((factor, True), b)
    return sol[layout.order].reshape(rhs.shape)


@jax.custom_jvp
def _implicit(
    params: FoldParams, u: Array, reference: Reference, factor: Array, scale: Array, problem
):
    """Positions ``start + gauge(u)`` of the equilibrium ``u`` of ``params`` (primal: no work).

    Its JVP is the implicit derivative; ``scale`` (1, or NaN when the solve is not usable)
    multiplies every tangent. Only ``params`` is differentiated: the other inputs come from the
    forward solve and are constants to it."""
    return positions(problem, u)


@_implicit.defjvp
def _implicit_jvp(primals, tangents):
    params, u, reference, factor, scale, problem = primals
    params_dot = tangents[0]
    problem = replace(problem, params=params)

    def residual(p):  # F(u*, p) = dE/du
        return jax.grad(objective)(u, replace(problem, params=p), reference)

    _, f_dot = jax.jvp(residual, (params,), (params_dot,))

    # the gauge as an explicit linear map (its scatter form has no transpose)
    v = u.shape[0]
    proj = jnp.broadcast_to(jnp.eye(3, dtype=u.dtype), (v, 3, 3))
    proj = proj.at[problem.pinned].set(problem.projectors)

    def project(w):
        return jnp.einsum("vij,vj->vi", proj, w)

    def matvec(w):  # H w, by forward-over-reverse (used only to differentiate the solve)
        hw = jax.jvp(lambda y: jax.grad(objective)(y, problem, reference), (u,), (w,))[1]
        return hw + w - project(w)

    def solve(_, b):
        return _linear_solve(problem, factor, b)

    layout: HessianLayout = problem.aux
    if layout.sparse and problem.structure.contact is not None:
        # the sparse factor holds each contact pair's curvature on its corners' diagonal blocks
        # only (the sheet's sparsity): a preconditioner, refined to the exact Hessian by CG
        solve = functools.partial(_refined_solve, matvec, solve)
    u_dot = jax.lax.custom_linear_solve(matvec, -f_dot, solve, symmetric=True)
    return positions(problem, u), project(u_dot) * scale


#: relative residual to which the implicit derivative's conjugate gradients solve (sparse
#: layouts with contact), and their most iterations
CG_TOL = 1e-12
CG_MAX_ITER = 200


def _refined_solve(matvec: Callable, precondition: Callable, _, b: Array) -> Array:
    """``H^-1 b`` by conjugate gradients on the exact ``matvec``, preconditioned by the factored
    approximation; NaN where they do not reach :data:`CG_TOL` (never a silent wrong
    derivative)."""
    tol = jnp.maximum(CG_TOL, 100 * jnp.finfo(b.dtype).eps)
    sol, _ = jax.scipy.sparse.linalg.cg(
        matvec, b, M=lambda r: precondition(None, r), tol=tol, maxiter=CG_MAX_ITER
    )
    res = jnp.max(jnp.abs(b - matvec(sol)))
    ok = res <= 10 * tol * jnp.maximum(jnp.max(jnp.abs(b)), jnp.finfo(b.dtype).tiny)
    return jnp.where(ok, sol, jnp.nan)


def _projectors(start: Array, triangles: Array) -> Array:
    """(3 P, 3, 3) gauge projectors of :func:`~origami_jax.solvers.base.rigid_gauge`, computed
    in JAX from ``start`` (differentiable, unlike the host-side gauge)."""
    d, n = pin_axes(*(start[triangles[:, k]] for k in range(3)))
    return jnp.stack(pin_projectors(d, n), axis=1).reshape(-1, 3, 3)


def equilibrium_fn(
    pattern: CreasePattern,
    solver: str | Solver = "newton",
    tol: float | None = None,
    max_iter: int = 500,
    strict: bool = True,
    barriers: Barriers | bool | None = None,
    contact: bool | float = False,
) -> Equilibrium:
    """A differentiable equilibrium of ``pattern``: ``solve(params, start=None)``.

    ``solve`` is pure and traceable: ``jit``, ``vmap`` (a batch of parameters or starts),
    ``grad``/``vjp`` and ``jvp``/``jacfwd`` all work on it. Its derivatives are implicit (one
    Hessian solve per tangent or cotangent, the factorization shared with the forward pass); the
    derivative with respect to ``start`` is taken as zero (the equilibrium does not depend on
    where the solve starts, as long as it reaches the same one).

    Args:
      pattern: the crease pattern; its triangulated mesh fixes the shapes.
      solver: a solver name or object (``"newton"``: its layout picks the dense Cholesky or the
        sparse host solve of the Hessian, ``dense_max`` vertices).
      tol: ``grad_norm_rel`` at which a solve has converged (relative to the flat sheet's
        gradient, whatever the start); default 1e-10 in float64, 1e-4 in float32. Derivatives
        are about as accurate as this.
      max_iter: iteration limit of one solve.
      strict: make derivatives NaN when the solve is not ``info.ok`` (default). ``False`` keeps
        them (flagged by ``info`` only): the implicit derivative at a non-equilibrium.
      barriers: as in :func:`~origami_jax.fold` (default: where the scene needs them); the
        derivatives include theirs. The solve is direct (from ``start``): warm starts follow
        a design's path.
      contact: self-contact, as in :func:`~origami_jax.fold` (``True``: the default reach
        ``dhat``; a number: that ``dhat``); its barrier is in the energy and in the
        derivatives, over candidate pairs gathered at the start of each solve (their capacity
        fixed here: a solve whose pairs outgrow it ends with status ``CONTACT_OVERFLOW``, not
        ``ok``). Parameters whose ``contact`` is ``None`` take the barrier's reach and weight
        fixed here (:attr:`Equilibrium.contact`).

    Returns:
      An :class:`Equilibrium` ``solve``, called as ``solve(params, start=None) -> (positions,
      info)``; a pytree, so a jitted function that takes it as an argument compiles once for
      all patterns of its shapes. ``params`` a
      :class:`~origami_jax.energy.FoldParams` (see :func:`make_params`; its dtype is the
      solve's), ``start`` (V, 3) positions to start from (a warm start, e.g. the last
      equilibrium; default the pattern's start or the flat sheet), ``positions`` (V, 3) the
      equilibrium (mesh vertices: the pattern's first), ``info`` an :class:`EquilibriumInfo`.

    Example:
      >>> import jax
      >>> from origami_jax import patterns
      >>> from origami_jax.design import equilibrium_fn, make_params
      >>> cp = patterns.single_crease(fold_angle=1.0)
      >>> solve = equilibrium_fn(cp)
      >>> x, info = solve(make_params(cp))
      >>> bool(info.converged), x.shape
      (True, (6, 3))
    """
    solver_obj = get_solver(solver)
    mesh = pattern.mesh
    structure = make_structure(mesh, barriers)
    start = checked_start(pattern, None)  # the pattern's pre-folded start, else flat
    default_start = mesh.vertices if start is None else start
    contact_params = None
    if contact is not False:
        dhat = contact_reach(contact, solver_obj)
        structure, with_params = with_contact(
            mesh, structure, make_params(pattern), dhat, default_start
        )
        contact_params = with_params.contact
    pinned, _ = rigid_gauge(mesh, default_start)
    # the solver's host-side data (Newton: the Hessian layout), built once
    probe = Problem(
        structure=structure,
        params=None,
        start=jnp.asarray(mesh.vertices),
        pinned=jnp.asarray(pinned),
        projectors=None,
        tol=None,
        max_step=None,
    )
    solver_aux = prepare(solver_obj, probe, mesh).aux
    # the implicit derivative factors the Hessian in Newton's layout, whatever the solver
    layout = None if isinstance(solver_aux, HessianLayout) else Newton().prepare(probe, mesh).aux
    return Equilibrium(
        structure=structure,
        flat=jnp.asarray(mesh.vertices),
        default_start=jnp.asarray(default_start),
        pinned=jnp.asarray(pinned),
        triangles=jnp.asarray(pinned.reshape(-1, 3)),
        max_step=jnp.asarray(default_max_step(mesh)),
        solver_aux=solver_aux,
        layout=layout,
        contact=contact_params,
        solver=solver_obj,
        tol=tol,
        max_iter=int(max_iter),
        strict=bool(strict),
    )


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=[
        "structure",
        "flat",
        "default_start",
        "pinned",
        "triangles",
        "max_step",
        "solver_aux",
        "layout",
        "contact",
    ],
    meta_fields=["solver", "tol", "max_iter", "strict"],
)
@dataclass(frozen=True, eq=False)  # hashed by identity: ``jax.jit(solve)`` keys on it
class Equilibrium:
    """The ``solve(params, start=None)`` of :func:`equilibrium_fn`: a pytree whose leaves are
    the pattern's arrays and whose static part is the solver and its options.

    Passed as an argument to a jitted function (as :func:`design` does), it compiles once per
    solver, options and array shapes: calls on the same pattern, or on another of the same
    shapes, reuse the compiled code.
    """

    structure: Any
    flat: Array
    default_start: Array
    pinned: Array
    triangles: Array  # (pieces, 3) the pinned triangle (a, b, c) of each piece
    max_step: Array
    solver_aux: Any
    layout: Any  # Newton's Hessian layout where the solver's own aux is not one, else None
    contact: ContactParams | None  # the barrier's reach and weight for params without them
    solver: Solver
    tol: float | None
    max_iter: int
    strict: bool

    def _problem(self, params: FoldParams, start: Array) -> Problem:
        dtype = params.rest_length.dtype
        start = jnp.asarray(start, dtype)
        return Problem(
            structure=self.structure,
            params=params,
            start=start,
            pinned=self.pinned,
            projectors=_projectors(start, self.triangles),
            tol=jnp.asarray(1.0, dtype),
            max_step=self.max_step.astype(dtype),
            aux=self.solver_aux if self.layout is None else self.layout,
        )

    def __call__(
        self, params: FoldParams, start: Array | None = None
    ) -> tuple[Array, EquilibriumInfo]:
        dtype = params.rest_length.dtype
        tol = default_tol(dtype) if self.tol is None else self.tol
        if self.contact is not None and params.contact is None:
            params = params._replace(contact=jax.tree.map(lambda a: a.astype(dtype), self.contact))
        fixed = jax.lax.stop_gradient(params)
        start = self.default_start if start is None else jax.lax.stop_gradient(start)
        # the force scale: the energy's gradient on the flat sheet (fold()'s grad_max0)
        flat = self._problem(fixed, self.flat)
        g_flat = jnp.max(jnp.abs(jax.grad(objective)(jnp.zeros_like(flat.start), flat, None)))
        g_flat = jnp.where(g_flat > 0, g_flat, 1.0)
        problem = self._problem(fixed, start)
        # the solver's own host data, in this dtype (Newton: the same layout)
        problem_solver = replace(
            problem,
            aux=jax.tree.map(
                lambda a: a.astype(dtype) if jnp.issubdtype(a.dtype, jnp.floating) else a,
                self.solver_aux,
            ),
        )
        state = self.solver.init(problem_solver)
        # the solver's tolerance is relative to its start's gradient: rescale to the flat one
        g0 = jnp.where(state.grad_max0 > 0, state.grad_max0, 1.0)
        problem_solver = replace(problem_solver, tol=jnp.asarray(tol * g_flat / g0, dtype))
        done = state.grad_max0 <= tol * g_flat
        state = state._replace(
            status=jnp.where(done, Status.CONVERGED, state.status).astype(jnp.int32)
        )
        state = self.solver.run(state, problem_solver, jnp.int32(self.max_iter))
        values = _hessian_values(problem, state.u, state.reference)
        factor, stable, rel = _factorize(problem, values)
        grad_rel = state.grad_max / g_flat
        converged = (state.status == Status.CONVERGED) | (grad_rel <= tol)
        info = EquilibriumInfo(
            converged=converged,
            status=state.status,
            iterations=state.iteration,
            grad_norm_rel=grad_rel,
            energy=state.energy,
            stable=stable,
            pivot_rel=rel,
        )
        ok = converged & stable if self.strict else jnp.ones((), bool)
        scale = jnp.where(ok, 1.0, jnp.nan).astype(dtype)
        x = _implicit(params, state.u, state.reference, factor, scale, problem)
        return x, info


# -- design goals: residuals of positions, loss = 1/2 sum r^2 ----------------------------------


def kabsch(x: Array, target: Array, weights: Array | None = None) -> Array:
    """``x`` (N, 3) moved by the proper rigid motion that best fits ``target`` (N, 3) in the
    (weighted) least-squares sense; differentiable (SVD) where the fit is unique."""
    w = jnp.ones(x.shape[0], x.dtype) if weights is None else jnp.asarray(weights, x.dtype)
    w = w / jnp.sum(w)
    cx = jnp.sum(w[:, None] * x, axis=0)
    ct = jnp.sum(w[:, None] * target, axis=0)
    h = ((x - cx) * w[:, None]).T @ (target - ct)
    # 3 x 3: reduced is full; jax before 0.8.1 differentiates only the reduced SVD
    u, _, vt = jnp.linalg.svd(h, full_matrices=False)
    d = jnp.sign(jnp.linalg.det(vt.T @ u.T))
    rot = vt.T @ jnp.diag(jnp.array([1.0, 1.0, 1.0], x.dtype).at[2].set(d)) @ u.T
    return (x - cx) @ rot.T + ct


def _positions_residual(target: Array, weights: Array | None, x: Array) -> Array:
    w = 1.0 if weights is None else jnp.sqrt(weights.astype(x.dtype))[:, None]
    return (w * (x - target.astype(x.dtype))).reshape(-1)


def target_positions(target, weights=None) -> Callable[[Array], Array]:
    """Residual ``sqrt(w) (x - target)`` (3 N,): reach given vertex positions, in the solve's
    frame (its pinned triangle). ``target`` (V, 3); ``weights`` (V,), 0 ignores a vertex.

    Like every ``target_*`` goal, a :class:`jax.tree_util.Partial`: its data are pytree
    leaves, so :func:`design` compiles once for all goals of one kind and shape."""
    weights = None if weights is None else jnp.asarray(weights)
    return Partial(_positions_residual, jnp.asarray(target), weights)


def _shape_residual(target: Array, weights: Array | None, x: Array) -> Array:
    t = target.astype(x.dtype)
    aligned = kabsch(x, t, weights)
    w = 1.0 if weights is None else jnp.sqrt(weights.astype(x.dtype))[:, None]
    return (w * (aligned - t)).reshape(-1)


def target_shape(target, weights=None) -> Callable[[Array], Array]:
    """Residual of :func:`target_positions` after the best rigid alignment (Kabsch) of ``x`` to
    ``target`` (V, 3): a shape up to rigid motion."""
    weights = None if weights is None else jnp.asarray(weights)
    return Partial(_shape_residual, jnp.asarray(target), weights)


def _height_residual(height: Array, axis: Array, x: Array) -> Array:
    z = jnp.take(x, axis, axis=1)
    return (jnp.max(z) - jnp.min(z) - jnp.asarray(height, x.dtype))[None]


def target_height(height: float, axis: int = 2) -> Callable[[Array], Array]:
    """Residual (1,): extent of the vertices along ``axis`` (default z) minus ``height``.

    Measured in the solve's frame, where the pinned facet keeps its place (see
    :func:`target_distance` for a measure independent of rigid motion)."""
    return Partial(_height_residual, jnp.asarray(height), jnp.asarray(axis, jnp.int32))


def _span_residual(span: Array, axes: Array, x: Array) -> Array:
    p = jnp.take(x, axes, axis=1)
    return jnp.max(p, axis=0) - jnp.min(p, axis=0) - jnp.asarray(span, x.dtype)


def target_span(span, axes=(0, 1)) -> Callable[[Array], Array]:
    """Residual (len(axes),): bounding-box extents along ``axes`` minus ``span`` (a scalar or
    one value per axis), in the solve's frame (the pinned facet keeps its place)."""
    axes = np.atleast_1d(np.asarray(axes, np.int32))
    return Partial(_span_residual, jnp.asarray(span), jnp.asarray(axes))


def _distance_residual(pairs: Array, distance: Array, x: Array) -> Array:
    d = x[pairs[:, 1]] - x[pairs[:, 0]]
    return jnp.sqrt(jnp.sum(d * d, axis=-1)) - jnp.asarray(distance, x.dtype)


def target_distance(pairs, distance) -> Callable[[Array], Array]:
    """Residual (P,): distances between vertex ``pairs`` (P, 2) minus ``distance`` (scalar or
    (P,)): a span measured between chosen vertices, independent of rigid motion."""
    pairs = np.atleast_2d(np.asarray(pairs, np.int32))
    return Partial(_distance_residual, jnp.asarray(pairs), jnp.asarray(distance))


def target_surface(
    surface: Callable[[Array], Array],
    kind: str = "height",
    free_offset: bool = True,
    weights=None,
) -> Callable[[Array], Array]:
    """Residual (V,): how far each vertex is from a surface, times ``sqrt(weights)``.

    ``kind="height"``: ``surface(xy)`` (N, 2) -> (N,) heights, residual ``z - f(x, y)``;
    ``kind="sdf"``: ``surface(x)`` (N, 3) -> (N,) signed distances, the residual itself.
    ``free_offset`` (heights only) removes the (weighted) mean residual: the sheet may sit at
    any height. ``weights`` (V,): 0 leaves a vertex free (e.g. fit only the outer corners of
    a corrugated tessellation, its envelope).
    """
    if kind not in ("height", "sdf"):
        raise ValueError(f"kind must be 'height' or 'sdf', got {kind!r}")

    # the surface is the user's function: this goal compiles anew for each one
    def residual(x: Array) -> Array:
        w = jnp.ones(x.shape[0], x.dtype) if weights is None else jnp.asarray(weights, x.dtype)
        if kind == "sdf":
            r = surface(x)
        else:
            r = x[:, 2] - surface(x[:, :2])
            if free_offset:
                r = r - jnp.sum(w * r) / jnp.sum(w)
        return jnp.sqrt(w) * r

    return Partial(residual)


# -- the design loop -----------------------------------------------------------------------------


class DesignResult(NamedTuple):
    """What :func:`design` found.

    Attributes:
      variables: final design variables (the free crease targets by default, radians).
      params: the :class:`~origami_jax.energy.FoldParams` they map to.
      positions: (V, 3) equilibrium for them.
      loss: final loss.
      info: :class:`EquilibriumInfo` of the final solve.
      history: ``{"loss": (n,), "grad_norm": (n,)}`` per accepted step (numpy), first the
        start.
      steps: steps taken.
      reason: why the loop stopped.
    """

    variables: Array
    params: FoldParams
    positions: Array
    loss: float
    info: EquilibriumInfo
    history: dict
    steps: int
    reason: str


def not_ok_reason(info: EquilibriumInfo, tol: float | None = None) -> str:
    """Why a solve of :func:`equilibrium_fn` is not ``ok``, in words (``tol``: the solve's
    tolerance, default that of the dtype): how the solver stopped, or the instability."""
    if not bool(info.converged):
        dtype = jnp.asarray(info.grad_norm_rel).dtype
        status = Status(int(info.status))
        why = status.describe(
            float(info.grad_norm_rel),
            default_tol(dtype) if tol is None else tol,
            int(info.iterations),
        )
        return f"equilibrium not ok: {why}"
    return (
        "equilibrium not ok: unstable, the Hessian there is not positive definite (smallest "
        f"over largest pivot {float(info.pivot_rel):.1e}): no derivative; another start or "
        "other parameters may reach a stable state"
    )


def _loss(residual: Array) -> Array:
    """A scalar objective as it is, a vector of residuals as ``1/2 sum r^2``."""
    return residual if jnp.ndim(residual) == 0 else 0.5 * jnp.sum(residual * residual)


def _as_tree(fn: Callable) -> Partial:
    """``fn`` as a pytree argument of the jitted steps: a :class:`~jax.tree_util.Partial`
    keeps its data as leaves; any other callable is static (compiled once per object)."""
    return fn if isinstance(fn, Partial) else Partial(fn)


def _free_targets(free: Array, z: Array, p: FoldParams) -> FoldParams:
    """The default ``to_params``: ``z`` are the targets of the creases marked ``free``."""
    return p._replace(target=jnp.where(free, z, p.target))


@jax.jit
def _value_and_grad(solve, objective, to_params, base, z, start, free_mask):
    """(loss, its gradient on the free variables, positions, info) at ``z`` (compiled once per
    solver, goal kind and shapes: every argument is a pytree)."""

    def f(z):
        x, info = solve(to_params(z, base), start)
        return _loss(objective(x)), (x, info)

    (value, (x, info)), g = jax.value_and_grad(f, has_aux=True)(z)
    return value, jnp.where(free_mask, g, 0.0), x, info


@jax.jit
def _residual_jacobian(solve, objective, to_params, base, z, start, free_mask):
    """(residuals, their Jacobian on the free variables by forward mode, positions, info)."""

    def r(z):
        x, info = solve(to_params(z, base), start)
        res = objective(x)
        return res, (res, x, info)

    jac, (res, x, info) = jax.jacfwd(r, has_aux=True)(z)
    return res, jnp.where(free_mask[None, :], jac, 0.0), x, info


def design(
    pattern: CreasePattern,
    objective: Callable[[Array], Array],
    init: Array | None = None,
    *,
    params: FoldParams | None = None,
    to_params: Callable[[Array, FoldParams], FoldParams] | None = None,
    optimizer: Any = "gauss_newton",
    steps: int = 100,
    fixed: Array | None = None,
    clip: bool = True,
    tol: float | None = None,
    gtol: float = 0.0,
    xtol: float = 0.0,
    ftol: float = 0.0,
    solver: str | Solver = "newton",
    max_iter: int = 500,
    contact: bool | float = False,
) -> DesignResult:
    """Optimise a pattern's crease targets (or any parametrisation) for a goal on the folded
    state; each solve warm-starts from the last equilibrium.

    Args:
      pattern: the crease pattern.
      objective: ``objective(x)`` of positions (V, 3): a scalar loss, or a vector of residuals
        (loss ``1/2 sum r^2``, needed by ``"gauss_newton"``), e.g. :func:`target_positions`.
      init: start variables (default: the pattern's targets of the free creases, radians).
      params: base parameters (default :func:`make_params` of ``pattern``, JAX's float).
      to_params: ``to_params(z, params) -> FoldParams`` maps variables ``z`` to parameters
        (default: ``z`` are the targets of the creases not in ``fixed``); then ``fixed`` and
        ``clip`` apply to ``z`` directly.
      optimizer: an ``optax.GradientTransformation`` (e.g. ``optax.adam(1e-2)``), or
        ``"gauss_newton"``: Levenberg-Marquardt steps on the residuals, the Jacobian by
        forward-mode implicit derivatives (converges fast on zero-residual goals).
      steps: most optimiser steps.
      fixed: (n,) bool mask of variables held fixed (by default of the driven creases).
      clip: keep the variables in [-pi, pi].
      tol: equilibrium tolerance (see :func:`equilibrium_fn`).
      gtol: stop once the gradient's max-abs is below this.
      xtol: stop once a step moves no variable by more than this (Gauss-Newton).
      ftol: stop once the loss is at or below this.
      solver, max_iter, contact: as for :func:`equilibrium_fn`.

    Returns:
      A :class:`DesignResult`. The loop stops early (and says why) when a solve is not ``ok``.

    Example:
      >>> import optax
      >>> from origami_jax import patterns
      >>> from origami_jax.design import design, target_height
      >>> cp = patterns.miura_ori(2, 2, fold_angle=1.0)
      >>> r = design(cp, target_height(0.5), steps=20)
      >>> r.loss < 1e-8
      True
    """
    solve = equilibrium_fn(pattern, solver=solver, tol=tol, max_iter=max_iter, contact=contact)
    base = make_params(pattern) if params is None else params
    dtype = base.rest_length.dtype
    objective = _as_tree(objective)
    if to_params is None:
        free = np.ones(base.target.shape[0], bool) if fixed is None else ~np.asarray(fixed)
        z0 = base.target if init is None else jnp.asarray(init, dtype)
        to_params = Partial(_free_targets, jnp.asarray(free))
    else:
        free = None if fixed is None else ~np.asarray(fixed)
        if init is None:
            raise ValueError("design: init is required with to_params")
        z0 = jnp.asarray(init, dtype)
        to_params = _as_tree(to_params)
    z0 = jnp.asarray(z0, dtype)
    free_mask = jnp.ones(z0.shape, bool) if free is None else jnp.asarray(free)

    def project(z):
        z = jnp.where(free_mask, z, z0)
        return jnp.clip(z, -jnp.pi, jnp.pi) if clip else z

    def value_and_grad(z, start):
        return _value_and_grad(solve, objective, to_params, base, z, start, free_mask)

    def jacobian(z, start):
        return _residual_jacobian(solve, objective, to_params, base, z, start, free_mask)

    z = project(z0)
    # an array from the first solve on (None would compile the solve once more for the warm starts)
    start = solve.default_start.astype(dtype)
    losses, gnorms = [], []
    reason = f"step limit {steps} reached"
    if optimizer == "gauss_newton":
        lam = 1e-3
        res, jac, x, info = jacobian(z, start)
        if res.ndim != 1:
            raise ValueError("gauss_newton needs an objective returning a vector of residuals")
        taken = 0
        for k in range(steps + 1):
            value = 0.5 * float(jnp.sum(res * res))
            g = jac.T @ res
            losses.append(value)
            gnorms.append(float(jnp.max(jnp.abs(g))))
            if not bool(info.ok):
                reason = not_ok_reason(info, tol)
                break
            if gnorms[-1] <= gtol or value <= ftol:
                reason = f"gradient {gnorms[-1]:.2e} <= gtol {gtol:.1e} or loss <= ftol {ftol:.1e}"
                break
            if k == steps:
                break
            jtj = jac.T @ jac
            diag = jnp.diag(jtj) + jnp.finfo(dtype).eps * jnp.max(jnp.diag(jtj))
            for _ in range(20):  # Levenberg-Marquardt: grow the damping until the loss drops
                a = jtj + jnp.diag(jnp.where(free_mask, lam * diag, 1.0))
                z_new = project(z - jnp.linalg.solve(a, g))
                # the trial's Jacobian comes with it: reused when the step is accepted
                trial = jacobian(z_new, x)
                if bool(trial[3].ok) and 0.5 * float(jnp.sum(trial[0] ** 2)) < value:
                    break
                lam *= 10.0
            else:
                reason = (
                    f"no decrease found from loss {value:.2e} (Levenberg-Marquardt damping "
                    "exhausted): the rounding floor of the loss, or a local minimum"
                )
                break
            moved = float(jnp.max(jnp.abs(z_new - z)))
            z, lam, taken = z_new, max(lam * 0.1, 1e-12), k + 1
            res, jac, x, info = trial
            if moved <= xtol:
                value = 0.5 * float(jnp.sum(res * res))
                losses.append(value)
                gnorms.append(float(jnp.max(jnp.abs(jac.T @ res))))
                reason = f"step {moved:.2e} <= xtol {xtol:.1e}"
                break
    else:
        opt_state = optimizer.init(z)
        value, g, x, info = value_and_grad(z, start)
        taken = 0
        for k in range(steps):
            losses.append(float(value))
            gnorms.append(float(jnp.max(jnp.abs(g))))
            if not bool(info.ok):
                reason = not_ok_reason(info, tol)
                break
            if gnorms[-1] <= gtol or float(value) <= ftol:
                reason = f"gradient {gnorms[-1]:.2e} <= gtol {gtol:.1e} or loss <= ftol {ftol:.1e}"
                break
            updates, opt_state = optimizer.update(g, opt_state, z)
            z = project(z + jnp.where(free_mask, updates, 0.0))
            value, g, x, info = value_and_grad(z, x)
            taken = k + 1
        else:
            losses.append(float(value))
            gnorms.append(float(jnp.max(jnp.abs(g))))
    return DesignResult(
        variables=z,
        params=to_params(z, base),
        positions=x,
        loss=float(value),
        info=info,
        history={"loss": np.array(losses), "grad_norm": np.array(gnorms)},
        steps=taken,
        reason=reason,
    )
