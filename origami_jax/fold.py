"""The one entry point: :func:`fold` a crease pattern to a folded 3-D state with its error figures.

The solve runs compiled, in chunks of iterations (each chunk one ``lax.while_loop``); between
chunks the host records a ``(wall_time, error)`` sample, updates the progress bar and checks the
iteration limit. Compiled functions are cached per (solver, array shapes and dtypes), so folding
another pattern of the same sizes, or the same pattern with other parameters, compiles nothing.
A problem solved in one compiled program (not Newton's sparse solves, not self-contact) is
padded to a size bucket first (:func:`prepared`, :mod:`origami_jax.padding`: at most 19 % more
vertices, inert padding), so patterns of similar size share their compiled solve too.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import time
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from origami_jax.barrier import HINGE_GAP
from origami_jax.caches import LruCache
from origami_jax.contact import (
    Capacity,
    ContactMesh,
    all_pairs,
    allocate,
    contact_energy,
    contact_mesh,
    contact_report,
    contact_stiffness,
    default_dhat,
    reallocate,
)
from origami_jax.energy import (
    NO_BARRIERS,
    Barriers,
    ContactParams,
    FoldParams,
    Stiffness,
    Structure,
    initial_reference,
    make_params,
    make_structure,
    needs_barriers,
)
from origami_jax.exported import compile_all, lower_stored
from origami_jax.intersections import INTERSECTION_DEPTH, intersecting_pairs
from origami_jax.metrics import (
    METRIC_NAMES,
    collapse_note,
    collapsed_triangles,
    edge_fold_angles,
    position_metrics,
    shape_error,
)
from origami_jax.padding import (
    BATCH_FLOORS,
    PLANAR_FLOORS,
    Floors,
    Sizes,
    bucket,
    pad_problem,
    sizes_of,
    unpad_metrics,
)
from origami_jax.pattern import CreasePattern, PatternError
from origami_jax.progress import ProgressBar
from origami_jax.solvers import Solver, Status, get_solver
from origami_jax.solvers.base import (
    default_max_step,
    make_problem,
    positions,
)

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


@dataclass(frozen=True)
class FoldResult:
    """A folded state and how it was reached (immutable: ``dataclasses.replace`` makes a
    changed copy).

    ``positions`` (V, 3): the pattern's vertices first, in its order (then copies made by cuts);
    ``fold_angles`` (E,): per mesh edge, radians (pattern edges first, then triangulation edges;
    0 on borders), unwrapped, so ``|angle| > pi`` means a crease folded through itself;
    ``history``: arrays over samples, ``wall_time`` from the start of the solve (compile time
    excluded) with ``fold_angle_error_max``, ``strain_max``, ``energy``, ``grad_norm_rel``;
    along a continuation path the samples are each step's, measured against that step's fold
    percent and stiffness (a step retried smaller included), then the result's;
    ``path``: ``"direct"`` or ``"continuation"``; ``barriers``: the :class:`Barriers` built;
    ``frames``: with continuation, the states of the path from flat (:class:`Frame`, one per
    fold percent, the last the result); with self-contact, ``contact_dhat`` its reach (the
    gap layers keep), ``contact_pairs`` the pairs of primitives closer than that at the
    result, ``contact_min_ratio`` the least distance of any pair over it and ``contact_kappa``
    the barrier's weight (``None``, 0, ``inf`` and ``None`` without contact; the forces:
    :attr:`contact_forces`); ``wall_time`` includes any try whose contact pairs outgrew their
    capacity (its compilation too: the fold starts again with more room).
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
    path: str = "direct"
    barriers: Barriers = NO_BARRIERS
    frames: list = field(default_factory=list)
    contact_dhat: float | None = None
    contact_pairs: int = 0
    contact_min_ratio: float = float("inf")
    contact_kappa: float | None = None

    @functools.cached_property
    def through_pi(self) -> np.ndarray:
        """Mesh edges whose crease folded through itself (unwrapped ``|angle|`` more than
        :data:`~origami_jax.barrier.HINGE_GAP`, 1e-5 rad, past ``pi``: a crease held at its
        barrier, or a fully folded one within the solver's tolerance, is not through): the paper
        passed through the paper there. Empty for a physical result."""
        return np.flatnonzero(np.abs(self.fold_angles) > np.pi + HINGE_GAP)

    @functools.cached_property
    def collapsed(self) -> np.ndarray:
        """Mesh triangles squeezed below 1e-6 of their flat area, the smallest first (see
        :func:`~origami_jax.metrics.collapsed_triangles`). Empty for a physical result."""
        return collapsed_triangles(self.positions, self.pattern.mesh)[0]

    @functools.cached_property
    def intersections(self) -> np.ndarray:
        """(K, 2) pairs of mesh triangles sharing no vertex that cross each other deeper than
        1e-6 of the diameter (see :func:`~origami_jax.intersections.intersecting_pairs`): the
        paper passed through the paper. Empty for a physical result."""
        return intersecting_pairs(
            self.positions, self.pattern.mesh.triangles, INTERSECTION_DEPTH * self.pattern.diameter
        )

    @functools.cached_property
    def contact_forces(self) -> np.ndarray:
        """(V, 3) the self-contact barrier's force on each vertex at the result (minus its
        gradient: force units, the stiffness's times length over length); zeros without
        contact. The pairs within ``contact_dhat`` are found again from the positions."""
        x = np.asarray(self.positions)
        if self.contact_dhat is None:
            return np.zeros_like(x)
        pairs = pairs_within(x, contact_mesh(self.pattern.mesh), self.contact_dhat)
        grad = _contact_gradient(jnp.asarray(x), pairs, self.contact_dhat, self.contact_kappa)
        return -np.asarray(grad, np.float64)

    @property
    def metrics(self) -> dict[str, float]:
        """The metrics of metrics.md by name (shape_error only when a reference was given)."""
        out = {name: getattr(self, name) for name in METRIC_NAMES}
        if self.shape_error is not None:
            out["shape_error"] = self.shape_error
        out["wall_time"], out["compile_time"] = self.wall_time, self.compile_time
        return out

    @property
    def advice(self) -> list[str]:
        """What keeps this result from being one to trust, in words, each with what to try:
        empty for a converged result with no crease through pi, no collapsed triangle and no
        faces through faces."""
        out = []
        if not self.converged:
            more = " or path='continuation' (the fold followed from flat)"
            out.append(
                "not converged: allow more time or iterations (max_time, max_iter)"
                + (more if self.path == "direct" else "")
            )
        barred = self.barriers.hinge_gap > 0 and self.barriers.area_floor > 0
        if len(self.through_pi):
            out.append(
                f"{len(self.through_pi)} creases folded through themselves: "
                + ("fold with barriers=True" if not barred else "let the solve converge")
            )
        if len(self.collapsed):
            out.append(
                f"{len(self.collapsed)} triangles collapsed: "
                + ("fold with barriers=True, " if not barred else "")
                + "or stiffer bars (stiffness=dict(axial=...))"
            )
        if len(self.intersections):
            out.append(
                f"{len(self.intersections)} pairs of faces pass through each other: "
                + (
                    "fold with contact=True (self-contact keeps layers apart)"
                    if self.contact_dhat is None
                    else "contact does not keep apart pieces that meet at a point (copies of "
                    "one vertex) near that point"
                )
            )
        far = self.fold_angle_error_max > 0.1
        # pairs within the barrier's reach push back: a fold they hold short of its targets
        # is contact's doing, not (only) targets that cannot all be met
        pressing = self.contact_dhat is not None and bool(self.contact_pairs)
        if pressing and (far or not self.converged):
            out.append(
                f"{self.contact_pairs} contact pairs within dhat ({self.contact_dhat:.3g}, the "
                f"closest at {self.contact_min_ratio:.2f} dhat) hold layers apart that the "
                f"targets bring closer (fold-angle error up to "
                f"{np.degrees(self.fold_angle_error_max):.3g} deg): a smaller contact distance "
                "(contact=<dhat>) lets them closer; layers that must pass each other to reach "
                "the targets cannot (contact=False folds through them)"
            )
        elif self.converged and far:
            out.append(
                f"fold-angle error up to {np.degrees(self.fold_angle_error_max):.3g} deg at "
                "equilibrium: the targets are not all reachable at once (not mutually "
                "consistent); softer facets (stiffness=dict(facet=...)) let faces bend"
            )
        return out

    def summary(self) -> str:
        """A short table: sizes, solver, iterations, times, the main errors and :attr:`advice`."""
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
        if self.contact_dhat is not None:
            rows.append(
                (
                    "contact",
                    f"{self.contact_pairs} pairs within dhat {self.contact_dhat:.3g}, the "
                    f"closest at {self.contact_min_ratio:.3g} dhat",
                )
            )
        flagged = (
            ("folded through pi", "edges", self.through_pi),
            ("collapsed", "triangles", self.collapsed),
            ("intersecting", "triangle pairs", self.intersections),
        )
        for label, kind, found in flagged:
            if len(found):
                shown = ", ".join("-".join(map(str, np.atleast_1d(k))) for k in found[:8])
                shown += " ..." if len(found) > 8 else ""
                rows.append((label, f"{len(found)} {kind}: {shown}"))
        rows += [("advice", line) for line in self.advice]
        width = max(len(k) for k, _ in rows)
        return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)

    def __repr__(self) -> str:
        return (
            f"FoldResult({self.pattern.name!r}, {self.solver}, converged={self.converged}, "
            f"iterations={self.iterations}, fold_angle_error_max={self.fold_angle_error_max:.3e},"
            f" wall_time={self.wall_time:.4f} s)"
        )


# -- compiled pieces, cached per (solver, shapes) -------------------------------------------------

_CACHE = LruCache()  # the most recently used compiled solves (origami_jax.caches)


def signature(tree) -> tuple:
    """A compiled function's cache key for arguments ``tree``: its structure, shapes, dtypes."""
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
    cache_key = (solver, signature(problem), num_edges)
    hit = _CACHE.get(cache_key)
    if hit is not None:
        return hit, 0.0
    start, advance = solve_fns(solver, num_edges)
    t0 = time.perf_counter()
    exportable = not solver.host_callbacks(problem)
    start_l = lower_stored(start, (problem,), (repr(solver), "start", num_edges), exportable)
    state_shape = start_l.out_info[0]  # not traced again
    steps = jax.ShapeDtypeStruct((), jnp.int32)
    advance_l = lower_stored(
        advance, (state_shape, problem, steps), (repr(solver), "advance", num_edges), exportable
    )
    start_c, advance_c = compile_all([start_l, advance_l])
    compile_time = time.perf_counter() - t0
    _CACHE[cache_key] = (start_c, advance_c)
    return (start_c, advance_c), compile_time


# a single fold's problem is padded to a size bucket (origami_jax.padding) of this many steps
# per doubling of its counts (at most 19 % more vertices): patterns of similar size then share
# one compiled solve, in the process and in the cache on disk (0: no padding)
BUCKETS_PER_OCTAVE = 4


class Padding(NamedTuple):
    """A padded problem's sizes (``sizes``) and those of its bucket (``to``)."""

    sizes: Sizes
    to: Sizes

    def metrics(self, m: dict) -> dict:
        """The padded solve's metrics (host values) for the real problem."""
        return unpad_metrics(m, self.sizes, self.to)

    def positions(self, x: np.ndarray) -> np.ndarray:
        """The real vertices' rows of padded positions ``x`` (host values)."""
        return x[: self.sizes.vertices]

    def edges(self, num_edges: int) -> int:
        """The edge count a padded solve reports fold angles for (one per padded bar: patterns
        of one bucket share it; the real edges come first)."""
        return max(num_edges, self.to.bars)


# the least sizes a padded problem gets (origami_jax.warmup: a small pattern padded to a larger
# bucket compiles that bucket's solve)
_AT_LEAST: contextvars.ContextVar[Sizes | None] = contextvars.ContextVar("at_least", default=None)


@contextlib.contextmanager
def padded_at_least(sizes: Sizes) -> Iterator[None]:
    """Within this context, :func:`fold` pads every problem it pads to at least ``sizes`` (a
    bucket's sizes, see :func:`origami_jax.padding.bucket`)."""
    token = _AT_LEAST.set(sizes)
    try:
        yield
    finally:
        _AT_LEAST.reset(token)


def bucket_floors(solver: Solver) -> Floors:
    """The least element counts of ``fold``'s buckets for ``solver``: those of every
    triangulated sheet of the bucket's vertex count where the elements cost little beside a
    dense factorization (Newton: one bucket per vertex count, whatever the pattern), else
    ``fold_batch``'s (padded elements would slow each iteration)."""
    return PLANAR_FLOORS if solver.cost_by_vertices() else BATCH_FLOORS


def prepared(solver: Solver, problem, mesh, dtype):
    """``(problem, padding)``: ``problem`` prepared for ``solver``, padded to its size bucket
    (:data:`BUCKETS_PER_OCTAVE`) and prepared as ``fold_batch`` prepares its members where
    the solver solves it in one compiled program (no host callbacks: not Newton's sparse
    solves) without contact; ``padding`` is then its :class:`Padding`, else ``None``. The
    padding is inert (:mod:`origami_jax.padding`)."""
    plain = solver.prepare(problem, mesh)
    if BUCKETS_PER_OCTAVE <= 0 or problem.structure.contact is not None:
        return plain, None
    if solver.host_callbacks(plain):
        return plain, None
    sizes = sizes_of(problem)
    to = bucket(sizes, BUCKETS_PER_OCTAVE, bucket_floors(solver))
    least = _AT_LEAST.get()
    if least is not None:
        to = to._replace(**{k: max(getattr(to, k), getattr(least, k)) for k in Sizes._fields[:7]})
    try:
        solver.check_batch(to.vertices)
    except ValueError:  # too large for the solver's batched (dense) solve
        return plain, None
    padded = pad_problem(problem, sizes, to)
    padded = jax.tree.map(
        lambda a: jnp.asarray(a, dtype if np.asarray(a).dtype.kind == "f" else None), padded
    )
    return solver.prepare_batch(padded, mesh), Padding(sizes, to)


CHUNK_SECONDS = 0.1  # how long a chunk of compiled iterations aims to run


def next_chunk(chunk: int, seconds: float, steps: int) -> int:
    """The next chunk's iteration count after ``steps`` took ``seconds``: about
    :data:`CHUNK_SECONDS`, growing at most 64x at a time. A chunk's time overstates its steps'
    (it includes the round trip), so chunks grow quickly: each host round trip costs a fast
    solve more than its iterations."""
    per_step = seconds / max(steps, 1)
    return max(1, min(64 * chunk, int(CHUNK_SECONDS / max(per_step, 1e-9))))


def chunk_steps(chunk: int, iterations_left: int, seconds_left, per_step: float) -> int:
    """The iterations of the next chunk: ``chunk``, but no more than ``iterations_left``, nor
    than fit in ``seconds_left`` (``None``: no time limit) at ``per_step`` seconds each, and at
    least one: a solve then stops within about one iteration of its time limit."""
    steps = min(chunk, iterations_left)
    if seconds_left is not None:
        steps = min(steps, max(1, int(seconds_left / max(per_step, 1e-9))))
    return steps


# the first chunk's iterations are guessed to cost this many times the start (one gradient and
# the metrics), then measured: a guess too low makes only the first chunk longer than planned
FIRST_ITERATION_COST = 20.0


class Pace:
    """Seconds an iteration, as last measured by :func:`drive`: handed from one ``drive`` to the
    next of the same compiled solve (the steps of a continuation), whose first chunk is then
    sized by it instead of by a guess."""

    def __init__(self):
        self.per_step: float | None = None


def drive(
    solver: Solver,
    start,
    advance,
    problem,
    max_iter: int,
    max_time,
    record_every,
    on_chunk=None,
    retol=None,
    pace: Pace | None = None,
):
    """The host loop of a solve: compiled chunks of iterations until no problem is RUNNING, the
    iteration limit or ``max_time``. Chunks grow (up to 64x at a time) to about a tenth of a second
    (or stay at ``record_every``), and none plans more iterations than fit in the time left (see
    :func:`chunk_steps`); a sample of the metrics is kept after each. Works for one
    problem and for a batch (statuses and metrics then have a leading batch axis). ``retol``:
    ``retol(state, problem) -> problem``, applied once the start state is known (a continuation
    sets each step's tolerance from its start gradient). ``pace``: the time an iteration took in
    an earlier ``drive`` of the same solve, updated here (see :class:`Pace`).

    Returns ``(state, metrics, positions, angles, samples, out_of_time)``.
    """
    t0 = time.perf_counter()
    state, m, x, angles = jax.block_until_ready(start(problem))
    solver.check_start(state)
    if retol is not None:
        problem = retol(state, problem)
    samples = [_sample(state, m, 0.0)]
    pace = Pace() if pace is None else pace
    per_step = pace.per_step
    if per_step is None:  # a small problem's whole solve fits one chunk: a round trip costs more
        per_step = FIRST_ITERATION_COST * (time.perf_counter() - t0)
    chunk, iterations = record_every or max(1, int(CHUNK_SECONDS / max(per_step, 1e-9))), 0
    out_of_time = False
    while np.any(samples[-1]["status"] == Status.RUNNING) and iterations < max_iter:
        seconds_left = None if max_time is None else max_time - (time.perf_counter() - t0)
        if seconds_left is not None and seconds_left <= 0:
            out_of_time = True
            break
        steps = chunk_steps(chunk, max_iter - iterations, seconds_left, per_step)
        t_chunk = time.perf_counter()
        # dispatch returns before the chunk has run: wait for it, or the clock (and the chunk
        # sizes and history times taken from it) would read the dispatch, not the solve
        state, m, x, angles = jax.block_until_ready(advance(state, problem, np.int32(steps)))
        now = time.perf_counter()
        samples.append(_sample(state, m, now - t0))
        done, iterations = iterations, int(np.max(samples[-1]["iteration"]))
        done = iterations - done  # fewer than planned where the solve stopped inside the chunk
        if on_chunk is not None:
            on_chunk(iterations, samples[-1])
        chunk = next_chunk(chunk, now - t_chunk, steps)
        per_step = pace.per_step = (now - t_chunk) / max(done, 1)
        if record_every is not None:
            chunk = record_every
    return state, m, x, angles, samples, out_of_time


def stop_reason(status: Status, m: dict, tol: float, iterations: int, x: np.ndarray, mesh) -> str:
    """Why the solve stopped; a solve that did not converge also names the worst collapsed
    triangle of its result (``x``), if any."""
    # only the one message is formatted: fold_batch writes one per problem
    text = Status(status).describe(m["grad_norm_rel"], tol, iterations)
    if status == Status.CONVERGED:
        return text
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
    barriers: Barriers | bool | None = None,
    path: str = "auto",
    contact: bool | float = False,
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
        about a tenth of a second, none planned longer than the time left at the pace measured,
        so it stops within about one iteration of ``max_time``.
      record_every: record a ``history`` sample every this many iterations (default: chunks
        that grow to about a tenth of a second each, which costs the solve nothing measurable;
        ``1`` resolves each Newton iteration, at one host round trip per sample).
      barriers: the hinge and area barriers of :mod:`origami_jax.barrier` (no crease through
        itself, no collapsed triangle): ``None`` (default) where a crease is driven to 0.9 pi
        or more (:func:`~origami_jax.energy.needs_barriers`), ``True``, ``False`` or an
        :class:`~origami_jax.energy.Barriers`.
      path: ``"continuation"``: follow the fold from flat, the fold percent raised in adaptive
        steps (the states in ``result.frames``); ``"direct"``: one solve at the full percent;
        ``"auto"`` (default): continuation with Newton where the scene has barriers by default
        and the start is the unfolded sheet, else direct; a direct Newton solve from the
        unfolded sheet that stalls (in float64), or ends with a crease through pi or a
        collapsed triangle,
        is then followed from flat (with the barriers, unless ``barriers=False``), and its
        time and iterations count in the result's.
      contact: self-contact (:mod:`origami_jax.contact`): faces that share no vertex are kept
        apart by a barrier, and no step passes one through another. ``True``: the default
        reach ``dhat`` (the gap folded layers keep: :func:`with_contact`); a number: that
        ``dhat``, pattern units; ``False`` (default): none. For solvers that bound their
        steps among contact pairs (``Solver.supports_contact``: Newton, L-BFGS, dynamics).

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
    if path not in ("auto", "direct", "continuation"):
        raise ValueError(f"path must be 'auto', 'direct' or 'continuation', got {path!r}")
    dhat = None if contact is False else contact_reach(contact, solver_obj)
    # a direct solve chosen by "auto" that ends with a warning sign is followed again from flat
    retry = False
    if path == "auto":
        # a given start (or a folded form's own) is where the user wants the solve to begin;
        # the first-order solvers' iterations are many already (dynamics has its own ramp)
        follows = solver_obj.follows_path
        flat = start is None or is_unfolded(start, mesh)
        path = "continuation" if follows and flat and needs_continuation(mesh) else "direct"
        retry = follows and flat and path == "direct"
    bars: list[ProgressBar] = []  # made at the first chunk: its clock starts after compiling

    def on_chunk(iterations, sample):
        if progress and not bars:
            bars.append(ProgressBar(max_iter))
        for bar in bars:
            bar.update(iterations, f"err {float(sample['fold_angle_error_max']):.2e} rad")

    room: list[Capacity] = []  # the contact pairs' capacity, once a solve has outgrown one

    def scene(which):
        structure = make_structure(mesh, which)
        if contact is False:
            return structure, params
        return with_contact(mesh, structure, params, dhat, start, room[-1] if room else None)

    lost = 0.0  # the time of tries whose contact pairs outgrew their room (compiling included)
    while True:  # again, with more room, while the contact pairs outgrow their capacity
        t_try = time.perf_counter()
        try:
            solved, structure, run_params, path = _fold_once(
                solver_obj,
                mesh,
                scene,
                barriers,
                start,
                tol,
                max_iter,
                # the tries that outgrew their room count in the result's time, and in its limit
                None if max_time is None else max(max_time - lost, 0.0),
                record_every,
                on_chunk,
                path,
                retry,
                dtype,
            )
            break
        except _ContactOverflow as overflow:
            room.append(overflow.capacity)
            lost += time.perf_counter() - t_try

    state, m, x, angles, samples, out_of_time, iterations, compile_time, wall_time, frames = solved
    wall_time += lost
    for bar in bars:
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
    touching = {}
    if structure.contact is not None:
        touching = contact_summary(x, state.reference.pairs, run_params)
    return FoldResult(
        pattern=pattern,
        positions=x,
        fold_angles=np.asarray(angles, np.float64),
        converged=status == Status.CONVERGED,
        status=status,
        reason=stop_reason(status, m, tol, iterations, x, pattern.mesh),
        iterations=iterations,
        solver=solver_obj.name,
        percent=float(percent),
        dtype=dtype.name,
        wall_time=wall_time,
        compile_time=compile_time,
        shape_error=shape_err,
        history=history,
        path=path,
        barriers=structure.barriers,
        frames=frames,
        **touching,
        **{k: m[k] for k in METRIC_NAMES},
    )


def _fold_once(
    solver_obj,
    mesh,
    scene,
    barriers,
    start,
    tol,
    max_iter,
    max_time,
    record_every,
    on_chunk,
    path,
    retry,
    dtype,
):
    """One try of :func:`fold`'s solve: ``(solved, structure, params, path)``."""
    structure, params = scene(barriers)

    if path == "continuation":
        solved = _solve_path(
            solver_obj,
            mesh,
            structure,
            params,
            start,
            tol,
            max_iter,
            max_time,
            record_every,
            on_chunk,
        )
    else:
        problem, padding = prepared(
            solver_obj, make_problem(mesh, structure, params, start, tol), mesh, dtype
        )
        edges = mesh.num_edges if padding is None else padding.edges(mesh.num_edges)
        (start_c, advance_c), compile_time = compiled(solver_obj, problem, edges)
        t0 = time.perf_counter()
        state, m, x, angles, samples, out_of_time = drive(
            solver_obj, start_c, advance_c, problem, max_iter, max_time, record_every, on_chunk
        )
        m, x, angles = jax.device_get((m, x, angles))
        angles = angles[: mesh.num_edges]
        if padding is not None:
            m, x = padding.metrics(m), padding.positions(x)
        _check_room(state, x, structure)
        solved = _Solved(
            state,
            m,
            x,
            angles,
            samples,
            out_of_time,
            int(state.iteration),
            compile_time,
            time.perf_counter() - t0,
            [],
        )
        warning = _warning_sign(solved, mesh, dtype)
        if retry and warning is not None and solved.iterations < max_iter:
            if warning != "stalled" and barriers is None:
                structure, params = scene(True)  # what went wrong is what they prevent
            spent = solved.wall_time
            again = _solve_path(
                solver_obj,
                mesh,
                structure,
                params,
                start,
                tol,
                max_iter - solved.iterations,
                None if max_time is None else max(max_time - spent, 0.0),
                record_every,
                None
                if on_chunk is None
                else functools.partial(_shifted, on_chunk, solved.iterations),
            )
            path = "continuation"
            solved = again._replace(
                samples=solved.samples
                + [
                    {
                        **sample,
                        "iteration": solved.iterations + sample["iteration"],
                        "wall_time": spent + sample["wall_time"],
                    }
                    for sample in again.samples
                ],
                iterations=solved.iterations + again.iterations,
                compile_time=solved.compile_time + again.compile_time,
                wall_time=spent + again.wall_time,
            )
    return solved, structure, params, path


#: candidate contact pairs are gathered this far beyond ``dhat``, in median triangle altitudes:
#: no vertex moves more than half of it from where they were gathered, and they are gathered
#: again once one has moved a quarter of it (contact.refreshed)
CONTACT_SKIN = 2.0
#: the first capacity for contact pairs holds this many times the start's
CONTACT_ROOM = 4.0
#: a sheet with at most this many pairs of primitives gets room for all of them at once
CONTACT_ALL_PAIRS = 20_000


class _ContactOverflow(Exception):
    """A solve's contact pairs outgrew their capacity: ``capacity`` holds the state it reached."""

    def __init__(self, capacity: Capacity):
        super().__init__(f"contact pairs outgrew their capacity: now {capacity}")
        self.capacity = capacity


def contact_reach(contact: bool | float, solver: Solver) -> float | None:
    """The reach ``dhat`` that ``contact=True`` or ``contact=<dhat>`` asks for (``None``: the
    default, :func:`with_contact`'s), checked: a solver that does not bound its steps among
    contact pairs, or a reach that is not finite and > 0, is refused (``ValueError``)."""
    if not solver.supports_contact:
        raise ValueError(
            f"contact: solver {solver.name!r} does not bound its steps among contact "
            f"pairs (Solver.supports_contact); newton, lbfgs and dynamics do"
        )
    if contact is True:
        return None
    if not (np.isfinite(float(contact)) and float(contact) > 0):
        raise ValueError(f"contact: dhat must be finite and > 0, got {contact}")
    return float(contact)


def with_contact(
    mesh,
    structure: Structure,
    params: FoldParams,
    dhat: float | None = None,
    start: np.ndarray | None = None,
    capacity: Capacity | None = None,
) -> tuple[Structure, FoldParams]:
    """A scene with self-contact (host side): the structure with its
    :class:`~origami_jax.contact.ContactMesh` and pair capacity, the parameters with
    :class:`~origami_jax.energy.ContactParams` (:func:`contact_settings`; capacities of
    :func:`contact_capacity` at ``start``, default the flat sheet, or grown from
    ``capacity``)."""
    cmesh, contact = contact_settings(mesh, params, dhat)
    x0 = np.asarray(mesh.vertices if start is None else start, np.float64)
    capacity = contact_capacity(cmesh, x0, float(contact.dhat + contact.skin), capacity)
    dtype = params.rest_length.dtype
    structure = replace(
        structure, contact=jax.tree.map(jnp.asarray, cmesh), contact_capacity=capacity
    )
    return structure, params._replace(
        contact=jax.tree.map(lambda v: jnp.asarray(v, dtype), contact)
    )


def contact_settings(
    mesh, params: FoldParams, dhat: float | None = None
) -> tuple[ContactMesh, ContactParams]:
    """The :class:`~origami_jax.contact.ContactMesh` of ``mesh`` and the
    :class:`~origami_jax.energy.ContactParams` of a scene with self-contact (host values).

    ``dhat`` (default :func:`~origami_jax.contact.default_dhat`, 1e-3 of the flat sheet's
    diameter, or half the least distance between two primitives of the flat sheet that share no
    vertex, if less: a sheet at rest has no pair in reach); the skin :data:`CONTACT_SKIN`
    median triangle altitudes; the barrier's weight
    :func:`~origami_jax.contact.contact_stiffness`."""
    flat = np.asarray(mesh.vertices, np.float64)
    cmesh = contact_mesh(mesh)
    if dhat is None:
        extent = flat.max(axis=0) - flat.min(axis=0)
        dhat = default_dhat(float(np.linalg.norm(extent)))
        at_rest = pairs_within(flat, cmesh, dhat)
        clearance = float(_contact_report(flat, at_rest, dhat).min_ratio) * dhat
        if clearance < dhat:
            if not clearance > 0:
                raise PatternError(
                    "contact: two primitives of the flat sheet that share no vertex touch; "
                    "give contact=<dhat> explicitly or mend the pattern"
                )
            dhat = 0.5 * clearance
    skin = CONTACT_SKIN * 2.0 * default_max_step(mesh)
    kappa = float(contact_stiffness(params))
    return cmesh, ContactParams(float(dhat), kappa, float(skin))


def contact_capacity(
    cmesh: ContactMesh, x0: np.ndarray, radius: float, capacity: Capacity | None = None
) -> Capacity:
    """Capacities for the candidate pairs of a solve from positions ``x0`` within ``radius``:
    for every pair of a sheet with at most :data:`CONTACT_ALL_PAIRS`, else for
    :data:`CONTACT_ROOM` times the pairs of ``x0`` (or grown from ``capacity``)."""
    if capacity is None and _few_pairs(cmesh):
        # room for every pair at once, and for boxes over 16 cells each (the most the broad
        # phase's grid gives on average): a small sheet's pairs never outgrow it (a fold that
        # does starts again, compiling again)
        t, e = len(cmesh.triangles), len(cmesh.edges)
        pt, ee = cmesh.num_vertices * t, e * (e - 1) // 2
        # (an edge pair can be met in several cells before the exact test: raw room to spare)
        return Capacity(16 * t, 4 * pt, pt, 16 * e, 16 * ee, ee)
    return allocate(x0, cmesh, radius, capacity, multiplier=CONTACT_ROOM).capacity


def _few_pairs(cmesh) -> bool:
    """Whether a sheet has at most :data:`CONTACT_ALL_PAIRS` pairs of primitives."""
    v, t, e = cmesh.num_vertices, len(cmesh.triangles), len(cmesh.edges)
    return v * t + e * (e - 1) // 2 <= CONTACT_ALL_PAIRS


def pairs_within(x: np.ndarray, cmesh, dhat: float):
    """Candidate pairs of positions ``x`` that hold every pair within ``dhat``: a small sheet's
    every pair, from the host (a broad phase compiles, seconds), else the broad phase's."""
    return all_pairs(cmesh, x) if _few_pairs(cmesh) else allocate(x, cmesh, dhat)


def contact_summary(x: np.ndarray, pairs, params: FoldParams) -> dict:
    """The result's contact figures at positions ``x`` over the solve's last candidate
    ``pairs`` (gathered there): ``contact_dhat``, ``contact_pairs`` (pairs closer than it) and
    ``contact_min_ratio`` (the least distance of a candidate over it)."""
    dhat = float(params.contact.dhat)
    report = _contact_report(jnp.asarray(x, params.rest_length.dtype), pairs, dhat)
    return {
        "contact_kappa": float(params.contact.kappa),
        "contact_dhat": dhat,
        "contact_pairs": int(report.num_active),
        "contact_min_ratio": float(report.min_ratio),
    }


def _check_room(state, x, structure: Structure) -> None:
    """Raise :class:`_ContactOverflow` where a solve stopped for want of room for its pairs,
    with capacities that hold those of ``x``, where it stopped."""
    if int(state.status) == Status.CONTACT_OVERFLOW:
        old = state.reference.pairs.capacity
        pairs = reallocate(jnp.asarray(x), state.reference.pairs, structure.contact, CONTACT_ROOM)
        # what overflowed at least doubled: a fold that outgrew its room mid-way grows on (each
        # try compiles)
        grown = (max(n, 2 * c) if n > c else c for n, c in zip(pairs.capacity, old, strict=True))
        raise _ContactOverflow(Capacity(*grown))


class _Solved(NamedTuple):
    """What a solve hands back to :func:`fold` (host values but the state)."""

    state: object
    metrics: dict
    positions: np.ndarray
    angles: np.ndarray
    samples: list
    out_of_time: bool
    iterations: int
    compile_time: float
    wall_time: float
    frames: list


class Frame(NamedTuple):
    """One state of a fold's path: its fold percent (a fraction), positions (V, 3) and per-edge
    fold angles (E,) (radians, unwrapped)."""

    percent: float
    positions: np.ndarray
    fold_angles: np.ndarray


# continuation in fold percent: the first step and the largest (fractions of the way), the
# smallest before a step is taken whatever it does, the fold-angle change (radians) beyond which
# a step counts as a jump to another branch, the intermediate steps' tolerance and iterations
PATH_FIRST_STEP = 0.125
PATH_MAX_STEP = 0.25
PATH_MIN_STEP = 1.0 / 512
PATH_JUMP = 1.0
# a step that jumps again to where the last one jumped, at least this fraction as far from
# halfway there, is taken: the jump does not shrink with the step (a snap-through; a branch
# turning fast but smoothly turns half as far in half the step)
PATH_SNAP = 0.75
PATH_TOL = 1e-6
PATH_STEP_ITERATIONS = 200
PATH_EASY_ITERATIONS = 20
PATH_SOFT_AXIAL = 30.0
# the hinge barriers' gap on the way (radians; narrowed back to the scene's with the stiffening):
# a crease held at a narrow wall lets a step turn it by a fraction of the gap only, and the
# second-order turn of any step that moves its faces is larger than that
PATH_HINGE_GAP = 1e-2
PATH_END = 2.0


# jitted: run op by op, its dozens of small programs would each compile anew for every shape
_initial_reference = jax.jit(initial_reference)
_contact_gradient = jax.jit(jax.grad(contact_energy))
_contact_report = jax.jit(contact_report)


def _shifted(on_chunk, offset: int, iterations: int, sample: dict) -> None:
    on_chunk(offset + iterations, sample)


def _warning_sign(solved: _Solved, mesh, dtype) -> str | None:
    """What makes a direct solve from flat worth following again from flat: it stalled (or met
    a non-finite value) in float64, a crease went through itself, or a triangle collapsed; else
    ``None`` (converged and clean, or cut short by the user's limits)."""
    status = int(solved.state.status)
    if status == Status.RUNNING:  # the user's limits: no time or iterations for another try
        return None
    # float32 stalls at its own rounding on a large sheet: the path would not lift that
    if status in (Status.STALLED, Status.NONFINITE) and dtype == jnp.float64:
        return "stalled"
    if np.any(np.abs(solved.angles) > np.pi + HINGE_GAP):
        return "through pi"
    if len(collapsed_triangles(np.asarray(solved.positions, np.float64), mesh)[0]):
        return "collapsed"
    return None


def is_unfolded(x: np.ndarray, mesh) -> bool:
    """Whether positions ``x`` (V, 3) are the flat, unfolded sheet, however it is placed (a FOLD
    file drawn in the x-z plane, say): every triangle's normal the same, to 1e-9. A sheet folded
    flat is planar too, but half its triangles face the other way."""
    p = np.asarray(x, np.float64)[mesh.triangles]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    if not np.all(norm > 0):
        return False
    n = n / norm
    return bool(np.min(n @ n[0]) >= 1.0 - 1e-9)


def needs_continuation(mesh) -> bool:
    """Whether :func:`fold` follows the path from flat by default: where the scene gets the
    barriers (a crease driven to a full fold, see :func:`~origami_jax.energy.needs_barriers`)."""
    return needs_barriers(mesh)


def _solve_path(
    solver, mesh, structure, params, start, tol, max_iter, max_time, record_every, on_chunk
) -> _Solved:
    """Fold along the physical path: the fold percent raised from 0 in steps, each solve
    started from the last one's state (positions and reference), as paper is folded and as
    Origami Simulator's percent slider does. A step that does not converge, or in which some
    crease turns by more than :data:`PATH_JUMP` (a jump to another branch), is retried at half
    the size; two easy steps in a row let the next grow. A jump that does not shrink when the
    step is halved (at least :data:`PATH_SNAP` of it, to the same fold percent from halfway) is
    a snap-through, where the branch followed ends: that step is taken.

    On the way the bars and facets are soft, in Origami Simulator's ratios to the crease
    (:data:`PATH_SOFT_AXIAL`, facets as the crease: a sheet that cannot fold rigidly bends and
    stretches instead of folding creases the wrong way), and the hinge barriers' gap is
    :data:`PATH_HINGE_GAP`; at full percent a second stretch of the path (to
    :data:`PATH_END`) stiffens them back to the user's and narrows the gap back to the scene's,
    so the result is the equilibrium of the model asked for. The tolerance is relative to the
    gradient at the flat start fully driven (the creases' alone there, as a direct solve's);
    the intermediate steps stop at :data:`PATH_TOL`."""
    dtype = params.rest_length.dtype
    full = params.percent
    x = np.asarray(mesh.vertices if start is None else start, np.float64)

    k = params.stiffness
    crease = jnp.mean(k.crease)
    # softer only, never stiffer, and not at all without creases' stiffness to measure by
    soft_axial = jnp.where(
        crease > 0, jnp.minimum(1.0, PATH_SOFT_AXIAL * crease / jnp.mean(k.axial)), 1.0
    )
    soft_facet = jnp.where(crease > 0, jnp.minimum(1.0, crease / jnp.mean(k.facet)), 1.0)
    base_gap = structure.barriers.hinge_gap
    wide = max(1.0, PATH_HINGE_GAP / base_gap) if base_gap > 0 else 1.0
    user_gap = 1.0 if params.gap_scale is None else params.gap_scale

    def problem_at(t, x, reference):
        # t in [0, 1]: the fold percent raised at soft stiffness; t in [1, 2]: the stiffness
        # raised to the user's at full percent
        soft = max(0.0, 1.0 - max(t - 1.0, 0.0))
        stiffness = k._replace(axial=k.axial * soft_axial**soft, facet=k.facet * soft_facet**soft)
        at = params._replace(
            percent=jnp.asarray(full * min(t, 1.0), dtype),
            stiffness=stiffness,
            gap_scale=jnp.asarray(wide**soft * user_gap, dtype),
        )
        problem = make_problem(mesh, structure, at, x, tol, reference=reference)
        return prepared(solver, problem, mesh, dtype)

    problem, padding = problem_at(1.0, x, None)
    # the start's reference, of the problem as solved (padded: compiled once per bucket)
    reference = _initial_reference(problem.start, problem.structure, problem.params)
    problem = replace(problem, reference=reference)
    edges = mesh.num_edges if padding is None else padding.edges(mesh.num_edges)
    (start_c, advance_c), compile_time = compiled(solver, problem, edges)
    t0 = time.perf_counter()
    first, m, _, angles = jax.device_get(start_c(problem))
    grad_ref = float(first.grad_max0)
    frames = [Frame(0.0, x, np.asarray(angles[: mesh.num_edges], np.float64))]
    samples = [_sample(first, m, 0.0)]  # the start, fully driven, as a direct solve's
    watched = np.asarray(structure.hinge_bars)[: structure.num_creases + structure.num_facets]
    done, step, iterations, calm = 0.0, PATH_FIRST_STEP, 0, True
    jumped = None  # (fraction, jump) of the last step refused for its jump alone
    pace = Pace()  # every step runs the same compiled solve
    while True:
        fraction = min(PATH_END, done + step)
        last = fraction >= PATH_END

        def retol(state, problem, last=last):
            g0 = float(state.grad_max0)
            goal = (tol if last else max(tol, PATH_TOL)) * grad_ref
            return replace(problem, tol=jnp.asarray(goal / g0 if g0 > 0 else tol, dtype))

        spent = time.perf_counter() - t0
        budget = max_iter - iterations if last else min(PATH_STEP_ITERATIONS, max_iter - iterations)
        state, m, xk, angles_k, chunk, out_of_time = drive(
            solver,
            start_c,
            advance_c,
            problem_at(fraction, x, reference)[0],
            budget,
            None if max_time is None else max(max_time - spent, 0.0),
            record_every,
            None if on_chunk is None else functools.partial(_shifted, on_chunk, iterations),
            retol=retol,
            pace=pace,
        )
        m, xk, angles_k = jax.device_get((m, xk, angles_k))
        angles_k = angles_k[: mesh.num_edges]
        if padding is not None:
            m, xk = padding.metrics(m), padding.positions(xk)
        _check_room(state, xk, structure)
        steps = int(state.iteration)
        for sample in chunk[1:]:  # each step's start is the last one's end
            samples.append(
                {
                    **sample,
                    "iteration": iterations + sample["iteration"],
                    "wall_time": spent + sample["wall_time"],
                    "grad_norm_rel": sample["grad_norm_rel"]
                    * float(state.grad_max0)
                    / (grad_ref if grad_ref > 0 else 1.0),
                }
            )
        iterations += steps
        converged = int(state.status) == Status.CONVERGED
        # a jump: a crease or facet (not a free hinge, which may swing) turning far in a step
        turned = np.abs(angles_k - frames[-1].fold_angles)[watched]
        jump = float(np.max(turned, initial=0.0))
        spent_all = out_of_time or iterations >= max_iter
        # a step to where the last one jumped that jumps about as far from halfway there: the
        # branch followed ends in between (a snap-through), and smaller steps would only
        # close in on that point
        again = jumped is not None and abs(fraction - jumped[0]) < 1e-12
        snap = converged and again and jump >= PATH_SNAP * jumped[1]
        if (converged and jump <= PATH_JUMP) or snap or step <= PATH_MIN_STEP or spent_all:
            if jumped is not None and fraction >= jumped[0] - 1e-12:
                jumped = None
            x = np.asarray(xk, np.float64)
            reference = state.reference
            done = fraction
            frame = Frame(float(full) * min(fraction, 1.0), x, np.asarray(angles_k, np.float64))
            if fraction > 1.0 and frames[-1].percent == frame.percent:
                frames[-1] = frame  # stiffening at full percent: one frame, the latest state
            else:
                frames.append(frame)
            if spent_all and not last:
                # out of time or iterations part of the way: whatever that step reached, the
                # fold is not done (fold() reports the limit)
                state = state._replace(status=jnp.asarray(Status.RUNNING, jnp.int32))
            if last or spent_all:
                break
            # grow after an easy step, and after a halving only once two in a row were easy: a
            # step just halved would fail again
            easy = converged and jump <= 0.5 * PATH_JUMP and steps <= PATH_EASY_ITERATIONS
            if easy and calm:
                step = min(PATH_MAX_STEP, 2.0 * step)
            calm = easy
        else:
            if converged:
                jumped = (fraction, jump)
            step *= 0.5
            calm = False
    m = dict(m)
    m["grad_norm_rel"] = float(state.grad_max) / grad_ref if grad_ref > 0 else 0.0
    return _Solved(
        state,
        m,
        x,
        np.asarray(angles_k, np.float64),
        samples,
        out_of_time,
        iterations,
        compile_time,
        time.perf_counter() - t0,
        frames,
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
