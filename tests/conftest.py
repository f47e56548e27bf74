"""Tests run in float64 (float32 is asked for explicitly where tested)."""

import os
import shutil
import tempfile
from pathlib import Path

# Compilation dominates the suite's time and its patterns are small: skip XLA's expensive CPU
# optimisations and its newer fusion emitters (together about half the compile time on a 3 x 3
# Miura-ori; the tests' runs are short anyway).
# tests/test_optimised.py runs some modules again as users run them: XLA's defaults
if not os.environ.get("ORIGAMI_JAX_TEST_XLA_DEFAULTS"):
    os.environ["XLA_FLAGS"] = (
        os.environ.get("XLA_FLAGS", "")
        + " --xla_backend_optimization_level=0 --xla_llvm_disable_expensive_passes=true"
        + " --xla_cpu_use_fusion_emitters=false"
    ).strip()

# One compilation cache for the whole run, set before pytest-xdist starts its workers and
# inherited by them and by the notebooks' kernels: a program compiled by one test (a solver
# for the seed's scene, say) is read back, not compiled again, by the next process that needs it.
# Made by the process that starts the run (the workers inherit it), which removes it at the end.
_CACHE_DIR = None
if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
    _CACHE_DIR = os.environ["JAX_COMPILATION_CACHE_DIR"] = tempfile.mkdtemp(
        prefix="origami-jax-jit-"
    )
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")

# One BLAS thread per worker: pytest-xdist runs a worker per core, and OpenBLAS's threads spin
# while they wait, so two workers' dense Cholesky factorizations on two cores ran 100x slower
# (a waterbomb's Newton iteration: 4 ms alone, 690 ms beside another busy process).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402
import pytest  # noqa: E402

jax.config.update("jax_enable_x64", True)

SHARED = Path(__file__).resolve().parents[2] / "shared"


@pytest.fixture(scope="session")
def shared_patterns() -> Path:
    """../shared/patterns beside the repository; tests using it skip cleanly when absent."""
    path = SHARED / "patterns"
    if not path.is_dir():
        pytest.skip("../shared/patterns is not present")
    return path


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Under pytest-xdist (``--dist loadgroup``, set in pyproject.toml) each test module runs
    on one worker, so the solvers compiled for its patterns and its module fixtures are shared
    by its tests; the notebooks, each compiling in its own kernel, spread over the workers.
    The stability tests run once, at XLA's defaults, where test_optimised.py is collected."""
    stems = {item.path.stem for item in items}
    if {"test_optimised", "test_stability"} <= stems and not os.environ.get(
        "ORIGAMI_JAX_TEST_XLA_DEFAULTS"
    ):
        # tests/test_optimised.py runs test_stability.py at XLA's defaults: not here as well
        dropped = [item for item in items if item.path.stem == "test_stability"]
        items[:] = [item for item in items if item.path.stem != "test_stability"]
        config.hook.pytest_deselected(items=dropped)
    for item in items:
        if item.path.stem != "test_notebooks":
            item.add_marker(pytest.mark.xdist_group(item.path.stem))


def pytest_unconfigure(config):
    """The run's compilation cache is removed by the process that made it."""
    if _CACHE_DIR is not None:
        shutil.rmtree(_CACHE_DIR, ignore_errors=True)
