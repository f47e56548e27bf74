"""The package's caches: bounded, least recently used out first, emptied by ``clear_caches()``."""

import numpy as np
import pytest
import scipy.sparse as sp

import origami_jax
from origami_jax import fold, fold_batch, patterns
from origami_jax.batch import compile_count
from origami_jax.caches import LruCache
from origami_jax.energy import make_structure
from origami_jax.solvers import hostsparse
from origami_jax.solvers.newton import hessian_layout


def test_lru_cache_keeps_the_most_recently_used_and_is_cleared_with_the_rest():
    cache = LruCache(3)
    for key in "abc":
        cache[key] = key.upper()
    assert cache["a"] == "A"  # read: now the most recent
    cache["d"] = "D"
    assert sorted(cache) == ["a", "c", "d"] and len(cache) == 3
    assert cache.get("b") is None and cache.setdefault("e", "E") == "E"
    assert sorted(cache) == ["a", "d", "e"]
    origami_jax.clear_caches()
    assert len(cache) == 0 and list(cache) == []
    with pytest.raises(ValueError, match="at least 1"):
        LruCache(0)


def test_clear_caches_empties_compiled_solves_and_layouts_and_folds_go_on():
    cp = patterns.single_crease(fold_angle=1.0)
    first = fold(cp)
    assert fold(cp).compile_time == 0.0  # cached: nothing compiled
    mesh = patterns.miura_ori(3, 3).mesh
    layout = hessian_layout(mesh, make_structure(mesh, False), sparse=True)
    assert hessian_layout(mesh, make_structure(mesh, False), sparse=True) is layout
    batch = [patterns.miura_ori(2, 2, fold_angle=a) for a in (0.4, 0.8)]
    fold_batch(batch, progress=False)
    before = compile_count()
    fold_batch(batch, progress=False)
    assert compile_count() == before  # the slot loop is cached

    origami_jax.clear_caches()
    again = fold(cp)
    assert again.compile_time > 0.0  # compiled again (JAX's own caches may serve it)
    assert again.converged
    np.testing.assert_allclose(again.positions, first.positions, rtol=0, atol=1e-12)
    assert hessian_layout(mesh, make_structure(mesh, False), sparse=True) is not layout
    results = fold_batch(batch, progress=False)
    assert compile_count() == before + 1 and all(r.converged for r in results)
    assert fold(cp).compile_time == 0.0  # cached again


def test_clear_caches_keeps_a_factorization_in_use():
    """The sparse analyses go; a factorization kept for a second solve still solves, and the
    next solve analyses its pattern again."""
    m = sp.random(30, 30, density=0.1, random_state=5)
    a = (m @ m.T + 2 * sp.eye(30)).tocsr()
    upper = sp.triu(a).tocsr()
    upper.sort_indices()
    args = (upper.indptr, upper.indices, upper.data)
    b = np.arange(30.0)
    exact = np.linalg.solve(a.toarray(), b)
    x, ok, token = hostsparse.factor_solve(*args, b, keep=True)
    assert ok and int(token) > 0
    origami_jax.clear_caches()
    np.testing.assert_allclose(hostsparse.resolve(token, 2 * b), 2 * exact, rtol=1e-10)
    x, ok = hostsparse.solve(*args, b)
    assert ok
    np.testing.assert_allclose(x, exact, rtol=1e-10)
