"""Damped dynamics on the same energy, in the jax-md style: a pure ``(init_fn, step_fn)`` pair.

Vertices are unit point masses (as in the seed and Origami Simulator); forces are
``-jax.grad`` of the energy. Two schemes:

* ``"fire"`` (default): semi-implicit Euler with FIRE's velocity mixing and adaptive time step
  (Bitzek et al. 2006), the fastest way down to a minimum;
* ``"viscous"``: semi-implicit Euler with velocities scaled by ``damping`` every step (the
  seed's global damping, 0.99997 per step at its 60,000 steps per second).

The time step comes from the stiffest mode: ``dt = safety * 2 / sqrt(lambda_max)``, with
``lambda_max`` the largest Hessian eigenvalue at the start, estimated by power iteration on
Hessian-vector products (``safety = 0.5`` by default; semi-implicit Euler is stable for
``dt < 2 / sqrt(lambda_max)``). FIRE grows the step up to ``dt_max_factor`` times that.

``init_fn(problem)`` and ``step_fn(state, problem)`` are pure, so ``jax.vmap`` runs many
simulations at once; :class:`Dynamics` wraps them as a solver for :func:`origami_jax.fold`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from origami_jax.energy import initial_reference
from origami_jax.geometry import fold_angles
from origami_jax.solvers.base import (
    Problem,
    Progress,
    Status,
    next_status,
    objective,
    positions,
)

__all__ = ["Dynamics", "DynamicsState", "max_eigenvalue"]


class DynamicsState(NamedTuple):
    u: Array  # (V, 3) displacement from problem.start, before the gauge
    v: Array  # (V, 3) velocities
    reference: Array  # (H,) unwrap reference of each torsion hinge, radians
    iteration: Array
    energy: Array
    grad_max: Array
    grad_max0: Array
    status: Array
    dt: Array
    dt_stable: Array
    alpha: Array  # FIRE mixing
    since_uphill: Array  # FIRE: steps since the power last turned negative
    progress: Progress


def max_eigenvalue(f, u: Array, iterations: int = 30) -> Array:
    """Largest eigenvalue of the Hessian of ``f`` at ``u`` by power iteration (Hessian-vector
    products through ``jax.jvp`` of ``jax.grad``); an estimate from below, hence a safety factor.
    """
    grad = jax.grad(f)

    def hvp(w):
        return jax.jvp(grad, (u,), (w,))[1]

    def body(_, w):
        hw = hvp(w)
        return hw / jnp.maximum(jnp.linalg.norm(hw), 1e-300)

    w0 = jnp.sin(jnp.arange(u.size, dtype=u.dtype).reshape(u.shape) * 1.7 + 0.3)
    w = jax.lax.fori_loop(0, iterations, body, w0 / jnp.linalg.norm(w0))
    return jnp.vdot(w, hvp(w))


@dataclass(frozen=True)
class Dynamics:
    """Damped dynamics as a solver (``solver="dynamics"``).

    Attributes:
      scheme: ``"fire"`` or ``"viscous"``.
      safety: fraction of the stability limit ``2 / sqrt(lambda_max)`` used as time step.
      damping: velocity factor per step of the viscous scheme.
      dt_max_factor: FIRE's largest time step, in units of the stable one.
      patience: steps with neither a new lowest energy nor a new smallest gradient before giving
        up (STALLED).
    """

    scheme: str = "fire"
    safety: float = 0.5
    damping: float = 0.99
    dt_max_factor: float = 1.0
    patience: int = 5000
    name: str = "dynamics"

    def __post_init__(self):
        if self.scheme not in ("fire", "viscous"):
            raise ValueError(f"unknown dynamics scheme {self.scheme!r} (fire, viscous)")

    def init(self, problem: Problem) -> DynamicsState:
        u = jnp.zeros_like(problem.start)
        reference = initial_reference(problem.start, problem.structure, problem.params)
        value, grad = jax.value_and_grad(objective)(u, problem, reference)
        lam = max_eigenvalue(lambda w: objective(w, problem, reference), u)
        dt = self.safety * 2.0 / jnp.sqrt(jnp.maximum(lam, jnp.finfo(u.dtype).tiny))
        gmax = jnp.max(jnp.abs(grad))
        ok = jnp.isfinite(value) & jnp.isfinite(gmax) & jnp.isfinite(dt)
        status = jnp.where(
            ok, jnp.where(gmax == 0, Status.CONVERGED, Status.RUNNING), Status.NONFINITE
        )
        zero = jnp.zeros((), jnp.int32)
        return DynamicsState(
            u=u,
            v=jnp.zeros_like(u),
            reference=reference,
            iteration=zero,
            energy=value,
            grad_max=gmax,
            grad_max0=gmax,
            status=status.astype(jnp.int32),
            dt=dt,
            dt_stable=dt,
            alpha=jnp.asarray(0.1, u.dtype),
            since_uphill=zero,
            progress=Progress(gmax, value, zero),
        )

    def step(self, s: DynamicsState, problem: Problem) -> DynamicsState:
        """One semi-implicit Euler step with the scheme's damping (pure; vmap-able)."""
        value, grad = jax.value_and_grad(objective)(s.u, problem, s.reference)
        force = -grad
        if self.scheme == "viscous":
            v = self.damping * (s.v + s.dt * force)
            dt, alpha, since_uphill = s.dt, s.alpha, s.since_uphill
        else:
            power = jnp.vdot(force, s.v)
            fnorm = jnp.linalg.norm(force)
            vnorm = jnp.linalg.norm(s.v)
            mixed = (1 - s.alpha) * s.v + s.alpha * vnorm * force / jnp.maximum(fnorm, 1e-300)
            uphill = power <= 0
            since_uphill = jnp.where(uphill, 0, s.since_uphill + 1)
            grow = (~uphill) & (since_uphill > 5)
            dt = jnp.where(
                uphill,
                0.5 * s.dt,
                jnp.where(grow, jnp.minimum(1.1 * s.dt, self.dt_max_factor * s.dt_stable), s.dt),
            )
            alpha = jnp.where(uphill, 0.1, jnp.where(grow, 0.99 * s.alpha, s.alpha))
            v = jnp.where(uphill, 0.0, mixed) + dt * force
        u = s.u + dt * v
        gmax = jnp.max(jnp.abs(grad))
        finite = jnp.isfinite(value) & jnp.isfinite(gmax) & jnp.all(jnp.isfinite(u))
        progress = s.progress.update(finite, gmax, value)
        converged = finite & (gmax <= problem.tol * s.grad_max0)
        status = next_status(converged, finite, progress.since_best >= self.patience)
        # on convergence or a non-finite value the state keeps the point the gradient was taken at
        take = finite & ~converged
        keep = lambda new, old: jnp.where(take, new, old)  # noqa: E731
        u = keep(u, s.u)
        reference = keep(
            fold_angles(positions(problem, u), problem.structure.hinges, s.reference), s.reference
        )
        return DynamicsState(
            u=u,
            v=keep(v, s.v),
            reference=reference,
            iteration=s.iteration + 1,
            energy=jnp.where(finite, value, s.energy),
            grad_max=jnp.where(finite, gmax, s.grad_max),
            grad_max0=s.grad_max0,
            status=status,
            dt=dt,
            dt_stable=s.dt_stable,
            alpha=alpha,
            since_uphill=since_uphill,
            progress=progress,
        )

    def run(self, state: DynamicsState, problem: Problem, steps: Array) -> DynamicsState:
        last = state.iteration + steps

        def cond(s):
            return (s.status == Status.RUNNING) & (s.iteration < last)

        return jax.lax.while_loop(cond, lambda s: self.step(s, problem), state)

    # jax-md style names
    def init_fn(self, problem: Problem) -> DynamicsState:
        return self.init(problem)

    def step_fn(self, state: DynamicsState, problem: Problem) -> DynamicsState:
        return self.step(state, problem)
