"""Process-wide settings that make large sheets faster: explicit opt-ins, all listed here.

Importing :mod:`origami_jax` changes no environment variable, no thread setting, no allocator
setting and no JAX flag, and loads no sparse backend (MKL's PARDISO and cvxopt's CHOLMOD are
looked for on the first sparse solve). Each setting below changes something the whole process
shares, so the library never makes it by itself; :func:`tune_process` opts in to all of them,
and the command line (``origami-jax``) and the benchmarks call it:

* **malloc** (:func:`origami_jax.memory.keep_freed_memory`): glibc's ``malloc`` keeps large
  freed blocks in its heap instead of unmapping them, so a Newton iteration on a large sheet
  stops paying the page faults of fresh buffers (about a fifth faster on a 100 x 100
  Miura-ori, a tenth on a 316 x 316); the process keeps its peak heap. Or set
  ``MALLOC_MMAP_THRESHOLD_`` and ``MALLOC_TRIM_THRESHOLD_`` before Python starts.
* **OpenBLAS kernels** (:func:`origami_jax.solvers.hostsparse.tune`, ``openblas_kernels``):
  cvxopt's wheels bundle an OpenBLAS too old to know recent CPUs, which then runs its slowest
  kernels (CHOLMOD about twice as slow). Opted in, cvxopt is loaded with this CPU's kernels
  named: ``OPENBLAS_CORETYPE`` is set only while cvxopt loads, only where you have not set it,
  and only if cvxopt is not loaded yet (it warns where it was, on the slowest kernels). Or set
  ``OPENBLAS_CORETYPE`` (see :func:`~origami_jax.solvers.hostsparse.openblas_coretype`) before
  Python starts.
* **MKL's thread wait** (:func:`origami_jax.solvers.hostsparse.tune`, ``mkl_blocktime``): after
  a parallel region, the OpenMP threads that PARDISO runs on spin for 200 ms by default, on the
  cores that XLA computes on next. Opted in, each PARDISO call first sets
  ``kmp_set_blocktime(0)`` for the calling thread's teams (unless ``KMP_BLOCKTIME`` is set), on
  Intel's OpenMP runtime, which other libraries in the process may share. A large sheet's
  Newton fold with PARDISO takes about a tenth less time with it (see
  docs/design-notes/newton.md). Or set ``KMP_BLOCKTIME=0`` before Python starts.

* **BLAS threads** (:func:`limit_blas_threads`, ``blas_threads``): JAX's CPU LAPACK (the dense
  Cholesky of Newton's dense solves, below 200 vertices, and of ``fold_batch``) calls the
  OpenBLAS that scipy bundles, whose threads spin while they wait. Beside another busy process
  on the same cores that turns a factorization many times slower: a waterbomb's Newton
  iteration took 4 ms alone and 690 ms beside one other busy process; with one BLAS thread, 6 ms
  beside it. Opted in, the OpenBLAS copies loaded in the process (scipy's and numpy's) run one
  thread each (unless ``OPENBLAS_NUM_THREADS`` is set). Or set ``OPENBLAS_NUM_THREADS=1``
  before Python starts.

The command line also turns on JAX's float64 (``jax_enable_x64``) and, with ``--cache``, its
persistent compilation cache, and prints warnings on one line: in its console entry point
(:func:`origami_jax.cli.console_main`), not in :func:`origami_jax.cli.main`.

Example:
  >>> import origami_jax
  >>> sorted(origami_jax.tune_process())  # doctest: +SKIP
  ['blas_threads', 'malloc', 'mkl_blocktime', 'openblas_kernels']
"""

from __future__ import annotations

import ctypes
import os

from origami_jax.memory import keep_freed_memory
from origami_jax.solvers import hostsparse

__all__ = ["tune_process", "limit_blas_threads"]

# the OpenBLAS entry points that set its thread count, by the prefixes and suffixes of the
# copies numpy and scipy bundle, and of a system OpenBLAS
_SET_THREADS = (
    "scipy_openblas_set_num_threads",
    "scipy_openblas_set_num_threads64_",
    "openblas_set_num_threads",
    "openblas_set_num_threads64_",
)


def _loaded_libraries() -> list[str]:
    """The shared libraries mapped into this process (Linux; elsewhere none are found)."""
    try:
        with open("/proc/self/maps", encoding="utf-8") as f:
            return sorted({line.split()[-1] for line in f if ".so" in line.split()[-1]})
    except OSError:
        return []


def limit_blas_threads(threads: int = 1) -> bool:
    """Run every OpenBLAS loaded in this process (scipy's, which JAX's CPU LAPACK calls, and
    numpy's) on ``threads`` threads, unless ``OPENBLAS_NUM_THREADS`` is set. Process-wide (see
    the module docstring). Returns whether any was set."""
    if threads < 1:
        raise ValueError(f"limit_blas_threads: threads must be >= 1, got {threads}")
    if "OPENBLAS_NUM_THREADS" in os.environ:
        return False
    import numpy  # noqa: F401  (loads numpy's OpenBLAS)
    import scipy.linalg.cython_lapack  # noqa: F401  (loads scipy's, the one JAX calls)

    done = False
    for path in _loaded_libraries():
        if "openblas" not in os.path.basename(path).lower():
            continue
        lib = ctypes.CDLL(path)
        for symbol in _SET_THREADS:
            setter = getattr(lib, symbol, None)
            if setter is not None:
                setter(ctypes.c_int(int(threads)))
                done = True
                break
    return done


def tune_process(
    malloc: bool = True,
    openblas_kernels: bool = True,
    mkl_blocktime: bool = True,
    blas_threads: int | None = 1,
) -> dict[str, bool]:
    """Opt in to the process-wide settings of this module's docstring (``False``: leave that one
    as it is). Call it early: the OpenBLAS kernels can only be named before cvxopt is first
    imported. ``blas_threads``: the OpenBLAS thread count (``None``: left alone). Returns, for
    each setting, whether it was asked for and is in effect (``False`` where one cannot take:
    not glibc, cvxopt loaded earlier, a variable of yours set, ...)."""
    took = {"malloc": keep_freed_memory() if malloc else False}
    took.update(hostsparse.tune(openblas_kernels=openblas_kernels, mkl_blocktime=mkl_blocktime))
    if not openblas_kernels:
        took["openblas_kernels"] = False
    if not mkl_blocktime:
        took["mkl_blocktime"] = False
    took["blas_threads"] = limit_blas_threads(blas_threads) if blas_threads else False
    return took
