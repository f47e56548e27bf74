"""A solver written by a user on the Solver contract alone (gradient descent with
backtracking) runs through fold and fold_batch: the example of docs/solvers.md."""

# --8<-- [start:descent]
from dataclasses import dataclass
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

from origami_jax.solvers import Solver, base
from origami_jax.solvers.base import Progress, objective


class DescentState(NamedTuple):
    u: jax.Array  # (V, 3) displacement from problem.start, before the gauge
    reference: object  # what the energy measures against (energy.Reference)
    iteration: jax.Array
    energy: jax.Array
    grad_max: jax.Array
    grad_max0: jax.Array
    status: jax.Array
    rate: jax.Array  # the last step's size, displacement per unit of gradient
    progress: Progress  # the best energy and gradient so far (stalls)


@dataclass(frozen=True)
class Descent(Solver):
    """Gradient descent: each step tries twice the last size, halved until the energy falls."""

    patience: int = 1000  # iterations without progress before it stalls

    def init(self, problem):
        u = jnp.zeros_like(problem.start)
        reference = base.start_reference(problem)
        e, g = jax.value_and_grad(objective)(u, problem, reference)
        gmax, zero = jnp.max(jnp.abs(g)), jnp.zeros((), jnp.int32)
        status = base.next_status(False, jnp.isfinite(e) & jnp.isfinite(gmax), False)
        g0 = base.tolerance_scale(problem, u, reference, gmax)
        rate = jnp.ones_like(e)
        return DescentState(u, reference, zero, e, gmax, g0, status, rate, Progress(gmax, e, zero))

    def step(self, s, problem):
        def f(u):
            return objective(u, problem, s.reference)

        g = jax.grad(f)(s.u)
        # no vertex moves further than problem.max_step: the solve follows a folding path
        rate = jnp.minimum(2 * s.rate, problem.max_step / jnp.max(jnp.linalg.norm(g, axis=1)))
        rate, _ = jax.lax.while_loop(  # halve (at most 60 times) until the energy falls
            lambda c: ~(f(s.u - c[0] * g) < s.energy) & (c[1] < 60),
            lambda c: (c[0] / 2, c[1] + 1),
            (rate, 0),
        )
        u = s.u - rate * g
        e, g = jax.value_and_grad(f)(u)
        gmax = jnp.max(jnp.abs(g))
        finite = jnp.isfinite(e) & jnp.isfinite(gmax)
        progress = s.progress.update(finite, gmax, e)
        converged = finite & base.has_converged(gmax, s.grad_max0, problem)
        status = base.next_status(converged, finite, progress.stalled(self.patience))
        u, ref = base.accept(finite, u, s, problem)  # a non-finite step: not taken
        keep = partial(jnp.where, finite)
        s = s._replace(u=u, reference=ref, iteration=s.iteration + 1, rate=rate, progress=progress)
        return s._replace(energy=keep(e, s.energy), grad_max=keep(gmax, s.grad_max), status=status)


# --8<-- [end:descent]

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from origami_jax import fold, fold_batch, patterns  # noqa: E402

jax.config.update("jax_enable_x64", True)

# easy scenes: a degree-4 vertex (8 vertices) at two fold angles; descent's tolerance is far
# looser than Newton's, and its fold angles are compared with Newton's to about 100x it
TOL = 1e-8
CPS = [patterns.degree4_vertex(fold_angle=a) for a in (1.0, 1.5)]


@pytest.fixture(scope="module")
def newton():
    return [fold(cp) for cp in CPS]


def _same_fold(result, reference):
    assert result.converged and result.solver == "descent", result.reason
    assert result.reason.startswith("converged: grad_norm_rel")
    assert result.iterations > 1000  # it did descend (Newton: a handful)
    np.testing.assert_allclose(result.fold_angles, reference.fold_angles, rtol=0, atol=1e-6)
    np.testing.assert_allclose(result.positions, reference.positions, rtol=0, atol=1e-6)


def test_user_solver_folds_like_newton(newton):
    result = fold(CPS[1], solver=Descent(), tol=TOL)
    _same_fold(result, newton[1])
    assert result.path == "direct"  # it does not follow the path from flat (follows_path)
    with pytest.raises(ValueError, match="does not bound its steps among contact pairs"):
        fold(CPS[1], solver=Descent(), contact=True)


@pytest.mark.parametrize("share", [False, True])
def test_user_solver_runs_in_fold_batch(newton, share):
    results = fold_batch(CPS, solver=Descent(), tol=TOL, share_topology=share, progress=False)
    for result, reference in zip(results, newton, strict=True):
        _same_fold(result, reference)


def test_a_solver_must_subclass_the_contract():
    with pytest.raises(TypeError, match="subclasses Solver"):
        fold(CPS[0], solver=object())
    with pytest.raises(TypeError, match="abstract"):
        Solver()
