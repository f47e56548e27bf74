"""Energy and dihedral: zero where it must be, invariant, differentiable, continuous through pi."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from origami_jax import CreasePattern
from origami_jax.energy import (
    energy,
    make_params,
    make_structure,
)
from origami_jax.geometry import (
    atan2_dihedral,
    dihedral_angles,
    dihedral_gradients,
    dihedral_hessians,
    fold_angles,
)

SQUARE = dict(
    vertices=[[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0], [0.5, 1], [0.5, 0.5]],
    edges=[[0, 4], [4, 1], [1, 2], [2, 5], [5, 3], [3, 0], [4, 6], [6, 5], [0, 6], [6, 2]],
    faces=[[0, 4, 6], [0, 6, 5, 3], [4, 1, 2, 6], [6, 2, 5]],
)


def square(assign="BBBBBBVVMF", angles=(0, 0, 0, 0, 0, 0, 1.0, 1.0, -2.0, 0)):
    return CreasePattern(**SQUARE, assignments=assign, fold_angles=angles)


def rotation(seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def hinge(rho):
    """Two unit triangles on the edge (0,0,0)-(0,1,0), folded to fold angle rho."""
    t = rho / 2
    return jnp.array(
        [[0, 0, 0], [0, 1, 0], [-np.cos(t), 0.5, np.sin(t)], [np.cos(t), 0.5, np.sin(t)]]
    ), jnp.array([[0, 1, 2, 3]])


def test_zero_on_flat_sheet_with_flat_targets():
    cp = square(angles=np.zeros(10), assign="BBBBBBUUUF")
    structure, params = make_structure(cp.mesh), make_params(cp)
    assert float(energy(jnp.asarray(cp.mesh.vertices), structure, params)) == 0.0
    # ... and not zero once the targets are not flat
    cp2 = square()
    assert (
        float(energy(jnp.asarray(cp2.mesh.vertices), make_structure(cp2.mesh), make_params(cp2)))
        > 1e-4
    )


def test_invariant_under_rigid_motion():
    cp = square()
    structure, params = make_structure(cp.mesh), make_params(cp)
    x = cp.mesh.vertices + 0.2 * np.random.default_rng(0).normal(size=cp.mesh.vertices.shape)
    e0 = float(energy(jnp.asarray(x), structure, params))
    for seed in range(3):
        y = x @ rotation(seed).T + np.array([3.0, -1.0, 7.0]) * seed
        assert float(energy(jnp.asarray(y), structure, params)) == pytest.approx(e0, rel=1e-12)
    mirrored = x * np.array([1, 1, -1])  # a mirror turns valleys into mountains: not invariant
    assert abs(float(energy(jnp.asarray(mirrored), structure, params)) - e0) > 1e-6


def near_full_fold(cp, rng):
    """The square folded about its middle crease to within 1e-3 rad of a full valley fold."""
    from origami_jax.kinematics import rigid_fold

    angles = np.where(cp.mesh.role == "driven", np.pi - 1e-3, 0.0) * (cp.mesh.target != 0)
    return rigid_fold(cp, angles) + 1e-4 * rng.normal(size=cp.mesh.vertices.shape)


@pytest.mark.parametrize("scale", [0.3, 1.0, "full fold"])
def test_gradient_matches_central_differences(scale):
    cp = square(angles=(0, 0, 0, 0, 0, 0, np.pi, np.pi, -2.0, 0), assign="BBBBBBVVMF")
    structure, params = make_structure(cp.mesh), make_params(cp)
    rng = np.random.default_rng(1)
    if scale == "full fold":
        cp = square(angles=(0, 0, 0, 0, 0, 0, np.pi, np.pi, 0, 0), assign="BBBBBBVVUF")
        structure, params = make_structure(cp.mesh), make_params(cp)
        x = near_full_fold(cp, rng)
    else:
        x = cp.mesh.vertices + scale * rng.normal(size=cp.mesh.vertices.shape)
    f = jax.jit(lambda y: energy(y, structure, params))
    g = np.asarray(jax.grad(f)(jnp.asarray(x)))
    h = 1e-6
    fd = np.zeros_like(x)
    for idx in np.ndindex(x.shape):
        d = np.zeros_like(x)
        d[idx] = h
        fd[idx] = (float(f(jnp.asarray(x + d))) - float(f(jnp.asarray(x - d)))) / (2 * h)
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-6 * np.abs(g).max())


def test_check_grads():
    cp = square()
    structure, params = make_structure(cp.mesh), make_params(cp)
    x = cp.mesh.vertices + 0.3 * np.random.default_rng(2).normal(size=cp.mesh.vertices.shape)
    check_grads(
        lambda y: energy(y, structure, params), (jnp.asarray(x),), order=1, modes=["fwd", "rev"]
    )


@pytest.mark.parametrize("rho", [np.pi - 1e-7, -np.pi + 1e-7, np.pi])
def test_gradient_near_full_fold(rho):
    x, h = hinge(rho)
    ref = jnp.array([np.pi * np.sign(rho) if rho != np.pi else np.pi])

    @jax.jit
    def f(y):
        return jnp.sum((fold_angles(y, h, ref) - 0.5) ** 2)

    g = jax.grad(f)(x)
    assert np.isfinite(np.asarray(g)).all()
    check_grads(f, (x,), order=1, modes=["fwd", "rev"], eps=1e-7)


def test_gradient_finite_on_flat_sheet_and_collapsed_input():
    cp = square()
    structure, params = make_structure(cp.mesh), make_params(cp)
    for x in [cp.mesh.vertices, np.zeros_like(cp.mesh.vertices)]:
        g = jax.grad(energy)(jnp.asarray(x), structure, params)
        assert np.isfinite(np.asarray(g)).all()


def test_dihedral_matches_built_hinges():
    angles = np.linspace(-np.pi, np.pi, 37)[1:]  # (-pi, pi]
    for rho in angles:
        x, h = hinge(rho)
        got = float(fold_angles(x, h)[0])
        assert got == pytest.approx(rho, abs=1e-12)
        # the seed's dihedral theta = pi - rho and the valley sign: wings above the plane
        assert (rho > 0) == (float(x[2, 2]) > 0) or abs(rho) < 1e-12


def test_closed_form_dihedral_gradient_and_its_jacobian_match_autodiff():
    rng = np.random.default_rng(3)
    corners = [hinge(rho)[0] for rho in (-np.pi + 1e-3, -2.0, 0.0, 1e-9, 1.0, 3.1)]
    corners += [jnp.asarray(rng.normal(size=(4, 3))) for _ in range(20)]
    corners += [1e-3 * c for c in corners[:3]] + [1e3 * c for c in corners[:3]]
    p = jnp.stack(corners)

    def one(q):
        return atan2_dihedral(q[None])[0]

    def closed(q):
        return dihedral_gradients(q[None])[0]

    def custom(q):  # differentiates through dihedral_angles' custom_jvp
        return dihedral_angles(q[None], jnp.ones(1))[0]

    @jax.jit  # compiled: op by op, the Hessians take several times longer
    def derivatives(p):
        g, h = jax.vmap(jax.grad(one))(p), jax.vmap(jax.hessian(one))(p)
        got = dihedral_gradients(p), jax.vmap(jax.jacfwd(closed))(p)
        custom_got = jax.vmap(jax.grad(custom))(p), jax.vmap(jax.hessian(custom))(p)
        # dihedral_hessians is block-major [h, a, b, i, j]; jax.hessian gives [h, a, i, b, j]
        return g, h, got, custom_got, (got[0], jnp.swapaxes(dihedral_hessians(p), 2, 3))

    g, h, *got = derivatives(p)
    scale_g = jnp.max(jnp.abs(g), axis=(1, 2), keepdims=True)
    scale_h = jnp.max(jnp.abs(h), axis=(1, 2, 3, 4), keepdims=True)
    for got_g, got_h in got:
        assert float(jnp.max(jnp.abs(got_g - g) / scale_g)) < 1e-12
        assert float(jnp.max(jnp.abs(got_h - h) / scale_h)) < 1e-10
    x = jnp.asarray(np.random.default_rng(4).normal(size=(5, 3)))
    hinges = jnp.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    assert float(jnp.max(jnp.abs(fold_angles(x, hinges) - atan2_dihedral(x[hinges])))) == 0.0


def test_dihedral_continuous_through_pi():
    reference = jnp.array([3.0])
    for rho in np.linspace(3.0, 3.4, 41):  # passes through pi
        x, h = hinge(rho)
        got = float(fold_angles(x, h, reference)[0])
        assert got == pytest.approx(rho, abs=1e-12)
        reference = jnp.array([got])
    # the principal value jumps there; the unwrapped one did not
    x, h = hinge(3.3)
    assert float(fold_angles(x, h)[0]) == pytest.approx(3.3 - 2 * np.pi, abs=1e-12)


def test_reference_does_not_change_gradient():
    cp = square()
    structure, params = make_structure(cp.mesh), make_params(cp)
    x = jnp.asarray(cp.mesh.vertices + 0.1)
    ref = jnp.zeros(structure.hinges.shape[0])
    ref2 = fold_angles(x, structure.hinges, ref)
    g1 = jax.grad(energy)(x, structure, params, ref)
    g2 = jax.grad(energy)(x, structure, params, ref2)
    np.testing.assert_allclose(np.asarray(g1), np.asarray(g2), rtol=1e-12, atol=1e-15)


def test_terms_the_scene_lacks_are_not_built():
    cp = CreasePattern(
        vertices=[[0, 0], [1, 0], [1, 1], [0, 1]],
        edges=[[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]],
        faces=[[0, 1, 2], [0, 2, 3]],
        assignments="BBBBV",
    )
    structure = make_structure(cp.mesh)
    assert structure.num_facets == 0 and structure.hinges.shape == (1, 4)
    jaxpr = str(jax.make_jaxpr(energy)(jnp.asarray(cp.mesh.vertices), structure, make_params(cp)))
    assert jaxpr.count("atan2") == 1  # one torsion term: creases only


def test_energy_differentiable_in_parameters():
    cp = square()
    structure, params = make_structure(cp.mesh), make_params(cp)
    x = jnp.asarray(cp.mesh.vertices + 0.05)
    g = jax.grad(lambda p: energy(x, structure, p))(params)
    assert np.isfinite(np.asarray(g.target)).all() and float(jnp.abs(g.target).max()) > 0
    batched = jax.vmap(lambda pc: energy(x, structure, params._replace(percent=pc)))(
        jnp.linspace(0, 1, 5)
    )
    assert batched.shape == (5,) and len(set(np.round(np.asarray(batched), 12))) == 5


def test_collapsed_wing_moves_along_the_other_wings_normal():
    # wing 2 lies on the axis 0 -> 1: its normal is undefined, the atan2 formula's derivative
    # is an artefact there; the closed form moves it out along wing 3's normal
    p = jnp.array([[[0.0, 0, 0], [0, 1, 0], [0, 0.5, 0], [0.8, 0.5, 0.3]]])
    g = np.asarray(dihedral_gradients(p)[0])
    n_right = np.cross(np.asarray(p[0, 3]), [0.0, 1.0, 0.0])
    assert np.allclose(g[2], n_right / np.linalg.norm(n_right))  # axis length 1
    assert np.allclose(g.sum(axis=0), 0.0, atol=1e-15)  # translations cost nothing
    assert np.isfinite(g).all() and np.linalg.norm(g[3]) > 0
    both = p.at[0, 3].set(jnp.array([0.0, 0.3, 0.0]))  # both wings collapsed: no direction
    assert np.allclose(np.asarray(dihedral_gradients(both)), 0.0)
    # the closed-form Hessian stays finite, the collapsed wing's own rows zero
    for q in (p, both):
        assert np.isfinite(np.asarray(dihedral_hessians(q))).all()
    assert np.allclose(np.asarray(dihedral_hessians(p)[0, 2]), 0.0)


def test_kernels_take_a_trailing_batch_axis():
    """The batch-innermost layout of fold_batch: every kernel given (..., B) arrays equals it
    vmapped over a leading batch; batch_innermost's vmap rule runs them so, falls back to a plain
    vmap for per-member index arrays, and leaves an unbatched call alone (jacfwd)."""
    from origami_jax.energy import FoldParams, Stiffness, residuals
    from origami_jax.solvers.innermost import batch_innermost

    cp = square()
    structure, params = make_structure(cp.mesh), make_params(cp)
    rng = np.random.default_rng(3)
    x = jnp.asarray(cp.mesh.vertices) + 0.2 * jnp.asarray(rng.normal(size=(3, 7, 3)))
    # per member: rest lengths and the facet stiffness; the rest shared
    scale = jnp.asarray([1.0, 1.1, 0.9])
    facet = jnp.asarray([0.01, 0.02, 0.05])
    batched = params._replace(
        rest_length=scale[:, None] * params.rest_length,
        stiffness=params.stiffness._replace(facet=facet),
    )
    axes = FoldParams(None, None, 0, Stiffness(None, 0, None))
    innermost = params._replace(  # the same, batch last: (E, B), (B,); shared arrays (n, 1)
        target=params.target[:, None],
        rest_length=batched.rest_length.T,
        stiffness=params.stiffness._replace(facet=facet),
    )
    x_last = jnp.moveaxis(x, 0, -1)
    p = x[:, structure.hinges]
    for kernel in (dihedral_angles, dihedral_gradients, dihedral_hessians):
        got = np.moveaxis(np.asarray(kernel(jnp.moveaxis(p, 0, -1))), -1, 0)
        np.testing.assert_allclose(got, jax.vmap(kernel)(p), atol=1e-12)
    per_member = jax.vmap(lambda x, prm: energy(x, structure, prm), in_axes=(0, axes))
    expected = per_member(x, batched)
    np.testing.assert_allclose(energy(x_last, structure, innermost), expected, rtol=1e-12)
    r, w = residuals(x_last, structure, innermost)
    r0, w0 = jax.vmap(lambda x, prm: residuals(x, structure, prm), in_axes=(0, axes))(x, batched)
    np.testing.assert_allclose(r.T, r0, atol=1e-12)
    np.testing.assert_allclose(w.T, w0, rtol=1e-12)

    wrapped = batch_innermost(energy, index_args=(1,))
    got = jax.vmap(lambda x, prm: wrapped(x, structure, prm), in_axes=(0, axes))(x, batched)
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    stacked = jax.tree.map(lambda a: jnp.stack([a] * 3), structure)  # per-member indices
    got = jax.vmap(wrapped, in_axes=(0, 0, axes))(x, stacked, batched)
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    grads = jax.vmap(jax.grad(energy), in_axes=(0, None, axes))(x, structure, batched)
    jac = jax.jacfwd(lambda y: wrapped(y, structure, params))(x[0])
    np.testing.assert_allclose(jac, jax.grad(energy)(x[0], structure, params), rtol=1e-10)
    jacs = jax.vmap(jax.jacfwd(lambda y, prm: wrapped(y, structure, prm)), in_axes=(0, axes))
    np.testing.assert_allclose(jacs(x, batched), grads, rtol=1e-10)
