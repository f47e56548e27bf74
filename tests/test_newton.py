"""What is particular to Newton: quadratic convergence, the exact Hessian and its hand-over to
the convex part, the Levenberg-Marquardt shift, geodesic acceleration, step expansion, gauge-free
steps, and its dense, sparse and block-sparse assembly and solves."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from origami_jax import fold, patterns
from origami_jax.energy import make_params, make_structure
from origami_jax.geometry import fold_angles
from origami_jax.kinematics import rigid_fold
from origami_jax.solvers import Newton, Status
from origami_jax.solvers.base import make_problem, positions, prepare


def test_newton_is_quadratic_near_the_solution():
    """Every iteration recorded: once the gradient is small, each step squares it (to a
    constant), down to the rounding floor; a linearly converging solve fails this."""
    cp = patterns.miura_ori(3, 3, sector_angle=np.radians(60), fold_angle=np.pi / 2)
    result = fold(cp, solver="newton", record_every=1)
    g = result.history["grad_norm_rel"]
    assert result.converged and len(g) == result.iterations + 1
    tail = g[np.flatnonzero(g < 1e-2)[0] :]
    assert len(tail) >= 3
    for before, after in zip(tail[:-1], tail[1:], strict=True):
        assert after <= max(10.0 * before**2, 1e-12), (before, after)


def test_an_exact_hessian_that_does_not_factor_hands_over_within_the_iteration():
    """Asked for the exact Hessian where it is indefinite (a sheet shrunk by a fifth: every bar
    compressed, so its transverse stiffness is negative), the host factorization takes the
    convex part's step at once and says so; where the exact Hessian factors it is used.
    Vmapped (the cond runs both branches), the same per member, and no host factorization is
    left kept. Dense, the attempt fails (``ok`` false) and costs its iteration. With a
    shift on exact attempts (``Newton.shift_after``) the compressed start's exact Hessian
    factors on the host."""
    from origami_jax.solvers import hostsparse

    cp = patterns.miura_ori(3, 3)
    mesh = cp.mesh

    def newton_step(solver, s, problem, exact):
        solve, used = solver._factor(s, problem, exact, keep=True)
        step, ok = solve(-s.grad)
        again, _ = solve(-2 * s.grad)  # the second solve releases a kept host factorization
        return step, ok, used[0], again

    sparse, dense = Newton(linear_solver="sparse"), Newton(linear_solver="dense")
    one = jax.jit(newton_step, static_argnums=0)
    steps, states, problems = {}, [], []
    for name, start in (("shrunk", 0.8 * mesh.vertices), ("flat", mesh.vertices)):
        problem = make_problem(mesh, make_structure(mesh), make_params(cp), start, 1e-9)
        problem = prepare(sparse, problem, mesh)
        s = sparse.init(problem)
        states.append(s)
        problems.append(problem)
        for exact in (True, False):
            step, ok, used, again = one(sparse, s, problem, jnp.asarray(exact))
            assert bool(ok) and bool(used) == (exact and name == "flat"), (name, exact)
            np.testing.assert_allclose(again, 2 * step, rtol=1e-9, atol=1e-12)
            steps[name, exact] = np.asarray(step)
    np.testing.assert_array_equal(steps["shrunk", True], steps["shrunk", False])
    assert np.max(np.abs(steps["flat", True] - steps["flat", False])) > 1e-3
    # shifted (``Newton.shift_after``), the compressed start's exact Hessian factors on the host
    shifted = states[0]._replace(shift=jnp.asarray(10.0, states[0].shift.dtype))
    step, ok, used, _ = one(sparse, shifted, problems[0], jnp.asarray(True))
    assert bool(ok) and bool(used)
    assert np.max(np.abs(np.asarray(step) - steps["shrunk", False])) > 1e-3
    both = jax.tree.map(lambda *a: jnp.stack(a), *states)
    start = jnp.stack([p.start for p in problems])
    problem = dataclasses.replace(problems[0], start=start)
    axes = dataclasses.replace(jax.tree.map(lambda _: None, problem), start=0)
    vmapped = jax.jit(jax.vmap(functools.partial(newton_step, sparse), in_axes=(0, axes, None)))
    step, ok, used, _ = vmapped(both, problem, jnp.asarray(True))
    assert np.all(np.asarray(ok)) and np.asarray(used).tolist() == [False, True]
    np.testing.assert_allclose(step[0], steps["shrunk", False], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(step[1], steps["flat", True], rtol=1e-9, atol=1e-12)
    assert not hostsparse._KEPT
    shrunk = prepare(dense, dataclasses.replace(problems[0], aux=None), mesh)
    _, ok, used, _ = one(dense, dense.init(shrunk), shrunk, jnp.asarray(True))
    assert bool(used) and not bool(ok)


def test_exact_attempts_are_shifted_after_repeated_rejections():
    """From the ``shift_after``-th rejected exact attempt in a row, exact attempts add a
    Levenberg-Marquardt shift (``shift_min`` first, 10x more with each rejection, 10x less
    with each exact step taken). At a compressed start (a Miura-ori 3 x 3 at 0.8 of its size)
    the exact Hessian is indefinite and its dense attempt is rejected; a large shift makes it
    factor, and the step it gives is not the convex part's, which the shift leaves alone. (The
    buckling check would skip these attempts: off here, tested below.)"""
    cp = patterns.miura_ori(3, 3)
    mesh = cp.mesh
    dense = Newton(linear_solver="dense", buckling_ratio=float("inf"))
    problem = make_problem(mesh, make_structure(mesh), make_params(cp), 0.8 * mesh.vertices, 1e-9)
    problem = prepare(dense, problem, mesh)
    s0 = dense.init(problem)
    step = jax.jit(lambda solver, s: solver.step(s, problem), static_argnums=0)

    def attempt(s, exact):
        solve, used = dense._factor(s, problem, exact, keep=False)
        d, ok = solve(-s.grad)
        return d, ok, used[0]

    attempt = jax.jit(attempt)
    n = dense.shift_after
    unshifted = s0._replace(exact=jnp.asarray(True), failures=jnp.asarray(n - 1, jnp.int32))
    after = step(dense, unshifted)
    assert int(after.failures) == n and float(after.shift) == dense.shift_min
    later = step(dataclasses.replace(dense, shift_after=n + 1), unshifted)
    assert int(later.failures) == n and float(later.shift) == 0.0
    _, ok, used = attempt(unshifted, jnp.asarray(True))
    assert bool(used) and not bool(ok)

    shifted = unshifted._replace(shift=jnp.asarray(10.0, s0.shift.dtype))
    d_exact, ok, used = attempt(shifted, jnp.asarray(True))
    d_convex, ok_convex, _ = attempt(shifted, jnp.asarray(False))
    assert bool(ok) and bool(used) and bool(ok_convex)
    assert np.max(np.abs(d_exact - d_convex)) > 1e-3 * np.max(np.abs(d_convex))
    # the shift is the exact attempts' alone: the convex part's step is the unshifted one
    np.testing.assert_array_equal(d_convex, attempt(unshifted, jnp.asarray(False))[0])
    taken = step(dense, shifted)
    assert int(taken.iteration) == 1 and float(taken.energy) < float(s0.energy)
    assert int(taken.failures) == 0 and float(taken.shift) == pytest.approx(1.0)


def test_vertex_buckling_is_the_compressed_bars_softening_against_the_hinges_support():
    """Per vertex: the compressed bars' ``axial / l0 (l0 / l - 1)`` summed, and the trace of
    the hinges' Gauss-Newton blocks (the convex part's hinge blocks); vmapped (batch innermost)
    the same per member."""
    from origami_jax.energy import initial_reference
    from origami_jax.solvers.newton import _vertex_buckling, element_blocks

    cp = patterns.waterbomb(1, 1, fold_angle=2.0)
    mesh = cp.mesh
    structure, params = make_structure(mesh), make_params(cp)
    rng = np.random.default_rng(3)
    xs = rigid_fold(cp, 0.3 * mesh.target) * rng.uniform(0.97, 1.03, (2, mesh.num_vertices, 1))
    bars, hinges = np.asarray(structure.bars), np.asarray(structure.hinges)
    l0 = np.asarray(params.rest_length)
    for x in xs:
        length = np.linalg.norm(x[bars[:, 1]] - x[bars[:, 0]], axis=1)
        eps = np.finfo(np.float64).eps  # compression up to 16 eps counts as none
        soft = np.maximum(l0 / length - 1 - 16 * eps, 0) / l0  # axial stiffness 1
        expected = np.zeros(mesh.num_vertices)
        np.add.at(expected, bars[:, 0], soft)
        np.add.at(expected, bars[:, 1], soft)
        hinge_blocks = element_blocks(
            jnp.asarray(x), structure, params, initial_reference(x, structure, params), False
        )[1]
        traces = np.trace(np.asarray(hinge_blocks)[:, range(4), range(4)], axis1=2, axis2=3)
        support = np.zeros(mesh.num_vertices)
        np.add.at(support, hinges.ravel(), traces.ravel())
        ref = initial_reference(x, structure, params)
        softening, got = _vertex_buckling(jnp.asarray(x), structure, params, ref)
        assert np.max(expected) > 0 and np.min(expected) == 0
        np.testing.assert_allclose(softening, expected, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(got, support, rtol=1e-12)
    # vmapped (batch innermost) with the parameters shared, and batched as fold_batch does
    stiffer = params._replace(stiffness=params.stiffness._replace(crease=0.01))
    both = jax.tree.map(lambda a, b: jnp.stack([a, b]), params, stiffer)
    refs = jax.vmap(initial_reference, in_axes=(0, None, None))(jnp.asarray(xs), structure, params)
    shared = jax.vmap(_vertex_buckling, in_axes=(0, None, None, 0))(
        jnp.asarray(xs), structure, params, refs
    )
    each = jax.vmap(_vertex_buckling, in_axes=(0, None, 0, 0))(
        jnp.asarray(xs), structure, both, refs
    )
    for i, (x, p) in enumerate(zip(xs, (params, stiffer), strict=True)):
        for batched, q in ((shared, params), (each, p)):
            ref = initial_reference(jnp.asarray(x), structure, params)
            single = _vertex_buckling(jnp.asarray(x), structure, q, ref)
            np.testing.assert_allclose(batched[0][i], single[0], rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(batched[1][i], single[1], rtol=1e-12)
    assert np.max(np.abs(each[1][1] - shared[1][1])) > 0  # the stiffer creases counted


def test_exact_attempts_are_skipped_where_compressed_bars_buckle_the_sheet():
    """After one convex step from flat, a waterbomb base's compressed bars outweigh its hinges'
    support at some vertex, and there its exact Hessian does not factor: asked for it, Newton
    without the check spends the iteration (a rejection), with it takes the convex step (the
    same as asked for the convex part) and counts no rejection. Near equilibrium (the gradient
    below ``buckling_far`` of its start) the check is off and the attempt goes ahead."""
    from origami_jax.solvers.newton import _vertex_buckling

    cp = patterns.waterbomb(1, 1, fold_angle=2.5)
    mesh = cp.mesh
    checked, unchecked = Newton(), Newton(buckling_ratio=float("inf"))
    problem = make_problem(mesh, make_structure(mesh), make_params(cp), None, 1e-10)
    problem = prepare(checked, problem, mesh)
    step = jax.jit(lambda solver, s: solver.step(s, problem), static_argnums=0)
    s = step(checked, checked.init(problem)._replace(exact=jnp.asarray(False)))
    softening, support = _vertex_buckling(
        positions(problem, s.u), problem.structure, problem.params, s.reference
    )
    assert np.max(np.asarray(softening) / np.asarray(support)) > checked.buckling_ratio
    assert float(s.grad_max) > checked.buckling_far * float(s.grad_max0)
    ask = s._replace(exact=jnp.asarray(True))
    spent = step(unchecked, ask)
    assert int(spent.failures) == 1 and float(spent.energy) == float(s.energy)
    skipped = step(checked, ask)
    convex = step(checked, s._replace(exact=jnp.asarray(False)))
    assert int(skipped.failures) == 0 and float(skipped.energy) < float(s.energy)
    np.testing.assert_array_equal(skipped.u, convex.u)
    near = ask._replace(grad_max0=s.grad_max / (0.5 * checked.buckling_far))
    assert int(step(checked, near).failures) == 1
    # on the host (sparse) path too: no exact factorization, the convex step, no failure
    sparse = Newton(linear_solver="sparse")
    host = prepare(sparse, dataclasses.replace(problem, aux=None), mesh)
    host_step = jax.jit(lambda s: sparse.step(s, host))
    skipped_host = host_step(ask)
    assert int(skipped_host.failures) == 0
    np.testing.assert_allclose(
        skipped_host.u, host_step(s._replace(exact=jnp.asarray(False))).u, rtol=0, atol=1e-12
    )


def test_the_hand_over_takes_the_same_steps_as_an_iteration_spent():
    """A sparse fold hands failed exact attempts over within the iteration; a dense one spends
    an iteration on each: the same end, in fewer iterations (Miura-ori 10 x 10; with exact
    attempts after every unexpanded full step, as ``convex_rate=0``, the default, makes
    them; the buckling check off, which would skip the attempts that fail here)."""
    cp = patterns.miura_ori(10, 10)
    unchecked = {"convex_rate": 0.0, "buckling_ratio": float("inf")}
    dense = fold(cp, solver=Newton(linear_solver="dense", **unchecked), tol=1e-10)
    sparse = fold(cp, solver=Newton(linear_solver="sparse", **unchecked), tol=1e-10)
    assert dense.converged and sparse.converged
    assert sparse.iterations < dense.iterations
    np.testing.assert_allclose(sparse.positions, dense.positions, atol=1e-10 * cp.diameter)


@pytest.mark.parametrize(
    "cp",
    [patterns.miura_ori(4, 4), patterns.seed_waterbomb()],
    ids=lambda cp: cp.name,
)
def test_geodesic_acceleration_saves_iterations_and_changes_no_answer(cp):
    """The same equilibrium with and without the curved step, in fewer iterations with it
    (Miura-ori 4 x 4: 20 -> 10; the seed's waterbomb: 23 -> 13, measured 2026-12-02)."""
    plain = fold(cp, solver=Newton(acceleration=0), path="direct")
    curved = fold(cp, solver=Newton(), path="direct")
    assert plain.converged and curved.converged
    assert curved.iterations < 0.75 * plain.iterations
    assert abs(curved.energy - plain.energy) <= 1e-9 * max(plain.energy, 1e-12) + 1e-14
    if cp.name.startswith("miura"):  # unique shape: the rigid fold
        np.testing.assert_allclose(curved.positions, plain.positions, atol=1e-8)


def test_step_expansion_saves_iterations_and_changes_no_answer():
    """Doubling full steps while the energy falls: the same Kresling state in fewer
    iterations (25 -> 23 measured 2026-12-03, after the gauge-free steps; Origami Simulator's
    BoxPleatInOutWave 218 -> 165; on a Miura-ori 12 x 12 both now take 12)."""
    cp = patterns.kresling()
    plain = fold(cp, solver=Newton(expansions=0))
    expanded = fold(cp, solver=Newton())
    assert plain.converged and expanded.converged
    assert expanded.iterations < plain.iterations
    np.testing.assert_allclose(expanded.positions, plain.positions, atol=1e-9 * cp.diameter)
    assert abs(expanded.energy - plain.energy) <= 1e-9 * plain.energy + 1e-15


def test_newton_element_hessians_match_autodiff():
    """The assembled exact Hessian equals jax.hessian of the energy (gauge off)."""
    from origami_jax.energy import energy, initial_reference
    from origami_jax.solvers.newton import assemble, hessian_layout

    cp = patterns.degree4_vertex(np.pi / 3, np.pi / 4, np.pi / 2)
    mesh = cp.mesh
    structure, params = make_structure(mesh), make_params(cp)
    x = rigid_fold(cp, 0.6 * mesh.target) + 0.01 * np.sin(np.arange(mesh.num_vertices * 3)).reshape(
        -1, 3
    )
    ref = initial_reference(x, structure, params)
    layout = hessian_layout(mesh, structure, sparse=False)
    n = layout.size
    # gauge off: no pinned vertex, so the assembly is the plain sum of the element blocks
    problem = dataclasses.replace(
        make_problem(mesh, structure, params),
        aux=layout,
        pinned=jnp.zeros(0, jnp.int32),
        projectors=jnp.zeros((0, 3, 3)),
    )

    @jax.jit  # compiled: op by op, these take several times longer
    def matrices(x):
        def assembled(exact):
            return assemble(x, problem, ref, exact).reshape(n, n)

        full = jax.hessian(lambda y: energy(y.reshape(-1, 3), structure, params, ref))(x.ravel())
        # vmapped (fold_batch) over traced flags: one branch for all, zero weight where unset
        mixed = jax.vmap(assembled)(jnp.array([True, False]))
        neither = jax.vmap(assembled)(jnp.array([False, False]))
        return assembled(True), full, assembled(False), mixed, neither

    assembled, expected, matrix, mixed, neither = matrices(jnp.asarray(x))
    np.testing.assert_allclose(assembled, expected, atol=1e-10)
    np.testing.assert_allclose(mixed[0], assembled, atol=1e-13)
    for convex in (mixed[1], neither[0], neither[1]):
        np.testing.assert_allclose(convex, matrix, atol=1e-13)
    assert np.abs(np.asarray(assembled) - np.asarray(matrix)).max() > 1e-3
    # the convex part is positive semi-definite
    assert np.linalg.eigvalsh(np.asarray(matrix)).min() > -1e-12


def test_newton_unknown_linear_solver():
    with pytest.raises(ValueError, match="unknown linear solver"):
        Newton(linear_solver="qr")


def test_newton_dense_step_vmaps_over_percent():
    """The dense Newton iteration is pure: jax.vmap folds one pattern to several percents."""
    cp = patterns.single_crease(fold_angle=2.0)
    mesh = cp.mesh
    solver = Newton(linear_solver="dense")
    params = make_params(cp)
    problem = prepare(solver, make_problem(mesh, make_structure(mesh), params), mesh)

    def solve(percent):
        p = dataclasses.replace(problem, params=params._replace(percent=percent))
        state = solver.run(solver.init(p), p, jnp.int32(100))
        crease = fold_angles(positions(p, state.u), p.structure.hinges, state.reference.angles)[0]
        return state.status, crease

    percents = jnp.array([0.25, 0.5, 1.0])
    status, crease = jax.jit(jax.vmap(solve))(percents)
    assert np.all(np.asarray(status) == Status.CONVERGED)
    np.testing.assert_allclose(crease, 2.0 * np.asarray(percents), atol=1e-8)


def test_sparse_assembly_matches_dense():
    """The sparse Hessian (its upper triangle: the corner pairs a <= b of each element, whole
    3 x 3 blocks scattered, those whose corners the order swaps into a transposed copy; only
    the pinned vertices' blocks projected) equals the dense one entry for entry, exact and
    convex, away from the flat state (every block nonzero, the pinned triangle's among
    them)."""
    import scipy.sparse as sp

    from origami_jax.energy import initial_reference
    from origami_jax.solvers.newton import gauged_hessian, hessian_layout

    cp = patterns.miura_ori(2, 3)
    mesh = cp.mesh
    structure, params = make_structure(mesh), make_params(cp)
    problem = make_problem(mesh, structure, params)
    x = rigid_fold(cp, 0.6 * mesh.target)
    x = jnp.asarray(x + 0.03 * np.random.default_rng(5).standard_normal(x.shape))
    ref = initial_reference(x, structure, params)
    n = 3 * mesh.num_vertices
    sparse = dataclasses.replace(problem, aux=hessian_layout(mesh, structure, sparse=True))
    dense = dataclasses.replace(problem, aux=hessian_layout(mesh, structure, sparse=False))
    layout = sparse.aux
    assert int(layout.vertex_blocks.shape[0]) == mesh.num_vertices
    num = layout.block_vertices.shape[0]
    assert 0 < np.sum(np.asarray(layout.blocks) >= num) < len(layout.blocks)  # some swapped
    for exact in (True, False):
        values = np.asarray(gauged_hessian(x, sparse, ref, exact))
        upper = sp.csr_matrix(
            (values, np.asarray(layout.indices), np.asarray(layout.indptr)), shape=(n, n)
        ).toarray()
        assert np.all(np.tril(upper, -1) == 0)  # only the upper triangle is stored
        got = upper + np.triu(upper, 1).T
        order = np.asarray(layout.order)
        want = np.asarray(gauged_hessian(x, dense, ref, exact)).reshape(n, n)
        scale = np.abs(want).max()
        assert np.abs(got[np.ix_(order, order)] - want).max() <= 1e-14 * scale
        # the gauge: the fully pinned vertex's rows hold only the identity on its own block
        a = 3 * int(problem.pinned[0])
        rows = got[np.ix_(order, order)][a : a + 3]
        assert np.abs(np.delete(rows, np.s_[a : a + 3], axis=1)).max() == 0.0
        assert np.abs(rows[:, a : a + 3]).max() > 0.0


def test_nested_dissection_is_the_order_its_definition_gives():
    """The fill-reducing order (NumPy over the adjacency's rows at each split) is the one its
    definition gives with scipy's slicing: split at the median of the longer side, the left
    half's vertices that touch the right half last, each half in turn; on a Miura-ori and on a
    jittered sheet with an adjacency of weighted and explicitly zero (no) entries."""
    import scipy.sparse as sp

    from origami_jax.solvers.hessian_layout import hessian_elements, nested_dissection

    def definition(xy, adjacency, leaf=16):
        out = []

        def visit(idx):
            if len(idx) <= leaf:
                return out.append(idx)
            p = xy[idx]
            axis = int(np.argmax(p.max(axis=0) - p.min(axis=0)))
            below = p[:, axis] <= np.median(p[:, axis])
            left, right = idx[below], idx[~below]
            if len(left) == 0 or len(right) == 0:
                return out.append(idx)
            touches = np.asarray((adjacency[left][:, right] != 0).sum(axis=1)).ravel() > 0
            visit(left[~touches])
            visit(right)
            out.append(left[touches])

        visit(np.arange(len(xy)))
        return np.concatenate(out)

    rng = np.random.default_rng(7)
    for cp in (patterns.miura_ori(12, 9), patterns.miura_ori(1, 1)):
        mesh = cp.mesh
        elements = [np.asarray(e) for e in hessian_elements(make_structure(mesh))]
        rows = np.concatenate([np.repeat(e, e.shape[1], axis=1).ravel() for e in elements])
        cols = np.concatenate([np.tile(e, (1, e.shape[1])).ravel() for e in elements])
        v = mesh.num_vertices
        weights = rng.choice([0.0, 1.0, 2.5], size=len(rows))
        for xy in (mesh.vertices[:, :2], mesh.vertices[:, :2] + 0.01 * rng.normal(size=(v, 2))):
            for w in (np.ones(len(rows)), weights):
                adjacency = sp.coo_matrix((w, (rows, cols)), shape=(v, v)).tocsr()
                order = nested_dissection(xy, adjacency, leaf=4)
                assert np.array_equal(np.sort(order), np.arange(v))
                np.testing.assert_array_equal(order, definition(xy, adjacency, leaf=4))


def test_block_sparse_solve_matches_dense():
    """fold_batch's block-sparse solve (one plan for a batch of one topology) gives the dense
    solve's step, unbatched and vmapped, and reports a matrix that is not positive definite."""
    from origami_jax.energy import initial_reference
    from origami_jax.solvers import blocksparse
    from origami_jax.solvers.assembly import (
        element_blocks,
        gauge_scale,
        gauged_hessian,
        vertex_projectors,
    )
    from origami_jax.solvers.hessian_layout import hessian_layout

    cp = patterns.miura_ori(2, 2)
    mesh = cp.mesh
    structure, params = make_structure(mesh), make_params(cp)
    problem = make_problem(mesh, structure, params)
    problem = dataclasses.replace(problem, aux=hessian_layout(mesh, structure, sparse=False))
    plan = jax.tree.map(
        jnp.asarray,
        blocksparse.block_plan(
            [np.asarray(structure.bars), np.asarray(structure.hinges)], mesh.num_vertices
        ),
    )
    # the elimination runs in consecutive segments, each padded to its own widest step
    cuts = plan.segments
    assert cuts[0][0] == 0 and cuts[-1][1] == mesh.num_vertices and len(cuts) > 1
    assert all(a[1] == b[0] for a, b in zip(cuts, cuts[1:], strict=False))
    widest = max(p.shape[1] for p in plan.pair_a)
    assert sum(p.size for p in plan.pair_a) < mesh.num_vertices * widest
    rng = np.random.default_rng(0)
    base = rigid_fold(cp, 0.5 * mesh.target)
    xs = jnp.asarray(base + 0.02 * rng.standard_normal((3, *base.shape)))
    rhs = jnp.asarray(rng.standard_normal((3, *base.shape)))
    mu = 1e-3

    def fast(x, b, shift):
        ref = initial_reference(x, structure, params)
        blocks = element_blocks(x, structure, params, ref, False)
        proj = vertex_projectors(x.shape[0], problem.pinned, problem.projectors)
        return blocksparse.solve(plan, blocks, proj, gauge_scale(problem), shift, b)

    def dense(x, b):
        ref = initial_reference(x, structure, params)
        n = 3 * x.shape[0]
        matrix = gauged_hessian(x, problem, ref, False).reshape(n, n)
        d = jnp.diag(matrix)
        matrix = matrix + jnp.diag(mu * d + jnp.finfo(x.dtype).eps * jnp.max(d))
        return jnp.linalg.solve(matrix, b.reshape(-1)).reshape(x.shape)

    batched = jax.jit(jax.vmap(fast, in_axes=(0, 0, None)))
    step, ok = batched(xs, rhs, mu)
    expected = jax.jit(jax.vmap(dense))(xs, rhs)
    assert np.all(np.asarray(ok))
    np.testing.assert_allclose(step, expected, rtol=1e-8, atol=1e-10 * np.abs(expected).max())
    single, single_ok = jax.jit(fast)(xs[0], rhs[0], mu)
    assert bool(single_ok)
    np.testing.assert_allclose(single, expected[0], rtol=1e-8, atol=1e-10 * np.abs(expected).max())
    # a shift of -2 x the diagonal leaves no positive definite matrix
    _, bad = batched(xs, rhs, -2.0)
    assert not np.any(np.asarray(bad))
    # a plan per member (no shared pattern) falls back to solving each member on its own
    plans = jax.tree.map(lambda a: jnp.stack([a, a]), plan)
    each = jax.jit(
        jax.vmap(
            lambda p, x, b: blocksparse.solve(
                p,
                element_blocks(
                    x, structure, params, initial_reference(x, structure, params), False
                ),
                vertex_projectors(x.shape[0], problem.pinned, problem.projectors),
                gauge_scale(problem),
                mu,
                b,
            )
        )
    )
    step2, ok2 = each(plans, xs[:2], rhs[:2])
    assert np.all(np.asarray(ok2))
    np.testing.assert_allclose(step2, expected[:2], rtol=1e-8, atol=1e-10 * np.abs(expected).max())


def test_dense_solve_batches_one_member_at_a_time_and_keeps_forward_derivatives():
    from origami_jax.solvers.newton import (
        _cholesky_solve,
        _dense_factor,
        _dense_solve_factored,
    )

    def _dense_solve(m, r):
        return _dense_solve_factored(_dense_factor(m), r)

    rng = np.random.default_rng(1)
    a = rng.normal(size=(3, 5, 5))
    a = a @ a.transpose(0, 2, 1) + 5 * np.eye(5)
    b = rng.normal(size=(3, 5))
    np.testing.assert_allclose(jax.vmap(_dense_solve)(a, b), jax.vmap(_cholesky_solve)(a, b))
    shared = jax.vmap(_dense_solve, in_axes=(None, 0))(a[0], b)
    np.testing.assert_allclose(shared, jax.vmap(_cholesky_solve, in_axes=(None, 0))(a[0], b))

    def total(solve):
        return lambda s: jnp.sum(solve(a[0] * s, b[0]))

    # forward mode batches only the tangents: the rule must not recurse
    assert np.isclose(jax.jacfwd(total(_dense_solve))(1.0), jax.jacfwd(total(_cholesky_solve))(1.0))
    bad = jax.vmap(_dense_solve)(a - 10 * np.eye(5), b)
    assert np.all(np.isnan(np.asarray(bad)))


def test_gauge_free_steps_save_iterations_and_change_no_answer():
    """Far from a solution Newton steps free of the gauge (rigid part removed, then reframed):
    the same rigid fold of a 10 x 10 Miura-ori in fewer iterations (pinned: 16, free: 12,
    measured 2026-12-03; 100 x 100: 32 -> 20)."""
    cp = patterns.miura_ori(10, 10)
    pinned = fold(cp, solver=Newton(free_turn=np.inf))
    free = fold(cp, solver=Newton())
    assert pinned.converged and free.converged
    assert free.iterations < pinned.iterations
    np.testing.assert_allclose(free.positions, pinned.positions, atol=1e-9 * cp.diameter)


def _two_squares():
    """Two unit squares, apart, each with a valley diagonal: a pattern in two pieces."""
    from origami_jax.pattern import CreasePattern

    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    return CreasePattern(
        vertices=np.concatenate([square, square + [3, 0.5]]),
        edges=[[0, 1], [1, 2], [2, 3], [3, 0], [0, 2], [4, 5], [5, 6], [6, 7], [7, 4], [4, 6]],
        faces=[[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]],
        assignments="BBBBVBBBBV",
        fold_angles=[0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0],
        name="two_squares",
    )


def _rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def test_reframe_and_rigid_free_piece_by_piece():
    """Each piece is moved back to its own pinned triangle's pose, and loses its own rigid
    motion, whatever the other piece does."""
    from origami_jax.solvers.base import gauge
    from origami_jax.solvers.reframe import reframe, reframing, rigid_free

    cp = _two_squares()
    mesh = cp.mesh
    problem = Newton().prepare(
        make_problem(mesh, make_structure(mesh), make_params(cp, dtype=jnp.float64)), mesh
    )
    piece = np.asarray(problem.aux.piece)
    pinned = np.asarray(problem.pinned)
    assert sorted(set(piece.tolist())) == [0, 1]
    assert [piece[pinned[3 * k]] for k in range(2)] == [0, 1]  # the gauge's own order
    rng = np.random.default_rng(3)
    # a folded state in the gauge (each square creased), then each piece moved rigidly
    x = np.asarray(positions(problem, jnp.asarray(0.2 * rng.standard_normal(mesh.vertices.shape))))
    moved = x.copy()
    for k, (axis, angle, shift) in enumerate(
        [([1, 2, 3], 0.8, [1, -2, 0.5]), ([0, 1, 0], -2.0, [4, 0, 0])]
    ):
        rows = piece == k
        moved[rows] = x[rows] @ _rotation(axis, angle).T + shift
    back = np.asarray(reframe(jnp.asarray(moved), problem))
    np.testing.assert_allclose(back, x, atol=1e-12)
    u = jnp.asarray(back) - problem.start
    np.testing.assert_allclose(np.asarray(gauge(problem, u)), np.asarray(u), atol=1e-12)

    # as a function of other points: the same motions; one for the whole sheet only where it
    # is in one piece (so that distances between any two vertices are kept)
    move, one = reframing(jnp.asarray(moved), problem)
    np.testing.assert_allclose(np.asarray(move(jnp.asarray(moved))), back, atol=1e-12)
    assert not bool(one)
    whole = moved.copy()
    whole[piece == 1] = x[piece == 1] @ _rotation([1, 2, 3], 0.8).T + [1, -2, 0.5]
    move, _ = reframing(jnp.asarray(whole), problem)
    y = rng.standard_normal(x.shape)
    far = np.asarray(move(jnp.asarray(y)))
    assert not np.allclose(far[piece == 0], y[piece == 0])
    # the pieces moved by one motion are moved back by one: any points keep their distances
    d = np.linalg.norm(y[:, None] - y[None], axis=-1)
    d_far = np.linalg.norm(far[:, None] - far[None], axis=-1)
    np.testing.assert_allclose(d_far, d, atol=1e-12)
    miura = patterns.miura_ori(2, 2)
    mesh1 = miura.mesh
    problem1 = Newton().prepare(
        make_problem(mesh1, make_structure(mesh1), make_params(miura, dtype=jnp.float64)), mesh1
    )
    x1 = np.asarray(problem1.start) @ _rotation([0, 1, 1], 1.1).T + [2, 0, 1]
    assert bool(reframing(jnp.asarray(x1), problem1)[1])

    # an infinitesimal rigid motion per piece is removed whole, and its turn reported
    w = np.zeros_like(x)
    for k, (omega, shift) in enumerate(
        [([0.0, 0.3, 0.1], [1, 2, 3]), ([0.5, 0.0, 0.0], [0, 0, 1])]
    ):
        rows = piece == k
        w[rows] = np.cross(omega, x[rows]) + shift
    free, turn = rigid_free(jnp.asarray(w), jnp.asarray(x), problem)
    np.testing.assert_allclose(np.asarray(free), 0.0, atol=1e-12)
    assert float(turn) == pytest.approx(0.5, rel=1e-12)
    # any other displacement keeps its deformation and loses all rigid motion
    w = rng.standard_normal(x.shape)
    free = np.asarray(rigid_free(jnp.asarray(w), jnp.asarray(x), problem)[0])
    for k in range(2):
        rows = piece == k
        centre = x[rows].mean(axis=0)
        np.testing.assert_allclose(free[rows].sum(axis=0), 0.0, atol=1e-12)
        np.testing.assert_allclose(
            np.cross(x[rows] - centre, free[rows]).sum(axis=0), 0.0, atol=1e-12
        )
    again, _ = rigid_free(jnp.asarray(free), jnp.asarray(x), problem)
    np.testing.assert_allclose(np.asarray(again), free, atol=1e-12)
    result = fold(cp, solver="newton", dtype=jnp.float64)
    assert result.converged, result.reason
    np.testing.assert_allclose(
        result.positions[pinned[0::3]], mesh.vertices[pinned[0::3]], atol=1e-12
    )


@pytest.mark.parametrize(
    "options, message",
    [
        ({"max_turn": 0.0}, "max_turn must be > 0.0"),
        ({"expansions": -1}, "expansions must be >= 0"),
        ({"mu_min": float("nan")}, "mu_min must be >= 0.0"),
        ({"shift_after": 1.5}, "shift_after must be an integer"),
    ],
)
def test_options_out_of_range_are_refused_by_name(options, message):
    with pytest.raises(ValueError, match=message):
        Newton(**options)
    Newton(buckling_ratio=float("inf"), acceleration=0.0, expansions=0)  # the edges allowed
