"""fold(): exact rigid shapes from flat, the seed's scene, results, failures, float32.

Compiled solvers are cached per shape, so the tests reuse a few small patterns.
"""

import importlib

import jax.numpy as jnp
import numpy as np
import pytest

from origami_jax import FoldResult, PatternError, Stiffness, fold, patterns
from origami_jax.fold import SUMMARY_ROWS, default_tol
from origami_jax.kinematics import rigid_fold
from origami_jax.metrics import METRIC_NAMES
from origami_jax.solvers import Status, get_solver


@pytest.fixture(scope="module")
def miura():
    return patterns.miura_ori(3, 3, sector_angle=np.radians(60), fold_angle=np.pi / 2)


@pytest.mark.parametrize(
    "gamma, rho", [(np.radians(60), np.pi / 2), (np.radians(45), 2.5), (np.radians(75), 0.8)]
)
def test_miura_folds_to_exact_rigid_shape(gamma, rho):
    cp = patterns.miura_ori(3, 3, sector_angle=gamma, fold_angle=rho)
    result = fold(cp, reference_positions=rigid_fold(cp))
    assert result.converged, result.reason
    assert result.shape_error <= 1e-8
    assert result.fold_angle_error_max <= 1e-8
    assert result.strain_max <= 1e-8


@pytest.mark.parametrize(
    "alpha, beta, rho, branch",
    [
        (np.pi / 3, np.pi / 4, np.pi / 2, 1),
        (np.pi / 2.5, np.pi / 5, 2.0, 2),
        (np.pi / 4, np.pi / 3, -1.2, 1),
        (2.0, 0.7, 3.0, 1),
        (2.5, 0.3, 3.1, 1),
    ],
)
def test_degree4_vertex_folds_to_exact_rigid_shape(alpha, beta, rho, branch):
    cp = patterns.degree4_vertex(alpha, beta, rho, branch=branch)
    result = fold(cp, reference_positions=rigid_fold(cp))
    assert result.converged, result.reason
    assert result.shape_error <= 1e-8
    assert result.fold_angle_error_max <= 1e-8


def test_seed_scene_reaches_a_stationary_point(capsys):
    cp = patterns.seed_waterbomb()
    result = fold(cp, stiffness=patterns.SEED_WATERBOMB_STIFFNESS, tol=1e-10)
    assert result.converged, result.reason
    assert result.grad_norm_rel <= 1e-9
    # the seed's start energy is reproduced by its stiffness; ours ends far below its 0.009519
    assert result.history["energy"][0] == pytest.approx(patterns.SEED_WATERBOMB_ENERGY, rel=1e-9)
    assert result.energy < 0.009519
    with capsys.disabled():
        print(
            f"\nseed scene: final energy {result.energy:.6f} (seed's simulator: 0.009519, "
            f"start 0.009890), grad_norm_rel {result.grad_norm_rel:.1e}, "
            f"{result.iterations} iterations, {result.wall_time * 1e3:.1f} ms"
        )


def test_result_fields_and_history(miura):
    result = fold(miura)
    assert isinstance(result, FoldResult)
    mesh = miura.mesh
    assert result.positions.shape == (mesh.num_vertices, 3)
    assert result.fold_angles.shape == (mesh.num_edges,)
    # the input's vertices first and in order: the pinned triangle keeps its flat position
    moved = np.linalg.norm(result.positions - mesh.vertices, axis=1)
    assert (moved < 1e-12).sum() >= 1 and moved.max() > 0.1
    # simulated fold angles reach the targets on driven creases, 0 on borders
    driven = mesh.edges_with_role("driven")
    np.testing.assert_allclose(result.fold_angles[driven], mesh.target[driven], atol=1e-8)
    assert np.all(result.fold_angles[mesh.edges_with_role("border")] == 0)
    assert set(METRIC_NAMES) <= set(result.metrics)
    h = result.history
    assert h["wall_time"][0] == 0 and np.all(np.diff(h["wall_time"]) >= 0)
    assert h["iteration"][-1] == result.iterations
    assert h["fold_angle_error_max"][-1] < 1e-3 * h["fold_angle_error_max"][0]
    assert result.compile_time >= 0 and result.wall_time > 0
    text = result.summary()
    for word in SUMMARY_ROWS:
        assert word in text


def test_compiled_solver_is_reused(miura):
    fold(miura)
    again = fold(miura.with_fold_angles(miura.fold_angles * 0.5))
    assert again.compile_time == 0.0 and again.converged


def test_percent_scales_targets():
    cp = patterns.single_crease(fold_angle=2.0)
    k = cp.mesh.edges_with_role("driven")[0]
    for percent in (0.25, 0.5, -0.5):
        result = fold(cp, percent=percent)
        assert result.converged
        assert result.fold_angles[k] == pytest.approx(2.0 * percent, abs=1e-8)


def test_iteration_limit_reports_not_converged(miura):
    result = fold(miura, max_iter=5)
    assert not result.converged and result.status == Status.MAX_ITER
    assert result.iterations == 5 and "iteration limit" in result.reason
    assert np.isfinite(result.positions).all()


def test_full_fold_valley_does_not_pass_through_pi():
    cp = patterns.single_crease(fold_angle=np.pi)
    result = fold(cp)
    assert result.converged
    k = cp.mesh.edges_with_role("driven")[0]
    assert result.fold_angles[k] == pytest.approx(np.pi, abs=1e-8)
    # flat-folded: one wing lies on the other, every vertex on one side of the crease line
    x = result.positions[:, 0]
    assert (x <= 0.5 + 1e-8).all() or (x >= 0.5 - 1e-8).all()
    # ... reached from the valley side: on the way the moving wing is above the sheet
    partial = fold(cp, percent=0.9)
    assert partial.positions[:, 2].max() > 0.1 and partial.positions[:, 2].min() > -1e-8


def test_pre_folded_start_past_pi_is_brought_back():
    cp = patterns.single_crease(fold_angle=np.pi)
    start = rigid_fold(cp, np.where(cp.mesh.role == "driven", 3.4, 0.0))  # folded through
    result = fold(cp, start=start)
    k = cp.mesh.edges_with_role("driven")[0]
    assert result.converged
    assert result.fold_angles[k] == pytest.approx(np.pi, abs=1e-8)
    assert len(result.through_pi) == 0
    # stopped early, the crease is still past pi, and the result says so
    early = fold(cp, start=start, max_iter=0)
    assert list(early.through_pi) == [k] and "folded through pi" in early.summary()


def test_float32():
    cp = patterns.miura_ori(3, 3)
    result = fold(cp, dtype=jnp.float32, reference_positions=rigid_fold(cp))
    assert result.dtype == "float32"
    assert result.converged, result.reason
    assert result.fold_angle_error_max <= 1e-4  # the bound docs/extreme.md gives float32
    assert result.shape_error <= 1e-4
    # asked for a tolerance below its rounding floor, float32 stops at the floor and says so
    floor = fold(cp, dtype=jnp.float32, tol=1e-12, max_iter=20_000)
    assert floor.status == Status.CONVERGED and floor.iterations < 200
    assert floor.metrics["grad_norm_rel"] > 1e-12 and "rounding floor" in floor.reason
    assert np.isfinite(floor.positions).all()
    assert default_tol(jnp.float32) > default_tol(jnp.float64)


def test_stiffness_changes_non_rigid_result():
    cp = patterns.seed_waterbomb()
    soft = fold(cp, stiffness=Stiffness(axial=1.0, facet=0.02, crease=0.001))
    stiff = fold(cp, stiffness=Stiffness(axial=100.0, facet=0.02, crease=0.001))
    assert soft.converged and stiff.converged
    assert stiff.strain_max < 0.2 * soft.strain_max


def test_bad_arguments():
    cp = patterns.single_crease()
    with pytest.raises(ValueError, match="unknown solver 'newtonn'"):
        fold(cp, solver="newtonn")
    with pytest.raises(PatternError, match="start: vertex 2 is not finite"):
        start = cp.mesh.vertices.copy()
        start[2, 0] = np.nan
        fold(cp, start=start)
    with pytest.raises(PatternError, match="start: expected shape"):
        fold(cp, start=np.zeros((2, 3)))
    with pytest.raises(PatternError, match="percent"):
        fold(cp, percent=float("nan"))
    with pytest.raises(TypeError, match="CreasePattern"):
        fold("not a pattern")


def test_collapsed_start_is_refused_and_partial_collapse_recovers():
    cp = patterns.single_crease()
    with pytest.raises(PatternError, match="start: every triangle .* is collapsed"):
        fold(cp, start=np.zeros_like(cp.mesh.vertices))
    start = cp.mesh.vertices.copy()
    wing = np.flatnonzero(start[:, 0] > 0.75)
    start[wing, 0] = 0.5  # squash one wing onto the crease line
    result = fold(cp, start=start)
    assert np.isfinite(result.positions).all() and np.isfinite(result.fold_angles).all()
    assert result.strain_max < 1e-6 or not result.converged


def test_a_result_with_a_collapsed_triangle_names_it():
    """A solve that stops on a collapsed triangle (the energy's kink) says which one, in
    ``reason``, ``collapsed`` and the summary; single folds and batches alike."""
    from origami_jax.batch import fold_batch
    from origami_jax.metrics import collapsed_triangles

    cp = patterns.single_crease()
    start = cp.mesh.vertices.copy()
    start[start[:, 0] > 0.75, 0] = 0.5  # one wing squashed onto the crease line
    tris = cp.mesh.triangles
    p = start[tris]
    area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    squashed = np.flatnonzero(area < 1e-12)
    assert 0 < len(squashed) < len(tris)
    found, ratio = collapsed_triangles(start, cp.mesh)
    assert sorted(found) == sorted(squashed) and np.all(np.diff(ratio) >= 0)
    stopped = [fold(cp, start=start, max_iter=0)]
    stopped += fold_batch([cp], starts=[start], max_iter=0, progress=False)
    for r in stopped:
        assert not r.converged and sorted(r.collapsed) == sorted(squashed)
        t = r.collapsed[0]
        vertices = ", ".join(str(v) for v in tris[t])
        assert f"triangle {t} (vertices {vertices}) collapsed to" in r.reason
        assert "larger axial stiffness" in r.reason and "collapsed" in r.summary()
    done = fold(cp, start=start)  # the squashed wing unfolds: nothing to report
    assert done.converged and len(done.collapsed) == 0
    assert "collapsed to" not in done.reason and "collapsed" not in done.summary()


def test_time_limit_and_history_times_count_the_chunks_run_not_their_dispatch():
    """``drive`` times each chunk once it has run (JAX dispatch returns at once): a solve
    stops near ``max_time`` and its history's times are completion times."""
    import time
    from typing import NamedTuple

    import jax

    from origami_jax.fold import drive

    class State(NamedTuple):
        iteration: jax.Array
        status: jax.Array
        a: jax.Array

    def start(problem):
        a = jnp.eye(200) * 0.5
        m = dict.fromkeys(("fold_angle_error_max", "strain_max", "energy", "grad_norm_rel"), 1.0)
        return State(jnp.int32(0), jnp.int32(Status.RUNNING), a), m, a, a

    @jax.jit
    def advance(s, problem, steps):  # about a millisecond of work per step, never done
        a = jax.lax.fori_loop(0, steps, lambda i, a: jnp.tanh(a @ a), s.a)
        m = dict.fromkeys(
            ("fold_angle_error_max", "strain_max", "energy", "grad_norm_rel"), a[0, 0]
        )
        return State(s.iteration + steps, s.status, a), m, a, a

    jax.block_until_ready(advance(start(None)[0], None, jnp.int32(1)))  # compile
    t0 = time.perf_counter()
    state, _, _, _, samples, out_of_time = drive(
        get_solver("lbfgs"), start, advance, None, 10**9, 0.3, None
    )
    elapsed = time.perf_counter() - t0
    assert out_of_time and int(state.iteration) > 0
    # chunks sized from dispatch times would grow without bound (seconds, here)
    assert elapsed < 2.0, elapsed
    times = [s["wall_time"] for s in samples]
    assert times == sorted(times) and times[-1] <= elapsed


def test_a_time_limit_holds_to_within_an_iteration(monkeypatch):
    """``drive`` plans no chunk longer than the time left (at the pace measured so far), so a
    solve stops within about one iteration of ``max_time``, not one chunk (a tenth of a second).
    Checked on a clock of its own, each iteration costing 1 ms of it: the chunks of 100
    iterations end with one of 50 and one of 1 (before: three of 100, 50 ms over). The
    steps of a continuation share a ``Pace``: a later ``drive`` whose start is quick (its
    guessed pace ten times too fast) sizes its first chunk by the pace measured instead."""
    from typing import NamedTuple

    module = importlib.import_module("origami_jax.fold")  # the package's ``fold`` is the function
    names = ("fold_angle_error_max", "strain_max", "energy", "grad_norm_rel")

    class State(NamedTuple):
        iteration: np.ndarray
        status: np.ndarray

    class Clock:
        now, start_cost = 0.0, 5e-5  # the start: the first chunk guesses 20x its time

        def perf_counter(self):
            return self.now

    clock = Clock()
    chunks = []

    def start(problem):
        clock.now += clock.start_cost
        return State(np.int32(0), np.int32(Status.RUNNING)), dict.fromkeys(names, 1.0), 0, 0

    def advance(s, problem, steps):
        clock.now += 1e-3 * int(steps)
        chunks.append(int(steps))
        return State(s.iteration + steps, s.status), dict.fromkeys(names, 1.0), 0, 0

    def run(max_time, pace):
        chunks.clear()
        t0 = clock.now
        state, *_, out_of_time = module.drive(
            get_solver("lbfgs"), start, advance, None, 10**9, max_time, None, pace=pace
        )
        assert out_of_time
        return int(state.iteration), clock.now - t0

    monkeypatch.setattr(module, "time", clock)
    pace = module.Pace()
    iterations, elapsed = run(0.2504, pace)
    assert chunks == [100, 100, 50, 1] and iterations == 251
    assert 0.2504 <= elapsed < 0.2504 + 1e-3, elapsed
    assert pace.per_step == pytest.approx(1e-3)
    clock.start_cost = 5e-6
    iterations, elapsed = run(0.0305, pace)
    assert chunks == [30, 1] and 0.0305 <= elapsed < 0.0305 + 1e-3, elapsed
