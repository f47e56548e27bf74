"""The process-wide malloc setting that large sheets run faster with."""

import ctypes
import ctypes.util
import platform

import pytest

from origami_jax.memory import keep_freed_memory


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
