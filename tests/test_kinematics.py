"""Tests of the exact rigid-folding reference (origami_jax.kinematics)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from origami_jax.geometry import fold_angles
from origami_jax.kinematics import check_rigid, fold_angles_np, rigid_fold, triangle_tree
from origami_jax.pattern import CreasePattern, PatternError
from origami_jax.patterns import (
    degree4_fold_angles,
    degree4_vertex,
    kresling,
    miura_ori,
    single_crease,
    yoshimura,
)

jax.config.update("jax_enable_x64", True)

TOL = 1e-12


_PAD_V, _PAD_H = 256, 512
_kernel = jax.jit(fold_angles)


def kernel_fold_angles(x: np.ndarray, hinges: np.ndarray) -> np.ndarray:
    """``geometry.fold_angles``, jitted once for padded shapes (the tests stay fast)."""
    nv, nh = len(x), len(hinges)
    assert nv <= _PAD_V and nh <= _PAD_H
    xp = np.zeros((_PAD_V, 3))
    xp[:nv] = x
    hp = np.tile(hinges[:1], (_PAD_H, 1))
    hp[:nh] = hinges
    return np.asarray(_kernel(jnp.asarray(xp), jnp.asarray(hp)))[:nh]


def wrapped(a):
    """Angles wrapped to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def lengths(cp: CreasePattern, x: np.ndarray) -> np.ndarray:
    e = cp.mesh.edges
    return np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1)


def assert_exact_fold(cp: CreasePattern, x: np.ndarray, tol: float = TOL) -> None:
    """Every mesh edge keeps its length; every interior edge has its target (geometry kernel)."""
    mesh = cp.mesh
    l0 = lengths(cp, mesh.vertices)
    np.testing.assert_allclose(lengths(cp, x), l0, rtol=tol, atol=0)
    inner = mesh.role != "border"
    assert inner.any()
    rho = kernel_fold_angles(x, mesh.hinges[inner])
    err = np.abs(wrapped(rho - mesh.target[inner]))
    assert err.max() < tol, f"fold angle error {err.max():.3g}"


# -- single crease ---------------------------------------------------------------------------


@pytest.mark.parametrize("rho", [0.3, np.pi / 2, -1.2, np.pi, -np.pi, 0.0])
def test_single_crease_exact(rho):
    cp = single_crease(fold_angle=rho, width=2.0, height=0.7)
    x = rigid_fold(cp)
    assert x.shape == (cp.mesh.num_vertices, 3) and x.dtype == np.float64
    assert_exact_fold(cp, x)
    strain, err = check_rigid(cp, x)
    assert strain < TOL and err < TOL


def test_valley_lifts_toward_plus_z_and_mountain_down():
    for rho, sign in [(0.4, 1.0), (-0.4, -1.0)]:
        cp = single_crease(fold_angle=rho, width=2.0)
        x = rigid_fold(cp)
        z = x[:, 2] * sign
        assert z.max() == pytest.approx(np.sin(0.4), abs=1e-12)  # the moving wing, width 1
        assert z.min() > -1e-15  # the root wing stays in the plane


def test_root_triangle_stays_flat_and_nearest_centroid():
    cp = miura_ori(nx=3, ny=3, fold_angle=1.0)
    root, steps = triangle_tree(cp)
    tris = cp.mesh.triangles
    centroids = cp.mesh.vertices[tris].mean(axis=1)
    centre = cp.vertices.mean(axis=0)
    d = np.linalg.norm(centroids - centre, axis=1)
    assert d[root] == d.min()
    assert len(steps) == len(tris) - 1
    x = rigid_fold(cp)
    np.testing.assert_allclose(x[tris[root]], cp.mesh.vertices[tris[root]], atol=1e-15)


# -- degree-4 vertex -------------------------------------------------------------------------

D4_CASES = [
    (np.pi / 3, np.pi / 4),
    (1.0, 2.0),
    (2.5, 0.3),
    (0.4, 0.9),
    (np.pi / 2, np.pi / 2 - 0.1),
]


@pytest.mark.parametrize("branch", [1, 2])
@pytest.mark.parametrize("alpha,beta", D4_CASES)
@pytest.mark.parametrize("rho1", [0.3, -1.1, 2.0, np.pi])
def test_degree4_rigid_and_closed_forms(alpha, beta, rho1, branch):
    cp = degree4_vertex(alpha=alpha, beta=beta, fold_angle=rho1, branch=branch, radius=1.3)
    x = rigid_fold(cp)
    assert_exact_fold(cp, x)
    # the four creases are pattern edges 0..3 (= mesh edges 0..3); their folded angles obey
    # the anchors' closed forms
    rho = fold_angles_np(x, cp.mesh.hinges[:4])
    if branch == 1:
        k = -np.cos((alpha + beta) / 2) / np.cos((alpha - beta) / 2)
        assert abs(wrapped(rho[2] - rho[0])) < TOL
        assert abs(wrapped(rho[3] + rho[1])) < TOL
    else:
        k = np.sin((alpha + beta) / 2) / np.sin((alpha - beta) / 2)
        assert abs(wrapped(rho[2] + rho[0])) < TOL
        assert abs(wrapped(rho[3] - rho[1])) < TOL
    assert abs(wrapped(rho[0] - rho1)) < TOL
    if abs(rho1) < np.pi:
        assert np.tan(rho[1] / 2) == pytest.approx(k * np.tan(rho1 / 2), rel=1e-11, abs=1e-13)


@pytest.mark.parametrize("branch", [1, 2])
def test_degree4_wrong_angles_are_detected(branch):
    """An inconsistent angle set cannot close the vertex: check_rigid sees the strain."""
    alpha, beta, rho1 = 1.0, 0.6, 1.2
    cp = degree4_vertex(alpha=alpha, beta=beta, fold_angle=rho1, branch=branch)
    rho = np.array(cp.mesh.target)
    rho[1] += 0.05
    strain, err = check_rigid(cp, rigid_fold(cp, rho), rho)
    assert strain > 1e-3 or err > 1e-3
    # the other branch's crease-2 angle does not fit this branch's other creases either
    other = degree4_fold_angles(alpha, beta, rho1, 3 - branch)
    rho2 = np.array(cp.mesh.target)
    rho2[1] = other[1]
    strain, err = check_rigid(cp, rigid_fold(cp, rho2), rho2)
    assert strain > 1e-3 or err > 1e-3


# -- Miura-ori -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "nx,ny,a,b,gamma,rho",
    [
        (4, 4, 1.0, 1.0, np.radians(60), np.pi / 2),
        (3, 5, 1.3, 0.7, np.radians(40), 2.0),
        (5, 2, 0.6, 1.8, np.radians(75), 0.7),
        (2, 3, 1.0, 2.0, 1.0, -1.2),
        (4, 3, 1.0, 1.0, np.radians(30), np.pi),
        (1, 1, 1.0, 1.0, np.radians(50), 1.0),
        (6, 6, 0.9, 1.1, np.radians(85), 2.9),
    ],
)
def test_miura_rigid(nx, ny, a, b, gamma, rho):
    cp = miura_ori(nx=nx, ny=ny, a=a, b=b, sector_angle=gamma, fold_angle=rho)
    x = rigid_fold(cp)
    assert_exact_fold(cp, x)
    strain, err = check_rigid(cp, x)
    assert strain < TOL and err < TOL


def test_miura_with_wrong_straight_angles_is_not_rigid():
    cp = miura_ori(nx=4, ny=4, fold_angle=1.5)
    mesh = cp.mesh
    rho = np.array(mesh.target)
    straight = np.abs(np.abs(rho) - np.abs(rho).max()) > 1e-9
    straight &= mesh.role == "driven"
    assert straight.any()
    rho[straight] *= 1.1
    strain, _ = check_rigid(cp, rigid_fold(cp, rho), rho)
    assert strain > 1e-4


# -- Yoshimura, Kresling ---------------------------------------------------------------------


@pytest.mark.parametrize(
    "n,m,rho,w,h", [(4, 3, np.pi / 2, 1.0, 1.0), (3, 4, 2.5, 0.7, 1.4), (2, 2, -0.8, 1.5, 0.4)]
)
def test_yoshimura_rigid(n, m, rho, w, h):
    cp = yoshimura(n=n, m=m, fold_angle=rho, width=w, height=h)
    assert_exact_fold(cp, rigid_fold(cp))


@pytest.mark.parametrize("alternate", [False, True])
def test_kresling_rigid(alternate):
    cp = kresling(n=7, stories=3, height=1.1, twist=1.4, alternate=alternate)
    assert_exact_fold(cp, rigid_fold(cp))


# -- arguments ---------------------------------------------------------------------------------


def test_rigid_fold_argument_errors():
    cp = single_crease()
    with pytest.raises(PatternError, match="one per mesh edge"):
        rigid_fold(cp, np.zeros(3))
    with pytest.raises(PatternError, match="finite"):
        rigid_fold(cp, np.full(cp.mesh.num_edges, np.nan))
    with pytest.raises(PatternError, match="positions must have shape"):
        check_rigid(cp, np.zeros((2, 3)))


def test_rigid_fold_refuses_a_pattern_in_pieces():
    cp = CreasePattern(
        vertices=[[0, 0], [1, 0], [2, 0], [2, 1], [1, 1], [0, 1]],
        edges=[[0, 1], [1, 2], [2, 3], [3, 4], [4, 5], [5, 0], [1, 4]],
        faces=[[0, 1, 4, 5], [1, 2, 3, 4]],
        assignments="BBBBBBC",
    )
    with pytest.raises(PatternError, match="pieces"):
        rigid_fold(cp)


def test_fold_angles_np_matches_geometry_kernel():
    rng = np.random.default_rng(0)
    cp = miura_ori(nx=3, ny=3)
    x = cp.mesh.vertices + 0.3 * rng.standard_normal(cp.mesh.vertices.shape)
    inner = cp.mesh.role != "border"
    ours = fold_angles_np(x, cp.mesh.hinges[inner])
    ref = kernel_fold_angles(x, cp.mesh.hinges[inner])
    direct = np.asarray(fold_angles(jnp.asarray(x), jnp.asarray(cp.mesh.hinges[inner])))
    np.testing.assert_allclose(ref, direct, atol=1e-13)
    np.testing.assert_allclose(ours, ref, atol=1e-13)
    assert np.abs(ours).max() > 0.1  # the perturbation really folds something
