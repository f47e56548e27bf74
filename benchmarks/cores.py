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


def cpu_name() -> str:
    """The CPU's model as the OS names it (with its family and model numbers on Linux): the
    same 2-core machine has come with different CPUs from day to day, so reports name it."""
    try:
        with open("/proc/cpuinfo") as f:
            info = dict(
                (k.strip(), v.strip()) for k, _, v in (line.partition(":") for line in f) if v
            )
        return f"{info['model name']} (family {info['cpu family']}, model {info['model']})"
    except (OSError, KeyError):
        import platform

        return platform.processor() or platform.machine()
