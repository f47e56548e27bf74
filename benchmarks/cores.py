"""The number of CPU cores this process may run on (its affinity, not the machine's count: a
container or ``taskset`` can allow fewer), for the benchmarks' device counts and reports."""

from __future__ import annotations

import os


def usable_cores() -> int:
    """Cores in this process's CPU affinity (``os.cpu_count()`` where that is unknown)."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1
