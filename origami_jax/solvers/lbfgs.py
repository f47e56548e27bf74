"""L-BFGS with optax's zoom line search, run inside one ``lax.while_loop``.

The unwrap references of the fold angles follow the iterates: after every accepted step each
crease's reference is moved to its new (continuous) angle, so a crease driven to +-pi is
tracked through it instead of snapping to the other side. Re-referencing changes neither the
energy at the current point nor its gradient, so optax's stored value and gradient stay valid.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import optax
from jax import Array

from origami_jax.energy import HingeReference, initial_reference, update_reference
from origami_jax.solvers.base import Problem, Status, objective, positions

__all__ = ["Lbfgs", "LbfgsState"]


class LbfgsState(NamedTuple):
    u: Array  # (V, 3) displacement from problem.start, before the gauge
    opt_state: optax.OptState
    reference: HingeReference
    iteration: Array
    energy: Array
    grad_max: Array
    grad_max0: Array
    status: Array
    stalls: Array  # consecutive steps without decrease


@dataclass(frozen=True)
class Lbfgs:
    """L-BFGS (``optax.lbfgs`` + zoom line search) on the energy, rigid motions gauged out.

    Attributes:
      memory_size: number of (step, gradient change) pairs kept.
      max_linesearch_steps: zoom line-search evaluations per iteration.
      max_stalls: steps in a row without energy decrease before giving up (STALLED).
    """

    memory_size: int = 10
    max_linesearch_steps: int = 30
    max_stalls: int = 8
    name: str = "lbfgs"

    def _optimizer(self) -> optax.GradientTransformationExtraArgs:
        return optax.lbfgs(
            memory_size=self.memory_size,
            linesearch=optax.scale_by_zoom_linesearch(
                max_linesearch_steps=self.max_linesearch_steps, initial_guess_strategy="one"
            ),
        )

    def init(self, problem: Problem) -> LbfgsState:
        u = jnp.zeros_like(problem.start)
        reference = initial_reference(problem.start, problem.structure, problem.params)
        value, grad = jax.value_and_grad(objective)(u, problem, reference)
        gmax = jnp.max(jnp.abs(grad))
        ok = jnp.isfinite(value) & jnp.isfinite(gmax)
        status = jnp.where(
            ok, jnp.where(gmax == 0, Status.CONVERGED, Status.RUNNING), Status.NONFINITE
        )
        return LbfgsState(
            u=u,
            opt_state=self._optimizer().init(u),
            reference=reference,
            iteration=jnp.zeros((), jnp.int32),
            energy=value,
            grad_max=gmax,
            grad_max0=gmax,
            status=status.astype(jnp.int32),
            stalls=jnp.zeros((), jnp.int32),
        )

    def run(self, state: LbfgsState, problem: Problem, steps: Array) -> LbfgsState:
        opt = self._optimizer()
        last = state.iteration + steps

        def cond(s: LbfgsState):
            return (s.status == Status.RUNNING) & (s.iteration < last)

        def body(s: LbfgsState) -> LbfgsState:
            def f(u):
                return objective(u, problem, s.reference)

            value, grad = optax.value_and_grad_from_state(f)(s.u, state=s.opt_state)
            updates, opt_state = opt.update(
                grad, s.opt_state, s.u, value=value, grad=grad, value_fn=f
            )
            u = s.u + updates
            new_value = optax.tree_utils.tree_get(opt_state, "value")
            new_grad = optax.tree_utils.tree_get(opt_state, "grad")
            gmax = jnp.max(jnp.abs(new_grad))
            finite = jnp.isfinite(new_value) & jnp.isfinite(gmax)
            stalls = jnp.where(new_value < value, 0, s.stalls + 1)
            converged = gmax <= problem.tol * s.grad_max0
            status = jnp.where(
                ~finite,
                Status.NONFINITE,
                jnp.where(
                    converged,
                    Status.CONVERGED,
                    jnp.where(stalls >= self.max_stalls, Status.STALLED, Status.RUNNING),
                ),
            ).astype(jnp.int32)
            # a non-finite step is not taken: the state keeps the last finite iterate
            keep = lambda new, old: jnp.where(finite, new, old)  # noqa: E731
            u = keep(u, s.u)
            reference = jax.tree.map(
                keep,
                update_reference(positions(problem, u), problem.structure, s.reference),
                s.reference,
            )
            opt_state = jax.tree.map(keep, opt_state, s.opt_state)
            return LbfgsState(
                u=u,
                opt_state=opt_state,
                reference=reference,
                iteration=s.iteration + 1,
                energy=keep(new_value, s.energy),
                grad_max=keep(gmax, s.grad_max),
                grad_max0=s.grad_max0,
                status=status,
                stalls=stalls,
            )

        return jax.lax.while_loop(cond, body, state)
