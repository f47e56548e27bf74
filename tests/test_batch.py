"""fold_batch: equal to single folds, padding inert, sharded equal to unsharded, errors."""

import os
import subprocess
import sys
import textwrap
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from origami_jax import PatternError, fold, patterns
from origami_jax import batch as batch_module
from origami_jax.batch import BatchSizes, bucket, compile_count, fold_batch, problem_sizes
from origami_jax.energy import Stiffness, energy, param_arrays
from origami_jax.fold import drive, solve_fns
from origami_jax.geometry import bar_lengths, fold_angles
from origami_jax.solvers import Dynamics, Newton, Status
from origami_jax.solvers.base import (
    default_max_step,
    default_max_steps,
    positions,
    rigid_gauge,
    rigid_gauges,
)
from origami_jax.solvers.dynamics import lumped_mass

jax.config.update("jax_enable_x64", True)

# two buckets: three Miura-ori 2 x 2 (one compile; in two slots, one refill), and the seed's scene
MIURAS = [patterns.miura_ori(2, 2, fold_angle=a) for a in (0.6, 1.2, 2.0)]
SEED = patterns.seed_waterbomb()


@pytest.fixture(scope="module")
def batch_and_singles():
    cps = [MIURAS[0], SEED, MIURAS[1], MIURAS[2]]
    results = fold_batch(cps, chunk_size=2, progress=False)
    singles = [fold(cp, path="direct") for cp in cps]
    return cps, results, singles


def test_batch_equals_single_folds(batch_and_singles):
    cps, results, singles = batch_and_singles
    assert len(results) == len(cps)
    for cp, r, s in zip(cps, results, singles, strict=True):
        assert r.pattern is cp  # input order
        assert r.converged and s.converged
        assert r.positions.shape == s.positions.shape
        assert np.max(np.abs(r.positions - s.positions)) <= 1e-10 * cp.diameter
        np.testing.assert_allclose(r.fold_angles, s.fold_angles, atol=1e-9)
        for name in ("fold_angle_error_max", "fold_angle_error_mean", "strain_mean", "energy"):
            assert getattr(r, name) == pytest.approx(getattr(s, name), rel=1e-6, abs=1e-12)
        assert len(r.history["wall_time"]) >= 2


def test_one_pattern_many_parameter_sets():
    percents = [0.25, 0.5, 1.0]
    results = fold_batch(MIURAS[1], percent=percents, progress=False)
    assert [r.percent for r in results] == percents
    for p, r in zip(percents, results, strict=True):
        single = fold(MIURAS[1], percent=p, path="direct")
        assert r.converged
        assert np.max(np.abs(r.positions - single.positions)) <= 1e-10 * MIURAS[1].diameter
    assert results[0].energy != pytest.approx(results[1].energy, rel=1e-3)


# one topology, three geometries: folded unpadded, with shared index arrays
VARIANTS = [
    patterns.miura_ori(2, 2, sector_angle=s, fold_angle=a)
    for s, a in ((1.0, 0.7), (1.2, 1.4), (0.9, 2.1))
]


def test_shared_topology_equals_single_folds():
    # two slots for three: one enters a refilled slot (the least folded, last: the queue takes
    # the furthest first; shared index arrays kept)
    results = fold_batch(VARIANTS, share_topology=True, chunk_size=2, progress=False)
    for cp, r in zip(VARIANTS, results, strict=True):
        single = fold(cp, path="direct")
        assert r.pattern is cp and r.converged and single.converged
        assert r.iterations == single.iterations
        assert np.max(np.abs(r.positions - single.positions)) <= 1e-10 * cp.diameter
        np.testing.assert_allclose(r.fold_angles, single.fold_angles, atol=1e-9)
        for name in ("fold_angle_error_max", "fold_angle_error_mean", "strain_mean", "energy"):
            assert getattr(r, name) == pytest.approx(getattr(single, name), rel=1e-6, abs=1e-12)


@pytest.mark.parametrize("solver", ["lbfgs", "dynamics"])
@pytest.mark.parametrize("share", [True, False])
def test_first_order_solvers_batched_equal_single_folds(solver, share):
    """L-BFGS and damped dynamics, vmapped with shared index arrays or padded to a bucket (two
    slots for three problems: a refill), stop on their own and match single folds."""
    cps = VARIANTS if share else MIURAS
    results = fold_batch(cps, solver=solver, share_topology=share, chunk_size=2, progress=False)
    for cp, r in zip(cps, results, strict=True):
        single = fold(cp, solver=solver, path="direct")
        assert r.pattern is cp and r.converged and single.converged
        assert r.solver == single.solver == solver
        assert r.grad_norm_rel <= 1e-10
        # first-order methods stop anywhere within their tolerance: the two paths' rounding
        # (another summation order) moves that point, here by up to 5e-11 of the sheet size
        assert np.max(np.abs(r.positions - single.positions)) <= 1e-10 * cp.diameter
        assert r.energy == pytest.approx(single.energy, rel=1e-6, abs=1e-12)


def test_which_problems_share_their_topology(monkeypatch):
    plans = []
    monkeypatch.setattr(
        batch_module,
        "_run_group",
        lambda group, to, size, shared, *a: plans.append((len(group), shared)),
    )
    monkeypatch.setattr(batch_module, "SHARED_TOPOLOGY_MIN", 3)
    # three of one topology reach the minimum, the seed's scene alone does not
    fold_batch(VARIANTS + [SEED], progress=False)
    assert sorted(plans) == [(1, False), (3, True)]
    plans.clear()
    fold_batch(VARIANTS[:2] + [SEED], progress=False)
    assert sorted(plans) == [(1, False), (2, False)]  # one bucket each
    plans.clear()
    fold_batch(SEED, percent=[0.5, 1.0], progress=False)  # one pattern: always shared
    assert plans == [(2, True)]
    plans.clear()
    fold_batch(VARIANTS, share_topology=False, progress=False)
    assert plans == [(3, False)]


def _padded_problem(cp, grow: int):
    (member,) = batch_module._members([cp], [0.7], [None], [None], 1e-10)
    to = bucket(member.sizes)
    bigger = BatchSizes(*(2 * v if v else 0 for v in to))
    bigger = bigger._replace(creases=bigger.creases or 4, facets=bigger.facets or 4)
    return member, batch_module._padded(member, bigger if grow else to, Newton())


@pytest.mark.parametrize("cp", [MIURAS[0], SEED, patterns.single_crease(1.0)], ids=str)
def test_padding_is_inert(cp):
    member, padded = _padded_problem(cp, grow=1)
    real, pad = member.problem, padded
    v = member.sizes.vertices
    rng = np.random.default_rng(1)
    x = real.start + 0.05 * rng.standard_normal(real.start.shape)
    x_pad = np.concatenate([x, pad.start[v:]])
    ref = np.zeros(len(real.structure.hinges))
    ref_pad = np.zeros(len(pad.structure.hinges))

    def e(xx, p, r):
        return energy(xx, p.structure, p.params, r)

    energy_and_force = jax.jit(jax.value_and_grad(e))  # compiled: op by op is slower
    e0, g0 = energy_and_force(jnp.asarray(x), real, jnp.asarray(ref))
    e1, g1 = energy_and_force(jnp.asarray(x_pad), pad, jnp.asarray(ref_pad))
    assert float(e1) == pytest.approx(float(e0), rel=1e-14)
    np.testing.assert_allclose(g1[:v], g0, rtol=1e-12, atol=1e-14)
    assert np.all(np.asarray(g1[v:]) == 0.0)
    # padded bars at rest length, padded hinges flat with goal 0: zero strain and error
    s = pad.structure
    nb = member.sizes.bars
    lengths = np.asarray(bar_lengths(jnp.asarray(x_pad), s.bars))
    assert np.all(lengths[nb:] == pad.params.rest_length[nb:])
    angles = np.asarray(fold_angles(jnp.asarray(x_pad), s.hinges))
    nc, pc = member.sizes.creases, pad.structure.num_creases
    assert np.all(angles[nc:pc] == 0) and np.all(pad.params.target[nc:] == 0)
    assert np.all(angles[pc + member.sizes.facets :] == 0)
    # padding vertices cannot move: pinned with a zero projector
    u = jnp.ones_like(jnp.asarray(pad.start))
    moved = np.asarray(positions(jax.tree.map(jnp.asarray, pad), u) - pad.start)
    assert np.all(moved[v:] == 0)


def test_padded_solve_equals_unpadded_bucket():
    """A problem solved in a bucket twice its size gives the same result (padding inert in
    the whole solver, Newton's dense Hessian included)."""
    cp = MIURAS[0]
    member, big = _padded_problem(cp, grow=1)
    _, small = _padded_problem(cp, grow=0)
    out = []
    for problem, num_edges in ((small, bucket(member.sizes).bars), (big, len(big.structure.bars))):
        problem = jax.tree.map(lambda a: jnp.asarray(a)[None], problem)
        solver = Newton()
        start, advance = solve_fns(solver, num_edges)
        start = jax.jit(jax.vmap(start))
        advance = jax.jit(jax.vmap(advance, in_axes=(0, 0, None)))
        state, m, x, _, _, _ = drive(solver, start, advance, problem, 200, None, None)
        out.append((np.asarray(x[0, : member.sizes.vertices]), float(m["energy"][0])))
    assert np.max(np.abs(out[0][0] - out[1][0])) <= 1e-10 * cp.diameter
    assert out[0][1] == pytest.approx(out[1][1], rel=1e-8, abs=1e-15)


def test_buckets_are_powers_of_two_with_room():
    sizes = problem_sizes(MIURAS[0])
    to = bucket(sizes)
    counts = [f for f in BatchSizes._fields if f != "barriers"]  # every count
    for real, padded in zip(
        [getattr(sizes, f) for f in counts], [getattr(to, f) for f in counts], strict=True
    ):
        assert padded >= real and (padded == 0 or padded & (padded - 1) == 0)
    assert to.vertices >= sizes.vertices + 4 and to.bars > sizes.bars


def test_patterns_of_one_size_share_a_bucket():
    # 9 vertices each; the Miura-ori has facet creases, the waterbomb none and twice the creases
    miura, bomb = problem_sizes(patterns.miura_ori(2, 2)), problem_sizes(patterns.waterbomb(1, 1))
    assert miura.vertices == bomb.vertices and (miura.creases, miura.facets) != (
        bomb.creases,
        bomb.facets,
    )
    assert bucket(miura) == bucket(bomb)


def test_stream_compiles_once_per_bucket():
    cps = [patterns.miura_ori(2, 2, fold_angle=a) for a in (0.3, 0.9)] + [MIURAS[2]]
    before = compile_count()
    for cp in cps:
        fold_batch(cp, progress=False)
    assert compile_count() - before <= 1  # all three share a bucket (maybe compiled already)


def test_interrupt_keeps_finished_problems(monkeypatch):
    # one slot, one iteration per call: the three Miura-ori run one after another, the one that
    # folds furthest first (the last given); Ctrl-C as the host reads the second one's result
    results_read = []
    result = batch_module._result

    def interrupted(*args):
        results_read.append(1)
        if len(results_read) == 2:
            raise KeyboardInterrupt
        return result(*args)

    monkeypatch.setattr(batch_module, "_result", interrupted)
    monkeypatch.setattr(batch_module, "next_chunk", lambda *args: 1)
    monkeypatch.setattr(batch_module, "_QUEUE_PER_SLOT", 1)  # as test_queue_in_rounds
    monkeypatch.setattr(batch_module, "_OUTBOX_PER_SLOT", 1)
    with pytest.warns(RuntimeWarning, match="interrupted: 1 of 3 problems have results"):
        results = fold_batch(MIURAS, chunk_size=1, devices=jax.devices()[:1], progress=False)
    assert [r is not None for r in results] == [False, False, True]
    assert results[2].converged


def test_progress_shows_problems_done(monkeypatch, capsys):
    # one slot, one iteration per call: the bar is redrawn after every call, counting the
    # problems done of the batch's three
    monkeypatch.setattr(batch_module, "next_chunk", lambda *args: 1)
    results = fold_batch(MIURAS, chunk_size=1, devices=jax.devices()[:1], progress=True)
    assert all(r.converged for r in results)
    err = capsys.readouterr().err
    counts = [int(line.split("/3 problems")[0].rsplit(" ", 1)[-1]) for line in err.split("\r")[1:]]
    assert counts == sorted(counts) and counts[0] == 0 and counts[-1] == 3
    assert {1, 2} <= set(counts) and err.endswith("\n")


def test_iteration_and_time_limits_in_refilled_slots():
    one = dict(chunk_size=1, devices=jax.devices()[:1], progress=False)
    for r, cp in zip(fold_batch(MIURAS, max_iter=3, **one), MIURAS, strict=True):
        single = fold(cp, max_iter=3, path="direct")
        assert r.status == Status.MAX_ITER and r.iterations == 3 == single.iterations
        assert np.max(np.abs(r.positions - single.positions)) <= 1e-10 * cp.diameter
    assert [r.iterations for r in fold_batch(MIURAS, max_iter=0, **one)] == [0, 0, 0]
    timed = fold_batch(MIURAS, max_time=0.0, **one)
    assert [(r.status, r.iterations) for r in timed] == [(Status.TIME_LIMIT, 0)] * 3
    with pytest.raises(ValueError, match="max_iter"):
        fold_batch(MIURAS, max_iter=-1)


def test_queue_in_rounds(monkeypatch):
    # a queue of one problem per slot: three rounds, each refilling the slot from the host;
    # an outbox of one exit: a call ends at each exit
    monkeypatch.setattr(batch_module, "_QUEUE_PER_SLOT", 1)
    monkeypatch.setattr(batch_module, "_OUTBOX_PER_SLOT", 1)
    one = dict(chunk_size=1, devices=jax.devices()[:1], progress=False)
    for cp, r in zip(MIURAS, fold_batch(MIURAS, **one), strict=True):
        single = fold(cp, path="direct")
        assert r.pattern is cp and r.converged and r.iterations == single.iterations
        assert np.max(np.abs(r.positions - single.positions)) <= 1e-10 * cp.diameter
        assert r.history["iteration"][-1] == r.iterations and r.wall_time > 0
    # more exits than the outbox holds in one call: every problem stops at its start
    cps = MIURAS * 3
    results = fold_batch(cps, max_iter=0, **{**one, "chunk_size": 2})
    assert [r.pattern for r in results] == cps
    assert all(r.iterations == 0 and r.status == Status.MAX_ITER for r in results)


def test_finished_slots_take_the_next_problems():
    # two slots for three problems of one bucket: one (the least folded) enters a refilled
    # slot, and every result equals a single fold (its history starting at its own entry)
    results = fold_batch(MIURAS, chunk_size=2, progress=False)
    for cp, r in zip(MIURAS, results, strict=True):
        single = fold(cp, path="direct")
        assert r.converged and r.iterations == single.iterations
        assert np.max(np.abs(r.positions - single.positions)) <= 1e-10 * cp.diameter
        assert r.history["wall_time"][0] == 0.0 and r.history["iteration"][0] == 0
        assert r.history["iteration"][-1] == r.iterations


def test_unstable_time_step_refused():
    # the host checks every problem's start state before the loop runs
    with pytest.raises(ValueError, match="exceeds the stability limit"):
        fold_batch(MIURAS, solver=Dynamics(dt=1e3), progress=False)


def test_bad_input():
    with pytest.raises(TypeError, match="problem 1"):
        fold_batch([MIURAS[0], "x"])
    with pytest.raises(ValueError, match="percent: 2 values for 3 problems"):
        fold_batch(MIURAS, percent=[0.5, 1.0])
    with pytest.raises(PatternError, match="percent 1: must be finite"):
        fold_batch(MIURAS[:2], percent=[0.5, float("nan")])
    bad = MIURAS[0].mesh.vertices.copy()
    bad[4, 2] = np.nan
    with pytest.raises(PatternError, match="start 1: vertex 4 is not finite"):
        fold_batch(MIURAS[:2], starts=[None, bad])
    with pytest.raises(ValueError, match="dense"):
        fold_batch(MIURAS[:1], solver=Newton(linear_solver="sparse"))
    flat = MIURAS[0].mesh.vertices.copy()
    flat[:, 1] = 0.0  # every triangle collapsed onto a line
    with pytest.raises(PatternError, match="start 2: every triangle .* is collapsed"):
        fold_batch(MIURAS, starts=[None, None, flat])


def test_gauges_of_one_topology_at_once_equal_one_by_one():
    # Miura-ori of other sector angles: one topology, other geometry; folded starts
    cps = [patterns.miura_ori(3, 2, sector_angle=a, fold_angle=1.0) for a in (0.9, 1.1, 1.3)]
    rng = np.random.default_rng(3)
    starts = [cp.mesh.vertices + 0.1 * rng.standard_normal(cp.mesh.vertices.shape) for cp in cps]
    tris = cps[0].mesh.triangles
    flat = np.stack([cp.mesh.vertices for cp in cps])
    pinned, projectors = rigid_gauges(tris, flat, np.stack(starts))
    steps = default_max_steps(tris, flat)
    for k, cp in enumerate(cps):
        one_pinned, one_projectors = rigid_gauge(cp.mesh, starts[k])
        np.testing.assert_array_equal(pinned[k], one_pinned)
        np.testing.assert_allclose(projectors[k], one_projectors, rtol=0, atol=1e-15)
        assert steps[k] == default_max_step(cp.mesh)
    # the gauge removes the rigid motions: fixed vertex, a line, a plane
    assert pinned.shape == (3, 3) and np.allclose(projectors[:, 0], 0.0)
    assert np.allclose(np.trace(projectors[:, 1], axis1=1, axis2=2), 1.0)
    assert np.allclose(np.trace(projectors[:, 2], axis1=1, axis2=2), 2.0)


SHARDED = textwrap.dedent(
    """
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    from origami_jax import patterns
    from origami_jax.batch import fold_batch
    assert len(jax.devices()) == 2, jax.devices()
    cps = [patterns.miura_ori(2, 2, fold_angle=a) for a in (0.5, 0.9, 1.3)]
    # two slots (one per device) for three problems: one enters a refilled slot
    two = fold_batch(cps, chunk_size=2, progress=False)
    one = fold_batch(cps, chunk_size=2, devices=jax.devices()[:1], progress=False)
    # one pattern, several parameter sets: shared index arrays, replicated on both devices
    percents = [0.4, 0.7, 1.0]
    two += fold_batch(cps[0], percent=percents, chunk_size=2, progress=False)
    one += fold_batch(
        cps[0], percent=percents, chunk_size=2, devices=jax.devices()[:1], progress=False
    )
    # padded, 8 slots per device: jaxlib's batched Cholesky once deadlocked here (its batch
    # split over the thread pool that both devices' programs wait in)
    many = [patterns.miura_ori(2, 2, fold_angle=a) for a in np.linspace(0.3, 2.0, 16)]
    two += fold_batch(many, chunk_size=16, share_topology=False, progress=False)
    one += fold_batch(
        many, chunk_size=16, share_topology=False, devices=jax.devices()[:1], progress=False
    )
    for a, b in zip(two, one, strict=True):
        assert a.converged and b.converged
        assert np.max(np.abs(a.positions - b.positions)) <= 1e-12, (a, b)
        assert a.iterations == b.iterations
    print("sharded ok")
    """
)


def test_sharded_equals_unsharded():
    # two host devices, at the suite's XLA optimisation level (conftest.py)
    flags = os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
    env = dict(os.environ, XLA_FLAGS=flags.strip())
    out = subprocess.run(
        [sys.executable, "-c", SHARDED], env=env, capture_output=True, text=True, timeout=900
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert "sharded ok" in out.stdout


def test_no_warning_on_a_plain_batch():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        (r,) = fold_batch(MIURAS[:1], progress=False)
    assert r.converged


def test_shared_topology_stacks_scalar_and_per_element_stiffness():
    cp = SEED  # strained at equilibrium: the axial stiffness changes the result
    per_bar = np.linspace(0.5, 2.0, cp.mesh.num_edges)
    stiffness = [None, {"axial": per_bar}]
    results = fold_batch(cp, stiffness=stiffness, progress=False)
    for k, r in zip(stiffness, results, strict=True):
        single = fold(cp, stiffness=k, path="direct")
        assert r.converged and single.converged
        assert np.max(np.abs(r.positions - single.positions)) <= 1e-10 * cp.diameter
    assert results[0].energy != pytest.approx(results[1].energy, rel=1e-6)


def test_problems_of_one_topology_stack_as_made_one_by_one():
    # the stacked slots hold exactly each problem's own parameters, gauges and lumped masses
    cps = [
        patterns.miura_ori(3, 2, sector_angle=a, fold_angle=f) for a, f in ((0.9, 1.0), (1.2, 2.0))
    ]
    percents = [0.5, 1.0]
    stiffness = [Stiffness(crease=0.3), {"axial": np.linspace(1.0, 2.0, cps[1].mesh.num_edges)}]
    members = batch_module._members(cps, percents, stiffness, [None, None], 1e-9)
    stacked = batch_module._stacked_shared(members, Dynamics(mass="area"), None, np.float64)
    for k, cp in enumerate(cps):
        params = param_arrays(cp, percents[k], stiffness[k])
        np.testing.assert_array_equal(stacked.params.target[k], params.target)
        np.testing.assert_array_equal(stacked.params.rest_length[k], params.rest_length)
        assert stacked.params.percent[k] == params.percent
        sizes = members[k].sizes
        for name, n in (("axial", sizes.bars), ("crease", sizes.creases)):
            expected = np.broadcast_to(getattr(params.stiffness, name), (n,))
            np.testing.assert_array_equal(getattr(stacked.params.stiffness, name)[k], expected)
        pinned, projectors = rigid_gauge(cp.mesh, cp.mesh.vertices)
        np.testing.assert_array_equal(stacked.pinned[k], pinned)
        np.testing.assert_array_equal(stacked.projectors[k], projectors)
        np.testing.assert_array_equal(stacked.aux[k], lumped_mass(cp.mesh))


@pytest.mark.parametrize("custom_start", [False, True])
def test_variants_of_one_geometry_stack_as_made_one_by_one(custom_start):
    # other fold angles of one crease pattern share its geometry: its gauges and step limits
    # are computed once; a start of its own gives a problem its own gauge
    cps = [patterns.miura_ori(3, 2, fold_angle=f) for f in (0.5, 1.0, 1.5)]
    starts = [None] * 3
    if custom_start:
        starts[1] = cps[1].mesh.vertices + 0.05 * np.random.default_rng(4).standard_normal(
            cps[1].mesh.vertices.shape
        )
    percents = [1.0, 0.5, 0.25]
    members = batch_module._members(cps, percents, [None] * 3, starts, 1e-9)
    assert all(m.group is members[0].group for m in members)
    # computed once and broadcast (stride 0) only where every flat sheet and start is the same
    assert (members[0].group.pinned.strides[0] == 0) == (not custom_start)
    # as the queue stacks them: another order, one repeated (a free slot)
    order = [2, 0, 1, 2]
    stacked = batch_module._stacked_shared([members[k] for k in order], Newton(), None, np.float64)
    for row, k in enumerate(order):
        cp = cps[k]
        start = cp.mesh.vertices if starts[k] is None else starts[k]
        pinned, projectors = rigid_gauge(cp.mesh, start)
        np.testing.assert_array_equal(stacked.pinned[row], pinned)
        np.testing.assert_allclose(stacked.projectors[row], projectors, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(stacked.start[row], start)
        assert stacked.max_step[row] == default_max_step(cp.mesh)
        params = param_arrays(cp, percents[k], None)
        np.testing.assert_array_equal(stacked.params.target[row], params.target)
        np.testing.assert_array_equal(stacked.params.rest_length[row], params.rest_length)
        assert stacked.params.percent[row] == params.percent
        for name, n in (("axial", members[k].sizes.bars), ("crease", members[k].sizes.creases)):
            expected = np.broadcast_to(getattr(params.stiffness, name), (n,))
            np.testing.assert_array_equal(getattr(stacked.params.stiffness, name)[row], expected)
        # the queue's order: how far each problem folds
        goal = np.abs(percents[k] * params.target)
        assert members[k].extent == np.max(goal)
    # members made by two calls stack problem by problem, to the same arrays
    again = batch_module._members(cps, percents, [None] * 3, starts, 1e-9)
    mixed = [again[k] if row % 2 else members[k] for row, k in enumerate(order)]
    assert mixed[0].group is not mixed[1].group
    one_by_one = batch_module._stacked_shared(mixed, Newton(), None, np.float64)
    for a, b in zip(jax.tree.leaves(stacked), jax.tree.leaves(one_by_one), strict=True):
        np.testing.assert_array_equal(a, b)


def test_fold_extents():
    targets = np.array([[1.0, -2.0, 0.5], [0.3, 0.2, -0.1]])
    np.testing.assert_array_equal(batch_module._fold_extents([0.5, -2.0], targets), [1.0, 0.6])
    np.testing.assert_array_equal(batch_module._fold_extents([1.0], np.zeros((1, 0))), [0.0])


def test_variants_of_one_pattern_get_the_barriers_each_needs():
    """One topology, two fold angles: the full fold gets barriers, the part fold none, in
    whatever order they come, and each equals its own direct fold."""
    part, full = patterns.single_crease(fold_angle=1.0), patterns.single_crease(fold_angle=np.pi)
    for order in ((part, full), (full, part)):
        results = fold_batch(list(order), progress=False)
        for cp, r in zip(order, results, strict=True):
            single = fold(cp, path="direct")
            assert r.barriers == single.barriers
            assert np.max(np.abs(r.positions - single.positions)) <= 1e-10 * cp.diameter


def test_a_mesh_has_a_hessian_layout_per_set_of_barriers():
    from origami_jax.energy import make_structure
    from origami_jax.solvers.newton import hessian_layout

    mesh = patterns.miura_ori(3, 3).mesh
    plain = hessian_layout(mesh, make_structure(mesh, False), sparse=True)
    barred = hessian_layout(mesh, make_structure(mesh, True), sparse=True)
    assert barred.blocks.shape[0] == plain.blocks.shape[0] + 6 * len(mesh.triangles)
    assert hessian_layout(mesh, make_structure(mesh, False), sparse=True) is plain
