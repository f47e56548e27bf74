"""Compiled solves kept on disk as exported programs, so a fresh process skips tracing them.

JAX's persistent compilation cache (:func:`origami_jax.caches.use_compilation_cache`) saves
XLA's compilation, but a fresh process still traces and lowers each solve before it can look
the compiled code up: seconds for a Newton solve. With the cache on, :func:`compile_stored`
also keeps each solve's lowered program (``jax.export``, serialized) in the cache folder, keyed
by everything the program depends on: the function's name and settings, the arguments'
structure, shapes and dtypes, the package's source, JAX's version and the backend. A later
process deserializes it and compiles it, which the persistent cache answers.

A program that cannot be exported (one with host callbacks: sparse Newton's linear solves) is
compiled as usual; JAX's persistent cache does not keep it either, so it compiles in every new
process. A stored file that cannot be read is replaced.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import tempfile
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache
from pathlib import Path
from typing import Any

import jax

from origami_jax.caches import exported_folder

__all__ = ["LoweredProgram", "compile_all", "compile_stored", "compiler_options", "lower_stored"]

#: XLA options of every solve compiled for CPUs, per program (no process-wide flag): the CPU
#: backend's older loop emitters, which compile a Newton solve in 15 to 30 % less time than its
#: fusion emitters, and run it as fast (docs/design-notes/compile-time.md)
CPU_COMPILER_OPTIONS = {"xla_cpu_use_fusion_emitters": False}


def compiler_options(platform: str | None = None) -> dict:
    """The XLA options a solve is compiled with on ``platform`` (default: JAX's default
    backend): :data:`CPU_COMPILER_OPTIONS` on CPUs, none elsewhere."""
    platform = platform or jax.default_backend()
    return dict(CPU_COMPILER_OPTIONS) if platform == "cpu" else {}


@lru_cache(maxsize=1)
def _source_digest() -> str:
    """A hash of the package's source files: a stored program of older code is never used."""
    h = hashlib.sha256()
    package = Path(__file__).parent
    for path in sorted(package.rglob("*.py")):
        h.update(str(path.relative_to(package)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def _digest(key: Any, treedef, specs: list) -> str:
    import jaxlib

    text = repr(
        (
            key,
            str(treedef),
            [(s.shape, s.dtype.name) for s in specs],
            jax.__version__,
            jaxlib.__version__,
            jax.default_backend(),
            bool(jax.config.jax_enable_x64),
            _source_digest(),
        )
    )
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def _flat(fn: Callable, treedef, out: dict) -> Callable:
    """``fn`` on a flat list of leaves, returning a flat list; ``out["tree"]``: the output's
    structure, recorded while it is traced."""

    def flat(*leaves):
        result = fn(*jax.tree.unflatten(treedef, leaves))
        out["tree"] = jax.tree.structure(result)
        return jax.tree.leaves(result)

    return flat


def _write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)  # whole or not at all: another process may be reading it
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _read(path: Path):
    """``(exported, output treedef)`` stored at ``path``, or ``None``."""
    from jax import export

    try:
        out_tree, blob = pickle.loads(path.read_bytes())
        return export.deserialize(bytearray(blob)), out_tree
    except FileNotFoundError:
        return None
    except Exception:  # a damaged or foreign file: compiled again and replaced
        return None


class _Stored:
    """A compiled exported program, called with the original function's pytree arguments."""

    def __init__(self, compiled, out_tree, out_avals):
        self._compiled = compiled
        self._out_tree = out_tree
        self.out_info = self.info(out_tree, out_avals)

    @staticmethod
    def info(out_tree, out_avals):
        """As ``Compiled.out_info``: the outputs' shapes and dtypes."""
        return jax.tree.unflatten(
            out_tree, [jax.ShapeDtypeStruct(a.shape, a.dtype) for a in out_avals]
        )

    def __call__(self, *args):
        return jax.tree.unflatten(self._out_tree, self._compiled(*jax.tree.leaves(args)))


class LoweredProgram:
    """A program lowered by :func:`lower_stored`, not yet compiled: ``out_info`` its outputs'
    shapes and dtypes; :meth:`compile` gives the callable."""

    def __init__(self, lowered, out_info, wrap: Callable | None = None):
        self._lowered = lowered
        self.out_info = out_info
        self._wrap = wrap

    def compile(self) -> Callable:
        compiled = self._lowered.compile(compiler_options())
        return compiled if self._wrap is None else self._wrap(compiled)


def lower_stored(fn: Callable, args: tuple, key: Any, exportable: bool = True) -> LoweredProgram:
    """``fn`` lowered for ``args`` (arrays or ``jax.ShapeDtypeStruct``, any pytree), its program
    read from the cache folder where stored there (and stored there otherwise); its
    :meth:`LoweredProgram.compile` is called like ``fn``, with ``out_info`` (the outputs' shapes and
    dtypes, as ``jax.stages.Compiled`` has). ``key``: what else the program depends on (the
    function and its settings: hashable, with a ``repr`` that is the same in every process).
    ``exportable=False``: the program has host callbacks, which ``jax.export`` refuses: lowered
    as usual.

    Without a folder (:func:`origami_jax.caches.use_compilation_cache` not called) or not
    exportable, this is ``jax.jit(fn).lower(*args)``."""
    folder = exported_folder()
    if folder is None or not exportable:
        lowered = jax.jit(fn).lower(*args)
        return LoweredProgram(lowered, lowered.out_info)
    from jax import export

    leaves, treedef = jax.tree.flatten(args)
    specs = [jax.ShapeDtypeStruct(jax.numpy.shape(x), jax.numpy.result_type(x)) for x in leaves]
    path = folder / f"{_digest(key, treedef, specs)}.bin"
    stored = _read(path)
    if stored is None:
        out: dict = {}
        exported = export.export(jax.jit(_flat(fn, treedef, out)))(*specs)
        out_tree = out["tree"]
        _write(path, pickle.dumps((out_tree, bytes(exported.serialize()))))
    else:
        exported, out_tree = stored
    lowered = jax.jit(exported.call).lower(*specs)
    info = _Stored.info(out_tree, exported.out_avals)
    return LoweredProgram(lowered, info, lambda c: _Stored(c, out_tree, exported.out_avals))


def compile_stored(fn: Callable, args: tuple, key: Any, exportable: bool = True) -> Callable:
    """:func:`lower_stored` compiled."""
    return lower_stored(fn, args, key, exportable).compile()


def compile_all(programs: list[LoweredProgram]) -> list[Callable]:
    """Each of ``programs`` compiled, at the same time (XLA compiles outside Python's lock: two
    programs take about the longer one's time where two cores are free)."""
    if len(programs) < 2:
        return [p.compile() for p in programs]
    pool = ThreadPoolExecutor(max_workers=len(programs))
    try:
        return [f.result() for f in [pool.submit(p.compile) for p in programs]]
    finally:
        # an interrupt returns at once (a compilation under way ends in its thread)
        pool.shutdown(wait=False)
