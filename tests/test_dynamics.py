"""Damped dynamics: a stable automatic step, vmap over runs (shared correctness: test_solvers)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from origami_jax import fold, patterns
from origami_jax.energy import make_params, make_structure
from origami_jax.solvers import Dynamics, Status
from origami_jax.solvers.base import make_problem, objective


def test_viscous_scheme_converges():
    cp = patterns.single_crease(fold_angle=1.0)
    result = fold(cp, solver=Dynamics(scheme="viscous", damping=0.95), max_iter=50_000)
    assert result.converged, result.reason
    assert result.fold_angle_error_max <= 1e-8


def test_time_step_from_stiffest_mode_and_vmapped_runs():
    cp = patterns.single_crease(fold_angle=1.0)
    mesh = cp.mesh
    solver = Dynamics()
    init = jax.jit(solver.init_fn)
    dts = []
    for axial in (1.0, 100.0):
        params = make_params(cp, stiffness={"axial": axial, "facet": 0.02, "crease": 0.001})
        problem = make_problem(mesh, make_structure(mesh), params, tol=1e-10)
        dts.append(float(init(problem).dt))
    # dt ~ 1 / sqrt(stiffness): 100x stiffer bars, 10x shorter step
    assert dts[0] / dts[1] == pytest.approx(10.0, rel=0.05)
    # many simulations in one call: vmap over fold percent
    params = make_params(cp)
    problem = make_problem(mesh, make_structure(mesh), params, tol=1e-10)

    def simulate(percent):
        p = dataclasses.replace(problem, params=params._replace(percent=percent))
        state = solver.init_fn(p)
        state = jax.lax.fori_loop(0, 300, lambda _, s: solver.step_fn(s, p), state)
        return objective(state.u, p, state.reference), state.status

    energies, status = jax.jit(jax.vmap(simulate))(jnp.array([0.25, 0.5, 1.0]))
    assert energies.shape == (3,) and np.all(np.asarray(energies) < 1e-6)
    assert np.all(np.asarray(status) != Status.NONFINITE)


def test_unknown_scheme():
    with pytest.raises(ValueError, match="unknown dynamics scheme"):
        Dynamics(scheme="leapfrog")
