"""The host's sparse Cholesky behind Newton's sparse solves (origami_jax.solvers.hostsparse):
PARDISO, CHOLMOD and SuperLU agree with each other and with the dense solve, fail cleanly, keep
and release their factorizations, count their time, and load the BLAS kernels of this CPU."""

import os
import re
import subprocess
import sys

import numpy as np
import pytest

from origami_jax import fold, patterns
from origami_jax.solvers import Newton


def _run_python(code: str, without: str) -> subprocess.CompletedProcess:
    """``python -c code`` in a fresh process whose environment lacks the variable ``without``."""
    env = {k: v for k, v in os.environ.items() if k != without}
    return subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=900
    )


_BACKENDS = ("pardiso", "cholmod", "superlu")


def _use_backend(name: str):
    """``hostsparse.using(name)``; the test skips where ``name`` is not installed."""
    from origami_jax.solvers import hostsparse

    if name not in hostsparse.available():
        pytest.skip(f"{name} is not installed")
    return hostsparse.using(name)


@pytest.mark.parametrize("backend", _BACKENDS)
def test_newton_sparse_and_dense_agree(backend):
    from origami_jax.solvers import hostsparse

    cp = patterns.miura_ori(3, 3, sector_angle=np.radians(60), fold_angle=np.pi / 2)
    dense = fold(cp, solver=Newton(linear_solver="dense"))
    with _use_backend(backend):
        assert hostsparse.backend() == backend
        sparse = fold(cp, solver=Newton(linear_solver="sparse"))
    assert dense.converged and sparse.converged
    np.testing.assert_allclose(sparse.positions, dense.positions, atol=1e-9)
    # the kept host factorizations (for the acceleration's second solve) were all released
    assert not hostsparse._KEPT


def test_cholmod_blas_runs_this_cpus_kernels_when_tuned():
    """cvxopt's bundled OpenBLAS (0.3.15) takes its slowest kernels on CPUs newer than itself;
    after ``tune_process()`` hostsparse loads it (on first use) with those that
    :func:`openblas_coretype` names for this CPU, and the variable that told it so is gone
    again."""

    from origami_jax.solvers import hostsparse

    wanted = hostsparse.openblas_coretype()
    if "cholmod" not in hostsparse.available() or wanted is None:
        pytest.skip("needs cvxopt on an x86-64 CPU with AVX2")
    script = (
        "import os, sys, origami_jax\n"
        "from origami_jax.solvers import hostsparse\n"
        "env = dict(os.environ)\n"
        "print(origami_jax.tune_process(malloc=False, mkl_blocktime=False))\n"
        "print('cvxopt' in sys.modules)\n"
        "print(hostsparse.cholmod_blas())\n"
        "print(dict(os.environ) == env)\n"
    )
    run = _run_python(script, without="OPENBLAS_CORETYPE")
    assert run.returncode == 0, run.stderr[-3000:]
    took, loaded, running, same_env = run.stdout.splitlines()
    if running == "None":
        pytest.skip("this cvxopt build does not bundle OpenBLAS")
    assert "'openblas_kernels': True" in took and loaded == "False"  # loaded on first use
    assert running.lower() == wanted.lower()
    assert same_env == "True"


def test_cvxopt_loaded_first_on_its_slowest_kernels_is_reported():
    """Tuned after cvxopt was loaded, hostsparse cannot name the kernels; where OpenBLAS then
    runs its slowest ones it warns, naming the variable that fixes it, and says it did not
    take."""

    from origami_jax.solvers import hostsparse

    if "cholmod" not in hostsparse.available() or hostsparse.openblas_coretype() is None:
        pytest.skip("needs cvxopt on an x86-64 CPU with AVX2")
    script = (
        "import warnings, cvxopt, origami_jax\n"
        "from origami_jax.solvers import hostsparse\n"
        "with warnings.catch_warnings(record=True) as w:\n"
        "    warnings.simplefilter('always')\n"
        "    took = origami_jax.tune_process(malloc=False, mkl_blocktime=False)\n"
        "print(hostsparse.cholmod_blas())\n"
        "print('|'.join(str(x.message) for x in w if x.category is RuntimeWarning))\n"
        "print(took['openblas_kernels'])\n"
    )
    run = _run_python(script, without="OPENBLAS_CORETYPE")
    assert run.returncode == 0, run.stderr[-3000:]
    out = run.stdout.splitlines()
    if out[0].lower() != "prescott":
        pytest.skip(f"this CPU's kernels are recognised ({out[0]})")
    assert "OPENBLAS_CORETYPE=" in out[1] and "slowest" in out[1]
    assert out[2] == "False"


@pytest.mark.parametrize("backend", _BACKENDS)
def test_host_sparse_backends_agree_and_fail_cleanly(backend):
    """PARDISO and CHOLMOD (where installed) and SuperLU solve a symmetric matrix given by its
    upper triangle; a matrix that is not positive definite (a zero pivot left out of the
    pattern too), or not finite, gives ok=False and zeros; kept factorizations (two at once)
    solve once each, in any order. A backend that is not installed is refused by name."""
    from origami_jax.solvers import hostsparse

    in_use = hostsparse.backend()
    with _use_backend(backend):
        assert hostsparse.backend() == backend
        _host_sparse_solves(hostsparse)
    assert not hostsparse._KEPT and hostsparse.backend() == in_use
    with pytest.raises(ValueError, match="'umfpack' is not installed"):
        with hostsparse.using("umfpack"):
            pass
    # a factorization kept by one backend solves after a switch to another; details name it
    args, b, exact = _spd_system()
    with _use_backend(backend):
        assert hostsparse.backend_details().startswith(backend)
        _, ok, token = hostsparse.factor_solve(*args, b, keep=True)
    with hostsparse.using("superlu"):
        assert np.allclose(hostsparse.resolve(token, b), exact, rtol=1e-10)
    assert ok and not hostsparse._KEPT
    if backend == "pardiso":
        assert re.fullmatch(r"20\d\d(\.\d+)*", hostsparse.mkl_version())


@pytest.mark.parametrize("backend", _BACKENDS)
def test_host_sparse_timings_add_up_the_callbacks_and_the_backend_phases(backend):
    """``hostsparse.timings()`` (a benchmark's opt-in) counts each callback and each phase of
    the backend inside its block; outside it nothing is counted, and a block starts at zero."""
    import origami_jax
    from origami_jax.solvers import hostsparse

    args, b, exact = _spd_system()
    with _use_backend(backend):
        origami_jax.clear_caches()  # the pattern analysed afresh, in the block
        hostsparse.solve(*args, b)  # not timed
        origami_jax.clear_caches()
        with hostsparse.timings() as t:
            x, ok, token = hostsparse.factor_solve(*args, b, keep=True)
            again = hostsparse.resolve(token, 2 * b)
        with hostsparse.timings() as fresh:
            pass
    assert ok and np.allclose(x, exact, rtol=1e-10) and np.allclose(again, 2 * exact, rtol=1e-10)
    assert (t["factor_solve_calls"], t["resolve_calls"]) == (1, 1)
    assert (t["factorizations"], t["solves"]) == (1, 2)
    assert t["analyses"] == (0 if backend == "superlu" else 1)  # SuperLU has no separate one
    assert (t["unknowns"], t["entries"]) == (40, len(args[1]))
    inside = t["analyse"] + t["factor"] + t["solve"]
    assert t["factor"] > 0 and t["solve"] > 0 and t["callbacks"] >= inside
    assert all(v == 0 for v in fresh.values()) and not hostsparse._KEPT


def _spd_system():
    """``((indptr, indices, data) of the upper triangle, b, exact solution)`` of a random
    symmetric positive definite 40 x 40 system."""
    import scipy.sparse as sp

    rng = np.random.default_rng(3)
    m = sp.random(40, 40, density=0.1, random_state=4)
    a = (m @ m.T + 2 * sp.eye(40)).tocsr()
    upper = sp.triu(a).tocsr()
    upper.sort_indices()
    assert upper.nnz < a.nnz  # the lower triangle is left out
    args = (upper.indptr.astype(np.int32), upper.indices.astype(np.int32), upper.data)
    b = rng.normal(size=40)
    return args, b, np.linalg.solve(a.toarray(), b)


def _host_sparse_solves(hostsparse) -> None:
    import scipy.sparse as sp

    args, b, exact = _spd_system()
    indptr, indices, data = args
    upper = sp.csr_matrix((data, indices, indptr), shape=(40, 40))
    a = hostsparse.symmetric_matrix(*args)
    x, ok = hostsparse.solve(*args, b)
    assert ok and np.allclose(x, exact, rtol=1e-10)
    x2, ok2, token = hostsparse.factor_solve(*args, 2 * b, keep=True)
    assert ok2 and token > 0 and np.allclose(x2, 2 * exact, rtol=1e-10)
    other = (3 * upper).tocsr()
    x3, ok3, token3 = hostsparse.factor_solve(other.indptr, other.indices, other.data, b, keep=True)
    assert ok3 and np.allclose(x3, exact / 3, rtol=1e-10)
    assert np.allclose(hostsparse.resolve(token, -b), -exact, rtol=1e-10)
    assert np.all(np.isnan(hostsparse.resolve(token, b)))  # released
    assert np.allclose(hostsparse.resolve(token3, b), exact / 3, rtol=1e-10)
    # float32 in, float32 out
    x32, ok32 = hostsparse.solve(args[0], args[1], upper.data.astype(np.float32), b.astype("f4"))
    assert ok32 and x32.dtype == np.float32 and np.allclose(x32, exact, rtol=1e-4)
    middle = np.median(np.linalg.eigvalsh(a.toarray()))
    indefinite = sp.triu(a - middle * sp.eye(40)).tocsr()
    indefinite.sort_indices()
    x4, ok4, token4 = hostsparse.factor_solve(
        indefinite.indptr, indefinite.indices, indefinite.data, b, keep=True
    )
    assert not ok4 and token4 == 0 and np.all(x4 == 0)
    nan = upper.data.copy()
    nan[5] = np.nan
    assert not hostsparse.solve(args[0], args[1], nan, b)[1]
    # a row without its diagonal entry (a zero pivot; PARDISO cannot read such a pattern)
    holed = sp.csr_matrix(np.array([[0.0, 1.0, 0.0], [0.0, 3.0, 1.0], [0.0, 0.0, 2.0]]))
    assert not hostsparse.solve(holed.indptr, holed.indices, holed.data, b[:3])[1]


def test_sparse_newton_in_float32_without_x64():
    """JAX's default (no x64): the sparse host solve's callback returns no 64-bit value (its
    factorization token was int64, which failed every sparse float32 solve before stop 20)."""

    code = (
        "import jax, jax.numpy as jnp\n"
        "assert not jax.config.jax_enable_x64\n"
        "from origami_jax import fold, patterns\n"
        "from origami_jax.solvers import Newton\n"
        "r = fold(patterns.miura_ori(3, 3), solver=Newton(linear_solver='sparse'), "
        "dtype=jnp.float32)\n"
        "assert r.converged and r.dtype == 'float32', r.reason\n"
        "assert r.fold_angle_error_max < 1e-4, r.fold_angle_error_max\n"
        "print('ok', r.iterations)\n"
    )
    out = _run_python(code, without="JAX_ENABLE_X64")
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.startswith("ok")
