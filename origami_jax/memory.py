"""Keep freed memory in the process: large sheets run about a fifth faster.

A Newton iteration on a large sheet allocates tens of megabytes of fresh buffers (element
Hessians, the assembled matrix, the host factorization's copies), and each call of a compiled
solve one block for all its temporaries (about 9 kB per vertex of a Miura-ori: 0.9 GB at
100,000 vertices). glibc's ``malloc`` maps blocks above its mmap threshold (128 KiB to 32 MiB,
adapted as it goes) straight from the operating system and returns them on ``free``, so every
iteration pays the page faults of touching them again. :func:`keep_freed_memory` raises that
threshold (by default as far as ``mallopt`` goes, 2 GiB) and the heap's trim threshold, so freed
blocks stay in the heap and are reused.

The cost: the process keeps its peak heap instead of handing
freed memory back. A process-wide setting, so the library never makes it on its own: call it,
or :func:`origami_jax.tune_process`, which makes the other opt-ins of :mod:`origami_jax.tuning`
too (the command-line interface and the benchmarks do), or set ``MALLOC_MMAP_THRESHOLD_`` and
``MALLOC_TRIM_THRESHOLD_`` in the environment before Python starts.

Example:
  >>> from origami_jax.memory import keep_freed_memory
  >>> keep_freed_memory() in (True, False)  # False where the C library is not glibc
  True
"""

from __future__ import annotations

import ctypes
import ctypes.util

__all__ = ["keep_freed_memory"]

_M_TRIM_THRESHOLD = -1  # mallopt parameters, from glibc's malloc.h
_M_MMAP_THRESHOLD = -3


# the largest value mallopt takes (a C int): a 100,000-vertex sheet's compiled iteration
# allocates 0.9 GB of temporaries at once, which a 256 MiB threshold left to fresh mappings
_LARGEST = 2**31 - 1


def keep_freed_memory(threshold: int = _LARGEST) -> bool:
    """Let glibc's ``malloc`` serve blocks up to ``threshold`` bytes (at most 2 GiB) from its
    heap and keep up to twice that (at most 2 GiB) free at the heap's top, instead of mapping and
    unmapping them from the system (see the module docstring). Returns whether the setting took
    (``False`` off glibc, e.g. macOS or musl). Calling it again sets them again (the last call's
    values hold)."""
    if threshold <= 0:
        raise ValueError(f"keep_freed_memory(): threshold must be positive, got {threshold}")
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError, TypeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    value = min(int(threshold), _LARGEST)  # an int for mallopt; glibc keeps it as size_t
    ok = mallopt(_M_MMAP_THRESHOLD, value) == 1
    return ok and mallopt(_M_TRIM_THRESHOLD, min(2 * value, _LARGEST)) == 1
