"""Sparse Cholesky of a Newton system on the host, called from ``jit`` through ``pure_callback``.

The symmetric matrix comes as CSR arrays ``(indptr, indices, data)`` of its **upper triangle**
(diagonal included; the same arrays are the lower triangle's CSC, which CHOLMOD reads), already
in a fill-reducing order (the nested dissection of
:func:`origami_jax.solvers.hessian_layout.hessian_layout`), each row's column indices increasing.
Three backends, the first available picked (:func:`backend`), each looked for on the first sparse
solve (or the first call that asks about backends), not when the package is imported:

* **PARDISO** (Intel oneMKL's parallel direct solver, when MKL's runtime library
  ``libmkl_rt`` is installed: ``pip install "origami-jax[pardiso]"``, x86-64 only). It is
  called through ``ctypes`` (its 64-bit-integer entry ``pardiso_64``), given this order as the
  user's permutation. Each PARDISO handle is analysed once and then only factors numerically;
  a pattern keeps up to two spare handles for the next calls. (timings:
  docs/design-notes/measurements.md). MKL is free to use and
  redistribute under Intel's Simplified Software License; it is optional.
* **CHOLMOD** (supernodal Cholesky, from ``cvxopt`` when it is installed:
  ``pip install "origami-jax[cholmod]"``). Its symbolic analysis is done once per sparsity
  pattern and kept; each call only factors numerically. (timings:
  docs/design-notes/measurements.md). cvxopt is GPL-3 licensed; it is optional. Its wheels bundle
  an OpenBLAS
  too old to know recent CPUs, which then runs its slowest kernels: with :func:`tune`'s
  ``openblas_kernels`` (an opt-in, see :mod:`origami_jax.tuning`) cvxopt is loaded with this
  CPU's kernels named (see :func:`openblas_coretype`).
* **SuperLU** from scipy (a dependency of jax), in symmetric mode without pivoting, when
  neither is installed (a pivot that is not positive counts as a failure, as in Cholesky).
  Its factorizations are made, used and freed on one thread of this module's own: scipy frees a
  SuperLU's memory only in the Python thread state that allocated it, and JAX runs each host
  callback in a fresh one, so a factorization kept for the next callback leaked whole
  (docs/design-notes/newton.md, "Memory of long sparse solves").

Nothing here changes a process-wide setting unless asked to by :func:`tune` (the OpenBLAS
kernels above; MKL's OpenMP threads not spinning after each PARDISO call).

:func:`timings` (an opt-in for benchmarks) adds up the seconds spent in the callbacks and in
each backend's analysis, factorizations and solves inside a ``with`` block.

A factorization can be kept for a second right-hand side (Newton's geodesic acceleration):
:func:`factor_solve` with ``keep=True`` returns a token, and :func:`resolve` solves with it
once and releases it. Nothing here raises: a matrix that does not factor gives ``ok=False``
and a zero solution (as one that is not positive definite); an unknown token gives NaN.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import itertools
import os
import platform
import sys
import threading
import time
import warnings
from collections import OrderedDict
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from origami_jax.caches import on_clear


def openblas_coretype() -> str | None:
    """The OpenBLAS kernels for this CPU by its features (``"SkylakeX"`` with AVX-512 SKX,
    ``"Haswell"`` with AVX2 and FMA), or ``None`` (not x86-64, or features unknown).

    cvxopt's wheels bundle OpenBLAS 0.3.15, which does not recognise CPUs newer than itself
    and then falls back to its slowest kernels ("Prescott"). (measured:
    docs/design-notes/measurements.md)."""
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
    """cvxopt's CHOLMOD (or ``None``), its bundled OpenBLAS given this CPU's kernels where
    :func:`tune` asked for them: where ``OPENBLAS_CORETYPE`` is unset and cvxopt not yet
    loaded, the variable is set while cvxopt loads (OpenBLAS reads it then) and removed again,
    so no other library sees it."""
    coretype = None
    if _named_kernels_wanted() and "cvxopt" not in sys.modules:
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


_UNLOADED = object()  # a backend not looked for yet
_LOAD_LOCK = threading.Lock()
# optional: PARDISO (MKL's runtime library) and CHOLMOD (cvxopt), loaded on first use
_mkl = _cholmod = _UNLOADED
_cvx_matrix = _cvx_spmatrix = None
# opt-ins of tune(); process-wide effects, so off unless asked for
_TUNING = {"openblas_kernels": False, "mkl_blocktime": False}


def _mkl_lib():
    """MKL's runtime library (with ``pardiso_64``) or ``None``; looked for on the first call."""
    global _mkl
    if _mkl is _UNLOADED:
        with _LOAD_LOCK:
            if _mkl is _UNLOADED:
                _mkl = _load_mkl()
    return _mkl


def _cholmod_lib():
    """cvxopt's ``cholmod`` module or ``None``; imported on the first call."""
    global _cholmod, _cvx_matrix, _cvx_spmatrix
    if _cholmod is _UNLOADED:
        with _LOAD_LOCK:
            if _cholmod is _UNLOADED:
                _cholmod, _cvx_matrix, _cvx_spmatrix = _import_cholmod()
    return _cholmod


def _named_kernels_wanted() -> bool:
    """Whether cvxopt is to load with this CPU's OpenBLAS kernels named (see :func:`tune`)."""
    return _TUNING["openblas_kernels"] and "OPENBLAS_CORETYPE" not in os.environ


def cholmod_blas() -> str | None:
    """The kernels that the OpenBLAS bundled with cvxopt runs (its ``openblas_get_corename``,
    e.g. ``"SkylakeX"``), or ``None`` (no cvxopt, or a build without its own OpenBLAS). Loads
    cvxopt if not yet loaded."""
    cholmod = _cholmod_lib()
    if cholmod is None:
        return None
    import ctypes
    import glob

    libs = os.path.join(os.path.dirname(cholmod.__file__), os.pardir, "cvxopt.libs")
    for path in sorted(glob.glob(os.path.join(libs, "libopenblas*"))):
        try:
            blas = ctypes.CDLL(path)
            blas.openblas_get_corename.restype = ctypes.c_char_p
            return blas.openblas_get_corename().decode()
        except (OSError, AttributeError):
            continue
    return None


def _named_kernels_run() -> bool:
    """Whether cvxopt, already loaded, runs this CPU's kernels; a warning where it runs
    OpenBLAS's slowest instead (nothing changes them in this process any more)."""
    wanted, running = openblas_coretype(), cholmod_blas()
    if wanted is None or running is None:
        return False
    if running.lower() == "prescott":
        warnings.warn(
            f"cvxopt's bundled OpenBLAS runs its slowest kernels ({running}) on this CPU, which "
            f"has {wanted}'s: sparse Newton solves (CHOLMOD) take about twice as long. Opt in "
            f"before cvxopt is first imported, or set OPENBLAS_CORETYPE={wanted} before Python "
            f"starts.",
            RuntimeWarning,
            stacklevel=3,
        )
    return running.lower() == wanted.lower()


def tune(openblas_kernels: bool = True, mkl_blocktime: bool = True) -> dict[str, bool]:
    """Opt in to the sparse backends' process-wide tuning (off by default; documented with the
    others in :mod:`origami_jax.tuning`, whose :func:`~origami_jax.tuning.tune_process` calls
    this). ``False`` leaves a setting as it is.

    * ``openblas_kernels``: load cvxopt (CHOLMOD) with this CPU's OpenBLAS kernels named
      (``OPENBLAS_CORETYPE`` set only while cvxopt loads, only where unset). cvxopt must not
      be loaded yet; where it was, on OpenBLAS's slowest kernels, this warns.
    * ``mkl_blocktime``: before each PARDISO call, ``kmp_set_blocktime(0)`` on the calling
      thread (unless ``KMP_BLOCKTIME`` is set), so MKL's OpenMP threads sleep at once instead of
      spinning on the cores that XLA computes on next. The OpenMP runtime is shared with any
      other library that uses Intel's.

    Returns which of the two are in effect: ``openblas_kernels`` true where cvxopt runs (or will
    load with) this CPU's kernels by this setting, ``mkl_blocktime`` where the calls will set it.
    """
    if openblas_kernels:
        _TUNING["openblas_kernels"] = True
    if mkl_blocktime:
        _TUNING["mkl_blocktime"] = True
    if _cholmod is not _UNLOADED or "cvxopt" in sys.modules:
        named = _named_kernels_wanted() and _named_kernels_run()
    else:  # to be loaded so, where installed
        installed = importlib.util.find_spec("cvxopt") is not None
        named = _named_kernels_wanted() and installed and openblas_coretype() is not None
    return {
        "openblas_kernels": named,
        "mkl_blocktime": _TUNING["mkl_blocktime"] and "KMP_BLOCKTIME" not in os.environ,
    }


def _load_mkl():
    """MKL's ``pardiso_64`` from its runtime library where installed (by pip or conda: in this
    environment's or the user's ``lib``, or on the loader's path), else ``None``. The 64-bit
    entry reads 64-bit integers whatever interface layer MKL was told to use."""
    import ctypes
    import ctypes.util
    import glob
    import site

    places = [sys.prefix, getattr(site, "USER_BASE", None) or sys.prefix]
    paths = [
        path
        for place in places
        for pattern in ("lib/libmkl_rt.so*", "lib/libmkl_rt*.dylib", "Library/bin/mkl_rt*.dll")
        for path in sorted(glob.glob(os.path.join(place, pattern)))
    ]
    found = ctypes.util.find_library("mkl_rt")
    for path in [*paths, *([found] if found else [])]:
        try:
            lib = ctypes.CDLL(path)
            entry = lib.pardiso_64
        except (OSError, AttributeError):
            continue
        i64 = ctypes.POINTER(ctypes.c_int64)
        ints = np.ctypeslib.ndpointer(np.int64, flags="C")
        reals = np.ctypeslib.ndpointer(np.float64, flags="C")
        # pt, maxfct, mnum, mtype, phase, n, a, ia, ja, perm, nrhs, iparm, msglvl, b, x, error
        entry.argtypes = [ints, i64, i64, i64, i64, i64, reals, ints, ints, ints]
        entry.argtypes += [i64, ints, i64, reals, reals, i64]
        entry.restype = None
        return lib
    return None


@functools.cache
def _blocktime_setter(lib):
    """``kmp_set_blocktime`` of the OpenMP runtime that MKL's threads run on, or ``None``:
    looked up among the libraries already loaded (MKL loads its own when its threads first
    start), so that no second copy of the runtime is ever loaded."""
    import ctypes

    lib.mkl_get_max_threads()  # starts MKL's threading layer and its OpenMP runtime
    mode = getattr(os, "RTLD_NOLOAD", None)
    if mode is None:  # pragma: no cover - not on Linux or macOS
        return None
    for name in ("libiomp5.so", "libiomp5.dylib"):
        try:
            return ctypes.CDLL(name, mode=mode).kmp_set_blocktime
        except (OSError, AttributeError):
            continue
    return None


def mkl_version() -> str | None:
    """The version of the MKL that PARDISO runs from (e.g. ``"2026.2"``), or ``None``."""
    mkl = _mkl_lib()
    if mkl is None:
        return None
    import ctypes
    import re

    text = ctypes.create_string_buffer(256)
    mkl.mkl_get_version_string(text, len(text))
    found = re.search(r"Version ([0-9][0-9.]*)", text.value.decode(errors="replace"))
    return found.group(1) if found else "unknown"


__all__ = [
    "available",
    "backend",
    "backend_details",
    "cholmod_blas",
    "factor_solve",
    "mkl_version",
    "openblas_coretype",
    "resolve",
    "solve",
    "superlu",
    "symmetric_matrix",
    "timings",
    "tune",
    "using",
]

_KEPT_MAX = 4096  # kept factorizations never released (an interrupted solve) are dropped
_SPARE = 2  # released factors a pattern keeps for reuse (each holds a numeric factorization)

# seconds and counts collected by timings() (None: off, the default: no clock is read)
_TIMES: dict[str, float] | None = None


@contextlib.contextmanager
def timings() -> Iterator[dict[str, float]]:
    """Add up where the host's sparse solves spend their time inside the ``with`` block (an
    opt-in for benchmarks; off, nothing is timed). Yields a dict, filled as the callbacks run:

    * ``callbacks``: seconds inside :func:`factor_solve` and :func:`resolve` (what JAX's host
      callbacks run, their arguments already on the host), ``factor_solve_calls`` and
      ``resolve_calls`` how many of each;
    * ``analyse``: the backend's symbolic analysis (PARDISO's phase 11, CHOLMOD's ``symbolic``;
      once per pattern and factor object), ``analyses`` how many;
    * ``factor``: numeric factorizations (SuperLU's whole ``splu``), ``factorizations``;
    * ``solve``: triangular solves, ``solves``;
    * ``unknowns`` and ``entries``: the size of the last matrix factored (rows, stored entries).

    The rest of ``callbacks`` is the callbacks' own work (checks, copies, the pattern's look-up).
    Not thread-safe against another ``timings`` block; the callbacks themselves hold a lock.

    Example:
      >>> from origami_jax.solvers import hostsparse
      >>> with hostsparse.timings() as t:
      ...     pass  # fold(...) here
      >>> t["callbacks"]
      0.0
    """
    global _TIMES
    keys = ("callbacks", "analyse", "factor", "solve")
    counts = ("factor_solve_calls", "resolve_calls", "analyses", "factorizations", "solves")
    counts += ("unknowns", "entries")
    times: dict[str, float] = {**dict.fromkeys(keys, 0.0), **dict.fromkeys(counts, 0)}
    saved, _TIMES = _TIMES, times
    try:
        yield times
    finally:
        _TIMES = saved


@contextlib.contextmanager
def _timed(key: str, count: str | None = None):
    """Add the block's seconds to ``_TIMES[key]`` (and one to ``count``) while timings() is on."""
    times = _TIMES
    if times is None:
        yield
        return
    start = time.perf_counter()
    try:
        yield
    finally:
        times[key] += time.perf_counter() - start
        if count is not None:
            times[count] += 1


def backend() -> str:
    """``"pardiso"`` when MKL is installed, else ``"cholmod"`` when cvxopt is, else
    ``"superlu"``."""
    if _mkl_lib() is not None:
        return "pardiso"
    return "superlu" if _cholmod_lib() is None else "cholmod"


def available() -> tuple[str, ...]:
    """The installed backends, the one in use first (see :func:`backend`)."""
    return tuple(
        name
        for name, lib in (("pardiso", _mkl_lib()), ("cholmod", _cholmod_lib()), ("superlu", 1))
        if lib is not None
    )


@contextlib.contextmanager
def using(name: str):
    """Use backend ``name`` (one of :func:`available`) inside the ``with`` block, as if those
    before it were not installed: for comparisons and tests. Not thread-safe.

    Example:
      >>> from origami_jax.solvers import hostsparse
      >>> with hostsparse.using("superlu"):
      ...     hostsparse.backend()
      'superlu'
    """
    global _mkl, _cholmod
    if name not in available():  # both looked for: saved and restored below
        raise ValueError(f"host sparse backend {name!r} is not installed: {available()}")
    saved = _mkl, _cholmod
    if name != "pardiso":
        _mkl = None
    if name == "superlu":
        _cholmod = None
    try:
        yield
    finally:
        _mkl, _cholmod = saved


def backend_details() -> str:
    """:func:`backend` with what it runs on, e.g. ``"pardiso (MKL 2026.2)"`` or
    ``"cholmod (OpenBLAS kernels SkylakeX)"``."""
    name = backend()
    if name == "pardiso":
        return f"pardiso (MKL {mkl_version()})"
    if name == "cholmod":
        return f"cholmod (OpenBLAS kernels {cholmod_blas()})"
    return name


class _Pattern:
    """One sparsity pattern's analysis and a pool of factors of it (each factor object holds
    one numeric factorization at a time, so kept factorizations need one each)."""

    def __init__(self, indptr: np.ndarray, indices: np.ndarray):
        self.indptr, self.indices = indptr.copy(), indices.copy()
        self.free: list = []

    def matches(self, indptr: np.ndarray, indices: np.ndarray) -> bool:
        return np.array_equal(indptr, self.indptr) and np.array_equal(indices, self.indices)

    def release(self, factor) -> None:
        """Back to the pool, which keeps at most ``_SPARE`` (a factor holds its memory)."""
        if len(self.free) < _SPARE:
            self.free.append(factor)


class _PardisoFactor:
    """A PARDISO handle (its internal memory freed with the object) analysed for one pattern,
    holding at most one numeric factorization and the values it factored."""

    def __init__(self, pattern: _Pardiso):
        self.n, self.ia, self.ja, self.perm = pattern.n, pattern.ia, pattern.ja, pattern.perm
        # the library it was made with: released through it even after a switch of backend
        self.lib = _mkl_lib()
        self.handle = np.zeros(64, np.int64)  # PARDISO's internal pointers, zero before use
        self.iparm = np.zeros(64, np.int64)
        # our own settings (iparm[0]); the matrix's order as the user's permutation (iparm[4]),
        # indices from zero (iparm[34]); no iterative refinement (iparm[7]): mtype 2 (real
        # symmetric positive definite) perturbs no pivot, a pivot that is not positive fails
        self.iparm[[0, 1, 4, 34]] = [1, 2, 1, 1]
        self.values = np.zeros(0)
        self.analysed = False

    def call(self, phase: int, values: np.ndarray, rhs: np.ndarray | None = None):
        """Run PARDISO ``phase`` (11 analysis, 22 factorization, 33 solve, -1 release):
        ``(x, error)``, where error 0 is success and -4 a pivot that is not positive."""
        import ctypes

        n = self.n
        b = np.zeros(n) if rhs is None else np.array(rhs, np.float64, order="C").ravel()
        x = np.zeros(n)
        error = ctypes.c_int64(0)

        def int_(v):
            return ctypes.byref(ctypes.c_int64(v))

        if _TUNING["mkl_blocktime"] and "KMP_BLOCKTIME" not in os.environ:
            # opted in (tune): MKL's threads otherwise spin for 200 ms after each call, on the
            # cores that XLA's threads compute on next; this thread's teams only
            set_blocktime = _blocktime_setter(self.lib)
            if set_blocktime is not None:
                set_blocktime(0)
        self.lib.pardiso_64(
            self.handle, int_(1), int_(1), int_(2), int_(phase), int_(n), values, self.ia, self.ja,
            self.perm, int_(1), self.iparm, int_(0), b, x, ctypes.byref(error),
        )  # fmt: skip
        return x, error.value

    def __del__(self):
        if self.analysed:
            try:
                self.call(-1, np.zeros(1))
            except Exception:  # pragma: no cover - the interpreter shutting down
                pass


class _Pardiso(_Pattern):
    """One sparsity pattern for PARDISO: its arrays as ``pardiso_64`` reads them and a pool of
    analysed handles (one analysis each: about 60 ms for a Miura-ori 100 x 100)."""

    def __init__(self, indptr: np.ndarray, indices: np.ndarray):
        super().__init__(indptr, indices)
        self.n = indptr.shape[0] - 1
        self.ia, self.ja = indptr.astype(np.int64), indices.astype(np.int64)
        self.perm = np.arange(self.n, dtype=np.int64)
        self.readable = self.layout_ok(indptr, indices)

    @staticmethod
    def layout_ok(indptr: np.ndarray, indices: np.ndarray) -> bool:
        """PARDISO reads only rows that begin with their diagonal, their columns increasing
        (a row without its diagonal has a zero pivot: not positive definite anyway)."""
        n = indptr.shape[0] - 1
        starts, ends = indptr[:-1], indptr[1:]
        if n < 1 or indptr[0] != 0 or indptr[-1] != len(indices) or np.any(ends <= starts):
            return False
        if np.any(indices[starts] != np.arange(n)):
            return False
        within = np.ones(len(indices) - 1, bool)
        within[ends[:-1] - 1] = False  # from a row's last entry to the next row's first
        return bool(np.all(np.diff(indices)[within] > 0) and indices.max() < n)

    def factor(self, data: np.ndarray):
        """A handle holding the numeric factor of ``data``, or ``None``."""
        if not self.readable:
            return None
        handle = self.free.pop() if self.free else _PardisoFactor(self)
        values = np.array(data, np.float64, order="C")  # kept: the solves are given it too
        if not handle.analysed:
            handle.analysed = True  # from here on its memory is released with it
            with _timed("analyse", "analyses"):
                analysed = handle.call(11, values)[1] == 0
            if not analysed:
                return None
        with _timed("factor", "factorizations"):
            factored = handle.call(22, values)[1] == 0
        if not factored:
            self.release(handle)
            return None
        handle.values = values
        return handle

    def solve(self, handle: _PardisoFactor, rhs: np.ndarray) -> np.ndarray:
        with _timed("solve", "solves"):
            x, error = handle.call(33, handle.values, rhs)
        return x if error == 0 else np.full_like(x, np.nan)


class _Cholmod(_Pattern):
    """One sparsity pattern's CHOLMOD analysis: the lower triangle's pattern and a pool of
    symbolic factors."""

    def __init__(self, indptr: np.ndarray, indices: np.ndarray):
        super().__init__(indptr, indices)
        self.lib = _cholmod_lib()  # kept factors solve through it after a switch of backend
        n = indptr.shape[0] - 1
        rows = np.repeat(np.arange(n), np.diff(indptr))
        # the upper triangle's CSR, row by row, is the lower triangle's CSC
        self.matrix = _cvx_spmatrix(
            np.zeros(len(indices)),
            _cvx_matrix(indices.astype(np.int32)),
            _cvx_matrix(rows.astype(np.int32)),
            (n, n),
        )
        self.identity = _cvx_matrix(np.arange(n, dtype=np.int32))

    def factor(self, data: np.ndarray):
        """A numeric factor of ``data`` (a symbolic factor from the pool), or ``None``."""
        with _cholmod_options(self.lib):
            if self.free:
                symbolic = self.free.pop()
            else:
                with _timed("analyse", "analyses"):
                    symbolic = self.lib.symbolic(self.matrix, p=self.identity)
            self.matrix.V = _cvx_matrix(np.ascontiguousarray(data, np.float64))
            try:
                with _timed("factor", "factorizations"):
                    self.lib.numeric(self.matrix, symbolic)
            except ArithmeticError:  # not positive definite
                self.release(symbolic)
                return None
        return symbolic

    def solve(self, numeric, rhs: np.ndarray) -> np.ndarray:
        b = _cvx_matrix(np.array(rhs, np.float64))
        with _cholmod_options(self.lib), _timed("solve", "solves"):
            self.lib.solve(numeric, b)
        return np.asarray(b).ravel()


class _cholmod_options:
    """Supernodal factorization in the given order; cvxopt's global options restored after."""

    def __init__(self, lib):
        self.lib = lib

    def __enter__(self):
        self.saved = dict(self.lib.options)
        self.lib.options.update(supernodal=2, postorder=True)

    def __exit__(self, *exc):
        self.lib.options.clear()
        self.lib.options.update(self.saved)


_PATTERNS: list[_Pattern] = []  # the most recent patterns, newest last
_KEPT: OrderedDict[int, tuple] = OrderedDict()
_TOKENS = itertools.count(1)
_LOCK = threading.Lock()  # callbacks may come from several threads (devices)


@on_clear
def _clear_patterns() -> None:
    """Drop the patterns' analyses and spare factors (origami_jax.clear_caches); kept
    factorizations hold their own."""
    with _LOCK:
        _PATTERNS.clear()


def _pattern(indptr: np.ndarray, indices: np.ndarray) -> _Pattern | None:
    """The pattern's analysis by the backend in use; ``None``: SuperLU."""
    kind = {"pardiso": _Pardiso, "cholmod": _Cholmod}.get(backend())
    if kind is None:
        return None
    for p in _PATTERNS:
        if type(p) is kind and p.matches(indptr, indices):
            return p
    p = kind(indptr, indices)
    _PATTERNS.append(p)
    del _PATTERNS[:-4]
    return p


def _factor(indptr, indices, data):
    """``(solve, release)`` of the factored matrix, or ``None`` if it does not factor."""
    indptr, indices, data = np.asarray(indptr), np.asarray(indices), np.asarray(data)
    if not np.all(np.isfinite(data)):
        return None
    pattern = _pattern(indptr, indices)
    if pattern is not None:
        numeric = pattern.factor(data)
        if numeric is None:
            return None
        return (lambda b: pattern.solve(numeric, b)), (lambda: pattern.release(numeric))
    key = _on_superlu_thread(_superlu_factor, indptr, indices, data)
    if key == 0:
        return None
    solve_fn = functools.partial(_on_superlu_thread, _superlu_solve, key)
    return solve_fn, functools.partial(_on_superlu_thread, _superlu_free, key)


# scipy's SuperLU records each block it allocates in a dict kept in the current Python thread
# state, and frees a block only if that dict lists it. JAX runs a host callback on one of XLA's
# threads in a thread state made for that call and dropped after it, so a factorization kept
# from one callback to the next (Newton's second solve, ``resolve``) was freed where no dict
# knew it: none of its memory came back (about a megabyte per Newton iteration on a 248-vertex
# sheet). Every SuperLU of the solves below lives on one long-lived thread instead: made, used
# and dropped there, and never handed out (a result holding one would be dropped by the caller).
_SUPERLU: dict[int, spla.SuperLU] = {}  # read and written only on that thread
_SUPERLU_KEYS = itertools.count(1)
_SUPERLU_START = threading.Lock()
_superlu_thread: tuple[int, ThreadPoolExecutor] | None = None  # (process id, its one worker)


def _on_superlu_thread(fn, *args):
    """``fn(*args)`` run on the SuperLU thread (started on first use, again in a forked child,
    which inherits no threads), the caller waiting."""
    global _superlu_thread
    with _SUPERLU_START:
        if _superlu_thread is None or _superlu_thread[0] != os.getpid():
            _SUPERLU.clear()  # a fork's copies: made on a thread this process does not have
            worker = ThreadPoolExecutor(1, thread_name_prefix="origami-superlu")
            _superlu_thread = (os.getpid(), worker)
        worker = _superlu_thread[1]
    return worker.submit(fn, *args).result()


def _superlu_factor(indptr, indices, data) -> int:
    """(On the SuperLU thread.) The key of the kept factorization, 0 if it does not factor."""
    with _timed("factor", "factorizations"):
        found = superlu(indptr, indices, data)
    # without pivoting, U's diagonal is D of L D L^T: all positive iff positive definite
    if found is None or not np.all(found[1] > 0):
        return 0
    key = next(_SUPERLU_KEYS)
    _SUPERLU[key] = found[0]
    return key


def _superlu_solve(key: int, rhs: np.ndarray) -> np.ndarray:
    """(On the SuperLU thread.)"""
    with _timed("solve", "solves"):
        return _SUPERLU[key].solve(rhs)


def _superlu_free(key: int) -> None:
    """(On the SuperLU thread: where the factorization is dropped, its memory is freed.)"""
    _SUPERLU.pop(key, None)


def symmetric_matrix(indptr, indices, data) -> sp.csr_matrix:
    """The whole symmetric matrix given by the CSR arrays of its upper triangle."""
    n = len(indptr) - 1
    upper = sp.csr_matrix((data, indices, indptr), shape=(n, n))
    return (upper + sp.triu(upper, k=1).T).tocsr()


def superlu(indptr, indices, data) -> tuple[spla.SuperLU, np.ndarray] | None:
    """SuperLU of the symmetric matrix (given by its upper triangle) in its given order, without
    pivoting, and its pivots (``U``'s diagonal, which is ``D`` of ``L D L^T``); ``None`` if it
    does not factor so (SuperLU swaps rows where a diagonal entry is left out of the pattern:
    that matrix is not positive definite either)."""
    try:
        matrix = symmetric_matrix(indptr, indices, data).tocsc()
        lu = spla.splu(
            matrix, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
        )
    except (RuntimeError, ValueError):
        return None
    if not np.array_equal(lu.perm_r, np.arange(matrix.shape[0])):
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
    with _LOCK, _timed("callbacks", "factor_solve_calls"):
        if _TIMES is not None:
            _TIMES["unknowns"], _TIMES["entries"] = len(indptr) - 1, len(indices)
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
    with _LOCK, _timed("callbacks", "resolve_calls"):
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
