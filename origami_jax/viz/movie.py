"""Animations: the fold from flat to folded by continuation, written as a GIF (pillow) or
an MP4 (ffmpeg)."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from origami_jax.fold import FoldResult
from origami_jax.io.fold import atomic_path
from origami_jax.pattern import CreasePattern
from origami_jax.viz.colors import COLOR_LABELS, face_values, mesh_positions
from origami_jax.viz.extras import require
from origami_jax.viz.figures import colour_bar, draw_fold, frame, setup_3d
from origami_jax.viz.views import camera

__all__ = ["fold_frames", "movie_settings", "animate_fold"]


def fold_frames(
    pattern: CreasePattern,
    frames: int = 30,
    solver: str = "newton",
    percent: float = 1.0,
    **fold_kwargs: Any,
) -> list[FoldResult]:
    """The fold at percents ``linspace(0, percent, frames)`` by continuation: each frame is
    ``fold(pattern, percent=p, start=previous positions)`` (the first from flat), so every frame
    reuses one compiled solver and starts near its answer.

    Returns:
      One :class:`~origami_jax.FoldResult` per frame (the first is the flat sheet).

    Example:
      >>> results = fold_frames(oj.patterns.miura_ori(3, 3), frames=10)   # doctest: +SKIP
      >>> [r.converged for r in results]                                  # doctest: +SKIP
    """
    from origami_jax.fold import fold

    if int(frames) < 2:
        raise ValueError(f"frames: need at least 2, got {frames}")
    out: list[FoldResult] = []
    start = pattern.mesh.vertices
    for p in np.linspace(0.0, percent, int(frames)):
        out.append(fold(pattern, percent=float(p), solver=solver, start=start, **fold_kwargs))
        start = out[-1].positions
    return out


def movie_settings(path: str | os.PathLike) -> dict[str, str]:
    """matplotlib settings a movie of ``path`` needs (.gif, .mp4: ffmpeg's), or a clear error."""
    require("matplotlib")
    from matplotlib import animation

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".gif":
        return {}
    if suffix != ".mp4":
        raise ValueError(f"{path}: unsupported animation format {path.suffix!r} (use .gif or .mp4)")
    if animation.writers.is_available("ffmpeg"):
        return {}
    try:
        import imageio_ffmpeg
    except ImportError:
        raise RuntimeError(
            f"{path}: writing MP4 needs ffmpeg: install it (e.g. apt install ffmpeg) or "
            "pip install imageio-ffmpeg; or write a .gif"
        ) from None
    return {"animation.ffmpeg_path": imageio_ffmpeg.get_ffmpeg_exe()}


@contextlib.contextmanager
def _writer(path: Path, fps: int):
    """A matplotlib movie writer for ``path``'s suffix (.gif: pillow, .mp4: ffmpeg)."""
    from matplotlib import animation, rc_context

    rc = movie_settings(path)
    if path.suffix.lower() == ".gif":
        yield animation.PillowWriter(fps=fps)
        return
    with rc_context(rc):  # the ffmpeg path for this save only
        # yuv420p (what players expect) needs even sizes: pad by a pixel where odd
        pad = ["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-pix_fmt", "yuv420p"]
        yield animation.FFMpegWriter(fps=fps, codec="h264", extra_args=pad)


def animate_fold(
    pattern: CreasePattern,
    path: str | os.PathLike,
    frames: int | Sequence[np.ndarray] = 30,
    fps: int = 15,
    solver: str = "newton",
    *,
    percent: float = 1.0,
    color: str | None = None,
    show_facets: bool = False,
    elev: float | None = None,
    azim: float | None = None,
    cmap: str = "viridis",
    dpi: int = 100,
    figsize: tuple[float, float] = (6.0, 5.0),
    proj_type: str = "ortho",
    hide_occluded: bool = True,
    **fold_kwargs: Any,
) -> list[np.ndarray]:
    """Animate the fold from flat to ``percent`` and write it to ``path`` (.gif or .mp4).

    Args:
      pattern: the crease pattern.
      path: ``.gif`` (pillow) or ``.mp4`` (ffmpeg: a system ``ffmpeg`` or the
        ``imageio-ffmpeg`` package); written atomically.
      frames: a number of frames, folded by continuation in fold percent (see
        :func:`fold_frames`, ``solver`` and ``fold_kwargs`` go to :func:`~origami_jax.fold`),
        or precomputed frames: results of :func:`fold_frames`, a fold's path
        (``fold(...).frames``, the states it followed from flat) or (V, 3) position arrays
        (e.g. a dynamics trajectory).
      fps: frames per second.
      color: ``None``, ``"strain"`` or ``"fold_angle_error"`` (against each frame's percent,
        one colour scale for all frames).
      elev, azim: camera angles in degrees; default: :func:`default_view` of the last frame.

    The camera frames the union of all frames (fixed limits), so the sheet never leaves it.

    Returns:
      The frames' mesh positions, a list of (V_mesh, 3) arrays.

    Example:
      >>> animate_fold(oj.patterns.miura_ori(4, 4), "miura.gif", frames=24)  # doctest: +SKIP
    """
    require("matplotlib")
    from matplotlib import colormaps
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    path = Path(path)
    if color is not None and color not in COLOR_LABELS:
        raise ValueError(f"color: expected 'strain' or 'fold_angle_error', got {color!r}")
    # the writer first: a missing ffmpeg fails before any folding
    with _writer(path, fps) as writer:
        if isinstance(frames, (int, np.integer)):
            frames = fold_frames(pattern, int(frames), solver, percent, **fold_kwargs)
        frames = list(frames)
        if not frames:
            raise ValueError("frames: empty")
        # results and a fold's path frames (``result.frames``) carry positions and a percent
        positions = [mesh_positions(getattr(f, "positions", f), pattern) for f in frames]
        percents = None  # known for results and path frames: titled by percent, else by number
        if all(hasattr(f, "percent") for f in frames):
            percents = np.array([f.percent for f in frames])
        values = None
        cm = colormaps[cmap]
        norm = None
        # a bare Figure (no pyplot): nothing to close, no window, any backend
        fig = Figure(figsize=figsize)
        ax = fig.add_subplot(projection="3d")
        fig.subplots_adjust(left=0, right=1 if color is None else 0.9, bottom=0, top=0.94)
        if color is not None:  # one colour scale for all frames
            pcts = percents if percents is not None else np.full(len(positions), percent)
            values = [
                face_values(x, color, pattern, p) for x, p in zip(positions, pcts, strict=True)
            ]
            top = max(float(np.max(v)) for v in values)
            norm = Normalize(0.0, top if top > 0 else 1.0)
            colour_bar(ax, norm, cm, COLOR_LABELS[color])
        everything = np.concatenate(positions)
        elev, azim = camera(positions[-1], elev, azim)
        with atomic_path(path) as tmp, writer.saving(fig, str(tmp), dpi):
            for k, x in enumerate(positions):
                ax.clear()
                setup_3d(ax, elev, azim, False, proj_type)
                v = None if values is None else values[k]
                draw_fold(ax, pattern, x, v, norm, cm, True, show_facets, elev, azim, hide_occluded)
                frame(ax, everything)
                if percents is None:
                    ax.set_title(f"{pattern.name}  frame {k + 1}/{len(positions)}")
                else:
                    ax.set_title(f"{pattern.name}  {100 * percents[k]:.0f} %")
                writer.grab_frame()
    return positions
