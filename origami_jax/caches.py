"""The package's in-process caches: bounded, and all cleared by :func:`clear_caches`.

``fold`` and ``fold_batch`` keep what they compiled (solves, per shape), Newton keeps each
mesh's Hessian layout, the host's sparse solver each pattern's analysis: a second call on the
same shapes starts at once. Each cache keeps only its most recently used entries
(:class:`LruCache`), so a long-running process that folds many shapes does not grow without
bound; :func:`clear_caches` drops everything (the next call of each shape compiles again).

Across processes, compiled code can be kept on disk in JAX's persistent compilation cache:
:func:`use_compilation_cache` is the one-line opt-in (the command line has it on by default).
A fresh process then loads a pattern's solve instead of compiling it again.

Example:
  >>> import origami_jax
  >>> origami_jax.clear_caches()
  >>> origami_jax.use_compilation_cache()  # doctest: +SKIP
"""

from __future__ import annotations

import hashlib
import os
import platform
import threading
import weakref
from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterator, MutableMapping
from pathlib import Path
from typing import Any

__all__ = [
    "DEFAULT_SIZE",
    "LruCache",
    "clear_caches",
    "on_clear",
    "cache_folder",
    "use_compilation_cache",
    "exported_folder",
]

DEFAULT_SIZE = 32  # entries a cache keeps: a compiled solve each, some megabytes

# by reference (equal contents are not the same cache); a cache that is collected drops out
_CACHES: weakref.WeakValueDictionary[int, LruCache] = weakref.WeakValueDictionary()
_CLEARERS: list[Callable[[], None]] = []


class LruCache(MutableMapping):
    """A mapping that keeps its ``maxsize`` most recently used entries (read or written), and
    is cleared by :func:`clear_caches`. Thread-safe for single operations."""

    def __init__(self, maxsize: int = DEFAULT_SIZE):
        if maxsize < 1:
            raise ValueError(f"LruCache: maxsize must be at least 1, got {maxsize}")
        self.maxsize = int(maxsize)
        self._data: OrderedDict[Hashable, Any] = OrderedDict()
        self._lock = threading.Lock()
        _CACHES[id(self)] = self

    def __getitem__(self, key: Hashable) -> Any:
        with self._lock:
            value = self._data[key]
            self._data.move_to_end(key)
            return value

    def __setitem__(self, key: Hashable, value: Any) -> None:
        with self._lock:
            self._data[key] = value
            self._data.move_to_end(key)
            while len(self._data) > self.maxsize:
                self._data.popitem(last=False)

    def __delitem__(self, key: Hashable) -> None:
        with self._lock:
            del self._data[key]

    def __iter__(self) -> Iterator[Hashable]:
        with self._lock:
            return iter(list(self._data))

    def __len__(self) -> int:
        return len(self._data)

    def clear(self) -> None:
        with self._lock:
            self._data.clear()

    def __repr__(self) -> str:
        return f"LruCache({len(self)} of {self.maxsize})"


def on_clear(clear: Callable[[], None]) -> Callable[[], None]:
    """Register ``clear`` (no arguments) to be called by :func:`clear_caches`: for a cache that
    is not an :class:`LruCache`. Returns it (usable as a decorator)."""
    _CLEARERS.append(clear)
    return clear


def clear_caches() -> None:
    """Empty every cache of the package: compiled solves, Hessian layouts, sparse analyses (a
    factorization kept for a solve in progress stays valid). JAX's own caches are left alone:
    they belong to the whole process (``jax.clear_caches()`` clears them)."""
    for cache in list(_CACHES.values()):
        cache.clear()
    for clear in list(_CLEARERS):
        clear()


# -- JAX's persistent compilation cache ------------------------------------------------------


def _machine_key() -> str:
    """A short hash of this machine's CPU model and features (XLA compiles for them)."""
    text = platform.machine() + platform.processor()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            text += "".join(
                line for line in f if line.startswith(("flags", "model name", "Features"))
            )[:100_000]
    except OSError:
        pass
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def cache_folder() -> Path:
    """The per-user folder of compiled code: ``$XDG_CACHE_HOME/origami_jax/<machine>``
    (``~/.cache/origami_jax/<machine>`` without ``XDG_CACHE_HOME``), one folder per CPU kind,
    so code compiled for other CPU features is never loaded."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "origami_jax" / _machine_key()


def use_compilation_cache(
    path: str | os.PathLike | None = None, min_compile_time: float = 0.0
) -> Path:
    """Keep compiled code on disk, in JAX's persistent compilation cache: a fresh process
    that folds a pattern of shapes folded before loads the solve instead of compiling it. The
    solves' traced programs are kept there too (:mod:`origami_jax.exported`), so that process
    does not trace them again either.

    This changes JAX's configuration for the whole process (``jax_compilation_cache_dir`` and
    ``jax_persistent_cache_min_compile_time_secs``): it is what the command line does, and an
    opt-in for the library. It takes effect for what is compiled after it.

    Args:
      path: the folder (created when first written); default :func:`cache_folder`.
      min_compile_time: programs that compiled faster than this (seconds) are not kept; 0
        keeps every one (a fold also compiles small programs, and together they take seconds).

    Returns:
      The folder.

    XLA (jaxlib 0.10) may log a line per loaded program that the CPU features it was compiled
    for differ from the host's (``cpu_aot_loader``): a known false alarm on the same machine.
    The command line hides it (``TF_CPP_MIN_LOG_LEVEL=3`` unless set).
    """
    import jax

    if min_compile_time < 0 or min_compile_time != min_compile_time:
        raise ValueError(f"min_compile_time: must be >= 0, got {min_compile_time}")
    global _EXPORTED
    folder = Path(path) if path is not None else cache_folder()
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_time))
    _EXPORTED = folder / "exported"
    return folder


_EXPORTED: Path | None = None


def exported_folder() -> Path | None:
    """Where solves are kept as exported programs (:mod:`origami_jax.exported`): a folder of
    the compilation cache once :func:`use_compilation_cache` was called, else ``None``."""
    return _EXPORTED
