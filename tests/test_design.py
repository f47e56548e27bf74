"""Implicit derivatives of the folded state, design goals and the design loop (float64)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from origami_jax import CreasePattern, patterns
from origami_jax.design import (
    design,
    equilibrium_fn,
    kabsch,
    make_params,
    target_distance,
    target_height,
    target_positions,
    target_shape,
    target_span,
    target_surface,
)
from origami_jax.solvers import Newton
from origami_jax.solvers.base import objective

TOL = 1e-13  # tight equilibria, so that central differences are meaningful


def random_pattern(seed: int = 0, n: int = 3) -> CreasePattern:
    """A jittered (n+1) x (n+1) grid, each square split by a random diagonal; interior edges
    random mountains and valleys with random targets (not rigid-foldable)."""
    rng = np.random.default_rng(seed)
    xy = np.array([[i, j] for j in range(n + 1) for i in range(n + 1)], float)
    inner = (xy > 0) & (xy < n)
    xy += inner.all(axis=1)[:, None] * rng.uniform(-0.15, 0.15, xy.shape)

    def idx(i, j):
        return j * (n + 1) + i

    edges, faces = set(), []
    for j in range(n):
        for i in range(n):
            a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            tris = [(a, b, c), (a, c, d)] if rng.random() < 0.5 else [(a, b, d), (b, c, d)]
            faces += tris
            for t in tris:
                for k in range(3):
                    edges.add(tuple(sorted((t[k], t[(k + 1) % 3]))))
    edges = sorted(edges)
    count = {e: 0 for e in edges}
    for t in faces:
        for k in range(3):
            count[tuple(sorted((t[k], t[(k + 1) % 3])))] += 1
    assign, angles = [], []
    for e in edges:
        if count[e] == 1:
            assign.append("B")
            angles.append(0.0)
        else:
            rho = rng.choice([-1, 1]) * rng.uniform(0.2, 0.8)
            assign.append("V" if rho > 0 else "M")
            angles.append(rho)
    return CreasePattern(xy, np.array(edges), faces, assign, angles, name=f"random_{seed}")


def fd_gradient(f, p, h=1e-5):
    """Central differences of ``f`` over every entry of ``p`` (1-D)."""
    out = []
    for i in range(p.shape[0]):
        e = jnp.zeros_like(p).at[i].set(h)
        out.append((f(p + e) - f(p - e)) / (2 * h))
    return np.array(out)


def scene(name):
    if name == "miura":
        cp = patterns.miura_ori(2, 2, sector_angle=np.radians(60), fold_angle=1.2)
        return cp, make_params(cp)
    if name == "seed_waterbomb":
        cp = patterns.seed_waterbomb()
        return cp, make_params(cp, stiffness=patterns.SEED_WATERBOMB_STIFFNESS)
    cp = random_pattern(0)
    return cp, make_params(cp)


@pytest.fixture(scope="module")
def miura():
    """The Miura scene, its solve and compiled pieces shared by several tests."""
    cp, params = scene("miura")
    solve = equilibrium_fn(cp, tol=TOL)
    w = jnp.asarray(np.random.default_rng(1).normal(size=(cp.mesh.num_vertices, 3)))

    def loss(t):
        return jnp.vdot(w, solve(params._replace(target=t))[0])

    value_and_grad = jax.jit(jax.value_and_grad(loss))  # one compiled solve for both
    return {
        "cp": cp,
        "params": params,
        "solve": solve,
        "loss": loss,
        "positions": jax.jit(lambda t: solve(params._replace(target=t))),
        "value": lambda t: value_and_grad(t)[0],
        "grad": lambda t: value_and_grad(t)[1],
    }


def test_miura_gradient_matches_central_differences(miura):
    """(The fixture's compiled gradient, shared with the tests below.)"""
    t = miura["params"].target
    fd = fd_gradient(miura["value"], t)
    err = np.max(np.abs(np.asarray(miura["grad"](t)) - fd)) / np.max(np.abs(fd))
    print(f"miura: gradient vs central differences, relative error {err:.2e}")
    assert err < 1e-6, err


@pytest.mark.parametrize("name", ["seed_waterbomb", "random"])
def test_gradient_matches_central_differences(name):
    cp, params = scene(name)
    solve = equilibrium_fn(cp, tol=TOL)
    w = jnp.asarray(np.random.default_rng(1).normal(size=(cp.mesh.num_vertices, 3)))

    def loss(t, start):
        x, info = solve(params._replace(target=t), start)
        return jnp.vdot(w, x), (x, info)

    flat = jnp.asarray(cp.mesh.vertices)
    value_and_grad = jax.jit(jax.value_and_grad(loss, has_aux=True))  # one compile for both
    (_, (x0, info)), g = value_and_grad(params.target, flat)
    assert bool(info.ok), info
    # warm-started from the equilibrium: the same one, in a few iterations
    fd = fd_gradient(lambda t: value_and_grad(t, x0)[0][0], params.target)
    err = np.max(np.abs(np.asarray(g) - fd)) / np.max(np.abs(fd))
    print(f"{name}: gradient vs central differences, relative error {err:.2e}")
    assert err < 1e-6, err


def test_gradient_other_parameters(miura):
    """percent, stiffnesses and rest lengths are differentiable too."""
    params, solve = miura["params"], miura["solve"]
    x0, _ = miura["positions"](params.target)
    w = jnp.asarray(np.random.default_rng(2).normal(size=x0.shape))

    def flat(p):
        return jnp.concatenate([p.percent[None], p.stiffness.crease[None], p.rest_length[:3]])

    def unflat(v):
        rest = params.rest_length.at[:3].set(v[2:])
        stiff = params.stiffness._replace(crease=v[1])
        return params._replace(percent=v[0], stiffness=stiff, rest_length=rest)

    def loss(v):
        return jnp.vdot(w, solve(unflat(v), x0)[0])

    value_and_grad = jax.jit(jax.value_and_grad(loss))  # one compile for both
    v0 = flat(params)
    g = value_and_grad(v0)[1]
    fd = fd_gradient(lambda v: value_and_grad(v)[0], v0, h=1e-6)
    assert np.allclose(g, fd, rtol=1e-5, atol=1e-7 * np.max(np.abs(fd))), (g, fd)


def test_assembled_hessian_is_the_gauged_hessian(monkeypatch):
    """The factored matrix is d^2E/du^2, plus an identity on the gauged-out directions."""
    import origami_jax.design as d

    cp = random_pattern(1, n=2)
    params = make_params(cp)
    seen = {}
    original = d._implicit

    def spy(params, u, reference, factor, scale, problem):
        # the solve is compiled (op by op it takes several times longer): the values come
        # back to the host through a callback
        leaves, tree = jax.tree.flatten((problem, u, reference))
        names = ("problem", "u", "reference")

        def keep(*a):
            seen.update(zip(names, tree.unflatten(a), strict=True))

        jax.debug.callback(keep, *leaves)
        return original(params, u, reference, factor, scale, problem)

    monkeypatch.setattr(d, "_implicit", spy)
    jax.block_until_ready(jax.jit(equilibrium_fn(cp))(params))
    problem, reference = seen["problem"], seen["reference"]
    u = seen["u"] + 0.01 * jnp.asarray(np.random.default_rng(0).normal(size=seen["u"].shape))
    n = u.size

    @jax.jit  # compiled: op by op, the Hessian takes several times longer
    def both(u):
        full = jax.hessian(lambda v: objective(v.reshape(u.shape), problem, reference))
        return d._hessian_values(problem, u, reference), full(u.reshape(-1))

    values, h = both(u)
    gauged = np.ones((u.shape[0], 3, 3)) * np.eye(3)
    gauged[np.asarray(problem.pinned)] = np.asarray(problem.projectors)
    off = np.zeros((n, n))
    for k in range(u.shape[0]):
        off[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] = np.eye(3) - gauged[k]
    scale = float(jnp.mean(params.stiffness.axial / params.rest_length))
    assert not problem.aux.sparse
    assert np.allclose(values.reshape(n, n), h + scale * off, atol=1e-12)


def test_forward_and_reverse_mode_agree(miura):
    t = miura["params"].target
    forward = jax.jit(jax.jacfwd(miura["loss"]))(t)  # jvp, one tangent per target
    assert np.allclose(forward, miura["grad"](t), rtol=1e-10, atol=1e-13)


def test_vmap_over_a_batch_of_targets(miura):
    params, solve = miura["params"], miura["solve"]
    w = jnp.asarray(np.random.default_rng(1).normal(size=(miura["cp"].mesh.num_vertices, 3)))

    def loss(t):  # the fixture's loss, with the solve's output as well
        x, info = solve(params._replace(target=t))
        return jnp.vdot(w, x), (x, info)

    targets = params.target[None] * jnp.array([0.6, 0.8, 1.0])[:, None]
    grads, (xs, infos) = jax.jit(jax.vmap(jax.grad(loss, has_aux=True)))(targets)
    assert xs.shape == (3, miura["cp"].mesh.num_vertices, 3) and bool(jnp.all(infos.ok))
    for k in range(3):
        x, _ = miura["positions"](targets[k])
        assert np.allclose(xs[k], x, atol=1e-10)
        assert np.allclose(grads[k], miura["grad"](targets[k]), rtol=1e-8, atol=1e-12)


def test_unconverged_solve_is_flagged_and_gradient_is_nan():
    cp, params = scene("miura")
    solve = equilibrium_fn(cp, tol=TOL, max_iter=2)

    def loss(t):
        x, info = solve(params._replace(target=t))
        return x.sum(), info

    g, info = jax.jit(jax.grad(loss, has_aux=True))(params.target)
    assert not bool(info.converged) and not bool(info.ok) and int(info.iterations) == 2
    assert bool(jnp.all(jnp.isnan(g)))  # never a silent wrong gradient


def test_sparse_hessian_solve_matches_dense(miura):
    params = miura["params"]
    sparse = equilibrium_fn(miura["cp"], solver=Newton(linear_solver="sparse"), tol=TOL)
    w = jnp.asarray(np.random.default_rng(1).normal(size=(miura["cp"].mesh.num_vertices, 3)))

    def loss(t):
        x, info = sparse(params._replace(target=t))
        return jnp.vdot(w, x), info

    g, info = jax.jit(jax.grad(loss, has_aux=True))(params.target)
    assert bool(info.ok) and float(info.pivot_rel) > 0
    assert np.allclose(g, miura["grad"](params.target), rtol=1e-8)


def test_float32():
    """A float32 solve's gradient is float32 and agrees with float64's to about its tolerance
    (1e-4 relative: derivatives are as accurate as the solve)."""
    cp = patterns.miura_ori(2, 2, fold_angle=1.0)
    solve = equilibrium_fn(cp)
    grads = {}
    for dtype in (jnp.float32, jnp.float64):
        params = make_params(cp, dtype=dtype)

        def loss(t, params=params):
            x, info = solve(params._replace(target=t))
            return x[:, 2].sum(), (x, info)

        g, (x, info) = jax.jit(jax.grad(loss, has_aux=True))(params.target)
        assert x.dtype == dtype and g.dtype == dtype and bool(info.ok)
        grads[dtype] = np.asarray(g, np.float64)
    scale = np.max(np.abs(grads[jnp.float64]))
    assert np.max(np.abs(grads[jnp.float32] - grads[jnp.float64])) <= 1e-4 * scale


def test_losses():
    rng = np.random.default_rng(3)
    x = jnp.asarray(rng.normal(size=(7, 3)))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.linalg.det(q))
    moved = x @ q.T + jnp.array([1.0, -2.0, 0.5])
    assert np.allclose(kabsch(x, moved), moved, atol=1e-10)
    assert float(jnp.max(jnp.abs(target_shape(moved)(x)))) < 1e-10
    assert float(jnp.max(jnp.abs(target_positions(x)(x)))) == 0.0
    r = target_height(1.0)(x)
    assert np.isclose(r[0], float(x[:, 2].max() - x[:, 2].min() - 1.0))
    assert target_span(2.0)(x).shape == (2,)
    assert np.isclose(target_distance([1, 4], 0.5)(x)[0], float(jnp.linalg.norm(x[4] - x[1])) - 0.5)
    flat = jnp.asarray(rng.normal(size=(5, 3))).at[:, 2].set(0.3)
    assert float(jnp.max(jnp.abs(target_surface(lambda p: 0 * p[:, 0])(flat)))) < 1e-15
    sdf = target_surface(lambda p: jnp.linalg.norm(p, axis=1) - 1.0, kind="sdf")
    assert np.allclose(sdf(jnp.eye(3)), 0.0)
    # the Kabsch alignment's gradient against central differences
    shape_loss = jax.jit(lambda y: 0.5 * jnp.sum(target_shape(moved)(y) ** 2))
    y = x + 0.01 * jnp.asarray(rng.normal(size=x.shape))
    g = np.asarray(jax.grad(shape_loss)(y))
    h = 1e-6
    fd = np.zeros(g.size)
    for i in range(g.size):
        e = jnp.zeros(g.size).at[i].set(h).reshape(x.shape)
        fd[i] = (float(shape_loss(y + e)) - float(shape_loss(y - e))) / (2 * h)
    assert np.allclose(g.reshape(-1), fd, rtol=1e-5, atol=1e-9)


def test_design_recovers_hidden_fold_angles():
    cp = random_pattern(5)
    base = make_params(cp)
    hidden = base.target
    solve = equilibrium_fn(cp, tol=TOL)
    goal, info = jax.jit(solve)(base)  # compiled: op by op, one solve takes longer
    assert bool(info.ok)
    init = hidden + jnp.asarray(np.random.default_rng(4).uniform(-0.15, 0.15, hidden.shape))
    r = design(cp, target_positions(goal), init, params=base, tol=TOL, steps=30, xtol=1e-12)
    assert bool(r.info.ok), r.reason
    assert float(jnp.max(jnp.abs(r.variables - hidden))) <= 1e-6, r.reason
    assert r.history["loss"][-1] < 1e-20


def test_design_miura_fold_angle_for_a_distance():
    """One scalar, the zig-zag fold angle, mapped to every target by the rigid-fold relation
    ``tan(rho_s / 2) = cos(gamma) tan(rho_z / 2)``, reaches a given span: the distance between
    the ends of a zig-zag border, ``2 S`` over two panels with
    ``S = b cos(t) tan(g) / sqrt(1 + cos(t)^2 tan(g)^2)``, ``t`` half the fold angle."""
    gamma = np.radians(60)
    cp = patterns.miura_ori(2, 2, sector_angle=gamma, fold_angle=1.0)
    base = make_params(cp)
    zigzag = jnp.isclose(jnp.abs(base.target), 1.0)
    sign = jnp.sign(base.target)

    def to_params(z, p):
        straight = 2 * jnp.arctan(np.cos(gamma) * jnp.tan(z[0] / 2))
        return p._replace(target=sign * jnp.where(zigzag, z[0], straight))

    goal = 1.4  # flat: 2 sin(60 deg) = 1.73; at 1 rad: 1.67
    span = target_distance([0, 2], goal)  # vertices (0, 0) and (2, 0)
    r = design(cp, span, jnp.array([1.0]), params=base, to_params=to_params, steps=20)
    assert bool(r.info.ok) and abs(float(span(r.positions)[0])) < 1e-8, r.reason
    c = np.cos(float(r.variables[0]) / 2) * np.tan(gamma)
    assert np.isclose(2 * c / np.sqrt(1 + c * c), goal, atol=1e-6)


def test_design_with_optax_respects_fixed_creases():
    optax = pytest.importorskip("optax")
    cp = patterns.miura_ori(2, 2, fold_angle=1.0)
    base = make_params(cp)
    fixed = np.zeros(base.target.shape[0], bool)
    fixed[0] = True
    r = design(
        cp, target_height(0.4), params=base, optimizer=optax.adam(0.05), steps=15, fixed=fixed
    )
    assert r.history["loss"][-1] < 0.1 * r.history["loss"][0]
    assert float(r.variables[0]) == float(base.target[0])
    # the result is consistent: its loss is the goal's at its positions, the equilibrium of
    # its parameters
    x, info = equilibrium_fn(cp)(r.params)
    assert bool(info.ok) and np.allclose(x, r.positions, atol=1e-9)
    assert r.loss == pytest.approx(0.5 * float(target_height(0.4)(x)[0] ** 2), rel=1e-9)
    assert len(r.history["loss"]) == r.steps + 1


def test_design_calls_reuse_the_compiled_solve():
    """A second design() on the same pattern, another goal of the same kind, and a pattern of
    the same shapes compile nothing (issue 44: design loops)."""
    compiles = []

    def listener(event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            compiles.append(duration)

    cp = patterns.miura_ori(2, 2, fold_angle=1.0)
    first = design(cp, target_height(0.5), steps=3)
    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        again = design(cp, target_height(0.5), steps=3)
        other_goal = design(cp, target_height(0.45), steps=3)
        same_shapes = patterns.miura_ori(2, 2, fold_angle=0.9)
        other_pattern = design(same_shapes, target_height(0.5), steps=3)
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    assert compiles == []
    np.testing.assert_array_equal(again.variables, first.variables)
    for r in (first, other_goal, other_pattern):
        assert bool(r.info.ok) and r.loss < 1e-8, r.reason
    assert not np.allclose(other_goal.variables, first.variables)


def test_gradient_through_contact_matches_central_differences():
    """A full valley held short of flat by contact: where it stops moves with the crease's
    target and stiffness and with the facets' through the barrier's force; the implicit
    derivative (the barrier's exact Hessian in it) matches central differences."""
    from origami_jax.contact import all_pairs, contact_mesh, contact_report

    cp = patterns.single_crease(fold_angle=np.pi)
    solve = equilibrium_fn(cp, solver=Newton(linear_solver="dense"), tol=TOL, contact=True)
    params = make_params(cp)
    w = jnp.asarray(np.random.default_rng(3).normal(size=(cp.mesh.num_vertices, 3)))

    def unflat(v):
        stiff = params.stiffness._replace(crease=v[1], facet=v[2])
        return params._replace(target=params.target.at[0].set(v[0]), stiffness=stiff)

    def loss(v):
        x, info = solve(unflat(v))  # from flat, directly
        return jnp.vdot(w, x), (x, info)

    value_and_grad = jax.jit(jax.value_and_grad(loss, has_aux=True))
    v0 = jnp.asarray([params.target[0], params.stiffness.crease, params.stiffness.facet])
    (_, (x0, info)), g = value_and_grad(v0)
    assert bool(info.ok), info
    # the barrier holds it: pairs within reach, the crease short of pi
    dhat = float(solve.contact.dhat)
    report = contact_report(x0, all_pairs(contact_mesh(cp.mesh), np.asarray(x0)), dhat)
    assert int(report.num_active) >= 1 and 0.0 < float(report.min_ratio) < 1.0
    fd = fd_gradient(lambda v: value_and_grad(v)[0][0], v0, h=1e-6)
    err = np.max(np.abs(np.asarray(g) - fd)) / np.max(np.abs(fd))
    print(f"gradient through contact vs central differences, relative error {err:.2e}")
    assert err < 1e-6, (err, g, fd)


def test_refined_solve_reaches_the_exact_system_from_an_approximate_factor():
    """Sparse layouts with contact: the factored sheet holds each pair's curvature on its
    corners' diagonal blocks only; conjugate gradients on the exact Hessian, preconditioned by
    it, solve the exact system, and give NaN (not a wrong derivative) where they cannot."""
    from origami_jax.design import _refined_solve

    rng = np.random.default_rng(4)
    q = rng.normal(size=(12, 12))
    a = jnp.asarray(q @ q.T + 12 * np.eye(12))  # positive definite
    approx = jnp.diag(jnp.diag(a))  # its diagonal only: a preconditioner
    b = jnp.asarray(rng.normal(size=(4, 3)))

    def matvec(v):
        return (a @ v.reshape(-1)).reshape(v.shape)

    def precondition(_, r):
        return jnp.linalg.solve(approx, r.reshape(-1)).reshape(r.shape)

    x = _refined_solve(matvec, precondition, None, b)
    np.testing.assert_allclose(x.reshape(-1), np.linalg.solve(a, b.reshape(-1)), rtol=1e-10)
    # singular, with b outside its range: no solution, and NaN says so
    u, _, _ = np.linalg.svd(q)
    bad = jnp.asarray(u @ np.diag(np.r_[0.0, np.ones(11)]) @ u.T)
    b = jnp.asarray(u[:, 0].reshape(4, 3))
    x = _refined_solve(lambda v: (bad @ v.reshape(-1)).reshape(v.shape), precondition, None, b)
    assert np.all(np.isnan(np.asarray(x)))


def test_a_solve_that_is_not_ok_says_why_in_words():
    from origami_jax.design import EquilibriumInfo, not_ok_reason
    from origami_jax.solvers import Status

    def info(converged, status, stable=True):
        return EquilibriumInfo(
            converged=jnp.asarray(converged),
            status=jnp.asarray(status, jnp.int32),
            iterations=jnp.asarray(7),
            grad_norm_rel=jnp.asarray(3e-4),
            energy=jnp.asarray(0.5),
            stable=jnp.asarray(stable),
            pivot_rel=jnp.asarray(-2e-3),
        )

    assert not_ok_reason(info(False, Status.MAX_ITER), 1e-10) == (
        "equilibrium not ok: iteration limit 7 reached: grad_norm_rel 3.00e-04 > tol 1.0e-10"
    )
    assert "more contact pairs than their capacity" in not_ok_reason(
        info(False, Status.CONTACT_OVERFLOW)
    )
    unstable = not_ok_reason(info(True, Status.CONVERGED, stable=False))
    assert "unstable" in unstable and "-2.0e-03" in unstable
