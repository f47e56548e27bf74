"""Single folds padded to size buckets (origami_jax.padding): inert, and shared compiled code."""

import importlib

import numpy as np
import pytest

from origami_jax import fold, patterns
from origami_jax.geometry import bar_lengths
from origami_jax.padding import Sizes, bucket, round_up

fold_module = importlib.import_module("origami_jax.fold")  # the name `fold` is the function


def test_round_up_to_quarter_octaves():
    assert [round_up(n) for n in (0, 1, 3, 5, 17)] == [0, 1, 4, 8, 32]
    steps = [round_up(n, 4) for n in range(1, 300)]
    assert sorted(set(steps))[:12] == [1, 2, 3, 4, 5, 6, 7, 8, 10, 11, 13, 16]
    assert all(s >= n and s <= 1.19 * n + 1 for n, s in zip(range(1, 300), steps, strict=True))


def test_bucket_floors_tie_the_elements_to_the_vertices():
    to = bucket(Sizes(9, 16, 6, 2, 0, 3, 8), 4)
    assert to[:7] == (13, 26, 13, 13, 0, 3, 26)


@pytest.mark.parametrize(
    "pattern",
    [patterns.miura_ori(3, 3), patterns.waterbomb(1, 1), patterns.degree4_vertex(2.5, 0.3, 3.1)],
    ids=["miura", "waterbomb", "full-fold"],
)
def test_a_padded_fold_is_the_unpadded_one(pattern, monkeypatch):
    """The same iterations, status and positions (to rounding), the mesh's own counts, and the
    means over the real elements only (the last case follows the path from flat)."""
    padded = fold(pattern)
    monkeypatch.setattr(fold_module, "BUCKETS_PER_OCTAVE", 0)
    alone = fold(pattern)
    assert padded.path == alone.path and padded.iterations == alone.iterations
    assert padded.status == alone.status and padded.converged
    assert padded.positions.shape == (pattern.mesh.num_vertices, 3)
    assert padded.fold_angles.shape == (pattern.mesh.num_edges,)
    np.testing.assert_allclose(padded.positions, alone.positions, atol=1e-9)
    np.testing.assert_allclose(padded.fold_angles, alone.fold_angles, atol=1e-9)
    for key in ("strain_mean", "fold_angle_error_mean", "energy"):
        assert getattr(padded, key) == pytest.approx(getattr(alone, key), rel=1e-6, abs=1e-14)
    # the last gradient of a converged solve is rounding (its sums run in another order): equal
    # to 1 % of the tolerance
    assert padded.grad_norm_rel == pytest.approx(alone.grad_norm_rel, rel=1e-6, abs=1e-12)
    mesh = pattern.mesh
    rest = bar_lengths(mesh.vertices, mesh.edges)
    strain = np.abs(np.asarray(bar_lengths(padded.positions, mesh.edges)) / rest - 1.0)
    assert padded.strain_mean == pytest.approx(float(np.mean(strain)), rel=1e-6, abs=1e-15)
    for a, b in zip(padded.frames, alone.frames, strict=True):
        assert a.positions.shape == b.positions.shape
        np.testing.assert_allclose(a.positions, b.positions, atol=1e-9)


def test_patterns_of_one_bucket_share_a_compiled_solve():
    """A Miura-ori 2 x 2 and a waterbomb 1 x 1 (9 vertices each, other elements) pad to one
    bucket: the second fold compiles nothing."""
    first = fold(patterns.miura_ori(2, 2))
    second = fold(patterns.waterbomb(1, 1))
    assert first.converged and second.converged
    assert second.compile_time == 0.0


def test_warmup_compiles_what_a_new_pattern_of_its_bucket_needs():
    """After warmup of the 13-vertex bucket (direct and along the path), a Miura-ori 2 x 2
    (direct) and a degree-4 vertex folded fully (the path from flat) compile nothing."""
    from origami_jax import clear_caches, warmup
    from origami_jax.warmup import vertex_buckets

    assert vertex_buckets(9) == [8, 10, 11, 13]
    clear_caches()
    done = warmup(buckets=[13])
    assert set(done) == {(13, "continuation"), (13, "direct"), (13, "direct-barriers")}
    direct = fold(patterns.miura_ori(2, 2))
    path = fold(patterns.degree4_vertex(2.5, 0.3, 3.1))
    assert direct.path == "direct" and path.path == "continuation"
    assert direct.compile_time == 0.0 and path.compile_time == 0.0
    assert set(warmup(buckets=[13]).values()) == {0.0}
    with pytest.raises(ValueError, match="at least 8"):
        warmup(buckets=[5])


@pytest.mark.parametrize(
    "pattern",
    [
        patterns.miura_ori(3, 3),
        patterns.waterbomb(2, 2),
        patterns.seed_waterbomb(),
        patterns.yoshimura(3, 4),
        patterns.kresling(6, 2),
        patterns.square_twist(),
        patterns.degree4_vertex(2.5, 0.3, 3.1),
    ],
    ids=["miura", "waterbomb", "seed", "yoshimura", "kresling", "twist", "vertex"],
)
def test_newton_buckets_depend_on_the_vertex_count_alone(pattern):
    """At Newton's floors every triangulated sheet of one piece fits its vertex bucket's least
    sizes (Euler's bounds), whatever its mix of bars, creases and facets."""
    from origami_jax.padding import PLANAR_FLOORS, floor_sizes, problem_sizes

    sizes = problem_sizes(pattern)
    to = bucket(sizes, 4, PLANAR_FLOORS)
    assert to == floor_sizes(to.vertices, PLANAR_FLOORS, sizes.barriers)
