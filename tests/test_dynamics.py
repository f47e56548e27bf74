"""Damped dynamics: a stable automatic step, vmap over runs (shared correctness: test_solvers)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from origami_jax import fold, patterns
from origami_jax.energy import make_params, make_structure
from origami_jax.kinematics import rigid_fold
from origami_jax.solvers import Dynamics, Status, origami_simulator
from origami_jax.solvers.base import make_problem, objective, positions
from origami_jax.solvers.dynamics import lumped_mass


def test_viscous_scheme_converges():
    cp = patterns.single_crease(fold_angle=1.0)
    result = fold(cp, solver=Dynamics(damping="viscous", velocity_scale=0.95), max_iter=50_000)
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


@pytest.fixture(scope="module")
def miura():
    cp = patterns.miura_ori(3, 3, sector_angle=np.radians(60), fold_angle=np.pi / 2)
    return cp, rigid_fold(cp)


@pytest.mark.parametrize(
    "solver",
    # options paired where they are independent: each solver object compiles anew
    [Dynamics(integrator="verlet", mass="area"), Dynamics(ramp_steps=400)],
    ids=["verlet-area-mass", "ramp"],
)
def test_options_reach_the_exact_shape(miura, solver):
    cp, exact = miura
    result = fold(cp, solver=solver, reference_positions=exact)
    assert result.converged, result.reason
    assert result.shape_error <= 1e-8
    assert result.iterations >= solver.ramp_steps


@pytest.mark.parametrize(
    "solver",
    # origami_simulator(): bar damping with semi-implicit Euler
    [Dynamics(damping="bar", integrator="verlet"), origami_simulator()],
    ids=["bar-verlet", "origami-simulator"],
)
def test_bar_damping_converges(solver):
    cp = patterns.single_crease(fold_angle=1.0)
    result = fold(cp, solver=solver, max_iter=200_000)
    assert result.converged, result.reason
    assert result.fold_angle_error_max <= 1e-8


def test_lumped_mass_is_a_third_of_each_triangle():
    cp = patterns.single_crease(width=2.0, height=3.0)
    mass = lumped_mass(cp.mesh)
    assert mass.sum() == pytest.approx(6.0)
    assert mass.shape == (cp.mesh.num_vertices,) and (mass > 0).all()


def test_origami_simulator_time_step():
    cp = patterns.single_crease(width=2.0, height=1.0)
    mesh = cp.mesh
    params = make_params(cp, stiffness={"axial": 4.0})
    problem = make_problem(mesh, make_structure(mesh), params)
    state = jax.jit(origami_simulator().init_fn)(problem)
    k = 4.0 / np.asarray(params.rest_length)
    assert float(state.dt) == pytest.approx(0.9 / (2 * np.pi * np.sqrt(k.max())))


def test_user_time_step_is_checked():
    cp = patterns.single_crease(fold_angle=1.0)
    mesh = cp.mesh
    problem = make_problem(mesh, make_structure(mesh), make_params(cp))
    limit = float(jax.jit(Dynamics().init_fn)(problem).dt_stable)
    with pytest.raises(ValueError, match="exceeds the stability limit"):
        fold(cp, solver=Dynamics(dt=1.5 * limit))
    result = fold(cp, solver=Dynamics(dt=0.5 * limit))
    assert result.converged, result.reason


def test_momentum_removal():
    cp = patterns.single_crease(fold_angle=1.0)
    mesh = cp.mesh
    problem = make_problem(mesh, make_structure(mesh), make_params(cp))
    solver = Dynamics(damping="viscous", remove_momentum=True)

    @jax.jit  # compiled: five steps op by op take several times longer
    def five_steps(problem):
        state = solver.init_fn(problem)
        return jax.lax.fori_loop(0, 5, lambda _, s: solver.step_fn(s, problem), state)

    state = five_steps(problem)
    x = np.asarray(positions(problem, state.u))
    v = np.asarray(state.v)
    assert np.abs(v).max() > 1e-6  # it moves
    np.testing.assert_allclose(v.sum(axis=0), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.cross(x - x.mean(axis=0), v).sum(axis=0), 0.0, atol=1e-12)


def test_unknown_options():
    with pytest.raises(ValueError, match="unknown dynamics damping"):
        Dynamics(damping="leapfrog")
    with pytest.raises(ValueError, match="unknown dynamics integrator"):
        Dynamics(integrator="rk4")
    with pytest.raises(ValueError, match="dt must be a positive"):
        Dynamics(dt=-1.0)
