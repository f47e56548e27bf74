"""Fold many problems in one compiled, vmapped solve: :func:`fold_batch`.

Problems of different sizes are padded to shared **size buckets** (powers of two of the vertex,
bar, crease, facet, free-hinge and pinned counts, the element counts at least proportional to
the vertex bucket: :func:`bucket`), so that a stream of new patterns compiles only once per
bucket. Padding is inert by construction, with no mask in any kernel:

* padded vertices are pinned (they never move) and padded bars join two of them at their rest
  length 1 with zero stiffness: no energy, no force, no strain;
* padded hinges lie on four padded vertices folded flat, with target 0 and zero stiffness: no
  energy, no force, no fold-angle error;

so every energy, gradient, Hessian and maximum over a padded problem equals that of the
problem alone (means are rescaled to the real counts on the host). Results come back unpadded,
one :class:`~origami_jax.fold.FoldResult` per problem, in input order.

Problems that share one **topology** (the same pattern folded with other parameters, or
variants of one pattern with other geometry) are vmapped directly instead, unpadded, with one
copy of their index arrays for all the slots: the batched gathers and scatters then move
whole rows of the batch instead of one member's entries at a time (1.0 to 1.7 times the folds
per second of the same sets padded, over the runs of ``benchmarks/batch.py``). That is the
default for a topology with at least :data:`SHARED_TOPOLOGY_MIN` problems in one call (or one
pattern given for many parameter sets); it compiles once per topology instead of per bucket
(``share_topology`` chooses).

Problems of one compiled shape run in a fixed number of **slots** (``chunk_size``), each call
one vmapped solve of some iterations in which every member stops on its own tolerance; between
calls the members that have stopped hand in their results and their slots take the next
problems of the queue (continuous batching: nobody waits for the slowest member of a fixed
chunk). With several devices the slots are split across them (``jax.shard_map``). Between
calls the host shows progress; an interrupted batch (Ctrl-C) returns the problems already done.

Example:
  >>> from origami_jax import fold_batch, patterns
  >>> cps = [patterns.miura_ori(2, 2, fold_angle=a) for a in (0.5, 1.0, 1.5)]
  >>> results = fold_batch(cps)
  >>> [bool(r.converged) for r in results]
  [True, True, True]
"""

from __future__ import annotations

import time
import warnings
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import replace
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from origami_jax.energy import FoldParams, Stiffness, param_arrays, structure_arrays
from origami_jax.fold import (
    HISTORY_FIELDS,
    FoldResult,
    _reason,
    _sample,
    compiled,
    default_tol,
    next_chunk,
)
from origami_jax.metrics import METRIC_NAMES
from origami_jax.pattern import CreasePattern, PatternError
from origami_jax.progress import ProgressBar
from origami_jax.solvers import Dynamics, Newton, Solver, Status, get_solver
from origami_jax.solvers.base import (
    Problem,
    check_start,
    default_max_steps,
    rigid_gauge,
    rigid_gauges,
)
from origami_jax.solvers.blocksparse import block_plan
from origami_jax.solvers.dynamics import lumped_mass
from origami_jax.solvers.newton import layout_arrays

__all__ = [
    "fold_batch",
    "BatchSizes",
    "bucket",
    "problem_sizes",
    "compile_count",
    "SHARED_TOPOLOGY_MIN",
]

# four padding vertices carry every padded bar and hinge: a unit bar 0-1 and a flat hinge
_PAD_VERTICES = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
# the largest padded vertex count that batched Newton solves dense
BATCH_DENSE_MAX = 512
# problems of one topology in a call from which fold_batch vmaps them unpadded, with shared
# index arrays (below it they join the size buckets, whose compiled solves a stream reuses)
SHARED_TOPOLOGY_MIN = 16


class BatchSizes(NamedTuple):
    """The array sizes of a problem: vertices, bars, driven creases, facet creases, free
    hinges and pinned vertices (the static shapes a compiled solve depends on)."""

    vertices: int
    bars: int
    creases: int
    facets: int
    free: int
    pinned: int


def _pow2(n: int) -> int:
    return 0 if n <= 0 else 1 << (int(n) - 1).bit_length()


def bucket(sizes: BatchSizes) -> BatchSizes:
    """The padded sizes of a problem: each count rounded up to a power of two, with room for
    the four padding vertices and one padding bar (which padded hinges point to), and at least
    twice the padded vertex count of bars and as many creases and facet creases as vertices.

    The floors tie the element counts to the vertex bucket, so patterns of one size share a
    compiled solve whatever their mix of creases and facets (a stream of 100 random Miura-ori
    and waterbomb sheets makes 7 buckets instead of 17); dense Newton's cost is set by the
    vertex count, and the extra padded elements cost little."""
    vertices = _pow2(sizes.vertices + len(_PAD_VERTICES))
    return BatchSizes(
        vertices=vertices,
        bars=max(_pow2(sizes.bars + 1), 2 * vertices),
        creases=max(_pow2(sizes.creases), vertices),
        facets=max(_pow2(sizes.facets), vertices),
        free=_pow2(sizes.free),
        pinned=_pow2(sizes.pinned),
    )


def problem_sizes(pattern: CreasePattern) -> BatchSizes:
    """The unpadded :class:`BatchSizes` of a pattern's folding problem."""
    mesh = pattern.mesh
    s = structure_arrays(mesh)
    pieces = len(rigid_gauge(mesh, mesh.vertices)[0])
    return BatchSizes(
        mesh.num_vertices, len(s.bars), s.num_creases, s.num_facets, len(s.free), pieces
    )


class _Member(NamedTuple):
    index: int
    pattern: CreasePattern
    problem: Problem  # unpadded, NumPy leaves
    sizes: BatchSizes


def _pad_rows(a: np.ndarray, n: int, fill) -> np.ndarray:
    """``a`` with rows appended up to ``n``, each equal to ``fill``."""
    a = np.asarray(a)
    extra = n - a.shape[0]
    if extra <= 0:
        return a
    pad = np.broadcast_to(np.asarray(fill, a.dtype), (extra, *a.shape[1:]))
    return np.concatenate([a, pad])


def _per_element(k: Stiffness, sizes: BatchSizes) -> Stiffness:
    """Stiffnesses as one value per element (scalars broadcast), so problems stack."""
    return Stiffness(
        axial=np.broadcast_to(k.axial, (sizes.bars,)),
        facet=np.broadcast_to(k.facet, (sizes.facets,)),
        crease=np.broadcast_to(k.crease, (sizes.creases,)),
    )


def _padded(member: _Member, to: BatchSizes, solver: Solver) -> Problem:
    """The member's problem padded to the sizes ``to`` (NumPy leaves)."""
    p, s = member.problem, member.sizes
    st, prm = p.structure, p.params
    v = s.vertices
    pad_bar = [v, v + 1]
    pad_hinge = [v, v + 1, v + 2, v + 3]
    nc = st.num_creases
    hinges = np.concatenate(
        [
            _pad_rows(st.hinges[:nc], to.creases, pad_hinge),
            _pad_rows(st.hinges[nc:], to.facets, pad_hinge),
        ]
    ).astype(np.int32)
    hinge_bars = np.concatenate(
        [
            _pad_rows(st.hinge_bars[:nc], to.creases, s.bars),
            _pad_rows(st.hinge_bars[nc:], to.facets, s.bars),
        ]
    ).astype(np.int32)
    structure = replace(
        st,
        bars=_pad_rows(st.bars, to.bars, pad_bar).astype(np.int32),
        hinges=hinges,
        hinge_bars=hinge_bars,
        free=_pad_rows(st.free, to.free, pad_hinge).astype(np.int32),
        free_bars=_pad_rows(st.free_bars, to.free, s.bars).astype(np.int32),
        num_creases=to.creases,
    )
    k = _per_element(prm.stiffness, s)
    stiffness = Stiffness(
        axial=_pad_rows(k.axial, to.bars, 0.0),
        facet=_pad_rows(k.facet, to.facets, 0.0),
        crease=_pad_rows(k.crease, to.creases, 0.0),
    )
    params = FoldParams(
        target=_pad_rows(prm.target, to.creases, 0.0),
        percent=prm.percent,
        rest_length=_pad_rows(prm.rest_length, to.bars, 1.0),
        stiffness=stiffness,
    )
    start = np.concatenate([p.start, _pad_rows(_PAD_VERTICES, to.vertices - v, _PAD_VERTICES[0])])
    # every padding vertex is pinned in place (its rows repeat the first one): the gauge's
    # pins, then the padding vertices, then fill, to a length that fits every member of a bucket
    pinned = np.concatenate([p.pinned, np.arange(v, to.vertices)])
    projectors = np.concatenate([p.projectors, np.zeros((to.vertices - v, 3, 3))])
    length = to.pinned + to.vertices
    pinned = _pad_rows(pinned, length, v).astype(np.int32)
    projectors = _pad_rows(projectors, length, np.zeros((3, 3)))
    problem = replace(
        p,
        structure=structure,
        params=params,
        start=start,
        pinned=pinned,
        projectors=projectors,
    )
    return replace(problem, aux=_padded_aux(solver, member, problem, to))


def _padded_aux(solver: Solver, member: _Member, problem: Problem, to: BatchSizes):
    if isinstance(solver, Newton):
        st = problem.structure
        return layout_arrays(np.asarray(st.bars), np.asarray(st.hinges), to.vertices, None)
    if isinstance(solver, Dynamics) and solver.mass != "unit":
        return _pad_rows(lumped_mass(member.pattern.mesh), to.vertices, 1.0)
    return None


def _start(index: int, pattern: CreasePattern, start) -> np.ndarray:
    """The checked (V, 3) start of problem ``index`` (the pattern's own, else flat)."""
    mesh = pattern.mesh
    if start is None and pattern.start is not None:
        start = pattern.start[mesh.source_vertex]
    if start is None:
        start = mesh.vertices
    start = np.asarray(start, np.float64)
    if start.shape != mesh.vertices.shape:
        raise PatternError(
            f"start {index}: expected shape {mesh.vertices.shape}, got {start.shape}"
        )
    bad = ~np.isfinite(start).all(axis=1)
    if bad.any():
        raise PatternError(f"start {index}: vertex {int(np.flatnonzero(bad)[0])} is not finite")
    return start


def _members(patterns, percents, stiffnesses, starts, tol) -> list[_Member]:
    """The problems (unpadded, NumPy leaves): index arrays, gauges and step limits computed
    once for all the patterns of one mesh topology (on arrays this small Python's per-call
    overhead costs more than the arithmetic: 0.4 ms a problem, one by one)."""
    n = len(patterns)
    checked = [_start(k, cp, starts[k]) for k, cp in enumerate(patterns)]
    groups: dict[tuple, list[int]] = {}
    for k, cp in enumerate(patterns):
        mesh = cp.mesh
        arrays = (mesh.triangles, mesh.edges, mesh.role)
        groups.setdefault((mesh.num_vertices, *(a.tobytes() for a in arrays)), []).append(k)
    shared: list = [None] * n
    for ks in groups.values():
        mesh = patterns[ks[0]].mesh
        structure = structure_arrays(mesh)
        flat = np.stack([patterns[k].mesh.vertices for k in ks])
        start = np.stack([checked[k] for k in ks])
        pinned, projectors = rigid_gauges(mesh.triangles, flat, start, ks)
        steps = default_max_steps(mesh.triangles, flat)
        for j, k in enumerate(ks):
            shared[k] = (structure, pinned[j], projectors[j], steps[j])
    members = []
    for k, cp in enumerate(patterns):
        structure, pinned, projectors, max_step = shared[k]
        problem = Problem(
            structure=structure,
            params=param_arrays(cp, percents[k], stiffnesses[k]),
            start=checked[k],
            pinned=pinned,
            projectors=projectors,
            tol=np.asarray(tol),
            max_step=np.asarray(max_step),
        )
        sizes = BatchSizes(
            cp.mesh.num_vertices,
            len(structure.bars),
            structure.num_creases,
            structure.num_facets,
            len(structure.free),
            len(pinned),
        )
        members.append(_Member(k, cp, problem, sizes))
    return members


def _topology(member: _Member) -> tuple:
    """What a compiled solve with shared index arrays needs equal: the structure's arrays."""
    st = member.problem.structure
    arrays = (st.bars, st.hinges, st.hinge_bars, st.free, st.free_bars)
    return (member.sizes, *(np.asarray(a).tobytes() for a in arrays))


def _shared(member: _Member, solver: Solver, layout) -> Problem:
    """The member's problem unpadded (NumPy leaves), stiffnesses as per-element arrays (so
    scalar and per-element ones stack), with its solver's static data (Newton: ``layout``,
    built once for all slots)."""
    problem, s = member.problem, member.sizes
    stiffness = _per_element(problem.params.stiffness, s)
    aux = layout if isinstance(solver, Newton) else _padded_aux(solver, member, problem, s)
    return replace(problem, params=problem.params._replace(stiffness=stiffness), aux=aux)


def _problem_axes(solver: Solver) -> Problem:
    """vmap axes of slots with shared topology: index arrays (and Newton's layout, built
    from them) unbatched, the rest batched."""
    aux = None if isinstance(solver, Newton) else 0
    return Problem(
        structure=None, params=0, start=0, pinned=0, projectors=0, tol=0, max_step=0, aux=aux
    )


def _per_problem(value, n: int, what: str) -> list:
    """A value shared by all ``n`` problems, or a sequence with one per problem."""
    if isinstance(value, (list, tuple)) and not isinstance(value, Stiffness):
        if len(value) != n:
            raise ValueError(f"{what}: {len(value)} values for {n} problems")
        return list(value)
    if isinstance(value, np.ndarray) and what in ("percent", "tol") and value.ndim == 1:
        if len(value) != n:
            raise ValueError(f"{what}: {len(value)} values for {n} problems")
        return list(value)
    return [value] * n


_COMPILES: list[int] = [0]


def compile_count() -> int:
    """How many batched solves :func:`fold_batch` has compiled in this process."""
    return _COMPILES[0]


def _wrap(devices: list):
    """vmap over the batch axis; with several devices, each takes a slice of it."""

    def wrap(fn, in_axes):
        batched = jax.vmap(fn, in_axes=in_axes)
        if len(devices) == 1:
            return batched
        mesh = jax.sharding.Mesh(np.array(devices), ("batch",))
        spec = jax.sharding.PartitionSpec("batch")
        in_specs = jax.tree.map(
            lambda a: spec if a == 0 else jax.sharding.PartitionSpec(),
            in_axes,
            is_leaf=lambda a: a is None,
        )
        return jax.shard_map(batched, mesh=mesh, in_specs=in_specs, out_specs=spec, check_vma=False)

    return wrap


def _chunk_size(requested: int | None, n: int, solver: Solver, to: BatchSizes, devices) -> int:
    if requested is None:
        requested = 256
        if isinstance(solver, Newton):
            # keep the slots' dense matrices near 256 MB in all
            per_member = (3 * to.vertices) ** 2 * 8
            requested = max(1, min(256, 2 ** int(np.log2(max(2**28 // per_member, 1)))))
    size = min(int(requested), _pow2(n))
    d = len(devices)
    return -(-size // d) * d


def fold_batch(
    patterns: CreasePattern | Sequence[CreasePattern],
    percent: float | Sequence[float] = 1.0,
    stiffness: Stiffness | dict | Sequence | None = None,
    starts: Sequence[np.ndarray | None] | None = None,
    solver: str | Solver = "newton",
    tol: float | None = None,
    max_iter: int = 100_000,
    dtype=None,
    chunk_size: int | None = None,
    devices: Sequence | None = None,
    progress: bool | None = None,
    max_time: float | None = None,
    share_topology: bool | None = None,
) -> list[FoldResult | None]:
    """Fold many problems in vmapped, compiled solves; one :class:`FoldResult` per problem.

    Args:
      patterns: one pattern (folded once per parameter set) or a sequence of patterns, any
        sizes and topologies.
      percent, stiffness: one value for all, or a sequence with one per problem.
      starts: ``None`` or a sequence with one start (V_mesh, 3) or ``None`` per problem.
      solver: ``"newton"`` (dense Cholesky per member; solved (padded) sizes up to
        ``BATCH_DENSE_MAX`` vertices), ``"lbfgs"``, ``"dynamics"``, or a solver object.
      tol, max_iter, dtype, max_time: as in :func:`~origami_jax.fold`; ``max_time`` applies
        to each problem, from the moment it enters a slot.
      chunk_size: problems solved at once, the slots of a compiled solve (default 256, less
        for large Newton problems); rounded to a multiple of the device count.
      devices: the devices to split the slots across (default all of JAX's default backend).
      progress: show problems done / total on stderr (default: once a batch has run 2 s).
      share_topology: vmap problems of one topology unpadded with shared index arrays
        (faster; compiled once per topology): ``None`` (default) for a topology with at
        least :data:`SHARED_TOPOLOGY_MIN` problems or one pattern given for several
        parameter sets, ``True`` for every topology, ``False`` never (size buckets only).

    Returns:
      A list in input order. A problem's result equals folding it alone (to the rounding of a
      different summation order). Above Newton's ``dense_max`` (200) vertices, where a single
      fold solves sparse, its iteration count can be lower than the batch member's: it hands
      an exact-Hessian attempt that does not factor over to the convex part within the
      iteration, where the member spends one (the same steps; so at an iteration or time
      limit the two can stop at different points). When interrupted (KeyboardInterrupt),
      the list holds the results of the problems already done and ``None`` for the rest,
      with a warning.
    """
    one_pattern = isinstance(patterns, CreasePattern)
    if one_pattern:
        lengths = [
            len(v)
            for v in (percent, stiffness, starts)
            if isinstance(v, (list, tuple)) and not isinstance(v, Stiffness)
        ]
        if isinstance(percent, np.ndarray) and percent.ndim == 1:
            lengths.append(len(percent))
        patterns = [patterns] * (max(lengths) if lengths else 1)
    patterns = list(patterns)
    n = len(patterns)
    for k, cp in enumerate(patterns):
        if not isinstance(cp, CreasePattern):
            raise TypeError(f"fold_batch(): problem {k} is a {type(cp).__name__}, not a pattern")
    solver_obj = get_solver(solver)
    if isinstance(solver_obj, Dynamics) and solver_obj.remove_momentum:
        raise ValueError("fold_batch(): remove_momentum is not supported (padding has mass)")
    if isinstance(solver_obj, Newton) and solver_obj.linear_solver == "sparse":
        raise ValueError("fold_batch(): batched Newton solves dense; use linear_solver='auto'")
    dtype = jnp.dtype(dtype or jnp.result_type(float))
    if dtype == jnp.float64 and not jax.config.jax_enable_x64:
        raise ValueError(
            "float64 needs jax.config.update('jax_enable_x64', True) (or JAX_ENABLE_X64=1)"
        )
    tol = default_tol(dtype) if tol is None else float(tol)
    if int(max_iter) < 0:
        raise ValueError(f"max_iter must be >= 0, got {max_iter}")
    percents = _per_problem(percent, n, "percent")
    for k, pc in enumerate(percents):
        if not np.isfinite(pc):
            raise PatternError(f"percent {k}: must be finite, got {pc}")
    stiffnesses = _per_problem(stiffness, n, "stiffness")
    start_list = [None] * n if starts is None else _per_problem(list(starts), n, "starts")
    devices = list(devices) if devices is not None else jax.devices()

    members = _members(patterns, percents, stiffnesses, start_list, tol)
    topologies = [_topology(m) for m in members]
    count = Counter(topologies)
    # key: (sizes compiled for, topology if shared else None)
    groups: dict[tuple[BatchSizes, tuple | None], list[_Member]] = {}
    for m, topology in zip(members, topologies, strict=True):
        shared = share_topology
        if shared is None:
            shared = count[topology] >= (2 if one_pattern else SHARED_TOPOLOGY_MIN)
        key = (m.sizes, topology) if shared else (bucket(m.sizes), None)
        groups.setdefault(key, []).append(m)
    if isinstance(solver_obj, Newton):
        for to, _ in groups:
            if to.vertices > BATCH_DENSE_MAX:
                raise ValueError(
                    f"fold_batch(): a problem of {to.vertices} (padded) vertices is too large for "
                    f"batched dense Newton (<= {BATCH_DENSE_MAX}); use fold() or "
                    "solver='lbfgs'"
                )
    plan = []
    for (to, topology), group in groups.items():
        size = _chunk_size(chunk_size, len(group), solver_obj, to, devices)
        plan.append((to, group, size, topology is not None))

    results: list[FoldResult | None] = [None] * n
    bar = None
    if progress is not False:
        bar = ProgressBar(n, delay=0.0 if progress else 2.0, unit="problems")
    t_start = time.perf_counter()
    solved = [0]

    def finish(done: list[tuple[int, FoldResult]]) -> None:
        for index, result in done:
            results[index] = result
        solved[0] += len(done)
        if bar is not None:
            rate = solved[0] / max(time.perf_counter() - t_start, 1e-9)
            bar.update(solved[0], f"{rate:.0f}/s")

    try:
        for to, group, size, shared in plan:
            _run_group(
                group, to, size, shared, solver_obj, dtype, devices, max_iter, max_time, finish
            )
    except KeyboardInterrupt:
        warnings.warn(
            f"fold_batch() interrupted: {solved[0]} of {n} problems have results, the rest "
            "are None",
            RuntimeWarning,
            stacklevel=2,
        )
    finally:
        if bar is not None:
            bar.close()
    return results


def _stack(*trees):
    return jax.tree.map(lambda *a: np.stack(a), *trees)


def _host_problem(problems: list[Problem], axes, dtype) -> Problem:
    """The slots' problems stacked along the batch axis (leaves of axis None taken once),
    floats in ``dtype``: NumPy arrays whose rows :func:`_set_rows` replaces."""
    stacked = jax.tree.map(
        lambda a, *rest: rest[0] if a is None else _stack(*rest),
        axes,
        *problems,
        is_leaf=lambda a: a is None,
    )
    floats = (stacked.params, stacked.start, stacked.projectors, stacked.tol, stacked.max_step)
    floats = jax.tree.map(lambda a: np.array(a, dtype), floats)
    aux = stacked.aux
    return replace(
        stacked,
        params=floats[0],
        start=floats[1],
        projectors=floats[2],
        tol=floats[3],
        max_step=floats[4],
        aux=aux.astype(dtype) if isinstance(aux, np.ndarray) and aux.dtype.kind == "f" else aux,
    )


def _set_rows(host: Problem, axes, rows: list[int], problems: list[Problem]) -> None:
    """Put ``problems`` into slots ``rows`` of the stacked ``host`` problem (batched leaves)."""

    def put(a, stacked, *values):
        if a is not None:
            jax.tree.map(lambda s, *v: s.__setitem__(rows, np.stack(v)), stacked, *values)

    jax.tree.map(put, axes, host, *problems, is_leaf=lambda a: a is None)


def _to_devices(tree, axes, devices):
    """``tree`` on ``devices``: batched leaves (axis 0) split across them, shared ones (axis
    None) copied to each."""
    if len(devices) == 1:
        return jax.device_put(tree, devices[0])
    mesh = jax.sharding.Mesh(np.array(devices), ("batch",))
    split = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("batch"))
    copied = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec())
    shardings = jax.tree.map(
        lambda a, leaf: jax.tree.map(lambda _: copied if a is None else split, leaf),
        axes,
        tree,
        is_leaf=lambda a: a is None,
    )
    return jax.device_put(tree, shardings)


def _take_rows(rows: list[int], new, old):
    """``old`` (host arrays with a batch axis) with ``rows`` taken from ``new``."""
    take = np.zeros(len(jax.tree.leaves(old)[0]), bool)
    take[rows] = True
    return jax.tree.map(
        lambda a, b: np.where(take.reshape(-1, *[1] * (a.ndim - 1)), a, b), new, old
    )


def _run_group(group, to, size, shared, solver, dtype, devices, max_iter, max_time, finish):
    """Solve problems of one compiled shape in ``size`` slots (padded to ``to``, or with
    ``shared`` topology unpadded): each call runs every slot for a number of iterations; the
    members that have stopped are handed to ``finish([(index, result), ...])`` and their slots
    take the next problems of the queue, so no member waits for the slowest of a fixed chunk.

    Slots left without a problem (the queue is empty) keep their last one, stopped: a member
    out of ``max_time`` is marked TIME_LIMIT in the state so its lane stops too.
    """
    queue = deque(group)
    first = group[0]
    axes = _problem_axes(solver) if shared else 0
    layout = None
    if shared and isinstance(solver, Newton):
        # one topology: all slots factor their Newton systems at once (blocksparse)
        st = first.problem.structure
        elements = [np.asarray(st.bars)] + ([np.asarray(st.hinges)] if len(st.hinges) else [])
        layout = replace(
            _padded_aux(solver, first, first.problem, to),
            plan=block_plan(elements, to.vertices),
        )

    def prepared(member: _Member) -> Problem:
        return _shared(member, solver, layout) if shared else _padded(member, to, solver)

    slots: list[_Member | None] = [queue.popleft() for _ in range(min(size, len(queue)))]
    slots += [None] * (size - len(slots))
    host = _host_problem([prepared(m or first) for m in slots], axes, dtype)
    problem = _to_devices(host, axes, devices)
    (start, advance), compile_time = compiled(
        solver,
        problem,
        to.bars,
        wrap=_wrap(devices),
        key=("batch", tuple(devices), shared),
        problem_axes=axes,
    )
    if compile_time > 0:
        _COMPILES[0] += 1
    t0 = time.perf_counter()
    state, m, x, angles = start(problem)
    check_start(solver, state)
    # (sample, entry): a refill's sample (entry: the slots refilled) counts only for those
    samples = [(_sample(state, m, 0.0), None)]
    entered = np.zeros(size)  # when each slot's problem entered, seconds after t0
    since = np.zeros(size, np.int64)  # index of its first sample
    # refill once this many slots are free (each refill costs a start of every slot)
    batch_refill = max(1, size // 16)
    free: list[int] = []
    chunk = 1
    while True:
        now = time.perf_counter() - t0
        status, iteration = samples[-1][0]["status"], samples[-1][0]["iteration"]
        occupied = np.array([member is not None for member in slots])
        going = (status == int(Status.RUNNING)) & (iteration < max_iter)
        if max_time is not None:
            going &= now - entered < max_time
        stopped = np.flatnonzero(occupied & ~going).tolist()
        if stopped:
            host_out = jax.device_get((state, m, x, angles))
            table, counts = _history_table(samples, size)
            done = []
            for b in stopped:
                out_of_time = status[b] == Status.RUNNING and iteration[b] < max_iter
                rows = since[b] + np.flatnonzero(counts[since[b] :, b])
                history = {k: v[rows, b] for k, v in table.items()}
                result = _result(
                    slots[b], b, to, *host_out, history, entered[b], out_of_time, solver,
                    dtype, now - entered[b], compile_time,
                )  # fmt: skip
                done.append((slots[b].index, result))
                slots[b] = None
            finish(done)
            free += stopped
            timed = [b for b in stopped if status[b] == Status.RUNNING]
            if timed:  # stop their lanes: a running lane keeps the vmapped loop going
                flags = np.array(host_out[0].status)
                flags[timed] = Status.TIME_LIMIT
                state = _to_devices(host_out[0]._replace(status=flags), 0, devices)
        running = [b for b, member in enumerate(slots) if member is not None]
        if queue and free and (len(free) >= batch_refill or not running):
            refill = free[: len(queue)]
            free = free[len(refill) :]
            for b in refill:
                slots[b] = queue.popleft()
            _set_rows(host, axes, refill, [prepared(slots[b]) for b in refill])
            problem = _to_devices(host, axes, devices)
            fresh = start(problem)
            check_start(solver, fresh[0])
            old = (state, m, x, angles)
            state, m, x, angles = _take_rows(refill, *jax.device_get((fresh, old)))
            state = _to_devices(state, 0, devices)
            entry = np.zeros(size, bool)
            entry[refill] = True
            samples.append((_sample(state, m, time.perf_counter() - t0), entry))
            entered[refill] = samples[-1][0]["wall_time"]
            since[refill] = len(samples) - 1
            continue  # a refilled problem may stop at its start (max_iter 0, say)
        if not running:
            break
        # only the running members' samples are still needed
        keep = int(np.min(since[running]))
        samples, since = samples[keep:], since - keep
        iteration = samples[-1][0]["iteration"]
        steps = max(1, min(chunk, max_iter - int(np.max(iteration[running]))))
        t_chunk = time.perf_counter()
        # dispatch returns before the chunk has run: wait for it (see fold.drive)
        state, m, x, angles = jax.block_until_ready(advance(state, problem, np.int32(steps)))
        t_done = time.perf_counter()
        samples.append((_sample(state, m, t_done - t0), None))
        chunk = next_chunk(chunk, t_done - t_chunk, steps)


def _history_table(samples: list, size: int) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The samples' history fields as (S, size) arrays, and (S, size) whether each sample counts
    for each slot (a refill's sample counts only for the slots refilled)."""
    table = {
        k: np.stack([np.broadcast_to(np.asarray(s[k], np.float64), size) for s, _ in samples])
        for k in HISTORY_FIELDS
    }
    counts = np.stack([np.ones(size, bool) if e is None else e for _, e in samples])
    return table, counts


def _result(
    member, b, to, state, m, x, angles, history, entered, out_of_time, solver, dtype, wall, comp
):
    """Slot ``b``'s result, unpadded; ``history`` its samples' fields since it ``entered``."""
    s = member.sizes
    status = Status(int(state.status[b]))
    if status == Status.RUNNING:
        status = Status.TIME_LIMIT if out_of_time else Status.MAX_ITER
    metrics = {k: float(m[k][b]) for k in METRIC_NAMES}
    # padding adds exact zeros: means over the real elements only
    metrics["strain_mean"] *= to.bars / s.bars
    metrics["fold_angle_error_mean"] *= to.creases / s.creases if s.creases else 0.0
    iterations = int(state.iteration[b])
    tol = float(member.problem.tol)
    history = {**history, "wall_time": history["wall_time"] - entered}
    positions = np.asarray(x[b, : s.vertices], np.float64)
    return FoldResult(
        pattern=member.pattern,
        positions=positions,
        fold_angles=np.asarray(angles[b, : s.bars], np.float64),
        converged=status == Status.CONVERGED,
        status=status,
        reason=_reason(status, metrics, tol, iterations, positions, member.pattern.mesh),
        iterations=iterations,
        solver=solver.name,
        percent=float(member.problem.params.percent),
        dtype=dtype.name,
        wall_time=wall,
        compile_time=comp,
        history=history,
        **metrics,
    )
