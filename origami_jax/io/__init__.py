"""Reading and writing patterns and results.

* :func:`load` reads a crease pattern: ``.fold`` / ``.json`` (FOLD 1.2, see
  :mod:`origami_jax.io.fold`) or ``.svg`` (Origami Simulator's conventions, see
  :mod:`origami_jax.io.svg`).
* :func:`save` writes a pattern or a simulation result: ``.fold`` / ``.json`` (FOLD, the pattern
  plus the folded state), ``.svg`` (the crease pattern, Origami Simulator's colours),
  ``.obj``, ``.ply``, ``.stl``, ``.vtu`` (the triangle mesh, see
  :mod:`origami_jax.io.mesh`). Every file is written atomically.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from origami_jax.io.fold import from_fold_dict, load_fold, save_fold, to_fold_dict
from origami_jax.io.mesh import MESH_FORMATS, save_mesh
from origami_jax.io.planar import pattern_from_segments
from origami_jax.io.svg import load_svg, save_svg, to_svg
from origami_jax.pattern import CreasePattern, PatternError

__all__ = [
    "load",
    "save",
    "from_fold_dict",
    "to_fold_dict",
    "load_fold",
    "load_svg",
    "save_svg",
    "to_svg",
    "pattern_from_segments",
    "save_fold",
    "save_mesh",
    "INPUT_FORMATS",
    "OUTPUT_FORMATS",
]

INPUT_FORMATS = (".fold", ".json", ".svg")
OUTPUT_FORMATS = (".fold", ".json", ".svg", *MESH_FORMATS)


def _shown(suffix: str) -> str:
    return f"'{suffix}'" if suffix else "(no suffix)"


def load(path: str | os.PathLike) -> CreasePattern:
    """The crease pattern in a file, by suffix: ``.fold`` or ``.json`` (FOLD), ``.svg``.

    Raises:
      PatternError: an unsupported suffix, a missing or unreadable file (the message names the
        path), or an invalid pattern.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in INPUT_FORMATS:
        raise PatternError(
            f"{path}: unsupported input format {_shown(path.suffix)} "
            f"(supported: {', '.join(INPUT_FORMATS)})"
        )
    if suffix == ".svg":
        return load_svg(path)
    return load_fold(path)


def save(path: str | os.PathLike, obj: Any) -> None:
    """Write a crease pattern or a simulation result, by suffix, atomically.

    ``.fold`` / ``.json``: :func:`save_fold`; ``.svg``: :func:`save_svg`; ``.obj``, ``.ply``,
    ``.stl``, ``.vtu``: :func:`save_mesh`.

    Raises:
      ValueError: an unsupported suffix (the message lists the supported ones).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".fold", ".json"):
        save_fold(path, obj)
    elif suffix == ".svg":
        save_svg(path, obj)
    elif suffix in MESH_FORMATS:
        save_mesh(path, obj)
    else:
        raise ValueError(
            f"{path}: unsupported output format {_shown(path.suffix)} "
            f"(supported: {', '.join(OUTPUT_FORMATS)})"
        )
