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


# JAX CPU devices per core for fold_batch. A device runs its slots' kernels one after another
# on about one core and now and then waits (between kernels, for the host): with one device per
# core 1.66-1.74 of this machine's 2 cores were busy, with two 1.77-1.86, and fold_batch folded
# more in each of 21 rounds alternating in one process (the waterbomb set's medians +12 to
# +16 %; 2026-12-06, docs/design-notes/batch.md).
DEVICES_PER_CORE = 2


def cpu_devices() -> int:
    """The JAX CPU devices the benchmarks make: :data:`DEVICES_PER_CORE` per usable core."""
    return DEVICES_PER_CORE * usable_cores()


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
