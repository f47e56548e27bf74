"""Memory: the process-wide malloc setting that large sheets run faster with, and a long
sparse solve whose memory stays flat."""

import ctypes
import ctypes.util
import os
import platform

import pytest

from origami_jax import patterns
from origami_jax.energy import make_params, make_structure
from origami_jax.fold import compiled, drive
from origami_jax.memory import keep_freed_memory
from origami_jax.solvers import Newton, hostsparse
from origami_jax.solvers.base import make_problem, prepare


def _glibc() -> bool:
    try:
        ctypes.CDLL(ctypes.util.find_library("c")).gnu_get_libc_version  # noqa: B018
    except (OSError, AttributeError, TypeError):
        return False
    return platform.system() == "Linux"


def test_keep_freed_memory_takes_on_glibc_and_refuses_a_bad_threshold():
    assert keep_freed_memory() is _glibc()
    assert keep_freed_memory(64 * 2**20) is _glibc()  # again, another value: fine
    with pytest.raises(ValueError, match="threshold must be positive, got 0"):
        keep_freed_memory(0)


def _resident_bytes() -> int:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    raise RuntimeError("no VmRSS in /proc/self/status")


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="reads Linux's /proc")
@pytest.mark.parametrize("backend", ("pardiso", "cholmod", "superlu"))
def test_a_long_sparse_newton_solve_keeps_its_memory_flat(backend):
    """Every iteration of a sparse Newton solve factors on the host and solves twice with that
    factorization (the step, then geodesic acceleration), in two host callbacks. From the 50th
    iteration of a solve of some 680 (a Miura-ori 14 x 14, its steps kept short by
    ``max_turn``) to its end, resident memory grows by less than 50 kB an iteration: SuperLU's
    kept factorizations used to leak whole there, about 0.5 MB an iteration (scipy frees them
    only in the Python thread state that made them; JAX runs each callback in a fresh one)."""
    if backend not in hostsparse.available():
        pytest.skip(f"{backend} is not installed")
    cp = patterns.miura_ori(14, 14)
    mesh = cp.mesh
    solver = Newton(linear_solver="sparse", max_turn=0.0015)
    problem = make_problem(mesh, make_structure(mesh), make_params(cp), None, 1e-9)
    problem = prepare(solver, problem, mesh)
    (start, advance), _ = compiled(solver, problem, mesh.num_edges)
    samples = []
    with hostsparse.using(backend):
        drive(solver, start, advance, problem, 800, None, 50,
              lambda iterations, _: samples.append((iterations, _resident_bytes())))  # fmt: skip
    (first, at_first), (last, at_last) = samples[0], samples[-1]
    assert first == 50 and last > 500, samples  # a long solve, sampled every 50 iterations
    per_iteration = (at_last - at_first) / (last - first)
    assert per_iteration < 50e3, f"{per_iteration / 1e3:.0f} kB an iteration: {samples}"
    assert not hostsparse._KEPT
