"""Tests of the barriers (origami_jax.barrier) and of the energy terms built on them."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from origami_jax import fold, patterns
from origami_jax.barrier import (
    HINGE_GAP,
    S_MIN,
    area_barrier,
    hinge_barrier,
    ipc,
    rest_areas,
    signed_areas,
    triangle_normals,
)
from origami_jax.energy import (
    Barriers,
    Reference,
    barrier_distances,
    energy,
    initial_reference,
    make_params,
    make_structure,
    needs_barriers,
    triangle_terms,
)
from origami_jax.geometry import fold_angles
from origami_jax.kinematics import rigid_fold
from origami_jax.solvers.newton import UPPER_PAIRS, element_blocks, hessian_elements


def test_ipc_barrier_closed_form_and_its_derivatives():
    s = np.array([0.05, 0.3, 0.5, 0.9, 0.999])
    b, b1, b2 = (np.asarray(v) for v in ipc(jnp.asarray(s)))
    np.testing.assert_allclose(b, -((s - 1) ** 2) * np.log(s), rtol=1e-14)
    np.testing.assert_allclose(b1, -2 * (s - 1) * np.log(s) - (s - 1) ** 2 / s, rtol=1e-13)
    np.testing.assert_allclose(
        b2, -2 * np.log(s) - 4 * (s - 1) / s + (s - 1) ** 2 / s**2, rtol=1e-13
    )
    assert b[2] == pytest.approx(0.25 * np.log(2.0), rel=1e-14)
    # autodiff of the value gives the written-out derivatives, on both sides of S_MIN
    grid = jnp.array([-0.5, -1e-3, 0.0, 0.5 * S_MIN, 2 * S_MIN, 0.2, 0.7, 0.99, 1.0, 1.5])
    d1 = jax.vmap(jax.grad(lambda t: ipc(t)[0]))(grid)
    d2 = jax.vmap(jax.grad(jax.grad(lambda t: ipc(t)[0])))(grid)
    np.testing.assert_allclose(d1, ipc(grid)[1], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(d2, ipc(grid)[2], rtol=1e-12, atol=1e-12)


def test_ipc_barrier_limits():
    # zero with both derivatives at the edge of its zone and beyond: inactive, it changes nothing
    for v in ipc(jnp.array([1.0, 1.2, 50.0])):
        np.testing.assert_array_equal(np.asarray(v), 0.0)
    # convex, decreasing, unbounded towards the wall; below S_MIN its Taylor continuation
    # (continuous with its first two derivatives) is finite, also past the wall
    s = jnp.array([1e-1, 1e-2, S_MIN * 1.0001])
    b, b1, b2 = ipc(s)
    assert np.all(np.diff(np.asarray(b)) > 0) and np.all(np.asarray(b1) < 0)
    assert np.all(np.asarray(b2) > 0)
    for k in range(3):
        below, above = ipc(jnp.array([S_MIN * (1 - 1e-9), S_MIN * (1 + 1e-9)]))[k]
        assert float(below) == pytest.approx(float(above), rel=1e-6)
    past = np.asarray(ipc(jnp.array([0.0, -1.0]))[0])
    assert np.all(np.isfinite(past)) and past[1] > past[0] > float(ipc(jnp.array(S_MIN))[0])


def test_hinge_barrier_acts_only_past_pi_and_is_symmetric():
    w, gap = 0.3, 0.01
    rho = jnp.array([0.0, 2.0, np.pi, -np.pi, np.pi + 0.5 * gap, -np.pi - 0.5 * gap])
    e, d1, d2 = (np.asarray(v) for v in hinge_barrier(rho, w, gap))
    np.testing.assert_array_equal(e[:4], 0.0)
    np.testing.assert_array_equal(d1[:4], 0.0)
    assert e[4] == pytest.approx(w * gap * 0.25 * np.log(2.0), rel=1e-12)
    assert e[4] == e[5] and d1[4] == -d1[5] and d1[4] > 0  # its force -d1 pushes back to pi
    grad = jax.vmap(jax.grad(lambda r: hinge_barrier(r, w, gap)[0]))(rho)
    np.testing.assert_allclose(grad, d1, rtol=1e-12)
    curv = jax.vmap(jax.grad(jax.grad(lambda r: hinge_barrier(r, w, gap)[0])))(rho)
    np.testing.assert_allclose(curv, d2, rtol=1e-10)


def test_area_barrier_acts_below_its_floor():
    w, floor = 2.0, 0.25
    ratio = jnp.array([1.0, 0.25, 0.125, 0.0, -0.1])
    e, d1, _ = (np.asarray(v) for v in area_barrier(ratio, w, floor))
    np.testing.assert_array_equal(e[:2], 0.0)
    assert e[2] == pytest.approx(w * 0.25 * np.log(2.0), rel=1e-12)
    assert np.all(np.isfinite(e)) and e[4] > e[3] > e[2] and np.all(d1[2:] < 0)


def test_rest_areas_and_signed_areas():
    sides = jnp.array([[3.0, 4.0, 5.0], [1.0, 1.0, 1.0], [1.0, 2.0, 3.0], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(
        rest_areas(sides), [6.0, np.sqrt(3) / 4, 0.0, 0.0], rtol=1e-14, atol=1e-15
    )
    x = jnp.array([[0.0, 0, 0], [2, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    tri = jnp.array([[0, 1, 2]])
    up = triangle_normals(x, tri)
    np.testing.assert_allclose(up, [[0, 0, 1.0]])
    assert float(signed_areas(x, tri, up)[0]) == pytest.approx(1.0)
    # the apex moved through the base line: the triangle turned over, its area negative
    flipped = x.at[2].set(jnp.array([0.0, -0.5, 0.0]))
    assert float(signed_areas(flipped, tri, up)[0]) == pytest.approx(-0.5)
    assert float(signed_areas(x.at[2].set(jnp.array([1.0, 0, 0])), tri, up)[0]) == 0.0


def test_barriers_are_built_where_a_crease_folds_nearly_flat():
    assert needs_barriers(patterns.single_crease(fold_angle=np.pi).mesh)
    assert not needs_barriers(patterns.miura_ori(3, 3).mesh)
    structure = make_structure(patterns.miura_ori(3, 3).mesh)
    assert structure.barriers == Barriers(0.0, 0.0) and structure.triangles.shape == (0, 3)
    forced = make_structure(patterns.miura_ori(3, 3).mesh, True)
    assert forced.barriers == Barriers() and forced.triangles.shape[0] > 0


def test_inactive_barriers_change_no_energy_or_gradient():
    """On a rigid Miura-ori fold (every crease short of pi, every triangle its rest area) the
    energy is that of the springs alone, exactly, and so is its gradient (to rounding)."""
    cp = patterns.miura_ori(3, 3, fold_angle=2.5)
    x = jnp.asarray(rigid_fold(cp, 0.9 * cp.mesh.target) * 1.001)
    params = make_params(cp)
    plain, barred = make_structure(cp.mesh, False), make_structure(cp.mesh, True)
    for structure in (plain, barred):
        assert structure.hinges.shape[0] > 0
    ref = initial_reference(x, barred, params)
    assert float(energy(x, plain, params)) == float(energy(x, barred, params, ref))
    g = np.asarray(jax.grad(energy)(x, plain, params))
    # equal to rounding: the sums are ordered differently once more terms are compiled in
    np.testing.assert_allclose(
        jax.grad(energy)(x, barred, params, ref), g, rtol=0, atol=1e-15 * np.abs(g).max()
    )


def _squeezed_single_crease():
    """A single crease folded 0.3 rad past pi (through itself) with one triangle squeezed to a
    tenth of its area: both barriers active."""
    cp = patterns.single_crease(fold_angle=np.pi)
    mesh = cp.mesh
    structure = make_structure(mesh, Barriers(hinge_gap=0.5, area_floor=0.5))
    params = make_params(cp, stiffness=dict(axial=1.0, facet=0.1, crease=0.05))
    x = rigid_fold(cp, np.where(mesh.role == "driven", np.pi + 0.3, 0.0))
    tri = np.asarray(mesh.triangles[0])
    x[tri[2]] = 0.9 * x[tri[0]] + 0.1 * x[tri[2]] + 0.0 * x[tri[1]]
    x = jnp.asarray(x)
    angles = fold_angles(x, structure.hinges, 0.5 * jnp.pi * jnp.ones(structure.hinges.shape[0]))
    return cp, structure, params, x, Reference(angles, triangle_normals(x, structure.triangles))


def test_gap_scale_widens_the_hinge_barrier_as_a_wider_structure_gap():
    """``FoldParams.gap_scale`` (what the path widens the gap by, traced so the path compiles
    once) gives exactly the energy, gradient and barrier distances of a structure built with
    the gap that many times wider."""
    cp, structure, params, x, ref = _squeezed_single_crease()
    wide = make_structure(cp.mesh, Barriers(hinge_gap=0.5 * 1.6, area_floor=0.5))
    scaled = params._replace(gap_scale=jnp.asarray(1.6))
    assert float(energy(x, structure, scaled, ref)) == pytest.approx(
        float(energy(x, wide, params, ref)), rel=1e-13
    )
    assert float(energy(x, structure, scaled, ref)) != pytest.approx(
        float(energy(x, structure, params, ref)), rel=1e-3
    )
    np.testing.assert_allclose(
        jax.grad(energy)(x, structure, scaled, ref),
        jax.grad(energy)(x, wide, params, ref),
        rtol=1e-12,
        atol=1e-15,
    )
    np.testing.assert_allclose(
        barrier_distances(x, structure, scaled, ref),
        barrier_distances(x, wide, params, ref),
        rtol=1e-13,
    )


def test_barrier_hessian_blocks_are_exact_and_the_convex_part_is_psd():
    cp, structure, params, x, ref = _squeezed_single_crease()
    ratio = np.asarray(triangle_terms(x, structure, params, ref.normals)[0])
    assert ratio.min() < 0.5  # the area barrier is active
    assert np.abs(np.asarray(ref.angles)).max() > np.pi  # and the hinge barrier
    v = x.shape[0]

    def assembled(exact):
        out = jnp.zeros((v, v, 3, 3))
        blocks = element_blocks(x, structure, params, ref, exact)
        for part, e in zip(blocks, hessian_elements(structure), strict=True):
            out = out.at[e[:, :, None], e[:, None, :]].add(part)
        return np.asarray(jnp.swapaxes(out, 1, 2).reshape(3 * v, 3 * v))

    full = np.asarray(jax.hessian(lambda y: energy(y, structure, params, ref))(x))
    full = full.reshape(3 * v, 3 * v)
    np.testing.assert_allclose(assembled(True), full, rtol=1e-9, atol=1e-9 * np.abs(full).max())
    assert np.linalg.eigvalsh(assembled(False)).min() >= -1e-9 * np.abs(full).max()
    upper = element_blocks(x, structure, params, ref, True, upper=True)
    for u, f in zip(upper, element_blocks(x, structure, params, ref, True), strict=True):
        np.testing.assert_array_equal(u, f[(slice(None), *UPPER_PAIRS[f.shape[1]])])


@pytest.mark.parametrize("solver", ["newton", "lbfgs", "dynamics"])
def test_a_crease_started_through_itself_is_brought_back_by_its_barrier(solver):
    cp = patterns.single_crease(fold_angle=np.pi)
    start = rigid_fold(cp, np.where(cp.mesh.role == "driven", 3.4, 0.0))
    k = cp.mesh.edges_with_role("driven")[0]
    result = fold(cp, start=start, solver=solver)
    assert result.converged, result.reason
    assert result.barriers == Barriers()
    assert abs(result.fold_angles[k]) <= np.pi + HINGE_GAP and len(result.through_pi) == 0
    assert result.fold_angles[k] == pytest.approx(np.pi, abs=1e-6)


def test_design_gradient_through_an_active_hinge_barrier():
    """A crease driven past pi (percent 1.02) rests against its barrier at equilibrium; the
    implicit gradient of a loss of the folded positions in the target, through the barrier's
    exact Hessian, matches central differences (float64; the active set does not change). A
    wide zone (0.2 rad) keeps the held crease compliant enough for differences to see."""
    from origami_jax.design import equilibrium_fn

    cp = patterns.single_crease(fold_angle=np.pi)
    params = make_params(cp, percent=1.02, stiffness=dict(axial=1.0, facet=0.02, crease=0.02))
    solve = equilibrium_fn(cp, tol=1e-12, barriers=Barriers(hinge_gap=0.2, area_floor=0.25))
    w = jnp.asarray(np.random.default_rng(4).normal(size=(cp.mesh.num_vertices, 3)))
    structure = make_structure(cp.mesh, Barriers(hinge_gap=0.2, area_floor=0.25))

    def loss(t, start):
        x, info = solve(params._replace(target=t), start)
        return jnp.vdot(w, x), (x, info)

    value_and_grad = jax.jit(jax.value_and_grad(loss, has_aux=True))
    (_, (x0, info)), g = value_and_grad(params.target, jnp.asarray(cp.mesh.vertices))
    assert bool(info.ok), info
    rho = float(fold_angles(x0, structure.hinges, jnp.full(1, 3.0))[0])
    assert np.pi < rho < np.pi + 0.2  # inside the barrier's zone: it is active
    t = params.target

    def central(h):
        return float(value_and_grad(t + h, x0)[0][0] - value_and_grad(t - h, x0)[0][0]) / (2 * h)

    # Richardson's extrapolation of two central differences cancels their h^2 error, large
    # here: the barrier's stiffness changes fast across its zone
    fd = (4 * central(5e-5) - central(1e-4)) / 3
    assert abs(float(g[0]) - fd) <= 1e-6 * abs(fd), (g, fd)


def test_free_hinges_get_the_hinge_barrier_only():
    """A hinge without a spring (``U``) has no energy until it is folded through itself."""
    from origami_jax import CreasePattern

    cp = CreasePattern(
        vertices=[[0, 0], [1, 0], [1, 1], [0, 1]],
        edges=[[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]],
        faces=[[0, 1, 2], [0, 2, 3]],
        assignments="BBBBU",
    )
    barred = make_structure(cp.mesh, Barriers(hinge_gap=0.5, area_floor=0.25))
    plain = make_structure(cp.mesh, False)
    assert barred.num_free == 1 and barred.free.shape[0] == 0 and barred.num_facets == 0
    assert plain.num_free == 0 and plain.free.shape[0] == 1 and plain.hinges.shape[0] == 0
    params = make_params(cp)
    k = cp.mesh.edges_with_role("free")[0]
    for angle, active in ((2.0, False), (np.pi + 0.25, True)):
        x = jnp.asarray(rigid_fold(cp, np.where(np.arange(cp.mesh.num_edges) == k, angle, 0.0)))
        ref = initial_reference(x, barred, params)._replace(angles=jnp.array([angle]))
        e = float(energy(x, barred, params, ref))
        assert (e > 1e-12) == active, (angle, e)
        assert float(energy(x, plain, params)) < 1e-20
