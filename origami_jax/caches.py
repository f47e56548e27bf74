"""The package's in-process caches: bounded, and all cleared by :func:`clear_caches`.

``fold`` and ``fold_batch`` keep what they compiled (solves, per shape), Newton keeps each
mesh's Hessian layout, the host's sparse solver each pattern's analysis: a second call on the
same shapes starts at once. Each cache keeps only its most recently used entries
(:class:`LruCache`), so a long-running process that folds many shapes does not grow without
bound; :func:`clear_caches` drops everything (the next call of each shape compiles again).

Example:
  >>> import origami_jax
  >>> origami_jax.clear_caches()
"""

from __future__ import annotations

import threading
import weakref
from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterator, MutableMapping
from typing import Any

__all__ = ["DEFAULT_SIZE", "LruCache", "clear_caches", "on_clear"]

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
