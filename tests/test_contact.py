"""Self-contact's building blocks (origami_jax.contact): exact distances against closed forms
and sampled minima, finite gradients at degenerate configurations, the barrier against its hand
formulas, the broad phase against brute force, and the step bound."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from origami_jax import contact, patterns
from origami_jax.barrier import S_MIN
from origami_jax.contact import (
    EDGE_EDGE_CASES,
    POINT_TRIANGLE_CASES,
    Capacity,
    all_pairs,
    allocate,
    build_pairs,
    contact_energy,
    contact_mesh,
    contact_report,
    needs_update,
    reallocate,
    step_bound,
)
from origami_jax.energy import make_params
from origami_jax.intersections import intersecting_pairs
from origami_jax.kinematics import rigid_fold

jax.config.update("jax_enable_x64", True)


def _pt(q):
    return contact.point_triangle_distance_sq(
        q[..., 0, :], q[..., 1, :], q[..., 2, :], q[..., 3, :]
    )


def _ee(q):
    return contact.edge_edge_distance_sq(q[..., 0, :], q[..., 1, :], q[..., 2, :], q[..., 3, :])


# compiled once for the module: (n, 4, 3) corner sets in, per row out
PT_D2 = jax.jit(_pt)
EE_D2 = jax.jit(_ee)
PT_TYPE = jax.jit(
    lambda q: contact.point_triangle_distance_type(q[:, 0], q[:, 1], q[:, 2], q[:, 3])
)
EE_TYPE = jax.jit(lambda q: contact.edge_edge_distance_type(q[:, 0], q[:, 1], q[:, 2], q[:, 3]))
PT_GRAD = jax.jit(jax.vmap(jax.grad(_pt)))
EE_GRAD = jax.jit(jax.vmap(jax.grad(_ee)))
PT_HESS = jax.jit(jax.vmap(jax.hessian(_pt)))
EE_HESS = jax.jit(jax.vmap(jax.hessian(_ee)))


def rotation(seed: int) -> np.ndarray:
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.diag(r))


# -- distances: closed forms -------------------------------------------------------------------

T0, T1, T2 = [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]
# point, the unit triangle's closest feature, squared distance by hand
POINT_TRIANGLE = [
    ([0.2, 0.3, 0.5], "p-plane", 0.25),
    ([0.2, 0.3, -0.7], "p-plane", 0.49),
    ([-1.0, -2.0, 0.5], "p-t0", 1.0 + 4.0 + 0.25),
    ([2.0, -0.5, 0.0], "p-t1", 1.0 + 0.25),
    ([-0.5, 2.0, 1.0], "p-t2", 0.25 + 1.0 + 1.0),
    ([0.3, -0.4, 0.3], "p-e0", 0.16 + 0.09),
    ([0.8, 0.8, 0.1], "p-e1", 0.6**2 / 2 + 0.01),  # foot (0.5, 0.5, 0) on x + y = 1
    ([-0.3, 0.5, -0.4], "p-e2", 0.09 + 0.16),
]
# edge a, edge b, case, squared distance by hand
EDGE_EDGE = [
    ([[0, 0, 0], [2, 0, 0]], [[1, -1, 0.5], [1, 1, 0.5]], "ea-eb", 0.25),
    ([[0, 0, 0], [1, 0, 0]], [[2, 1, 0], [3, 2, 0]], "a1-b0", 2.0),
    ([[1, 0, 0], [0, 0, 0]], [[3, 2, 0], [2, 1, 0]], "a0-b1", 2.0),
    ([[0, 0, 0], [-1, 0, 0]], [[-2, 1, 1], [-3, 3, 1]], "a1-b0", 3.0),
    ([[0, 0, 0], [1, 0, 0]], [[-2, 0, 3], [-3, 0, 3]], "a0-b0", 4.0 + 9.0),
    ([[0, 0, 0], [1, 0, 0]], [[2, -1, 1], [2, 1, 1]], "a1-eb", 2.0),
    ([[1, 0, 0], [0, 0, 0]], [[2, -1, 1], [2, 1, 1]], "a0-eb", 2.0),
    ([[-1, 0, 0], [1, 0, 0]], [[0, 1, 1], [0, 2, 3]], "b0-ea", 2.0),
    ([[-1, 0, 0], [1, 0, 0]], [[0, 2, 3], [0, 1, 1]], "b1-ea", 2.0),
    # parallel, apart along their direction: an end point pair
    ([[0, 0, 0], [1, 0, 0]], [[2, 1, 0], [3, 1, 0]], "a1-b0", 2.0),
    # collinear, apart
    ([[0, 0, 0], [1, 0, 0]], [[3, 0, 0], [4, 0, 0]], "a1-b0", 4.0),
]
# parallel edges that overlap along their direction: an end point case (which one is a tie),
# never the lines' formula
PARALLEL = [
    ([[0, 0, 0], [2, 0, 0]], [[1, 0.5, 0], [3, 0.5, 0]], 0.25),
    ([[0, 0, 0], [2, 0, 0]], [[3, 0.5, 0.5], [1, 0.5, 0.5]], 0.5),  # anti-parallel
    ([[0, 0, 0], [4, 0, 0]], [[1, 0, 0.3], [2, 0, 0.3]], 0.09),  # b within a's span
    ([[0, 0, 0], [2, 0, 0]], [[0, 0, 0.2], [2, 0, 0.2]], 0.04),  # stacked, same span
    ([[0, 0, 0], [2, 0, 0]], [[1, 0, 0], [3, 0, 0]], 0.0),  # collinear, overlapping
]


def test_point_triangle_closed_forms():
    q = np.array([[p, T0, T1, T2] for p, _, _ in POINT_TRIANGLE])
    want = np.array([d2 for _, _, d2 in POINT_TRIANGLE])
    np.testing.assert_allclose(PT_D2(q), want, rtol=1e-14, atol=1e-15)
    names = [POINT_TRIANGLE_CASES[k] for k in np.asarray(PT_TYPE(q))]
    assert names == [case for _, case, _ in POINT_TRIANGLE]
    # a rigid motion and a scale: the same cases, distances times the scale squared
    moved = 3.0 * q @ rotation(0).T + np.array([5.0, -2.0, 1.0])
    np.testing.assert_allclose(PT_D2(moved), 9.0 * want, rtol=1e-12)
    assert np.array_equal(PT_TYPE(moved), PT_TYPE(q))


def test_edge_edge_closed_forms_including_parallel():
    q = np.array([a + b for a, b, _, _ in EDGE_EDGE], float)
    want = np.array([d2 for *_, d2 in EDGE_EDGE])
    np.testing.assert_allclose(EE_D2(q), want, rtol=1e-14, atol=1e-15)
    assert [EDGE_EDGE_CASES[k] for k in np.asarray(EE_TYPE(q))] == [c for _, _, c, _ in EDGE_EDGE]
    moved = 0.5 * q @ rotation(1).T + np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(EE_D2(moved), 0.25 * want, rtol=1e-12)

    q = np.array([a + b for a, b, _ in PARALLEL], float)
    want = np.array([d2 for *_, d2 in PARALLEL])
    for r in (np.eye(3), rotation(2)):  # exactly parallel, and parallel within rounding
        np.testing.assert_allclose(EE_D2(q @ r.T), want, rtol=1e-12, atol=1e-15)
        cases = {EDGE_EDGE_CASES[k] for k in np.asarray(EE_TYPE(q @ r.T))}
        assert "ea-eb" not in cases
    # nearly parallel (1e-6 rad), crossing in projection: the lines' formula, exact
    a, b = np.array([[-1.0, 0, 0], [1, 0, 0]]), np.array([[-1.0, -1e-6, 0.1], [1, 1e-6, 0.1]])
    q = np.concatenate([a, b])[None]
    assert EDGE_EDGE_CASES[int(EE_TYPE(q)[0])] == "ea-eb"
    np.testing.assert_allclose(EE_D2(q), [0.01], rtol=1e-9)


def test_distances_in_float32():
    pt = np.array([[p, T0, T1, T2] for p, _, _ in POINT_TRIANGLE], np.float32)
    np.testing.assert_allclose(PT_D2(pt), [d2 for *_, d2 in POINT_TRIANGLE], rtol=1e-6, atol=1e-7)
    # parallel within float32 rounding: an end point case, not the lines' garbage
    q = (np.array([a + b for a, b, _ in PARALLEL]) @ rotation(2).T).astype(np.float32)
    np.testing.assert_allclose(EE_D2(q), [d2 for *_, d2 in PARALLEL], rtol=1e-5, atol=1e-6)
    assert EDGE_EDGE_CASES.index("ea-eb") not in np.asarray(EE_TYPE(q))
    assert EE_D2(q).dtype == jnp.float32
    assert np.all(np.isfinite(EE_GRAD(jnp.asarray(q))))


# -- distances: sampled brute force ------------------------------------------------------------


def _sampled_point_triangle(p: np.ndarray, t: np.ndarray, n: int) -> float:
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    u, v = i[keep] / n, j[keep] / n
    pts = t[0] + u[:, None] * (t[1] - t[0]) + v[:, None] * (t[2] - t[0])
    return float(np.min(np.sum((pts - p) ** 2, axis=1)))


def _sampled_edge_edge(a: np.ndarray, b: np.ndarray, n: int) -> float:
    s = np.linspace(0.0, 1.0, n + 1)[:, None]
    pa, pb = a[0] + s * (a[1] - a[0]), b[0] + s * (b[1] - b[0])
    return float(np.min(np.sum((pa[:, None] - pb[None]) ** 2, axis=2)))


def test_distances_match_sampled_minimum_on_random_configurations():
    rng = np.random.default_rng(3)
    n = 200  # samples per unit of parameter: the sampled minimum is within size / n
    pt_cases, ee_cases = set(), set()
    for k in range(60):
        # corners in a unit box, the point or second edge at varied distances
        t = rng.uniform(-1, 1, size=(3, 3))
        p = rng.uniform(-1, 1, size=3) * (0.3 if k % 2 else 2.0)
        q = np.concatenate([p[None], t])[None]
        exact = float(PT_D2(q)[0])
        sampled = _sampled_point_triangle(p, t, n)
        size = np.max(np.linalg.norm(t - np.roll(t, 1, axis=0), axis=1))
        assert exact <= sampled + 1e-12
        assert np.sqrt(sampled) - np.sqrt(exact) <= 2.0 * size / n
        pt_cases.add(int(PT_TYPE(q)[0]))

        a, b = rng.uniform(-1, 1, size=(2, 3)), rng.uniform(-1, 1, size=(2, 3))
        b = b * (0.3 if k % 2 else 1.5)
        q = np.concatenate([a, b])[None]
        exact = float(EE_D2(q)[0])
        sampled = _sampled_edge_edge(a, b, 4 * n)
        size = max(np.linalg.norm(a[1] - a[0]), np.linalg.norm(b[1] - b[0]))
        assert exact <= sampled + 1e-12
        assert np.sqrt(sampled) - np.sqrt(exact) <= 2.0 * size / (4 * n)
        ee_cases.add(int(EE_TYPE(q)[0]))
    # the random configurations met the face, edge and vertex cases (not one formula only)
    assert {0, 1, 2} & pt_cases and {3, 4, 5} & pt_cases and 6 in pt_cases
    assert 8 in ee_cases and {4, 5, 6, 7} & ee_cases


# -- gradients --------------------------------------------------------------------------------

DEGENERATE_PT = [
    [[0.2, 0.3, 0.0], T0, T1, T2],  # on the face
    [[0.5, 0.0, 0.0], T0, T1, T2],  # on an edge
    [T1, T0, T1, T2],  # on a corner
    [[0.3, 0.4, 0.2], T0, T1, [2.0, 0.0, 0.0]],  # collapsed triangle (collinear corners)
    [[0.3, 0.4, 0.2], T0, T0, T2],  # two corners at one place
    [T0, T0, T0, T0],  # everything at one place (a padding row)
    [[0.5, 0.0, 0.0], T0, T1, [2.0, 0.0, 0.0]],  # on a collapsed triangle
]
DEGENERATE_EE = [
    [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]],  # parallel
    [[0, 0, 0], [2, 0, 0], [1, 0, 0], [3, 0, 0]],  # collinear, overlapping
    [[0, 0, 0], [1, 0, 0], [0, 0, 0], [1, 0, 0]],  # coincident
    [[0, 0, 0], [1, 0, 0], [1, 0, 0], [0, 0, 0]],  # coincident, reversed
    [[0, 0, 0], [0, 0, 0], [0.5, 0.3, 0], [1, 1, 1]],  # a zero-length edge
    [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]],  # both zero-length, at one place
    [[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0]],  # crossing
    [[0, 0, 0], [1, 0, 0], [1, 0, 0], [1, 1, 0]],  # touching at an end point
    [[0, 0, 0], [1, 0, 0], [0.5, 0, 0], [0.5, 1, 0]],  # an end point on the other edge
]


def test_gradients_finite_at_degenerate_configurations():
    for d2, grad, hess, cases in (
        (PT_D2, PT_GRAD, PT_HESS, DEGENERATE_PT),
        (EE_D2, EE_GRAD, EE_HESS, DEGENERATE_EE),
    ):
        q = jnp.asarray(np.array(cases, float))
        assert np.all(np.isfinite(d2(q)))
        assert np.all(np.isfinite(grad(q)))
        assert np.all(np.isfinite(hess(q)))
        # and through the barrier, at the wall (d = 0) and inside its zone
        energy = jax.vmap(jax.grad(lambda r, f=d2: contact.contact_barrier(f(r), 0.7, 2.0)))
        assert np.all(np.isfinite(energy(q)))


def _central_differences(f, q: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """(q.size, *f(q).shape) derivatives of ``f`` in each entry of ``q``."""
    out = []
    for idx in np.ndindex(q.shape):
        up, down = q.copy(), q.copy()
        up[idx] += h
        down[idx] -= h
        out.append((np.asarray(f(up)) - np.asarray(f(down))) / (2 * h))
    return np.array(out)


def test_gradients_and_hessians_match_central_differences_in_every_case():
    rng = np.random.default_rng(4)
    r = rotation(5)
    pt = np.array([[p, T0, T1, T2] for p, _, _ in POINT_TRIANGLE]) @ r.T
    ee = np.array([a + b for a, b, _, _ in EDGE_EDGE] + [a + b for a, b, _ in PARALLEL[:3]]) @ r.T
    for q, d2, grad, hess in ((pt, PT_D2, PT_GRAD, PT_HESS), (ee, EE_D2, EE_GRAD, EE_HESS)):
        q = q + 1e-3 * rng.normal(size=q.shape)  # off the cases' boundaries
        g, h = np.asarray(grad(q)), np.asarray(hess(q))
        for k in range(len(q)):
            fd = _central_differences(lambda c, f=d2: f(c[None])[0], q[k])
            np.testing.assert_allclose(g[k].ravel(), fd, rtol=1e-6, atol=1e-8)
            fd2 = _central_differences(lambda c, f=grad: f(c[None])[0], q[k], 1e-5)
            np.testing.assert_allclose(h[k].reshape(12, 12), fd2.reshape(12, 12), atol=1e-5)


# -- the barrier ----------------------------------------------------------------------------


def _b(s):
    return -((s - 1) ** 2) * np.log(s)


def _b1(s):
    return -2 * (s - 1) * np.log(s) - (s - 1) ** 2 / s


def _b2(s):
    return -2 * np.log(s) - 4 * (s - 1) / s + (s - 1) ** 2 / s**2


# a point above the unit triangle's face, and a pair list holding it
TRIANGLE_PAIR = contact_mesh(np.array([[1, 2, 3]]), num_vertices=4)
PAIRS_ONE = all_pairs(TRIANGLE_PAIR)  # one vertex-triangle pair, no edge pair
ENERGY = jax.jit(contact_energy)
GRAD = jax.jit(jax.grad(contact_energy))
HESS = jax.jit(jax.hessian(contact_energy))


def test_barrier_value_gradient_and_hessian_against_hand_formulas():
    assert PAIRS_ONE.pt.tolist() == [[0, 1, 2, 3]] and PAIRS_ONE.ee.shape == (0, 4)
    dhat, kappa = 0.1, 2.5
    lam = np.array([0.5, 0.2, 0.3])  # the point's barycentric coordinates over the face
    for h in (0.01, 0.04, 0.07, 0.0999):
        x = np.array([[0.2, 0.3, h], T0, T1, T2])
        s = h * h / dhat**2
        de = kappa * _b1(s) * 2 * h / dhat**2  # dE/dh
        d2e = kappa * (_b2(s) * (2 * h / dhat**2) ** 2 + _b1(s) * 2 / dhat**2)
        assert float(ENERGY(x, PAIRS_ONE, dhat, kappa)) == pytest.approx(kappa * _b(s), rel=1e-12)
        g = np.asarray(GRAD(x, PAIRS_ONE, dhat, kappa))
        np.testing.assert_allclose(g[0], [0, 0, de], rtol=1e-10, atol=1e-12 * abs(de))
        # the face's corners: pushed by their barycentric share, the other way
        np.testing.assert_allclose(g[1:, 2], -lam * de, rtol=1e-10)
        np.testing.assert_allclose(g[1:, :2], 0.0, atol=1e-12 * abs(de))
        hess = np.asarray(HESS(x, PAIRS_ONE, dhat, kappa)).reshape(12, 12)
        assert hess[2, 2] == pytest.approx(d2e, rel=1e-10)
        np.testing.assert_allclose(hess[2, [5, 8, 11]], -lam * d2e, rtol=1e-10)
        # sliding along the face keeps the distance: no curvature in x or y
        np.testing.assert_allclose(hess[:2, :2], 0.0, atol=1e-10 * abs(d2e))
    # at dhat and beyond: no energy, force or stiffness
    for h in (0.1, 0.3):
        x = np.array([[0.2, 0.3, h], T0, T1, T2])
        assert float(ENERGY(x, PAIRS_ONE, dhat, kappa)) == 0.0
        assert not np.any(np.asarray(GRAD(x, PAIRS_ONE, dhat, kappa)))
        assert not np.any(np.asarray(HESS(x, PAIRS_ONE, dhat, kappa)))
    # at and through the face: finite (barrier.ipc's continuation below S_MIN)
    for h in (0.0, -0.01, 0.5 * np.sqrt(S_MIN) * dhat):
        x = np.array([[0.2, 0.3, h], T0, T1, T2])
        assert np.isfinite(float(ENERGY(x, PAIRS_ONE, dhat, kappa)))
        assert np.all(np.isfinite(np.asarray(HESS(x, PAIRS_ONE, dhat, kappa))))
    # growing to the face (through it the distance grows again: the step bound keeps a
    # solver's iterates from getting there)
    heights = (0.05, 0.03, 0.01, 0.003, 0.0)
    e = [
        float(ENERGY(np.array([[0.2, 0.3, h], T0, T1, T2]), PAIRS_ONE, dhat, kappa))
        for h in heights
    ]
    assert np.all(np.diff(e) > 0)


def test_contact_stiffness_is_the_bars_mean_work_scale():
    cp = patterns.miura_ori(2, 2)
    params = make_params(cp, stiffness={"axial": 3.0})
    want = 1e-3 * 3.0 * np.mean(np.asarray(params.rest_length))
    assert float(contact.contact_stiffness(params)) == pytest.approx(want, rel=1e-14)
    assert contact.default_dhat(cp.diameter) == pytest.approx(1e-3 * cp.diameter)


def test_edge_edge_mollifier():
    a = jnp.array([[0.0, 0, 0], [1, 0, 0]])
    eps_x = contact.MOLLIFIER_EPS  # rest lengths 1
    for angle, want in ((0.0, 0.0), (0.5, 1.0), (np.pi / 2, 1.0)):
        b = jnp.array([[0.0, 0, 1], [np.cos(angle), np.sin(angle), 1]])
        assert float(contact.edge_edge_mollifier(a[0], a[1], b[0], b[1], eps_x)) == want

    def m(angle):
        b0, b1 = jnp.array([0.0, 0, 1]), jnp.array([jnp.cos(angle), jnp.sin(angle), 1.0])
        return contact.edge_edge_mollifier(a[0], a[1], b0, b1, eps_x)

    # continuous with its slope where it reaches 1 (|ea x eb|^2 = eps_x)
    edge = float(np.arcsin(np.sqrt(eps_x)))
    assert float(m(edge - 1e-9)) == pytest.approx(1.0, abs=1e-6)
    assert float(jax.grad(m)(edge - 1e-9)) == pytest.approx(0.0, abs=1e-5)
    assert float(jax.grad(m)(0.5 * edge)) > 0
    # a mollified pair of parallel edges within dhat: no edge-edge energy
    mesh = contact_mesh(np.zeros((0, 3), int), 4, edges=np.array([[0, 1], [2, 3]]))
    pairs = all_pairs(mesh)
    x = jnp.array([[0.0, 0, 0], [1, 0, 0], [0, 0, 0.01], [1, 0, 0.01]])
    assert float(contact_energy(x, pairs, 0.1, 1.0)) > 0
    assert float(contact_energy(x, pairs, 0.1, 1.0, rest=x)) == 0.0


# -- sheets ---------------------------------------------------------------------------------


def grid_sheet(n: int, seed: int = 0, noise: float = 0.2, gap: float | None = None):
    """An n x n grid of unit squares, each split in two, its vertices jittered by ``noise``; with
    ``gap``, folded in half along x = n / 2 so its two layers lie ``gap`` apart."""
    rng = np.random.default_rng(seed)
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    x = np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], axis=1).astype(float)
    x[:, :2] += noise * rng.uniform(-0.5, 0.5, size=(len(x), 2))
    x[:, 2] += noise * rng.uniform(-0.5, 0.5, size=len(x))
    if gap is not None:
        half = n / 2
        over = x[:, 0] > half
        x[over, 0] = 2 * half - x[over, 0]
        x[over, 2] += gap + 0.5 * noise  # beyond the jitter: the layers stay apart
    v = (n + 1) * np.arange(n)[:, None] + np.arange(n)[None, :]
    v = v.ravel()
    tri = np.concatenate(
        [np.stack([v, v + n + 1, v + n + 2], 1), np.stack([v, v + n + 2, v + 1], 1)]
    )
    return x, tri


def soup(count: int, seed: int):
    """Loose triangles of sizes spread over two decades in a box, some far away."""
    rng = np.random.default_rng(seed)
    centre = rng.uniform(0, 4, size=(count, 1, 3))
    centre[: count // 10] += 40.0  # a far cluster
    size = np.exp(rng.uniform(np.log(0.05), np.log(5.0), size=(count, 1, 1)))
    x = (centre + size * rng.uniform(-0.5, 0.5, size=(count, 3, 3))).reshape(-1, 3)
    return x, np.arange(3 * count).reshape(-1, 3)


PT_DIST = jax.jit(lambda x, q: _pt(x[q]))
EE_DIST = jax.jit(lambda x, q: _ee(x[q]))


def within(x, mesh, dhat):
    """Brute force: the (vertex, triangle) and (edge, edge) pairs closer than ``dhat``."""
    ref = all_pairs(mesh)
    d_pt = np.asarray(PT_DIST(jnp.asarray(x), ref.pt))
    d_ee = np.asarray(EE_DIST(jnp.asarray(x), ref.ee))
    pt = {tuple(r) for r in np.asarray(ref.pt_ids)[d_pt < dhat * dhat].tolist()}
    ee = {tuple(r) for r in np.asarray(ref.ee_ids)[d_ee < dhat * dhat].tolist()}
    return pt, ee


def boxes(x, mesh, radius):
    """Brute force: the pairs the broad phase's box tests accept (in its arithmetic)."""
    ref = all_pairs(mesh)
    tri, edges = np.asarray(mesh.triangles), np.asarray(mesh.edges)
    v, t = np.asarray(ref.pt_ids).T
    lo, hi = x[tri].min(1) - radius, x[tri].max(1) + radius
    ok = np.all((lo[t] <= x[v]) & (x[v] <= hi[t]), axis=1)
    pt = {tuple(r) for r in np.asarray(ref.pt_ids)[ok].tolist()}
    a, b = np.asarray(ref.ee_ids).T
    lo, hi = x[edges].min(1) - 0.5 * radius, x[edges].max(1) + 0.5 * radius
    ok = np.all((lo[a] <= hi[b]) & (lo[b] <= hi[a]), axis=1)
    ee = {tuple(r) for r in np.asarray(ref.ee_ids)[ok].tolist()}
    return pt, ee


def found(pairs):
    """The candidate pairs as sets, checking that none is listed twice."""
    pt = np.asarray(pairs.pt_ids)[np.asarray(pairs.pt_mask)].tolist()
    ee = np.asarray(pairs.ee_ids)[np.asarray(pairs.ee_mask)].tolist()
    pt, ee = [tuple(r) for r in pt], [tuple(r) for r in ee]
    assert len(set(pt)) == len(pt) and len(set(ee)) == len(ee)
    return set(pt), set(ee)


def check_broad_phase(x, mesh, dhat, skin):
    pairs = allocate(x, mesh, dhat + skin)
    assert not bool(pairs.did_overflow)
    pt, ee = found(pairs)
    near_pt, near_ee = within(x, mesh, dhat)
    assert near_pt <= pt and near_ee <= ee
    # exactly the pairs whose inflated boxes meet: none missing, none extra
    assert (pt, ee) == boxes(x, mesh, dhat + skin)
    # the rows hold the pairs' vertices
    rows = np.asarray(pairs.pt)[np.asarray(pairs.pt_mask)]
    ids = np.asarray(pairs.pt_ids)[np.asarray(pairs.pt_mask)]
    assert np.array_equal(rows[:, 0], ids[:, 0])
    assert np.array_equal(rows[:, 1:], np.asarray(mesh.triangles)[ids[:, 1]])
    return pairs, near_pt, near_ee


@pytest.mark.parametrize("seed", [0, 1])
def test_broad_phase_finds_every_near_pair_on_random_sheets(seed):
    x, tri = grid_sheet(8, seed, gap=0.05)
    mesh = contact_mesh(tri, len(x))
    _, near_pt, near_ee = check_broad_phase(x, mesh, dhat=0.12, skin=0.05)
    assert near_pt and near_ee  # the folded layers do come within dhat
    x, tri = soup(150, seed)
    mesh = contact_mesh(tri, len(x))
    _, near_pt, near_ee = check_broad_phase(x, mesh, dhat=0.05, skin=0.02)
    assert near_pt and near_ee


def test_broad_phase_on_a_huge_sparse_grid_and_without_triangles():
    # clusters thousands of cells apart along every axis: some 1e10 cells, more than 31-bit
    # keys number, so cells are hashed (and told apart where two share a key)
    x, tri = soup(150, 2)
    shift = 3000.0 * np.random.default_rng(7).integers(0, 3, size=(len(tri), 3))
    shift[::2] = 0.0  # half of them stay together (and meet)
    x = x + np.repeat(shift, 3, axis=0)  # each triangle's corners moved together
    mesh = contact_mesh(tri, len(x))
    _, near_pt, near_ee = check_broad_phase(x, mesh, dhat=0.05, skin=0.02)
    assert near_pt and near_ee
    # edges only (no triangle, so no point-triangle pair), and triangles without edges
    x, tri = grid_sheet(4, 5, gap=0.05)
    edges = contact.mesh_edges(tri)
    wire = contact_mesh(np.zeros((0, 3), int), len(x), edges=edges)
    pairs = allocate(x, wire, 0.2)
    assert not np.asarray(pairs.pt_mask).any()
    assert found(pairs)[1] == boxes(x, contact_mesh(tri, len(x)), 0.2)[1]
    faces = contact_mesh(tri, len(x), edges=np.zeros((0, 2), int))
    pairs = allocate(x, faces, 0.2)
    assert not np.asarray(pairs.ee_mask).any()
    assert found(pairs)[0] == boxes(x, contact_mesh(tri, len(x)), 0.2)[0]


def test_broad_phase_on_a_folded_miura_ori():
    cp = patterns.miura_ori(4, 4, fold_angle=0.97 * np.pi)
    x = rigid_fold(cp)
    mesh = contact_mesh(cp.mesh)
    dhat = 0.05 * cp.diameter  # the nearly flat-folded layers lie within it
    pairs, near_pt, near_ee = check_broad_phase(x, mesh, dhat, 0.2 * dhat)
    assert len(near_pt) > 20 and len(near_ee) > 20
    # flat, at the default dhat: no pair is active
    flat = cp.mesh.vertices
    report = contact_report(
        flat,
        allocate(flat, mesh, 2 * contact.default_dhat(cp.diameter)),
        contact.default_dhat(cp.diameter),
    )
    assert int(report.num_active) == 0
    # folded, the report sees the near pairs
    report = contact_report(x, pairs, dhat)
    assert int(report.num_active) == len(near_pt) + len(near_ee)
    assert 0 < float(report.min_ratio) < 1


def test_overflow_is_detected_and_reallocation_fixes_it():
    x, tri = grid_sheet(6, 2, gap=0.05)
    mesh = jax.tree.map(jnp.asarray, contact_mesh(tri, len(x)))
    radius = 0.15
    want = allocate(x, mesh, radius)
    for small in range(6):  # each capacity too small in turn
        capacity = Capacity(*(16 if k == small else c for k, c in enumerate(want.capacity)))
        pairs = build_pairs(x, mesh, radius, capacity)
        assert bool(pairs.did_overflow)
        needed = np.asarray(pairs.needed)
        assert needed[small] > 16
        fixed = reallocate(x, pairs, mesh)
        assert not bool(fixed.did_overflow)
        assert found(fixed) == found(want)
    # the counts a build reports are what it holds
    needed = np.asarray(want.needed)
    assert needed[2] == int(want.pt_mask.sum()) and needed[5] == int(want.ee_mask.sum())


def test_pairs_stay_valid_within_the_skin_and_needs_update():
    x, tri = grid_sheet(6, 3, gap=0.08)
    mesh = contact_mesh(tri, len(x))
    dhat, skin = 0.1, 0.06
    pairs = allocate(x, mesh, dhat + skin)
    rng = np.random.default_rng(0)
    step = rng.normal(size=x.shape)
    step *= 0.499 * skin / np.linalg.norm(step, axis=1, keepdims=True)
    moved = x + step
    assert not bool(needs_update(moved, pairs.x_built, skin))
    near_pt, near_ee = within(moved, mesh, dhat)
    pt, ee = found(pairs)
    assert near_pt and near_pt <= pt and near_ee <= ee
    one = x.copy()
    one[5, 2] += 0.501 * skin
    assert bool(needs_update(one, pairs.x_built, skin))
    # update: the same capacity, built again where the sheet is now
    again = jax.jit(contact.update)(moved, pairs, jax.tree.map(jnp.asarray, mesh))
    assert again.capacity == pairs.capacity and not bool(again.did_overflow)
    assert found(again) == boxes(moved, mesh, dhat + skin)
    # refreshed: kept while every vertex moved at most a quarter of the skin, built again beyond
    fresh = jax.jit(contact.refreshed)
    mesh_j = jax.tree.map(jnp.asarray, mesh)
    near = x + 0.99 * 0.25 / 0.499 * step
    kept = fresh(near, pairs, mesh_j, skin)
    np.testing.assert_array_equal(np.asarray(kept.x_built), np.asarray(pairs.x_built))
    rebuilt = fresh(moved, pairs, mesh_j, skin)
    np.testing.assert_array_equal(np.asarray(rebuilt.x_built), moved)
    assert found(rebuilt) == found(again)


def test_candidates_per_triangle_stay_bounded_as_the_sheet_grows():
    per_triangle, raw_per_triangle = [], []
    for n in (8, 16, 32, 64):
        x, tri = grid_sheet(n, n, noise=0.3)
        mesh = contact_mesh(tri, len(x))
        needed = np.asarray(allocate(x, mesh, 0.2).needed)
        per_triangle.append((needed[2] + needed[5]) / len(tri))
        raw_per_triangle.append((needed[1] + needed[4]) / len(tri))
    # bounded (the grid's cells against the lattice vary a little with the jitter): nothing
    # grows with the sheet, as a quadratic search's n^2 / n pairs per triangle would
    assert max(per_triangle) < 6 and max(raw_per_triangle) < 50
    assert max(per_triangle[1:]) < 1.3 * min(per_triangle[1:])
    assert max(raw_per_triangle[1:]) < 1.5 * min(raw_per_triangle[1:])


# -- energy over candidates -------------------------------------------------------------------


def test_no_energy_or_gradient_beyond_dhat_and_shared_vertices_excluded():
    x, tri = grid_sheet(5, 4, gap=0.3)
    mesh = contact_mesh(tri, len(x))
    pairs = allocate(x, mesh, 0.5)
    report = contact_report(x, pairs, 0.1)
    assert int(report.num_active) == 0 and float(report.min_ratio) > 1.0
    assert float(ENERGY(x, pairs, 0.1, 1.0)) == 0.0
    assert not np.any(np.asarray(GRAD(x, pairs, 0.1, 1.0)))
    # with a dhat beyond the gap, the layers repel
    assert float(ENERGY(x, pairs, 0.4, 1.0)) > 0.0
    g = np.asarray(GRAD(x, pairs, 0.4, 1.0))
    assert np.all(np.isfinite(g)) and np.any(g)
    # a pair given by hand that shares a vertex (a triangle's own corner) counts nothing
    own = contact.ContactPairs(
        pt=jnp.asarray([[int(tri[0, 0]), *tri[0]]], jnp.int32),
        pt_ids=jnp.zeros((1, 2), jnp.int32),
        pt_mask=jnp.ones(1, bool),
        ee=jnp.zeros((0, 4), jnp.int32),
        ee_ids=jnp.zeros((0, 2), jnp.int32),
        ee_mask=jnp.zeros(0, bool),
        x_built=jnp.asarray(x),
        radius=jnp.asarray(0.0),
        needed=jnp.zeros(6, jnp.int32),
        capacity=Capacity(0, 0, 1, 0, 0, 0),
    )
    assert float(contact_energy(x, own, 0.4, 1.0)) == 0.0
    assert not np.any(np.asarray(jax.grad(contact_energy)(x, own, 0.4, 1.0)))


# -- step bound -----------------------------------------------------------------------------

TWO = contact_mesh(np.array([[0, 1, 2], [3, 4, 5]]), 6)
TWO_PAIRS = all_pairs(TWO)
ALL_D2 = jax.jit(lambda x: jnp.concatenate([_pt(x[TWO_PAIRS.pt]), _ee(x[TWO_PAIRS.ee])]))
BOUND = jax.jit(step_bound)


def test_step_bound_stops_two_triangles_before_they_cross():
    a = np.array([T0, T1, T2], float)
    # a tilted triangle above the unit triangle, moved down through it
    b = np.array([[0.2, 0.2, 0.5], [0.6, 0.1, 0.8], [0.1, 0.6, 0.9]])
    x = np.concatenate([a, b])
    dx = np.zeros_like(x)
    dx[3:, 2] = -0.7
    assert intersecting_pairs(x + dx, TWO.triangles, 0.0).tolist() == [[0, 1]]
    d0 = np.sqrt(np.asarray(ALL_D2(x)))
    t = float(BOUND(x, dx, TWO_PAIRS))
    # a translation: the bound is exact, 0.9 of the way to contact (0.5 down at speed 0.7)
    assert t == pytest.approx(0.9 * 0.5 / 0.7, rel=1e-12)
    for tau in np.linspace(0.0, t, 11):
        d = np.sqrt(np.asarray(ALL_D2(x + tau * dx)))
        assert np.all(d >= contact.STEP_KEEP * d0 - 1e-12)
    assert intersecting_pairs(x + t * dx, TWO.triangles, 0.0).tolist() == []
    assert np.min(np.sqrt(np.asarray(ALL_D2(x + t * dx)))) == pytest.approx(0.05, rel=1e-9)

    # turning and sliding as well: every pair keeps a tenth of its distance over the step
    rng = np.random.default_rng(6)
    for _ in range(5):
        dx = rng.normal(size=x.shape)
        dx[3:, 2] -= 2.0
        t = float(BOUND(x, dx, TWO_PAIRS))
        assert 0.0 < t < 1.0
        for tau in np.linspace(0.0, t, 21):
            d = np.sqrt(np.asarray(ALL_D2(x + tau * dx)))
            assert np.all(d >= contact.STEP_KEEP * d0 - 1e-12)
    # not moving at all: the whole step
    assert float(BOUND(x, np.zeros_like(x), TWO_PAIRS)) == 1.0


def test_step_bound_lets_sliding_and_parting_pairs_go_further():
    a = np.array([T0, T1, T2], float)
    x = np.concatenate([a, a + np.array([0.1, 0.1, 0.05])])  # a parallel layer 0.05 above
    d0 = np.sqrt(np.asarray(ALL_D2(x)))
    dx = np.zeros_like(x)
    dx[3:, 0] = 0.5  # sliding along the layer: never closer than 0.05
    one = float(BOUND(x, dx, TWO_PAIRS, 0.1, 1))
    assert one == pytest.approx(0.9 * 0.05 / 0.5, rel=1e-12)  # the one-shot bound
    t = float(BOUND(x, dx, TWO_PAIRS))
    assert t > 5 * one
    for tau in np.linspace(0.0, t, 41):
        d = np.sqrt(np.asarray(ALL_D2(x + tau * dx)))
        assert np.all(d >= contact.STEP_KEEP * d0 - 1e-12)
    dx = np.zeros_like(x)
    dx[3:, 2] = 1.0  # moving apart
    assert float(BOUND(x, dx, TWO_PAIRS)) == 1.0
    assert float(BOUND(x, dx, TWO_PAIRS, 0.1, 1)) < 1.0


def _unpacked(monkeypatch, fn, *args):
    """``fn(*args)`` with the pairs in play never packed (every row worked on)."""
    with monkeypatch.context() as m:
        m.setattr(contact, "NARROW_FROM", 1 << 62)
        return jax.jit(fn)(*args)


@pytest.mark.parametrize("dhat", [0.08, 1.5])
def test_packed_pairs_give_what_every_row_gives(monkeypatch, dhat):
    # a sheet folded in half, its layers 0.05 (+ jitter) apart, with every pair a candidate
    # (more rows than NARROW_FROM): at dhat 0.08 a few pairs are in reach and are packed, at
    # 1.5 more than a NARROW-th of them and every row is worked on; both as every row gives
    x, tri = grid_sheet(8, seed=3, noise=0.1, gap=0.05)
    mesh = contact_mesh(tri, num_vertices=len(x))
    pairs = all_pairs(mesh)
    rows = pairs.pt.shape[0] + pairs.ee.shape[0]
    assert rows >= contact.NARROW_FROM
    x = jnp.asarray(x)
    near = [int(np.sum(k)) for k in contact._maybe_within(x, pairs, dhat)]
    fits = [
        n <= k.shape[0] // contact.NARROW for n, k in zip(near, (pairs.pt, pairs.ee), strict=True)
    ]
    assert all(fits) == (dhat < 0.1), near
    kappa = 2.0

    def summed(x):
        return jnp.sum(jnp.concatenate(contact.pair_energies(x, pairs, dhat, kappa)))

    value, grad = jax.value_and_grad(lambda y: contact_energy(y, pairs, dhat, kappa))(x)
    want_value, want_grad = jax.value_and_grad(summed)(x)
    assert float(value) == pytest.approx(float(want_value), rel=1e-12)
    assert float(value) > 0
    np.testing.assert_allclose(grad, want_grad, rtol=0, atol=1e-9 * float(jnp.max(abs(want_grad))))

    def diagonal(corners, blocks):
        return jnp.zeros((len(x), 3, 3)).at[corners].add(blocks[:, jnp.arange(4), jnp.arange(4)])

    added = contact.add_pair_hessians(x, pairs, dhat, kappa, diagonal)
    want = diagonal(*contact.pair_hessians(x, pairs, dhat, kappa))
    np.testing.assert_allclose(added, want, rtol=0, atol=1e-9 * float(jnp.max(abs(want))))

    rng = np.random.default_rng(4)
    for scale in (0.001, 0.01, 0.1):
        dx = jnp.asarray(scale * rng.normal(size=x.shape))
        t = float(BOUND(x, dx, pairs))
        assert t == _unpacked(monkeypatch, step_bound, x, dx, pairs)
