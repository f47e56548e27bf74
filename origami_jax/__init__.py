"""origami_jax: a differentiable origami simulator in JAX.

Fold a crease pattern by minimising the bar-and-hinge energy of the seed paper (linear springs on
every edge, atan2-dihedral torsion springs on every crease):

    >>> import origami_jax as oj
    >>> result = oj.fold(oj.patterns.seed_waterbomb())      # doctest: +SKIP
    >>> print(result.summary())                             # doctest: +SKIP

Importing the package changes no global JAX setting; enable float64 yourself with
``jax.config.update("jax_enable_x64", True)`` when you need it. Nor does it change an
environment variable, a thread or an allocator setting, or load a sparse backend (on the first
sparse solve): the process-wide settings that make large sheets faster are opt-ins,
:func:`tune_process` (see :mod:`origami_jax.tuning`). Compiled solves are cached per shape, a
bounded number; :func:`clear_caches` empties the caches. :func:`use_compilation_cache` keeps
compiled code on disk for the next process (an opt-in: it sets JAX's configuration).

The public names below load on first use (JAX with them), so ``import origami_jax`` is cheap
and the command line answers ``--help`` without importing JAX.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover  (what the lazy names are, for type checkers and IDEs)
    from origami_jax import patterns  # noqa: F401
    from origami_jax.batch import fold_batch  # noqa: F401
    from origami_jax.caches import clear_caches, use_compilation_cache  # noqa: F401
    from origami_jax.energy import Barriers, FoldParams, Stiffness, build_energy, energy  # noqa: F401
    from origami_jax.fold import FoldResult, Frame, fold  # noqa: F401
    from origami_jax.io import from_fold_dict, load, save, to_fold_dict  # noqa: F401
    from origami_jax.pattern import (  # noqa: F401
        ASSIGNMENTS,
        CreasePattern,
        Mesh,
        PatternError,
        PatternWarning,
    )
    from origami_jax.tuning import tune_process  # noqa: F401
    from origami_jax.warmup import warmup  # noqa: F401

# public name -> the module that defines it (None: the name is a submodule)
_LAZY: dict[str, str | None] = {
    "ASSIGNMENTS": "origami_jax.pattern",
    "CreasePattern": "origami_jax.pattern",
    "Mesh": "origami_jax.pattern",
    "PatternError": "origami_jax.pattern",
    "PatternWarning": "origami_jax.pattern",
    "FoldParams": "origami_jax.energy",
    "Stiffness": "origami_jax.energy",
    "Barriers": "origami_jax.energy",
    "build_energy": "origami_jax.energy",
    "energy": "origami_jax.energy",
    "FoldResult": "origami_jax.fold",
    "Frame": "origami_jax.fold",
    "fold": "origami_jax.fold",
    "fold_batch": "origami_jax.batch",
    "load": "origami_jax.io",
    "save": "origami_jax.io",
    "from_fold_dict": "origami_jax.io",
    "to_fold_dict": "origami_jax.io",
    "patterns": None,
    "clear_caches": "origami_jax.caches",
    "use_compilation_cache": "origami_jax.caches",
    "tune_process": "origami_jax.tuning",
    "warmup": "origami_jax.warmup",
}
__all__ = list(_LAZY)


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("origami-jax")
    except PackageNotFoundError:  # a source tree on sys.path, not installed
        return "0+unknown"


def __getattr__(name: str) -> Any:
    if name == "__version__":
        value: Any = _version()
    elif name in _LAZY:
        module = _LAZY[name]
        if module is None:
            value = importlib.import_module(f"{__name__}.{name}")
        else:
            value = getattr(importlib.import_module(module), name)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__, "__version__"})


class _Package(types.ModuleType):
    """The package module: ``fold`` and ``energy`` name both a submodule and the function the
    package exports; importing the submodule binds it on the package, and the function must win
    (``origami_jax.fold(pattern)``), so that binding is skipped."""

    def __setattr__(self, name: str, value: Any) -> None:
        if isinstance(value, types.ModuleType) and _LAZY.get(name) is not None:
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
