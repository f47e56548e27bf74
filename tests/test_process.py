"""Importing the package leaves the process alone; its process-wide tuning is an opt-in.

Each check runs in a fresh interpreter (the test's own process has long imported everything).
"""

import os
import subprocess
import sys
import textwrap

import pytest

# the dependencies first: their own import-time changes (jax sets variables of its own) are not
# the package's; then every write to the environment and every library that ctypes loads is
# recorded while origami_jax is imported
IMPORT_SCRIPT = textwrap.dedent(
    """
    import ctypes, os, sys, warnings
    import jax, jax.numpy, meshio, numpy, optax, scipy.sparse.linalg, shapely, svgelements

    def mapped():
        try:  # Linux: the files mapped into this process
            with open("/proc/self/maps") as f:
                return {os.path.basename(line.split()[-1]) for line in f if "/" in line}
        except OSError:
            return set()

    jax.devices()
    env, libs = dict(os.environ), mapped()
    config = dict(jax.config.values)
    show, filters, errors = warnings.showwarning, list(warnings.filters), numpy.geterr()
    events = []
    put, unset, cdll = os.putenv, os.unsetenv, ctypes.CDLL
    os.putenv = lambda k, v: (events.append(("set", k)), put(k, v))[1]
    os.unsetenv = lambda k: (events.append(("unset", k)), unset(k))[1]

    class Recorded(cdll):
        def __init__(self, name, *args, **kw):
            events.append(("load", name))
            super().__init__(name, *args, **kw)

    ctypes.CDLL = Recorded
    import origami_jax
    for name in origami_jax.__all__:  # the public names load lazily: every one of them
        getattr(origami_jax, name)
    os.putenv, os.unsetenv, ctypes.CDLL = put, unset, cdll

    print("events:", events)
    print("environment:", dict(os.environ) == env)
    print("jax config:", dict(jax.config.values) == config)
    print("warnings:", warnings.showwarning is show and list(warnings.filters) == filters)
    print("numpy errors:", numpy.geterr() == errors)
    loaded = sorted(m for m in sys.modules if m.split(".")[0] in ("cvxopt", "mkl"))
    print("modules:", loaded)
    native = ("libmkl", "libiomp", "libopenblas")  # MKL, its OpenMP runtime, cvxopt's BLAS
    print("libraries:", sorted(x for x in mapped() - libs if x.startswith(native)))
    """
)


def _python(code: str, *args: str) -> list[str]:
    """The lines ``python -c code args`` prints (the package found as this test's is)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OPENBLAS_", "KMP_"))}
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [root, env.get("PYTHONPATH")]))
    # generous: CI runs these beside the rest of the suite
    run = subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=600, env=env
    )
    assert run.returncode == 0, run.stderr[-3000:]
    return run.stdout.splitlines()


def test_import_changes_nothing_process_wide_and_loads_no_sparse_backend():
    """No environment variable written (not even for a moment), no JAX flag, warning filter or
    NumPy error mode changed, no library loaded through ctypes (MKL, its OpenMP runtime, the C
    library for malloc's settings), cvxopt not imported: the sparse backends load on the first
    sparse solve."""
    out = dict(line.split(": ", 1) for line in _python(IMPORT_SCRIPT))
    assert out["events"] == "[]"
    assert out["environment"] == "True"
    assert out["jax config"] == "True"
    assert out["warnings"] == "True"
    assert out["numpy errors"] == "True"
    assert out["modules"] == "[]"
    assert out["libraries"] == "[]"


# a PARDISO solve (MKL, where installed), then the OpenMP wait time of the solving thread
BLOCKTIME_SCRIPT = textwrap.dedent(
    """
    import ctypes, os, sys
    import numpy as np
    import scipy.sparse as sp
    import origami_jax
    from origami_jax.solvers import hostsparse

    if "pardiso" not in hostsparse.available() or not hasattr(os, "RTLD_NOLOAD"):
        print("skip")
        sys.exit()
    if sys.argv[1] == "tuned":
        print(origami_jax.tune_process(malloc=False, openblas_kernels=False)["mkl_blocktime"])
    m = sp.random(40, 40, density=0.1, random_state=4)
    upper = sp.triu(m @ m.T + 2 * sp.eye(40)).tocsr()
    upper.sort_indices()
    with hostsparse.using("pardiso"):
        print(hostsparse.solve(upper.indptr, upper.indices, upper.data, np.ones(40))[1])
    for name in ("libiomp5.so", "libiomp5.dylib"):
        try:
            print(ctypes.CDLL(name, mode=os.RTLD_NOLOAD).kmp_get_blocktime())
            break
        except OSError:
            continue
    else:
        print("skip")
    """
)


def test_mkl_threads_spin_as_usual_unless_tuned():
    """A PARDISO solve leaves the OpenMP wait time (which every library on Intel's OpenMP
    runtime shares) at its default; after ``tune_process()`` the solving thread's is 0."""
    plain = _python(BLOCKTIME_SCRIPT, "plain")
    if plain[-1] == "skip":
        pytest.skip("needs MKL's PARDISO and Intel's OpenMP runtime")
    assert plain[0] == "True" and int(plain[1]) > 0
    assert _python(BLOCKTIME_SCRIPT, "tuned") == ["True", "True", "0"]


# JAX's CPU LAPACK calls scipy's OpenBLAS: its thread count before and after tuning
BLAS_SCRIPT = textwrap.dedent(
    """
    import ctypes, os, sys
    import scipy.linalg.cython_lapack
    import origami_jax

    def counts():
        with open("/proc/self/maps") as f:
            paths = {line.split()[-1] for line in f if "openblas" in line.lower()}
        out = []
        for path in sorted(p for p in paths if ".so" in p):
            lib = ctypes.CDLL(path)
            get = getattr(lib, "scipy_openblas_get_num_threads", None) or getattr(
                lib, "scipy_openblas_get_num_threads64_", None)
            if get is not None:
                out.append(get())
        return out

    if not os.path.exists("/proc/self/maps"):
        print("skip")
        sys.exit()
    before = counts()
    print(before)
    if sys.argv[1] == "tuned":
        print(origami_jax.tune_process(malloc=False, openblas_kernels=False, mkl_blocktime=False))
    print(counts())
    """
)


def test_blas_threads_are_left_alone_unless_tuned():
    """Importing the package leaves OpenBLAS's thread count as it found it; ``tune_process()``
    sets every loaded copy (scipy's, which JAX's LAPACK calls, among them) to one thread."""
    plain = _python(BLAS_SCRIPT, "plain")
    if plain[0] == "skip":
        pytest.skip("needs /proc/self/maps (Linux)")
    assert plain[0] == plain[1] and plain[0] != "[]"
    tuned = _python(BLAS_SCRIPT, "tuned")
    assert "'blas_threads': True" in tuned[1]
    assert set(eval(tuned[2])) == {1}
