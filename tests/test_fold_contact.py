"""Self-contact in the solve (fold(contact=...)): a sheet folded onto itself stops at the
barrier's reach and never crosses, the pair Hessians Newton assembles are the barrier's own made
positive semi-definite, and the switches and reports."""

from __future__ import annotations

import importlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from origami_jax import fold, patterns
from origami_jax.contact import (
    all_pairs,
    contact_barrier,
    contact_energy,
    contact_mesh,
    edge_edge_distance_sq,
    pair_hessians,
    point_triangle_distance_sq,
    step_bound,
)
from origami_jax.energy import build_energy
from origami_jax.intersections import intersecting_pairs
from origami_jax.solvers import Lbfgs, Newton
from origami_jax.viz.colors import face_values

jax.config.update("jax_enable_x64", True)


@pytest.mark.parametrize("linear_solver", ["dense", "sparse"])
def test_a_full_valley_stops_at_thickness(linear_solver):
    cp = patterns.single_crease(fold_angle=np.pi)
    solver = Newton(linear_solver=linear_solver)
    bare = fold(cp, solver=solver)
    thick = fold(cp, solver=solver, contact=True)
    # without contact the two halves fold flat onto each other: the crease at pi
    assert bare.converged and abs(bare.fold_angles).max() == pytest.approx(np.pi, abs=1e-8)
    assert thick.converged, thick.reason
    assert thick.contact_dhat == pytest.approx(1e-3 * np.sqrt(2.0))
    # with it they stop within the barrier's reach, apart, short of pi, crossing nowhere
    assert 0.0 < thick.contact_min_ratio <= 1.0
    assert thick.contact_pairs >= 1
    crease = np.abs(thick.fold_angles).max()
    assert np.pi - 0.01 < crease < np.pi - 1e-4
    assert len(thick.intersections) == 0 and len(thick.through_pi) == 0
    # the halves' diagonals cross half way out, where the closest pair is: the free corners lie
    # about twice its distance above the other half's plane, so the layers are within 2 dhat
    x = thick.positions
    normal = np.cross(x[2] - x[1], x[4] - x[1])
    normal /= np.linalg.norm(normal)
    gap = np.abs((x[[0, 5]] - x[1]) @ normal)
    assert np.all(gap > thick.contact_dhat) and np.all(gap <= 2 * thick.contact_dhat)
    assert "contact" in thick.summary() and thick.advice == []
    # the contact forces: equal and opposite over the pairs, and at equilibrium they balance
    # the springs' (the energy without contact) on every vertex
    force = thick.contact_forces
    assert np.abs(force).max() > 0 and np.abs(force.sum(axis=0)).max() < 1e-12
    springs, params = build_energy(cp)
    spring_force = -np.asarray(jax.grad(springs)(jnp.asarray(x), params))
    np.testing.assert_allclose(force + spring_force, 0.0, atol=1e-6 * np.abs(force).max())
    per_triangle = face_values(thick, "contact_force")
    assert per_triangle.shape == (len(cp.mesh.triangles),)
    assert per_triangle.max() == pytest.approx(np.linalg.norm(force, axis=1).max())
    assert not bare.contact_forces.any()


def test_a_full_valley_with_contact_at_extreme_stiffness_ratios_and_scales():
    """Bars 1 to 1e8 times the creases' stiffness, sheets 1e-6 and 1e6 wide: a full valley with
    contact converges within the barrier's reach, apart, in the same shape in units of its
    size (the barrier's weight and reach scale with the bars and the sheet)."""
    shapes = []
    for ratio, scale in ((1.0, 1.0), (1e4, 1.0), (1e8, 1.0), (1.0, 1e-6), (1.0, 1e6)):
        cp = patterns.single_crease(fold_angle=np.pi, width=scale, height=scale)
        stiffness = dict(axial=1.0, facet=20.0 / ratio, crease=1.0 / ratio)
        result = fold(cp, solver=Newton(linear_solver="dense"), contact=True, stiffness=stiffness)
        assert result.converged, (ratio, scale, result.reason)
        assert np.all(np.isfinite(result.positions))
        assert result.contact_dhat == pytest.approx(1e-3 * np.sqrt(2.0) * scale)
        assert 0.0 < result.contact_min_ratio <= 1.0 and result.contact_pairs >= 1
        assert np.pi - 0.01 < np.abs(result.fold_angles).max() < np.pi - 1e-4
        assert len(result.intersections) == 0 and len(result.through_pi) == 0
        if ratio == 1.0:
            shapes.append(result.positions / scale)
    # the same fold at every scale, to the barrier's reach (1e-3 of the sheet)
    for other in shapes[1:]:
        np.testing.assert_allclose(other, shapes[0], atol=1e-6)


def test_a_fold_held_short_by_contact_says_so():
    # a thickness of a seventh of the sheet's diameter: the halves stop far from flat, at
    # equilibrium, and the advice names contact (not targets that cannot all be met)
    cp = patterns.single_crease(fold_angle=np.pi)
    thick = fold(cp, contact=0.2)
    assert thick.converged, thick.reason
    assert thick.contact_pairs >= 1 and thick.fold_angle_error_max > 0.1
    (advice,) = thick.advice
    assert "contact pairs within dhat (0.2," in advice and "contact=<dhat>" in advice
    assert "not mutually consistent" not in advice


@pytest.mark.parametrize("solver", ["lbfgs", "dynamics"])
def test_first_order_solvers_stop_where_newton_does(solver):
    # the same equilibrium, reached with their own step limit (and, for dynamics, a time step
    # within the barrier's stability limit)
    cp = patterns.single_crease(fold_angle=np.pi)
    newton = fold(cp, contact=True)
    other = fold(cp, solver=solver, contact=True)
    assert other.converged, other.reason
    assert len(other.intersections) == 0 and len(other.through_pi) == 0
    assert other.contact_pairs >= 1 and 0.0 < other.contact_min_ratio <= 1.0
    shortfall = np.pi - np.abs(other.fold_angles).max()
    assert 1e-4 < shortfall < 0.01
    assert shortfall == pytest.approx(np.pi - np.abs(newton.fold_angles).max(), abs=1e-7)


def test_newton_steps_free_of_the_gauge_with_contact():
    # a sheet in one piece: steps that turn it are taken free and reframed, where the pairs
    # were gathered turned with it; the same state as steps kept in the gauge
    cp = patterns.single_crease(fold_angle=np.pi)
    free = fold(cp, contact=True)
    pinned = fold(cp, solver=Newton(free_turn=np.inf), contact=True)
    assert free.converged and pinned.converged
    assert len(free.intersections) == 0 and 0.0 < free.contact_min_ratio <= 1.0
    np.testing.assert_allclose(free.fold_angles, pinned.fold_angles, atol=1e-9)


T = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def test_two_triangles_pushed_together_stop_at_dhat_and_never_cross():
    # a triangle above the unit triangle, pulled down through it by a spring on its height;
    # descended with the step bound that every contact solve uses
    upper = np.array([[0.2, 0.2, 0.5], [0.6, 0.1, 0.6], [0.1, 0.6, 0.7]])
    x = jnp.asarray(np.concatenate([T, upper]))
    mesh = contact_mesh(np.array([[0, 1, 2], [3, 4, 5]]))
    pairs = all_pairs(mesh, x)
    dhat, kappa, k = 0.05, 1.0, 10.0

    def energy(y):
        pull = 0.5 * k * jnp.sum((y[3:, 2] + 1.0) ** 2)  # rest: 1 below the lower triangle
        return contact_energy(y, pairs, dhat, kappa) + pull

    grad = jax.jit(jax.grad(energy))
    value = jax.jit(energy)
    bound = jax.jit(step_bound)
    fixed = np.zeros((6, 3))
    fixed[3:, 2] = 1.0  # only the upper triangle's heights move
    for _ in range(300):
        g = np.asarray(grad(x)) * fixed
        dx = -0.01 * g
        t = float(bound(x, jnp.asarray(dx), pairs))
        while t > 1e-12 and float(value(x + t * dx)) > float(value(x)):
            t *= 0.5
        x = x + t * dx
        assert len(intersecting_pairs(np.asarray(x), np.array([[0, 1, 2], [3, 4, 5]]), 0.0)) == 0
    lowest = float(np.min(np.asarray(x)[3:, 2]))
    assert 0.0 < lowest <= dhat  # stopped within the barrier's reach, above the other one
    # at rest: the barrier's push balances the spring's pull (the gradient is nearly zero)
    assert np.max(np.abs(np.asarray(grad(x)) * fixed)) < 1e-6 * k


def test_pair_hessians_are_the_barriers_gauss_newton_part_or_whole():
    rng = np.random.default_rng(3)
    upper = np.array([[0.3, 0.3, 0.02], [0.9, 0.2, 0.03], [0.2, 0.8, 0.04]])
    x = jnp.asarray(np.concatenate([T, upper + 0.01 * rng.normal(size=(3, 3))]))
    mesh = contact_mesh(np.array([[0, 1, 2], [3, 4, 5]]))
    pairs = all_pairs(mesh, x)
    dhat, kappa = 0.1, 2.0
    corners, blocks = pair_hessians(x, pairs, dhat, kappa)
    rows = np.asarray(corners)
    gn = np.asarray(blocks).transpose(0, 1, 3, 2, 4).reshape(-1, 12, 12)
    # Newton's exact attempts take the whole Hessian, flag given as a traced value or not
    exact = [
        np.asarray(pair_hessians(x, pairs, dhat, kappa, flag)[1])
        .transpose(0, 1, 3, 2, 4)
        .reshape(-1, 12, 12)
        for flag in (True, jnp.asarray(True))
    ]
    n_pt = pairs.pt.shape[0]
    active = 0
    for r, q in enumerate(rows):
        distance = point_triangle_distance_sq if r < n_pt else edge_edge_distance_sq

        def d2(flat, distance=distance):
            c = flat.reshape(4, 3)
            return distance(c[0], c[1], c[2], c[3])

        corners_r = x[q].reshape(12)
        s = float(d2(corners_r)) / dhat**2
        g = np.asarray(jax.grad(d2)(corners_r))
        # the barrier's second derivative in d2 by the hand formula of b(s) = -(s - 1)^2 ln s
        b2 = -2 * np.log(s) - 4 * (s - 1) / s + (s - 1) ** 2 / s**2 if s < 1 else 0.0
        expected = kappa * b2 / dhat**4 * np.outer(g, g)
        np.testing.assert_allclose(gn[r], expected, rtol=1e-10, atol=1e-12 * np.abs(gn).max())
        assert np.linalg.eigvalsh(gn[r]).min() >= -1e-9 * (1 + np.abs(gn[r]).max())
        # and it is the full Hessian less e'(d2) times the squared distance's Hessian
        full = np.asarray(
            jax.hessian(lambda f, d2=d2: contact_barrier(d2(f), dhat, kappa))(corners_r)
        )
        b1 = -2 * (s - 1) * np.log(s) - (s - 1) ** 2 / s if s < 1 else 0.0
        rest = kappa * b1 / dhat**2 * np.asarray(jax.hessian(d2)(corners_r))
        np.testing.assert_allclose(gn[r] + rest, full, atol=1e-8 * (1 + np.abs(full).max()))
        for h in exact:
            np.testing.assert_allclose(h[r], full, atol=1e-8 * (1 + np.abs(full).max()))
        active += s < 1
    assert active >= 3  # the test saw pairs inside the barrier's reach


def test_contact_switches_and_bad_values():
    cp = patterns.single_crease(fold_angle=np.pi)

    class Unbounded(Lbfgs):  # a solver that does not limit its steps among contact pairs
        supports_contact = False

    from origami_jax.design import equilibrium_fn

    # refused alike by fold and by the design's equilibrium, before anything compiles
    for build in (fold, equilibrium_fn):
        with pytest.raises(ValueError, match="does not bound its steps among contact pairs"):
            build(cp, solver=Unbounded(), contact=True)
        for bad in (0.0, -1.0, float("nan")):
            with pytest.raises(ValueError, match="dhat must be finite and > 0"):
                build(cp, contact=bad)
    bare = fold(patterns.single_crease(fold_angle=1.0))
    assert bare.contact_dhat is None and bare.contact_pairs == 0


def test_a_square_base_from_flat_ends_flat_folded_with_layers_apart(shared_patterns, monkeypatch):
    from origami_jax import io

    fold_module = importlib.import_module("origami_jax.fold")  # the package's fold is the function

    cp = io.load(shared_patterns / "origami-simulator" / "Bases" / "squareBase.svg")
    # room for exactly the flat sheet's pairs (not for all, as a small sheet gets): the folding
    # sheet outgrows it, and the fold starts again with more (counted here), ending where a
    # roomier one does
    overflows = []
    check = fold_module._check_room

    def counted(state, x, structure):
        try:
            check(state, x, structure)
        except fold_module._ContactOverflow:
            overflows.append(state.reference.pairs.capacity)
            raise

    with monkeypatch.context() as m:
        m.setattr(fold_module, "CONTACT_ROOM", 1.0)
        m.setattr(fold_module, "CONTACT_ALL_PAIRS", 0)
        m.setattr(fold_module, "_check_room", counted)
        tight = fold(cp, contact=True)
    assert overflows
    result = fold(cp, contact=True)
    assert tight.converged
    np.testing.assert_allclose(tight.positions, result.positions, atol=1e-8 * cp.diameter)
    assert result.converged, result.reason
    assert len(result.intersections) == 0 and len(result.through_pi) == 0
    assert len(result.collapsed) == 0
    dhat = result.contact_dhat
    assert 0.0 < result.contact_min_ratio <= 1.0 and result.contact_pairs > 0
    # flat-folded: its four layers lie in a slab at most 2 dhat per layer gap thick
    x = result.positions - result.positions.mean(axis=0)
    normal = np.linalg.svd(x, full_matrices=False)[2][2]
    height = x @ normal
    assert np.ptp(height) <= 3 * 2 * dhat
    # the creases fold flat but for the layers' thickness
    assert result.fold_angle_error_max < 0.01
