"""L-BFGS with optax's zoom line search, run inside one ``lax.while_loop``.

The unwrap references of the fold angles follow the iterates: after every accepted step each
crease's reference is moved to its new (continuous) angle, so a crease driven to +-pi is
tracked through it instead of snapping to the other side. Re-referencing changes neither the
energy at the current point nor its gradient, so optax's stored value and gradient stay valid.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import optax
from jax import Array

from origami_jax.energy import Reference
from origami_jax.solvers.base import (
    Problem,
    Progress,
    Solver,
    Status,
    accept,
    check_options,
    contact_limit,
    gauge,
    has_converged,
    next_status,
    objective,
    positions,
    start_reference,
    tolerance_scale,
    with_overflow,
)

__all__ = ["Lbfgs", "LbfgsState"]


def limit_displacement(max_step) -> optax.GradientTransformation:
    """Scale an update of (V, 3) displacements so that no vertex moves more than ``max_step``."""

    def update(updates, state, params=None):
        largest = jnp.max(jnp.sqrt(jnp.sum(updates * updates, axis=-1)))
        return updates * jnp.minimum(1.0, max_step / jnp.maximum(largest, 1e-300)), state

    return optax.GradientTransformation(lambda params: optax.EmptyState(), update)


def limit_by(fraction) -> optax.GradientTransformation:
    """Scale an update by ``fraction(update)`` (a scalar in [0, 1]): the line search then
    looks no farther (its largest learning rate is 1)."""

    def update(updates, state, params=None):
        return updates * fraction(updates), state

    return optax.GradientTransformation(lambda params: optax.EmptyState(), update)


class LbfgsState(NamedTuple):
    u: Array  # (V, 3) displacement from problem.start, before the gauge
    opt_state: optax.OptState
    reference: Reference  # what the energy measures against (unwrap, triangle normals)
    iteration: Array
    energy: Array
    grad_max: Array
    grad_max0: Array
    status: Array
    stalls: Array  # consecutive iterations whose line search found no step at all
    progress: Progress


@dataclass(frozen=True)
class Lbfgs(Solver):
    """L-BFGS (``optax.lbfgs`` + zoom line search) on the energy, rigid motions gauged out.

    Attributes:
      memory_size: number of (step, gradient change) pairs kept.
      max_linesearch_steps: zoom line-search evaluations per iteration.
      max_stalls: iterations in a row without any step before giving up (STALLED).
      patience: iterations with neither a new lowest energy nor a new smallest gradient before
        giving up (STALLED): both have reached the rounding floor of the dtype.
    """

    memory_size: int = 10
    max_linesearch_steps: int = 30
    max_stalls: int = 8
    patience: int = 500
    name: str = "lbfgs"
    # it bounds its steps among contact pairs (fold(contact=...))
    supports_contact: ClassVar[bool] = True

    def __post_init__(self):
        counts = ("memory_size", "max_linesearch_steps", "max_stalls", "patience")
        check_options(self, at_least=dict.fromkeys(counts, 1), counts=counts)

    def _optimizer(self, max_step=1.0, fraction=None) -> optax.GradientTransformationExtraArgs:
        # with contact, ``fraction`` keeps the step within the skin and short of any face (in
        # the chain either way: the optimizer's state is the same with and without)
        whole = lambda du: 1.0  # noqa: E731
        return optax.chain(
            optax.scale_by_lbfgs(memory_size=self.memory_size),
            optax.scale(-1.0),
            limit_displacement(max_step),
            limit_by(whole if fraction is None else fraction),
            optax.scale_by_zoom_linesearch(
                max_linesearch_steps=self.max_linesearch_steps,
                max_learning_rate=1.0,
                initial_guess_strategy="one",
            ),
        )

    def init(self, problem: Problem) -> LbfgsState:
        """The start state, with the gradient scale of the tolerance (:func:`tolerance_scale`);
        the energy at the start is first evaluated by the first iteration."""
        u = jnp.zeros_like(problem.start)
        one = jnp.ones((), u.dtype)
        reference = start_reference(problem)
        g_start = jnp.max(jnp.abs(jax.grad(objective)(u, problem, reference)))
        return LbfgsState(
            u=u,
            opt_state=self._optimizer().init(u),
            reference=reference,
            iteration=jnp.zeros((), jnp.int32),
            energy=jnp.full((), jnp.inf, u.dtype),
            grad_max=one,
            grad_max0=tolerance_scale(problem, u, reference, g_start),
            status=with_overflow(jnp.asarray(Status.RUNNING, jnp.int32), reference),
            stalls=jnp.zeros((), jnp.int32),
            progress=Progress.start(u.dtype),
        )

    def step(self, s: LbfgsState, problem: Problem) -> LbfgsState:
        """One L-BFGS iteration with its line search (pure)."""
        fraction = None
        if problem.structure.contact is not None:
            x = positions(problem, s.u)

            def fraction(du):
                return contact_limit(x, gauge(problem, du), problem, s.reference)

        opt = self._optimizer(problem.max_step, fraction)

        def f(u):
            return objective(u, problem, s.reference)

        value, grad = optax.value_and_grad_from_state(f)(s.u, state=s.opt_state)
        first = s.iteration == 0
        g_start = jnp.max(jnp.abs(grad))
        grad_max0 = s.grad_max0
        updates, opt_state = opt.update(grad, s.opt_state, s.u, value=value, grad=grad, value_fn=f)
        u = s.u + updates
        new_value = optax.tree_utils.tree_get(opt_state, "value")
        new_grad = optax.tree_utils.tree_get(opt_state, "grad")
        gmax = jnp.max(jnp.abs(new_grad))
        finite = jnp.isfinite(new_value) & jnp.isfinite(gmax)
        # a start that is already stationary (or not finite) takes no step
        at_rest = first & (g_start == 0)
        bad_start = first & ~(jnp.isfinite(value) & jnp.isfinite(g_start))
        finite = finite & ~at_rest & ~bad_start
        moved = jnp.any(updates != 0)
        stalls = jnp.where(moved, 0, s.stalls + 1)
        progress = s.progress.update(finite, gmax, new_value)
        stalled = (stalls >= self.max_stalls) | progress.stalled(self.patience)
        converged = at_rest | (finite & has_converged(gmax, grad_max0, problem))
        status = next_status(converged, finite, stalled)
        # a non-finite step is not taken: the state keeps the last finite iterate
        keep = lambda new, old: jnp.where(finite, new, old)  # noqa: E731
        u, reference = accept(finite, u, s, problem)
        opt_state = jax.tree.map(keep, opt_state, s.opt_state)
        return LbfgsState(
            u=u,
            opt_state=opt_state,
            reference=reference,
            iteration=s.iteration + 1,
            energy=keep(new_value, value),
            grad_max=jnp.where(finite, gmax, jnp.where(first, g_start, s.grad_max)),
            grad_max0=grad_max0,
            status=with_overflow(status, reference),
            stalls=stalls,
            progress=progress,
        )
