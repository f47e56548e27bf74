"""Compile the common size buckets ahead of time: :func:`warmup` (``origami-jax warmup``).

:func:`~origami_jax.fold.fold` pads a problem to a size bucket (:mod:`origami_jax.padding`), so
one compiled solve serves every pattern of that bucket. :func:`warmup` compiles those solves
before any pattern needs them, by folding a square's diagonal padded up to each bucket: with a
full fold along the path from flat (with the barriers: what real crease patterns mostly take),
partly folded directly (without barriers: rigid-foldable tessellations), and fully folded
directly (with barriers: a FOLD file given folded). With the
persistent cache on (:func:`origami_jax.caches.use_compilation_cache`, on by default in the
command line) that work is kept for every later process on this machine.

A bucket is named by its padded vertex count; the element counts are the bucket's least
(:func:`~origami_jax.fold.bucket_floors`: for Newton those of any triangulated sheet of that
many vertices), so with Newton every sheet of one piece without free hinges falls in a warmed
bucket. Sheets with free hinges or several pieces, other solvers' sheets beyond the floors,
Newton's sparse solves (above its ``dense_max``, 200 vertices) and folds with self-contact
still compile on first use.

Example:
  >>> import origami_jax as oj
  >>> oj.use_compilation_cache()          # doctest: +SKIP
  >>> oj.warmup(max_vertices=60)          # doctest: +SKIP
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence

import numpy as np

from origami_jax.energy import NO_BARRIERS, Barriers
from origami_jax.fold import BUCKETS_PER_OCTAVE, bucket_floors, fold, padded_at_least
from origami_jax.padding import PAD_VERTICES, floor_sizes, round_up
from origami_jax.pattern import CreasePattern
from origami_jax.solvers import get_solver

__all__ = ["warmup", "vertex_buckets"]

# "continuation": a full fold along the path from flat, with barriers (most crease patterns);
# "direct": a partial fold without barriers (rigid-foldable tessellations); "direct-barriers":
# a full fold solved directly, with barriers (a FOLD file given folded, a start of one's own)
PATHS = ("continuation", "direct", "direct-barriers")


def _diagonal(fold_angle: float) -> CreasePattern:
    """A unit square folded along a diagonal: the smallest sheet (4 vertices, bucket 8)."""
    return CreasePattern(
        vertices=np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]),
        edges=np.array([[0, 1], [1, 2], [2, 0], [2, 3], [3, 0]]),
        faces=[(0, 1, 2), (0, 2, 3)],
        assignments="BBVBB",
        fold_angles=np.array([0.0, 0.0, fold_angle, 0.0, 0.0]),
        name="diagonal",
    )


def vertex_buckets(max_vertices: int) -> list[int]:
    """The padded vertex counts of the buckets that sheets of 4 to ``max_vertices`` vertices
    fall in (each with room for the padding's four vertices)."""
    top = round_up(int(max_vertices) + len(PAD_VERTICES), BUCKETS_PER_OCTAVE)
    first = round_up(2 * len(PAD_VERTICES), BUCKETS_PER_OCTAVE)
    out = {round_up(n, BUCKETS_PER_OCTAVE) for n in range(first, top + 1)}
    return sorted(out)


def warmup(
    max_vertices: int = 200,
    dtype=None,
    solver: str = "newton",
    paths: Sequence[str] = PATHS,
    buckets: Sequence[int] | None = None,
    progress: bool = False,
) -> dict[tuple[int, str], float]:
    """Compile :func:`~origami_jax.fold.fold`'s solves for the size buckets of sheets up to
    ``max_vertices`` vertices (or the padded vertex counts ``buckets``), for ``paths``
    (:data:`PATHS`: ``"continuation"``, full folds along the path from flat, with barriers;
    ``"direct"``, direct solves without barriers; ``"direct-barriers"``, direct solves with
    them, as a FOLD file given folded takes), in ``dtype`` (default JAX's default float) with
    ``solver``. Returns the compile time (seconds; 0 where it was compiled already) of each
    (bucket, path). ``progress``: a line per bucket on stderr."""
    if BUCKETS_PER_OCTAVE <= 0:
        raise ValueError("warmup: fold pads to no buckets (fold.BUCKETS_PER_OCTAVE is 0)")
    for path in paths:
        if path not in PATHS:
            raise ValueError(f"warmup: a path is one of {', '.join(PATHS)}, got {path!r}")
    if buckets is None:
        buckets = vertex_buckets(max_vertices)
    floors = bucket_floors(get_solver(solver))
    out = {}
    for n in buckets:
        if int(n) < 2 * len(PAD_VERTICES):
            raise ValueError(f"warmup: a bucket has at least 8 vertices, got {n}")
        for path in paths:
            full = path != "direct"
            barriers = Barriers() if full else NO_BARRIERS
            least = floor_sizes(n, floors, barriers)
            crease = _diagonal(np.pi if full else 1.0)
            how = "continuation" if path == "continuation" else "direct"
            t = time.perf_counter()
            with padded_at_least(least):
                result = fold(crease, solver=solver, dtype=dtype, path=how, barriers=full)
            out[(int(n), path)] = result.compile_time
            if progress:
                print(
                    f"bucket {n:4d} vertices, {path:12s}: {time.perf_counter() - t:6.1f} s",
                    file=sys.stderr,
                    flush=True,
                )
    return out
