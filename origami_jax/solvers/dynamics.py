"""Damped dynamics on the same energy, in the jax-md style: a pure ``(init_fn, step_fn)`` pair.

Forces are ``-jax.grad`` of the energy. The options (all of :class:`Dynamics`):

* ``integrator``: ``"euler"`` (semi-implicit / symplectic Euler, as Origami Simulator) or
  ``"verlet"`` (velocity Verlet);
* ``mass``: ``"unit"`` (every vertex mass 1, as the seed and Origami Simulator) or ``"area"``
  (lumped: a third of each adjacent triangle's flat area, the seed's "uniform density");
* ``damping``: ``"fire"`` (default; FIRE's velocity mixing and adaptive step, Bitzek et al.
  2006, the fastest way down to a minimum), ``"viscous"`` (velocities scaled by
  ``velocity_scale`` every step: the seed's global damping, 0.99997 at its 60,000 steps per
  second) or ``"bar"`` (Origami Simulator's: a dashpot on every bar's relative velocity,
  ``c = 2 zeta sqrt(k m)``, ``k = axial / l0``, ``zeta = 0.45``);
* ``remove_momentum``: remove the net linear and angular momentum every step (the seed's
  section 5);
* ``ramp_steps``: drive the fold percent from 0 to ``percent`` over that many steps (animates a
  fold; the solve cannot converge before the ramp ends).

The time step: ``dt_rule="hessian"`` (default) takes ``safety * 2 / sqrt(lambda_max)``, with
``lambda_max`` the largest eigenvalue of ``M^-1 H`` at the start (power iteration on
Hessian-vector products; explicit schemes are stable below ``2 / sqrt(lambda_max)``, and the
power iteration estimates from below, hence ``safety = 0.5``). ``dt_rule="bars"`` is Origami
Simulator's ``0.9 / (2 pi max_bars sqrt(k / m))``. A user's ``dt`` is checked against
``2 / sqrt(lambda_max)``: :func:`origami_jax.fold` raises ``ValueError`` above it.

``init_fn(problem)`` and ``step_fn(state, problem)`` are pure, so ``jax.vmap`` runs many
simulations at once; :class:`Dynamics` is also a solver for :func:`origami_jax.fold`.

Example:
  >>> from origami_jax import fold, patterns
  >>> from origami_jax.solvers import Dynamics
  >>> r = fold(patterns.single_crease(1.0), solver=Dynamics(integrator="verlet"))
  >>> bool(r.converged), r.fold_angle_error_max < 1e-6
  (True, True)
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, replace
from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from origami_jax.contact import stiffest_pair
from origami_jax.energy import Reference, springs_only
from origami_jax.pattern import Mesh
from origami_jax.solvers.base import (
    Problem,
    Progress,
    Solver,
    Status,
    accept,
    barrier_limit,
    contact_limit,
    doubled_areas,
    gauge,
    has_barriers,
    has_converged,
    next_status,
    objective,
    positions,
    start_reference,
    stop_closing,
    tolerance_scale,
    with_overflow,
)

__all__ = ["Dynamics", "DynamicsState", "max_eigenvalue", "lumped_mass", "origami_simulator"]


class DynamicsState(NamedTuple):
    u: Array  # (V, 3) displacement from problem.start, before the gauge
    v: Array  # (V, 3) velocities
    force: Array  # (V, 3) conservative force at u (velocity Verlet reuses it)
    reference: Reference  # what the energy measures against (unwrap, triangle normals)
    iteration: Array
    energy: Array
    grad_max: Array
    grad_max0: Array
    status: Array
    dt: Array
    dt_stable: Array  # 2 / sqrt(lambda_max): the stability limit at the start
    dt_max: Array  # the largest step FIRE may grow to
    alpha: Array  # FIRE mixing
    since_uphill: Array  # FIRE: steps since the power last turned negative
    progress: Progress


def lumped_mass(mesh: Mesh) -> np.ndarray:
    """(V,) a third of the flat area of every triangle at each vertex (density 1 per unit area)."""
    p = mesh.vertices[mesh.triangles]
    area = 0.5 * doubled_areas(p)
    mass = np.zeros(mesh.num_vertices)
    np.add.at(mass, mesh.triangles.ravel(), np.repeat(area / 3.0, 3))
    return mass


def max_eigenvalue(f, u: Array, inv_mass: Array | None = None, iterations: int = 30) -> Array:
    """Largest eigenvalue of ``M^-1 H`` (``H`` the Hessian of ``f`` at ``u``, ``M`` diagonal) by
    power iteration on ``M^-1/2 H M^-1/2`` (Hessian-vector products through ``jax.jvp`` of
    ``jax.grad``); an estimate from below, hence a safety factor."""
    grad = jax.grad(f)
    scale = jnp.ones_like(u) if inv_mass is None else jnp.sqrt(inv_mass)[:, None]

    def op(w):
        return scale * jax.jvp(grad, (u,), (scale * w,))[1]

    def body(_, w):
        hw = op(w)
        return hw / jnp.maximum(jnp.linalg.norm(hw), 1e-300)

    w0 = jnp.sin(jnp.arange(u.size, dtype=u.dtype).reshape(u.shape) * 1.7 + 0.3)
    w = jax.lax.fori_loop(0, iterations, body, w0 / jnp.linalg.norm(w0))
    return jnp.vdot(w, op(w))


def _remove_momentum(v: Array, x: Array, mass: Array) -> Array:
    """Subtract the rigid motion (linear and angular) that carries the net momentum of ``v``."""
    total = jnp.sum(mass)
    centre = jnp.sum(mass[:, None] * x, axis=0) / total
    v = v - jnp.sum(mass[:, None] * v, axis=0) / total
    r = x - centre
    angular = jnp.sum(mass[:, None] * jnp.cross(r, v), axis=0)
    rr = jnp.sum(r * r, axis=1)
    inertia = jnp.sum(
        mass[:, None, None]
        * (rr[:, None, None] * jnp.eye(3, dtype=x.dtype) - r[:, :, None] * r[:, None, :]),
        axis=0,
    )
    # a flat or collinear sheet has a singular inertia: a tiny shift keeps the solve finite
    inertia = inertia + jnp.eye(3, dtype=x.dtype) * (1e-12 * jnp.trace(inertia) + 1e-300)
    omega = jnp.linalg.solve(inertia, angular)
    return v - jnp.cross(omega, r)


@dataclass(frozen=True)
class Dynamics(Solver):
    """Damped dynamics as a solver (``solver="dynamics"``); see the module for the options.

    Attributes:
      integrator: ``"euler"`` (semi-implicit) or ``"verlet"`` (velocity Verlet).
      damping: ``"fire"``, ``"viscous"`` or ``"bar"``.
      mass: ``"unit"`` or ``"area"``.
      dt_rule: ``"hessian"`` or ``"bars"`` (Origami Simulator's).
      dt: a fixed time step (time units with unit stiffness and mass); ``None`` chooses it.
      safety: fraction of the stability limit ``2 / sqrt(lambda_max)`` used as time step.
      velocity_scale: velocity factor per step of ``damping="viscous"``.
      zeta: damping ratio of ``damping="bar"``.
      remove_momentum: remove net linear and angular momentum every step.
      ramp_steps: steps over which the fold percent ramps from 0 to its value (0: no ramp).
      dt_max_factor: FIRE's largest time step, in units of the chosen one.
      patience: steps with neither a new lowest energy nor a new smallest gradient before
        giving up (STALLED).
    """

    integrator: str = "euler"
    damping: str = "fire"
    mass: str = "unit"
    dt_rule: str = "hessian"
    dt: float | None = None
    safety: float = 0.5
    velocity_scale: float = 0.99
    zeta: float = 0.45
    remove_momentum: bool = False
    ramp_steps: int = 0
    dt_max_factor: float = 1.0
    patience: int = 5000
    name: str = "dynamics"
    # it bounds its steps among contact pairs (fold(contact=...))
    supports_contact: ClassVar[bool] = True

    def __post_init__(self):
        for option, allowed in [
            ("integrator", ("euler", "verlet")),
            ("damping", ("fire", "viscous", "bar")),
            ("mass", ("unit", "area")),
            ("dt_rule", ("hessian", "bars")),
        ]:
            if getattr(self, option) not in allowed:
                raise ValueError(
                    f"unknown dynamics {option} {getattr(self, option)!r} ({', '.join(allowed)})"
                )
        if self.dt is not None and not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a positive number, got {self.dt}")
        if self.ramp_steps < 0:
            raise ValueError(f"ramp_steps must be >= 0, got {self.ramp_steps}")

    # -- host side ---------------------------------------------------------------------------
    def prepare(self, problem: Problem, mesh: Mesh) -> Problem:
        """Attach the vertex masses (before ``jit``)."""
        if self.mass == "unit":
            return problem
        mass = jnp.asarray(lumped_mass(mesh), problem.start.dtype)
        return dataclasses.replace(problem, aux=mass)

    def prepare_batch(self, problem: Problem, mesh: Mesh) -> Problem:
        """The vertex masses, the padding's 1 (pinned in place: it never moves)."""
        if self.mass == "unit":
            return problem
        mass = np.ones(problem.start.shape[0])
        mass[: mesh.num_vertices] = lumped_mass(mesh)
        return dataclasses.replace(problem, aux=mass)

    def check_batch(self, num_vertices: int) -> None:
        if self.remove_momentum:
            raise ValueError("fold_batch(): remove_momentum is not supported (padding has mass)")

    def check_start(self, state: DynamicsState) -> None:
        """Refuse a user's time step above the stability limit (host side, after ``init``)."""
        limit = float(np.min(np.asarray(state.dt_stable)))  # the smallest one of a batch
        if self.dt is not None and self.dt > limit:
            raise ValueError(
                f"dt = {self.dt:.3g} exceeds the stability limit 2 / sqrt(lambda_max) = "
                f"{limit:.3g} of this scene (leave dt=None to choose it)"
            )

    # -- pure --------------------------------------------------------------------------------
    def _mass(self, problem: Problem) -> Array:
        if problem.aux is None:
            return jnp.ones(problem.start.shape[0], problem.start.dtype)
        return problem.aux

    def _at_percent(self, problem: Problem, iteration: Array) -> Problem:
        if not self.ramp_steps:
            return problem
        ramp = jnp.minimum(1.0, (iteration + 1) / self.ramp_steps).astype(problem.start.dtype)
        params = problem.params._replace(percent=ramp * problem.params.percent)
        return dataclasses.replace(problem, params=params)

    def _bar_damping(self, v: Array, problem: Problem, mass: Array) -> Array:
        """Origami Simulator's dashpots: ``c (v_j - v_i)`` on each bar end, ``c = 2 zeta
        sqrt(k m)``."""
        bars = problem.structure.bars
        k = problem.params.stiffness.axial / problem.params.rest_length
        m = 0.5 * (mass[bars[:, 0]] + mass[bars[:, 1]])
        c = 2.0 * self.zeta * jnp.sqrt(k * m)
        rel = c[:, None] * (v[bars[:, 1]] - v[bars[:, 0]])
        return jnp.zeros_like(v).at[bars[:, 0]].add(rel).at[bars[:, 1]].add(-rel)

    def init(self, problem: Problem) -> DynamicsState:
        u = jnp.zeros_like(problem.start)
        mass = self._mass(problem)
        p0 = self._at_percent(problem, jnp.zeros((), jnp.int32))
        reference = start_reference(problem)
        value, grad = jax.value_and_grad(objective)(u, p0, reference)
        # the springs' stiffest mode sets the step: a barrier's stiffness is unbounded, and its
        # walls are kept by the step limit instead (see ``step``)
        springs = replace(problem, structure=springs_only(problem.structure))
        lam = jnp.maximum(
            max_eigenvalue(lambda w: objective(w, springs, reference), u, 1.0 / mass),
            jnp.finfo(u.dtype).tiny,
        )
        if self.damping == "bar":
            # explicit dashpots: the step must also resolve the fastest decay (rate gamma);
            # symplectic Euler on x'' = -lam x - gamma x' is stable for lam dt^2 + 2 gamma dt < 4
            gamma = max_eigenvalue(
                lambda w: 0.5 * jnp.vdot(w, -self._bar_damping(w, problem, mass)), u, 1.0 / mass
            )
            dt_stable = (jnp.sqrt(gamma * gamma + 4.0 * lam) - gamma) / lam
        else:
            dt_stable = 2.0 / jnp.sqrt(lam)
        if self.dt is not None:
            dt = jnp.asarray(self.dt, u.dtype)
        elif self.dt_rule == "bars":
            bars = problem.structure.bars
            k = problem.params.stiffness.axial / problem.params.rest_length
            m = jnp.minimum(mass[bars[:, 0]], mass[bars[:, 1]])
            dt = 0.9 / (2 * jnp.pi * jnp.max(jnp.sqrt(k / m)))
        else:
            dt = self.safety * dt_stable
        gmax = jnp.max(jnp.abs(grad))
        ok = jnp.isfinite(value) & jnp.isfinite(gmax) & jnp.isfinite(dt)
        at_rest = (gmax == 0) & (self.ramp_steps <= 1)
        status = jnp.where(
            ok, jnp.where(at_rest, Status.CONVERGED, Status.RUNNING), Status.NONFINITE
        )
        zero = jnp.zeros((), jnp.int32)
        return DynamicsState(
            u=u,
            v=jnp.zeros_like(u),
            force=-grad,
            reference=reference,
            iteration=zero,
            energy=value,
            grad_max=gmax,
            grad_max0=tolerance_scale(p0, u, reference, gmax),
            status=with_overflow(status, reference).astype(jnp.int32),
            dt=dt,
            dt_stable=dt_stable,
            dt_max=self.dt_max_factor * dt,
            alpha=jnp.asarray(0.1, u.dtype),
            since_uphill=zero,
            progress=Progress(gmax, value, zero),
        )

    def step(self, s: DynamicsState, problem: Problem) -> DynamicsState:
        """One time step with the chosen integrator and damping (pure; vmap-able)."""
        mass = self._mass(problem)[:, None]
        p = self._at_percent(problem, s.iteration)
        grad_of = jax.value_and_grad(objective)
        v, dt, alpha, since_uphill, dt_max = s.v, s.dt, s.alpha, s.since_uphill, s.dt_max
        if self.integrator == "euler":
            value, grad = grad_of(s.u, p, s.reference)
            force = -grad
        else:
            force = s.force  # at s.u, from the previous step
        if self.damping == "fire":
            power = jnp.vdot(force, v)
            fnorm = jnp.linalg.norm(force)
            vnorm = jnp.linalg.norm(v)
            mixed = (1 - alpha) * v + alpha * vnorm * force / jnp.maximum(fnorm, 1e-300)
            uphill = power <= 0
            since_uphill = jnp.where(uphill, 0, since_uphill + 1)
            grow = (~uphill) & (since_uphill > 5)
            dt = jnp.where(uphill, 0.5 * dt, jnp.where(grow, jnp.minimum(1.1 * dt, dt_max), dt))
            alpha = jnp.where(uphill, 0.1, jnp.where(grow, 0.99 * alpha, alpha))
            v = jnp.where(uphill, 0.0, mixed)

        x = positions(problem, s.u)
        if problem.structure.contact is not None:
            # the contact barrier's stiffness grows without bound as layers close: the time
            # step stays within its stability limit (the other terms' was taken at the start)
            c = p.params.contact
            stiff = stiffest_pair(x, s.reference.pairs, c.dhat, c.kappa)
            dt = jnp.minimum(dt, self.safety * 2.0 / jnp.sqrt(stiff / jnp.min(mass)))

        def total_force(f, vel):
            if self.damping == "bar":
                f = f + self._bar_damping(vel, p, mass[:, 0])
            return f

        barriers = has_barriers(problem.structure)
        if self.integrator == "euler":
            v = v + dt * total_force(force, v) / mass
            if barriers:  # the barrier's stiffness is beyond any stable time step: see base
                v = stop_closing(v, x, p, s.reference)
            du = dt * v
        else:
            a = total_force(force, v) / mass
            if barriers:
                v = stop_closing(v, x, p, s.reference)
                a = stop_closing(a, x, p, s.reference)
            du = dt * v + 0.5 * dt * dt * a
        if barriers:
            # what still closes a barrier fast (one outside its zone) is cut short, with the
            # velocity: no step lands on a wall
            t = barrier_limit(x, gauge(problem, du), p, s.reference)
            du, v = t * du, t * v
        if problem.structure.contact is not None:
            # cut short within the skin and before any face passes through a face, with the
            # velocity (an inelastic stop)
            t = contact_limit(x, gauge(problem, du), p, s.reference)
            du, v = t * du, t * v
        u = s.u + du
        if self.integrator == "euler":
            new_force = force
        else:
            value, grad = grad_of(u, p, s.reference)
            new_force = -grad
            v = v + 0.5 * dt * (a + total_force(new_force, v) / mass)
        if self.damping == "viscous":
            v = self.velocity_scale * v
        if self.remove_momentum:
            v = _remove_momentum(v, positions(problem, u), mass[:, 0])
        gmax = jnp.max(jnp.abs(grad))
        finite = jnp.isfinite(value) & jnp.isfinite(gmax) & jnp.all(jnp.isfinite(u))
        progress = s.progress.update(finite, gmax, value)
        ramped = s.iteration + 1 >= self.ramp_steps
        converged = finite & ramped & has_converged(gmax, s.grad_max0, problem)
        stalled = ramped & progress.stalled(self.patience)
        status = next_status(converged, finite, stalled)
        # Euler: on convergence keep the point the gradient was taken at; never keep non-finite
        take = finite & ~converged if self.integrator == "euler" else finite
        keep = lambda new, old: jnp.where(take, new, old)  # noqa: E731
        u, reference = accept(take, u, s, problem)
        return DynamicsState(
            u=u,
            v=keep(v, s.v),
            force=keep(new_force, s.force),
            reference=reference,
            iteration=s.iteration + 1,
            energy=jnp.where(finite, value, s.energy),
            grad_max=jnp.where(finite, gmax, s.grad_max),
            grad_max0=s.grad_max0,
            status=with_overflow(status, reference),
            dt=dt,
            dt_stable=s.dt_stable,
            dt_max=dt_max,
            alpha=alpha,
            since_uphill=since_uphill,
            progress=progress,
        )

    # jax-md style names
    def init_fn(self, problem: Problem) -> DynamicsState:
        return self.init(problem)

    def step_fn(self, state: DynamicsState, problem: Problem) -> DynamicsState:
        return self.step(state, problem)


def origami_simulator() -> Dynamics:
    """Origami Simulator's scheme, for comparison: semi-implicit Euler, unit masses, bar
    damping with ``zeta = 0.45`` and ``dt = 0.9 / (2 pi max sqrt(k / m))``."""
    return Dynamics(
        integrator="euler", damping="bar", mass="unit", dt_rule="bars", name="origami_simulator"
    )
