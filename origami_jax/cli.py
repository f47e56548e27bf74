"""Command line: ``origami-jax fold INPUT|--example NAME --out OUT [options]``,
``origami-jax info INPUT`` (counts, pieces, holes, reading warnings, vertices that are not
flat-foldable; see :mod:`origami_jax.info`) and ``origami-jax render INPUT|--example NAME --out
fold.png|fold.html|fold.gif|fold.mp4`` (a picture, an interactive page or an animation of the
fold; see :mod:`origami_jax.viz`, needs ``pip install "origami-jax[viz]"``), and ``origami-jax
warmup [--max-vertices N]`` (compiles the common size buckets' solves into the cache ahead of
time; see :mod:`origami_jax.warmup`).

Arguments are checked when parsed (:func:`build_parser`, which imports neither JAX nor the
package's modules, so ``--help`` and ``--version`` answer at once; each command imports what it
needs). Runs in float64 unless ``--float32`` is given. ``fold`` and ``render`` keep compiled
code in the per-user persistent cache (:func:`origami_jax.caches.use_compilation_cache`:
``$XDG_CACHE_HOME/origami_jax/<machine>``, default ``~/.cache/origami_jax``, one folder per CPU
kind), so a later run on a pattern of the same shapes loads its solve instead of compiling it;
``--no-cache`` turns that off. Bad input prints one line ``error: ...`` and exits with code 2 (a bad
argument: argparse's usage line and ``error: argument ...``, also code 2).

The command (:func:`console_main`: the ``origami-jax`` script and ``python -m origami_jax``),
unlike the library, sets up its process: float64 (``jax_enable_x64``), the persistent cache
(with XLA's C++ log below fatal hidden, ``TF_CPP_MIN_LOG_LEVEL=3`` unless set: jaxlib 0.10
logs a false CPU-feature alarm for every program it loads from the cache), the tuning of
:func:`origami_jax.tuning.tune_process`, warnings printed on one line (``warning: ...``) and
matplotlib's non-interactive backend. :func:`main` runs a command in the
process as it finds it (float64, the default, then needs ``jax_enable_x64`` on).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import warnings
from collections.abc import Callable, Sequence
from typing import Any

EXAMPLES = (
    "seed_waterbomb",
    "miura_ori",
    "waterbomb",
    "yoshimura",
    "kresling",
    "square_twist",
    "single_crease",
    "degree4_vertex",
)
SEED_FINAL_ENERGY = 0.009519  # the seed's simulator, stopped by hand (anchors.md)


def _number(
    kind: type, what: str, low: float, high: float = math.inf, *, strict: bool = False
) -> Callable[[str], Any]:
    """An argparse ``type``: ``kind(text)`` in ``[low, high]`` (``(low, high]`` if ``strict``),
    else a clear error (argparse's usage line, ``error: argument --name: ...``, exit code 2)."""

    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            noun = "an integer" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"expected {noun}, got {text!r}") from None
        # written so that NaN fails: every comparison with it is false
        if not ((value > low if strict else value >= low) and value <= high):
            raise argparse.ArgumentTypeError(f"must be {what}, got {text}")
        return value

    return parse


def _scene_arguments(p: argparse.ArgumentParser, out_help: str) -> None:
    """The arguments ``fold`` and ``render`` share: what to fold, where to write it, how."""
    p.add_argument(
        "input", nargs="?", help="a .fold or .svg file (default: --example seed_waterbomb)"
    )
    p.add_argument(
        "--example",
        choices=EXAMPLES,
        metavar="NAME",  # the usage line stays short; the names are in the help
        help=f"fold a built-in pattern instead: {', '.join(EXAMPLES)}",
    )
    p.add_argument("--out", help=out_help)
    p.add_argument("--solver", default="newton", help="newton (default), lbfgs or dynamics")
    p.add_argument(
        "--percent",
        type=_number(float, "from 0 to 100", 0.0, 100.0),
        default=100.0,
        help="fold percent, 0 (flat) to 100 (every crease at its target angle; the default)",
    )
    p.add_argument(
        "--tol",
        type=_number(float, "a positive number", 0.0, strict=True),
        default=None,
        help="grad_norm_rel tolerance (default: 1e-10 in float64, 1e-4 in float32)",
    )
    p.add_argument(
        "--max-iter",
        type=_number(int, "0 or more", 0),
        default=100_000,
        help="iteration limit, per fold (default: 100000)",
    )
    p.add_argument(
        "--max-time",
        type=_number(float, "0 or more seconds", 0.0),
        default=None,
        help="time limit in seconds, per fold (default: none)",
    )
    p.add_argument("--float32", action="store_true", help="solve in float32 (default float64)")
    p.add_argument(
        "--stiffness",
        type=_stiffness_argument,
        metavar="A,F,C",
        help="spring constants AXIAL,FACET,CREASE (force units: energy per length; default "
        "1,0.02,0.001), or origami-simulator for Origami Simulator's (20,0.7,0.7)",
    )
    p.add_argument(
        "--contact",
        nargs="?",
        const=True,
        default=False,
        type=_number(float, "a positive length", 0.0, strict=True),
        metavar="DHAT",
        help="self-contact: faces kept apart by DHAT, pattern units (default without a value: "
        "1e-3 of the sheet's diameter)",
    )
    _cache_argument(
        p,
        "keep compiled code in the per-user persistent cache, so the next run of a pattern of "
        "the same shapes starts sooner (default: on; --no-cache: off)",
    )


def _stiffness_argument(text: str):
    """``--stiffness``: ``origami-simulator``, or (axial, facet, crease), axial positive and the
    others 0 or more (parsed without importing the package)."""
    if text == "origami-simulator":
        return text
    values = text.split(",")
    if len(values) != 3:
        raise argparse.ArgumentTypeError(
            f"expected AXIAL,FACET,CREASE or origami-simulator, got {text!r}"
        )
    axial = _number(float, "positive", 0.0, strict=True)(values[0].strip())
    rest = _number(float, "0 or more", 0.0)
    return (axial, rest(values[1].strip()), rest(values[2].strip()))


def _cache_argument(p: argparse.ArgumentParser, what: str) -> None:
    """``--cache`` / ``--no-cache`` (on by default): the persistent compilation cache."""
    p.add_argument("--cache", action=argparse.BooleanOptionalAction, default=True, help=what)


def build_parser() -> argparse.ArgumentParser:
    """The ``origami-jax`` argument parser; building it imports neither JAX nor the package's
    modules (``--help`` and ``--version`` answer at once)."""
    from origami_jax import __version__

    parser = argparse.ArgumentParser(
        prog="origami-jax", description="Fold crease patterns with a differentiable JAX solver."
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    f = sub.add_parser("fold", help="fold a crease pattern and write the folded state")
    _scene_arguments(
        f, "output file: .fold, .svg, .obj, .ply, .stl or .vtu (default: <name>-folded.fold)"
    )
    f.add_argument("--quiet", action="store_true", help="no progress bar")
    f.add_argument(
        "--path",
        choices=("auto", "direct", "continuation"),
        default="auto",
        help="follow the fold from flat (continuation) or solve directly; auto (default): "
        "from flat where a crease folds fully",
    )
    f.add_argument(
        "--barriers",
        choices=("auto", "on", "off"),
        default="auto",
        help="hinge and area barriers (no crease through itself, no collapsed triangle); "
        "auto (default): where a crease folds fully",
    )
    i = sub.add_parser("info", help="describe a crease pattern: counts, pieces, holes, checks")
    i.add_argument("input", help="a .fold or .svg file")
    r = sub.add_parser("render", help="fold a crease pattern and draw it (PNG, HTML, GIF, MP4)")
    _scene_arguments(
        r,
        ".png (3-D picture), .html (interactive, offline), .gif or .mp4 (the fold from flat;"
        " MP4 needs ffmpeg or imageio-ffmpeg) (default: <name>.png)",
    )
    r.add_argument(
        "--color",
        choices=("strain", "fold_angle_error", "contact_force"),
        help="colour the faces by this error (contact_force: with --contact)",
    )
    r.add_argument(
        "--frames",
        type=_number(int, "2 or more", 2),
        default=30,
        help="animation frames (default: 30)",
    )
    r.add_argument(
        "--fps",
        type=_number(int, "1 or more", 1),
        default=15,
        help="animation frames per second (15)",
    )
    r.add_argument(
        "--dpi",
        type=_number(int, "1 or more", 1),
        default=120,
        help="PNG / animation resolution (120)",
    )
    w = sub.add_parser(
        "warmup",
        help="compile the solves of the common size buckets ahead of time, into the cache",
    )
    w.add_argument(
        "--max-vertices",
        type=_number(int, "4 or more", 4),
        default=200,
        help="the largest sheet whose bucket is compiled (default: 200, Newton's dense limit)",
    )
    w.add_argument("--solver", default="newton", help="newton (default), lbfgs or dynamics")
    w.add_argument("--float32", action="store_true", help="compile for float32 (default float64)")
    _cache_argument(
        w,
        "keep what it compiles in the per-user persistent cache (default: on; without it the "
        "work is lost when the command ends)",
    )
    w.add_argument("--quiet", action="store_true", help="no line per bucket")
    return parser


def _solve_options(args: argparse.Namespace) -> dict[str, Any]:
    """The keyword arguments of :func:`~origami_jax.fold` that ``fold`` and ``render`` share."""
    import jax.numpy as jnp

    return dict(
        solver=args.solver,
        percent=args.percent / 100.0,
        tol=args.tol,
        max_iter=args.max_iter,
        max_time=args.max_time,
        dtype=jnp.float32 if args.float32 else jnp.float64,
        contact=args.contact,
    )


def _info(path: str) -> int:
    from origami_jax import PatternError, io
    from origami_jax.info import describe

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            pattern = io.load(path)
    except PatternError as exc:
        for w in caught:
            print(f"warning: {w.message}", file=sys.stderr)
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(describe(pattern, [str(w.message) for w in caught]).summary())
    return 0


def _load(args):
    """The pattern to fold and the stiffness to fold it with (None: the default)."""
    from origami_jax import io, patterns

    if args.input and args.example:
        raise ValueError("give an INPUT file or --example, not both")
    given = _stiffness(args.stiffness)
    if args.input:
        return io.load(args.input), given
    name = args.example or "seed_waterbomb"
    # the seed's scene folds with the seed's stiffness, so its energies compare with the seed's
    seed = patterns.SEED_WATERBOMB_STIFFNESS if name == "seed_waterbomb" else None
    return getattr(patterns, name)(), seed if given is None else given


def _stiffness(given):
    """The :class:`~origami_jax.energy.Stiffness` of ``--stiffness`` (None if not given)."""
    from origami_jax.energy import ORIGAMI_SIMULATOR_STIFFNESS, Stiffness

    if given is None:
        return None
    return ORIGAMI_SIMULATOR_STIFFNESS if given == "origami-simulator" else Stiffness(*given)


RENDER_FORMATS = (".png", ".html", ".gif", ".mp4")


def _render(args, pattern, stiffness) -> int:
    """``origami-jax render``: fold, then draw by the output's suffix, written atomically."""
    from pathlib import Path

    from origami_jax import viz
    from origami_jax.fold import fold
    from origami_jax.io.fold import atomic_path

    out = Path(args.out or f"{pattern.name}.png")
    suffix = out.suffix.lower()
    if suffix not in RENDER_FORMATS:  # before any work: nothing is written
        raise ValueError(
            f"{out}: unsupported render format {out.suffix!r} (use {', '.join(RENDER_FORMATS)})"
        )
    if not out.parent.is_dir():
        raise FileNotFoundError(f"{out}: the folder {out.parent} does not exist")
    if args.color == "contact_force" and (args.contact is False or suffix in (".gif", ".mp4")):
        raise ValueError(
            "--color contact_force: colours a picture (.png, .html) of a --contact fold"
        )
    # a missing extra or ffmpeg fails before the fold
    viz.require("plotly" if suffix == ".html" else "matplotlib")
    if suffix in (".gif", ".mp4"):
        viz.movie_settings(out)
    solve = dict(_solve_options(args), stiffness=stiffness)
    if suffix in (".gif", ".mp4"):
        frames = viz.fold_frames(pattern, args.frames, **solve)
        viz.animate_fold(pattern, out, frames, args.fps, color=args.color, dpi=args.dpi)
        result = frames[-1]
    else:
        result = fold(pattern, **solve)
        if suffix == ".html":
            viz.save_html(result, out, color=args.color)
        else:
            import matplotlib.pyplot as plt

            fig = viz.plot_fold(result, color=args.color)
            with atomic_path(out) as tmp:
                fig.savefig(tmp, dpi=args.dpi)
            plt.close(fig)
    print(result.summary())
    print(f"{'written':<20}  {out}")
    return 0 if result.converged else 1


def _show_warning(message, category, *rest, **kw) -> None:
    """Warnings on one line, like errors (the command's ``warnings.showwarning``)."""
    print(f"warning: {message}", file=sys.stderr)


def _set_up_process(args: argparse.Namespace) -> None:
    """The command's process-wide settings (see the module docstring); before any solve."""
    float32 = getattr(args, "float32", False)
    if getattr(args, "cache", False):  # read when XLA loads, so before JAX's first import
        os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")
    if not float32:
        os.environ.setdefault("JAX_ENABLE_X64", "1")
    import jax

    jax.config.update("jax_enable_x64", not float32)
    if getattr(args, "cache", False):
        from origami_jax.caches import use_compilation_cache

        use_compilation_cache()
    from origami_jax.tuning import tune_process

    tune_process()  # large sheets faster: before the first sparse solve loads its backend
    warnings.showwarning = _show_warning
    if args.command == "render":
        try:
            import matplotlib
        except ImportError:  # reported by the command, before any work
            return
        matplotlib.use("Agg")  # no window


def _warmup(args: argparse.Namespace) -> int:
    """``origami-jax warmup``: :func:`origami_jax.warmup.warmup`, a line per bucket."""
    import jax.numpy as jnp

    from origami_jax.warmup import warmup

    try:
        done = warmup(
            args.max_vertices,
            dtype=jnp.float32 if args.float32 else jnp.float64,
            solver=args.solver,
            progress=not args.quiet,
        )
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    fresh = sum(1 for seconds in done.values() if seconds > 0)
    print(f"{len(done)} solves ready ({fresh} compiled now)")
    return 0


def console_main(argv: Sequence[str] | None = None) -> int:
    """The ``origami-jax`` command (``[project.scripts]``, ``python -m origami_jax``): sets up
    the process (see the module docstring), then runs :func:`main`'s command."""
    args = build_parser().parse_args(argv)
    if args.command != "info":  # info solves nothing and reports its warnings itself
        _set_up_process(args)
    return _run(args)


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command (``fold``, ``info``, ``render`` or ``warmup``, with its arguments
    ``argv``; default ``sys.argv[1:]``) in this process, changing none of its settings; returns
    the exit code."""
    return _run(build_parser().parse_args(argv))


def _run(args: argparse.Namespace) -> int:
    if args.command == "info":
        return _info(args.input)
    if args.command == "warmup":
        return _warmup(args)
    from origami_jax import PatternError, io, patterns
    from origami_jax.fold import fold

    if args.command == "render":
        try:
            pattern, stiffness = _load(args)
            return _render(args, pattern, stiffness)
        except (PatternError, ValueError, OSError, ImportError, RuntimeError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    try:
        pattern, stiffness = _load(args)
        out = args.out or f"{pattern.name}-folded.fold"
        result = fold(
            pattern,
            stiffness=stiffness,
            **_solve_options(args),
            progress=not args.quiet,
            path=args.path,
            barriers={"auto": None, "on": True, "off": False}[args.barriers],
        )
        io.save(out, result)
    except (PatternError, ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(result.summary())
    if stiffness is patterns.SEED_WATERBOMB_STIFFNESS:
        print(
            f"{'seed paper':<20}  energy {result.history['energy'][0]:.6f} at the start, "
            f"{SEED_FINAL_ENERGY} when its simulator was stopped (it never converged)"
        )
    print(f"{'written':<20}  {out}")
    return 0 if result.converged else 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(console_main())
