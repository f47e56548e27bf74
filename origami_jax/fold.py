"""The one entry point: :func:`fold` a crease pattern to a folded 3-D state with its error figures.

The solve runs compiled, in chunks of iterations (each chunk one ``lax.while_loop``); between
chunks the host records a ``(wall_time, error)`` sample, updates the progress bar and checks the
iteration limit. Compiled functions are cached per (solver, array shapes and dtypes), so folding
another pattern of the same sizes, or the same pattern with other parameters, compiles nothing.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from origami_jax.energy import FoldParams, Stiffness, make_params, make_structure
from origami_jax.metrics import (
    METRIC_NAMES,
    collapse_note,
    collapsed_triangles,
    edge_fold_angles,
    position_metrics,
    shape_error,
)
from origami_jax.pattern import CreasePattern, PatternError
from origami_jax.progress import ProgressBar
from origami_jax.solvers import Solver, Status, get_solver
from origami_jax.solvers.base import check_start, make_problem, positions, prepare

__all__ = ["FoldResult", "fold", "default_tol"]

SUMMARY_ROWS = (
    "vertices",
    "edges",
    "solver",
    "iterations",
    "compile time",
    "run time",
    "max fold-angle error",
    "max strain",
)
HISTORY_FIELDS = (
    "iteration",
    "wall_time",
    "fold_angle_error_max",
    "strain_max",
    "energy",
    "grad_norm_rel",
)


def default_tol(dtype) -> float:
    """Default ``grad_norm_rel`` tolerance: 1e-10 in float64, 1e-4 in float32 (whose rounding
    floor lies near 1e-5)."""
    return 1e-10 if jnp.dtype(dtype) == jnp.float64 else 1e-4


@dataclass
class FoldResult:
    """A folded state and how it was reached.

    ``positions`` (V, 3): the pattern's vertices first, in its order (then copies made by cuts);
    ``fold_angles`` (E,): per mesh edge, radians (pattern edges first, then triangulation edges;
    0 on borders), unwrapped, so ``|angle| > pi`` means a crease folded through itself;
    ``history``: arrays over samples, ``wall_time`` from the start of the solve (compile time
    excluded) with ``fold_angle_error_max``, ``strain_max``, ``energy``, ``grad_norm_rel``.
    Units: radians, seconds, the pattern's length unit.
    """

    pattern: CreasePattern
    positions: np.ndarray
    fold_angles: np.ndarray
    converged: bool
    status: Status
    reason: str
    iterations: int
    solver: str
    percent: float
    dtype: str
    wall_time: float
    compile_time: float
    fold_angle_error_max: float
    fold_angle_error_mean: float
    facet_angle_error_max: float
    strain_max: float
    strain_mean: float
    energy: float
    grad_norm_rel: float
    shape_error: float | None = None
    history: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def through_pi(self) -> np.ndarray:
        """Mesh edges whose crease folded through itself (unwrapped ``|angle| > pi``): the paper
        passed through the paper there. Empty for a physical result."""
        return np.flatnonzero(np.abs(self.fold_angles) > np.pi + 1e-9)

    @property
    def collapsed(self) -> np.ndarray:
        """Mesh triangles squeezed below 1e-6 of their flat area, the smallest first (see
        :func:`~origami_jax.metrics.collapsed_triangles`). Empty for a physical result."""
        return collapsed_triangles(self.positions, self.pattern.mesh)[0]

    @property
    def metrics(self) -> dict[str, float]:
        """The metrics of metrics.md by name (shape_error only when a reference was given)."""
        out = {name: getattr(self, name) for name in METRIC_NAMES}
        if self.shape_error is not None:
            out["shape_error"] = self.shape_error
        out["wall_time"], out["compile_time"] = self.wall_time, self.compile_time
        return out

    def summary(self) -> str:
        """A short table: sizes, solver, iterations, times and the main errors."""
        mesh = self.pattern.mesh
        rows = [
            ("pattern", self.pattern.name),
            ("vertices", f"{mesh.num_vertices}"),
            ("edges", f"{mesh.num_edges} ({self.pattern.num_edges} in the pattern)"),
            ("solver", f"{self.solver} ({self.dtype})"),
            ("iterations", f"{self.iterations}"),
            ("status", self.reason),
            ("compile time", f"{self.compile_time:.3f} s"),
            ("run time", f"{self.wall_time:.4f} s"),
            (
                "max fold-angle error",
                f"{self.fold_angle_error_max:.3e} rad "
                f"({np.degrees(self.fold_angle_error_max):.3e} deg)",
            ),
            ("max strain", f"{self.strain_max:.3e}"),
            ("energy", f"{self.energy:.6g}"),
            ("grad_norm_rel", f"{self.grad_norm_rel:.3e}"),
        ]
        if self.shape_error is not None:
            rows.append(("shape error", f"{self.shape_error:.3e}"))
        flagged = (
            ("folded through pi", "edges", self.through_pi),
            ("collapsed", "triangles", self.collapsed),
        )
        for label, kind, found in flagged:
            if len(found):
                shown = ", ".join(str(k) for k in found[:8]) + (" ..." if len(found) > 8 else "")
                rows.append((label, f"{len(found)} {kind}: {shown}"))
        width = max(len(k) for k, _ in rows)
        return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)

    def __repr__(self) -> str:
        return (
            f"FoldResult({self.pattern.name!r}, {self.solver}, converged={self.converged}, "
            f"iterations={self.iterations}, fold_angle_error_max={self.fold_angle_error_max:.3e},"
            f" wall_time={self.wall_time:.4f} s)"
        )


# -- compiled pieces, cached per (solver, shapes) -------------------------------------------------

_CACHE: dict = {}


def _signature(tree) -> tuple:
    leaves, treedef = jax.tree.flatten(tree)
    return treedef, tuple((np.shape(x), jnp.result_type(x).name) for x in leaves)


def measured(state, problem, num_edges: int):
    """``(state, metrics, positions, per-edge fold angles)`` of a solver state (pure)."""
    x = positions(problem, state.u)
    m = position_metrics(x, problem.structure, problem.params, state.reference)
    m["grad_norm_rel"] = state.grad_max / jnp.where(state.grad_max0 > 0, state.grad_max0, 1)
    angles = edge_fold_angles(x, problem.structure, state.reference, num_edges)
    return state, m, x, angles


def solve_fns(solver: Solver, num_edges: int):
    """``(start, advance)``: ``start(problem)`` the solver's start state,
    ``advance(state, problem, steps)`` up to ``steps`` iterations more; each returns the state,
    the metrics, positions and per-edge fold angles (pure; :func:`fold` jits them)."""

    def start(problem):
        return measured(solver.init(problem), problem, num_edges)

    def advance(state, problem, steps):
        return measured(solver.run(state, problem, steps), problem, num_edges)

    return start, advance


def compiled(solver: Solver, problem, num_edges: int):
    """``(start, advance)`` of :func:`solve_fns` compiled for this solver and these shapes
    (cached), and the compile time (0 when cached)."""
    cache_key = (solver, _signature(problem), num_edges)
    if cache_key in _CACHE:
        return _CACHE[cache_key], 0.0
    start, advance = solve_fns(solver, num_edges)
    t0 = time.perf_counter()
    start_c = jax.jit(start).lower(problem).compile()
    state_shape = jax.eval_shape(start, problem)[0]
    steps = jax.ShapeDtypeStruct((), jnp.int32)
    advance_c = jax.jit(advance).lower(state_shape, problem, steps).compile()
    compile_time = time.perf_counter() - t0
    _CACHE[cache_key] = (start_c, advance_c)
    return _CACHE[cache_key], compile_time


CHUNK_SECONDS = 0.1  # how long a chunk of compiled iterations aims to run


def next_chunk(chunk: int, seconds: float, steps: int) -> int:
    """The next chunk's iteration count after ``steps`` took ``seconds``: about
    :data:`CHUNK_SECONDS`, growing at most 64x at a time. A chunk's time overstates its steps'
    (it includes the round trip), so chunks grow quickly: each host round trip costs a fast
    solve more than its iterations."""
    per_step = seconds / max(steps, 1)
    return max(1, min(64 * chunk, int(CHUNK_SECONDS / max(per_step, 1e-9))))


# the first chunk's iterations are guessed to cost this many times the start (one gradient and
# the metrics), then measured: a guess too low makes only the first chunk longer than planned
FIRST_ITERATION_COST = 20.0


def drive(solver, start, advance, problem, max_iter: int, max_time, record_every, on_chunk=None):
    """The host loop of a solve: compiled chunks of iterations until no problem is RUNNING, the
    iteration limit or ``max_time``. Chunks grow (up to 64x at a time) to about a tenth of a second
    (or stay at ``record_every``); a sample of the metrics is kept after each. Works for one
    problem and for a batch (statuses and metrics then have a leading batch axis).

    Returns ``(state, metrics, positions, angles, samples, out_of_time)``.
    """
    t0 = time.perf_counter()
    state, m, x, angles = jax.block_until_ready(start(problem))
    check_start(solver, state)
    samples = [_sample(state, m, 0.0)]
    # a small problem's whole solve fits one chunk: a round trip costs it more than iterations
    guess = FIRST_ITERATION_COST * (time.perf_counter() - t0)
    chunk, iterations = record_every or max(1, int(CHUNK_SECONDS / max(guess, 1e-9))), 0
    out_of_time = False
    while np.any(samples[-1]["status"] == Status.RUNNING) and iterations < max_iter:
        if max_time is not None and time.perf_counter() - t0 >= max_time:
            out_of_time = True
            break
        steps = min(chunk, max_iter - iterations)
        t_chunk = time.perf_counter()
        # dispatch returns before the chunk has run: wait for it, or the clock (and the chunk
        # sizes and history times taken from it) would read the dispatch, not the solve
        state, m, x, angles = jax.block_until_ready(advance(state, problem, np.int32(steps)))
        now = time.perf_counter()
        samples.append(_sample(state, m, now - t0))
        iterations = int(np.max(samples[-1]["iteration"]))
        if on_chunk is not None:
            on_chunk(iterations, samples[-1])
        chunk = next_chunk(chunk, now - t_chunk, steps)
        if record_every is not None:
            chunk = record_every
    return state, m, x, angles, samples, out_of_time


def _reason(status: Status, m: dict, tol: float, iterations: int, x: np.ndarray, mesh) -> str:
    """Why the solve stopped; a solve that did not converge also names the worst collapsed
    triangle of its result (``x``), if any."""
    g = m["grad_norm_rel"]
    # only the one message is formatted: fold_batch writes one per problem
    if status == Status.CONVERGED:
        if g <= tol:
            return f"converged: grad_norm_rel {g:.2e} <= tol {tol:.1e}"
        return (
            f"converged: grad_norm_rel {g:.2e} > tol {tol:.1e} is this dtype's rounding "
            "floor for these stiffnesses (the gradient is noise there)"
        )
    if status == Status.MAX_ITER:
        text = f"iteration limit {iterations} reached: grad_norm_rel {g:.2e} > tol {tol:.1e}"
    elif status == Status.TIME_LIMIT:
        text = (
            f"time limit reached after {iterations} iterations: grad_norm_rel {g:.2e} > "
            f"tol {tol:.1e}"
        )
    elif status == Status.NONFINITE:
        text = "stopped: non-finite energy or gradient; the last finite iterate is returned"
    elif status == Status.STALLED:
        text = (
            f"stalled at grad_norm_rel {g:.2e} > tol {tol:.1e}: the line search finds no "
            "decrease (the rounding floor of this dtype, or a kink such as a collapsed triangle)"
        )
    else:
        raise ValueError(f"no reason for status {status!r}")
    note = collapse_note(x, mesh)
    return text + (f"; {note}" if note else "")


def checked_start(pattern: CreasePattern, start, name: str = "start") -> np.ndarray | None:
    """The (V_mesh, 3) float64 start of a fold of ``pattern``: ``start``, else the pattern's own
    (a pre-folded input), else ``None`` (flat: the mesh's vertices, checked when the pattern was
    made). Raises :class:`PatternError` naming ``name`` and the first vertex that is not finite,
    or the shape expected."""
    mesh = pattern.mesh
    if start is None and pattern.start is not None:
        start = pattern.start[mesh.source_vertex]
    if start is None:
        return None
    start = np.asarray(start, np.float64)
    if start.shape != mesh.vertices.shape:
        raise PatternError(f"{name}: expected shape {mesh.vertices.shape}, got {start.shape}")
    bad = ~np.isfinite(start).all(axis=1)
    if bad.any():
        raise PatternError(f"{name}: vertex {int(np.flatnonzero(bad)[0])} is not finite")
    return start


def fold(
    pattern: CreasePattern,
    percent: float = 1.0,
    solver: str | Solver = "newton",
    tol: float | None = None,
    max_iter: int = 100_000,
    stiffness: Stiffness | dict | None = None,
    start: np.ndarray | None = None,
    dtype=None,
    reference_positions: np.ndarray | None = None,
    progress: bool = False,
    params: FoldParams | None = None,
    max_time: float | None = None,
    record_every: int | None = None,
) -> FoldResult:
    """Fold ``pattern`` to equilibrium from flat (or from ``start``).

    Args:
      pattern: the crease pattern.
      percent: fold percent as a fraction; each crease is driven to ``percent * target``.
      solver: ``"newton"`` (default: fewest iterations and the shortest run time on every
        pattern measured), ``"lbfgs"``, ``"dynamics"``, or a solver object.
      tol: stop when ``grad_norm_rel`` (max-abs gradient over its start value) is below this;
        default :func:`default_tol` of the dtype.
      max_iter: iteration limit; reaching it gives ``converged=False``.
      stiffness: a :class:`~origami_jax.energy.Stiffness` or dict (default ``Stiffness()``).
      start: (V_mesh, 3) start positions (default: the pattern's ``start`` if it has one, a
        pre-folded input, else the flat pattern).
      dtype: ``jnp.float32`` or ``jnp.float64``; default JAX's default float (float64 only
        when ``jax_enable_x64`` is on).
      reference_positions: an exact folded shape (V_mesh, 3) to report ``shape_error`` against.
      progress: show a progress bar on stderr once the solve has run for a second.
      params: full energy parameters (overrides ``percent`` and ``stiffness``).
      max_time: stop after about this many seconds of solving (compile time excluded);
        reaching it gives ``converged=False``. The solve checks it between compiled chunks of
        about a tenth of a second (or one iteration, if longer).
      record_every: record a ``history`` sample every this many iterations (default: chunks
        that grow to about a tenth of a second each, which costs the solve nothing measurable;
        ``1`` resolves each Newton iteration, at one host round trip per sample).

    Returns:
      A :class:`FoldResult`; it never holds NaN positions: a solve that meets a non-finite value
      stops, keeps its last finite iterate, and says so in ``reason``.

    Example:
      >>> from origami_jax import fold, patterns
      >>> result = fold(patterns.single_crease(fold_angle=1.0))
      >>> bool(result.converged), result.fold_angle_error_max < 1e-3
      (True, True)
    """
    if not isinstance(pattern, CreasePattern):
        raise TypeError(f"fold() needs a CreasePattern, got {type(pattern).__name__}")
    if not np.isfinite(percent):
        raise PatternError(f"percent: must be finite, got {percent}")
    if int(max_iter) < 0:
        raise ValueError(f"max_iter must be >= 0, got {max_iter}")
    if record_every is not None and int(record_every) < 1:
        raise ValueError(f"record_every must be >= 1, got {record_every}")
    solver_obj = get_solver(solver)
    dtype = jnp.dtype(dtype or jnp.result_type(float))
    if dtype == jnp.float64 and not jax.config.jax_enable_x64:
        raise ValueError(
            "float64 needs jax.config.update('jax_enable_x64', True) (or JAX_ENABLE_X64=1)"
        )
    tol = default_tol(dtype) if tol is None else float(tol)
    mesh = pattern.mesh
    start = checked_start(pattern, start)
    if params is None:
        params = make_params(pattern, percent, stiffness, dtype)
    else:
        params = jax.tree.map(lambda a: jnp.asarray(a, dtype), params)
        percent = float(params.percent)
    problem = make_problem(mesh, make_structure(mesh), params, start, tol)
    problem = prepare(solver_obj, problem, mesh)

    (start, advance), compile_time = compiled(solver_obj, problem, mesh.num_edges)
    t0 = time.perf_counter()
    bar = ProgressBar(max_iter) if progress else None

    def on_chunk(iterations, sample):
        if bar is not None:
            bar.update(iterations, f"err {float(sample['fold_angle_error_max']):.2e} rad")

    state, m, x, angles, samples, out_of_time = drive(
        solver_obj, start, advance, problem, max_iter, max_time, record_every, on_chunk
    )
    iterations = int(state.iteration)
    x, angles = jax.device_get((x, angles))
    wall_time = time.perf_counter() - t0
    if bar is not None:
        bar.close()

    status = Status(int(state.status))
    if status == Status.RUNNING:
        status = Status.TIME_LIMIT if out_of_time else Status.MAX_ITER
    m = {k: float(v) for k, v in jax.device_get(m).items()}
    x = np.asarray(x, np.float64)
    shape_err = None
    if reference_positions is not None:
        shape_err = shape_error(x, reference_positions, pattern.diameter)
    history = history_of(samples)
    return FoldResult(
        pattern=pattern,
        positions=x,
        fold_angles=np.asarray(angles, np.float64),
        converged=status == Status.CONVERGED,
        status=status,
        reason=_reason(status, m, tol, iterations, x, pattern.mesh),
        iterations=int(state.iteration),
        solver=solver_obj.name,
        percent=float(percent),
        dtype=dtype.name,
        wall_time=wall_time,
        compile_time=compile_time,
        shape_error=shape_err,
        history=history,
        **{k: m[k] for k in METRIC_NAMES},
    )


def _sample(state, m, t: float) -> dict:
    """The metrics after a chunk, with the iteration and status, as host arrays (scalars, or
    (B,) in a batch): one transfer."""
    keys = ("fold_angle_error_max", "strain_max", "energy", "grad_norm_rel")
    out = jax.device_get(
        {**{k: m[k] for k in keys}, "iteration": state.iteration, "status": state.status}
    )
    out["wall_time"] = t
    return out


def history_of(samples: list[dict]) -> dict[str, np.ndarray]:
    """The ``history`` arrays of one solve from the samples of :func:`drive` (a batch's come
    from ``origami_jax.batch._history_table``)."""
    return {k: np.array([float(s[k]) for s in samples]) for k in HISTORY_FIELDS}
