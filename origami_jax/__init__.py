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
bounded number; :func:`clear_caches` empties the caches.
"""

from origami_jax import patterns
from origami_jax.batch import fold_batch
from origami_jax.caches import clear_caches
from origami_jax.energy import Barriers, FoldParams, Stiffness, build_energy, energy
from origami_jax.fold import FoldResult, Frame, fold
from origami_jax.io import from_fold_dict, load, save, to_fold_dict
from origami_jax.pattern import ASSIGNMENTS, CreasePattern, Mesh, PatternError, PatternWarning
from origami_jax.tuning import tune_process

__all__ = [
    "ASSIGNMENTS",
    "CreasePattern",
    "Mesh",
    "PatternError",
    "PatternWarning",
    "FoldParams",
    "Stiffness",
    "Barriers",
    "build_energy",
    "energy",
    "FoldResult",
    "Frame",
    "fold",
    "fold_batch",
    "load",
    "save",
    "from_fold_dict",
    "to_fold_dict",
    "patterns",
    "clear_caches",
    "tune_process",
]
__version__ = "0.1.0"
