"""Sparse Cholesky of a Newton system on the host, called from ``jit`` through ``pure_callback``.

The symmetric matrix comes as CSR arrays ``(indptr, indices, data)`` of its **upper triangle**
(diagonal included; the same arrays are the lower triangle's CSC, which CHOLMOD reads), already
in a fill-reducing order (the nested dissection of
:func:`origami_jax.solvers.newton.hessian_layout`).
Two backends, picked once:

* **CHOLMOD** (supernodal Cholesky, from ``cvxopt`` when it is installed:
  ``pip install "origami-jax[cholmod]"``). Its symbolic analysis is done once per sparsity
  pattern and kept; each call only factors numerically. On this project's 2-core machine it
  factored the Hessian of a Miura-ori 100 x 100 (30,603 unknowns, 1.2 million stored entries)
  in 0.11 s and solved in 0.013 s, where SuperLU took 0.70 s for both (2026-12-02, best of 3,
  the same matrix). cvxopt is GPL-3 licensed; it is optional. Its wheels bundle an OpenBLAS
  too old to know recent CPUs, which then runs its slowest kernels: cvxopt is loaded here with
  this CPU's kernels named (see :func:`openblas_coretype`).
* **SuperLU** from scipy (a dependency of jax), in symmetric mode without pivoting, otherwise
  (a pivot that is not positive counts as a failure, as in Cholesky).

A factorization can be kept for a second right-hand side (Newton's geodesic acceleration):
:func:`factor_solve` with ``keep=True`` returns a token, and :func:`resolve` solves with it
once and releases it. Nothing here raises: a matrix that does not factor gives ``ok=False``
and a zero solution (as one that is not positive definite); an unknown token gives NaN.
"""

from __future__ import annotations

import itertools
import os
import platform
import sys
import threading
import warnings
from collections import OrderedDict

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def openblas_coretype() -> str | None:
    """The OpenBLAS kernels for this CPU by its features (``"SkylakeX"`` with AVX-512 SKX,
    ``"Haswell"`` with AVX2 and FMA), or ``None`` (not x86-64, or features unknown).

    cvxopt's wheels bundle OpenBLAS 0.3.15, which does not recognise CPUs newer than itself
    and then falls back to its slowest kernels ("Prescott"). On this project's 2-core machine
    on 2026-12-05 (an Intel Xeon of family 6, model 207, with AVX-512) that BLAS ran a
    1,000 x 1,000 dgemm at 18 GFlop/s (69 with the SkylakeX kernels) and CHOLMOD took
    182-191 ms to factor and solve the Hessian of a Miura-ori 100 x 100, 100-121 ms with the
    SkylakeX or Haswell kernels; a fold of that sheet took 4.0-4.4 s, then 2.4-2.9 s."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return None
    try:  # numpy's table of the CPU's features (numpy 2; numpy 1 named its module core)
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # pragma: no cover - depends on numpy's version
        try:
            from numpy.core._multiarray_umath import __cpu_features__ as features
        except ImportError:
            return None
    if features.get("AVX512_SKX"):
        return "SkylakeX"
    if features.get("AVX2") and features.get("FMA3"):
        return "Haswell"
    return None


def _import_cholmod():
    """cvxopt's CHOLMOD (or ``None``), its bundled OpenBLAS given this CPU's kernels: where
    ``OPENBLAS_CORETYPE`` is unset and cvxopt not yet loaded, the variable is set while cvxopt
    loads (OpenBLAS reads it then) and removed again, so no other library sees it."""
    coretype = None
    if "OPENBLAS_CORETYPE" not in os.environ and "cvxopt" not in sys.modules:
        coretype = openblas_coretype()
    try:
        if coretype is not None:
            os.environ["OPENBLAS_CORETYPE"] = coretype
        from cvxopt import cholmod, matrix, spmatrix

        return cholmod, matrix, spmatrix
    except ImportError:  # pragma: no cover - depends on the environment
        return None, None, None
    finally:
        if coretype is not None:
            del os.environ["OPENBLAS_CORETYPE"]


# optional: CHOLMOD
_cholmod, _cvx_matrix, _cvx_spmatrix = _import_cholmod()


def cholmod_blas() -> str | None:
    """The kernels that the OpenBLAS bundled with cvxopt runs (its ``openblas_get_corename``,
    e.g. ``"SkylakeX"``), or ``None`` (no cvxopt, or a build without its own OpenBLAS)."""
    if _cholmod is None:
        return None
    import ctypes
    import glob

    libs = os.path.join(os.path.dirname(_cholmod.__file__), os.pardir, "cvxopt.libs")
    for path in sorted(glob.glob(os.path.join(libs, "libopenblas*"))):
        try:
            blas = ctypes.CDLL(path)
            blas.openblas_get_corename.restype = ctypes.c_char_p
            return blas.openblas_get_corename().decode()
        except (OSError, AttributeError):
            continue
    return None


def _warn_if_slowest_kernels() -> None:
    """cvxopt loaded before this module runs the kernels OpenBLAS detected; say so when those
    are its slowest while this CPU has better ones."""
    if _cholmod is None or "OPENBLAS_CORETYPE" in os.environ:
        return
    wanted, running = openblas_coretype(), cholmod_blas()
    if wanted is not None and running is not None and running.lower() == "prescott":
        warnings.warn(
            f"cvxopt's bundled OpenBLAS runs its slowest kernels ({running}) on this CPU, which "
            f"has {wanted}'s: sparse Newton solves (CHOLMOD) take about twice as long. Import "
            f"origami_jax before cvxopt, or set OPENBLAS_CORETYPE={wanted} before Python starts.",
            RuntimeWarning,
            stacklevel=2,
        )


_warn_if_slowest_kernels()

__all__ = [
    "backend",
    "cholmod_blas",
    "factor_solve",
    "openblas_coretype",
    "resolve",
    "solve",
    "superlu",
    "symmetric_matrix",
]

_KEPT_MAX = 4096  # kept factorizations never released (an interrupted solve) are dropped


def backend() -> str:
    """``"cholmod"`` when cvxopt is installed, else ``"superlu"``."""
    return "superlu" if _cholmod is None else "cholmod"


class _Cholmod:
    """One sparsity pattern's CHOLMOD analysis: the lower triangle's pattern and a pool of
    symbolic factors (each holds one numeric factor at a time, so kept factors need one each)."""

    def __init__(self, indptr: np.ndarray, indices: np.ndarray):
        n = indptr.shape[0] - 1
        self.indptr, self.indices = indptr.copy(), indices.copy()
        rows = np.repeat(np.arange(n), np.diff(indptr))
        # the upper triangle's CSR, row by row, is the lower triangle's CSC
        self.matrix = _cvx_spmatrix(
            np.zeros(len(indices)),
            _cvx_matrix(indices.astype(np.int32)),
            _cvx_matrix(rows.astype(np.int32)),
            (n, n),
        )
        self.identity = _cvx_matrix(np.arange(n, dtype=np.int32))
        self.free: list = []

    def matches(self, indptr: np.ndarray, indices: np.ndarray) -> bool:
        return np.array_equal(indptr, self.indptr) and np.array_equal(indices, self.indices)

    def factor(self, data: np.ndarray):
        """A numeric factor of ``data`` (a symbolic factor from the pool), or ``None``."""
        with _cholmod_options():
            if self.free:
                symbolic = self.free.pop()
            else:
                symbolic = _cholmod.symbolic(self.matrix, p=self.identity)
            self.matrix.V = _cvx_matrix(np.ascontiguousarray(data, np.float64))
            try:
                _cholmod.numeric(self.matrix, symbolic)
            except ArithmeticError:  # not positive definite
                self.free.append(symbolic)
                return None
        return symbolic

    def solve(self, numeric, rhs: np.ndarray) -> np.ndarray:
        b = _cvx_matrix(np.array(rhs, np.float64))
        with _cholmod_options():
            _cholmod.solve(numeric, b)
        return np.asarray(b).ravel()


class _cholmod_options:
    """Supernodal factorization in the given order; cvxopt's global options restored after."""

    def __enter__(self):
        self.saved = dict(_cholmod.options)
        _cholmod.options.update(supernodal=2, postorder=True)

    def __exit__(self, *exc):
        _cholmod.options.clear()
        _cholmod.options.update(self.saved)


_PATTERNS: list[_Cholmod] = []  # the most recent patterns, newest last
_KEPT: OrderedDict[int, tuple] = OrderedDict()
_TOKENS = itertools.count(1)
_LOCK = threading.Lock()  # callbacks may come from several threads (devices)


def _pattern(indptr: np.ndarray, indices: np.ndarray) -> _Cholmod:
    for p in _PATTERNS:
        if p.matches(indptr, indices):
            return p
    p = _Cholmod(indptr, indices)
    _PATTERNS.append(p)
    del _PATTERNS[:-4]
    return p


def _factor(indptr, indices, data):
    """``(solve, release)`` of the factored matrix, or ``None`` if it does not factor."""
    indptr, indices, data = np.asarray(indptr), np.asarray(indices), np.asarray(data)
    if not np.all(np.isfinite(data)):
        return None
    if _cholmod is not None:
        pattern = _pattern(indptr, indices)
        numeric = pattern.factor(data)
        if numeric is None:
            return None
        return (lambda b: pattern.solve(numeric, b)), (lambda: pattern.free.append(numeric))
    found = superlu(indptr, indices, data)
    # without pivoting, U's diagonal is D of L D L^T: all positive iff positive definite
    if found is None or not np.all(found[1] > 0):
        return None
    return found[0].solve, lambda: None


def symmetric_matrix(indptr, indices, data) -> sp.csr_matrix:
    """The whole symmetric matrix given by the CSR arrays of its upper triangle."""
    n = len(indptr) - 1
    upper = sp.csr_matrix((data, indices, indptr), shape=(n, n))
    return (upper + sp.triu(upper, k=1).T).tocsr()


def superlu(indptr, indices, data) -> tuple[spla.SuperLU, np.ndarray] | None:
    """SuperLU of the symmetric matrix (given by its upper triangle) in its given order, without
    pivoting, and its pivots (``U``'s diagonal, which is ``D`` of ``L D L^T``); ``None`` if it
    does not factor."""
    try:
        matrix = symmetric_matrix(indptr, indices, data).tocsc()
        lu = spla.splu(
            matrix, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
        )
    except (RuntimeError, ValueError):
        return None
    return lu, lu.U.diagonal()


def _finish(x: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, bool]:
    ok = bool(np.all(np.isfinite(x)))
    return (x if ok else np.zeros_like(x)).astype(rhs.dtype), ok


def factor_solve(indptr, indices, data, rhs, active=True, keep: bool = False):
    """``(x, ok, token)``: the solution of ``A x = rhs`` and, with ``keep``, a token of the
    factorization for :func:`resolve` (``0`` when none is kept). Not ``active``: nothing is
    factored, zeros and ``ok=False`` (a ``lax.cond`` branch that ``vmap`` runs for every member,
    selected only for some)."""
    rhs = np.asarray(rhs)
    if not np.all(active):
        return np.zeros_like(rhs), np.asarray(False), np.asarray(0, np.int32)
    with _LOCK:
        return _factor_solve(indptr, indices, data, rhs, keep)


def _factor_solve(indptr, indices, data, rhs, keep):
    found = _factor(indptr, indices, data)
    if found is None:
        return np.zeros_like(rhs), np.asarray(False), np.asarray(0, np.int32)
    solve_fn, release = found
    x, ok = _finish(solve_fn(rhs), rhs)
    token = 0
    if keep and ok:
        token = next(_TOKENS) % (2**31 - 1) + 1  # int32: JAX without x64 has no int64
        _KEPT[token] = found
        while len(_KEPT) > _KEPT_MAX:
            _KEPT.popitem(last=False)[1][1]()
    else:
        release()
    return x, np.asarray(ok), np.asarray(token, np.int32)


def resolve(token, rhs):
    """Solve with a kept factorization and release it; NaN for an unknown token."""
    rhs = np.asarray(rhs)
    with _LOCK:
        found = _KEPT.pop(int(token), None)
        if found is None:
            return np.full_like(rhs, np.nan)
        solve_fn, release = found
        x = solve_fn(rhs).astype(rhs.dtype)
        release()
    return x


def solve(indptr, indices, data, rhs):
    """``(x, ok)``: the solution of ``A x = rhs`` (zero and ``ok=False`` if ``A`` does not
    factor)."""
    x, ok, _ = factor_solve(indptr, indices, data, rhs)
    return x, ok
