"""Fold many problems in one compiled, vmapped solve: :func:`fold_batch`.

Problems of different sizes are padded to shared **size buckets** (powers of two of the vertex,
bar, crease, facet, free-hinge and pinned counts, the element counts at least proportional to
the vertex bucket: :func:`bucket`), so that a stream of new patterns compiles only once per
bucket. Padding is inert by construction, with no mask in any kernel:

* padded vertices are pinned (they never move) and padded bars join two of them at their rest
  length 1 with zero stiffness: no energy, no force, no strain;
* padded hinges lie on four padded vertices folded flat, with target 0 and zero stiffness: no
  energy, no force, no fold-angle error;
* with self-contact (``contact=``), padded contact primitives lie on padded vertices, which are
  inert to contact (:mod:`origami_jax.padding`): no pair has one;

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

Problems of one compiled shape run in a fixed number of **slots** (``chunk_size``) of one
compiled loop, every member stopping on its own tolerance. The problems wait in a queue on the
devices; inside the loop, a few slots at a time, those whose problem has stopped write its
result out and take the next problem of the queue (continuous batching: no slot waits for the
slowest member of a chunk, nor for the host). The queue takes the problems that fold furthest
first (:func:`_fold_extents`): slots of like problems waste less of each vmapped iteration, and
the last problems to enter finish quickly. With several devices the slots and the queue are
split across them (``jax.shard_map``); with several processes (``jax.distributed``, one per
host say) each folds a share on its own devices and every process returns all the results
(:mod:`origami_jax.processes` carries them). Each call runs about a tenth of a second of
iterations; the next one is dispatched before the host reads the results of the last, shows
progress and hands the finished problems on; an interrupted batch (Ctrl-C) returns the problems
already done. Few slots suit CPUs (:data:`CPU_SLOTS`, 32 per device: one device's slots stay in
its caches) (measured: docs/design-notes/measurements.md).

Example:
  >>> from origami_jax import fold_batch, patterns
  >>> cps = [patterns.miura_ori(2, 2, fold_angle=a) for a in (0.5, 1.0, 1.5)]
  >>> results = fold_batch(cps)
  >>> [bool(r.converged) for r in results]
  [True, True, True]
"""

from __future__ import annotations

import hashlib
import pickle
import time
import warnings
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import replace
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from origami_jax.caches import LruCache
from origami_jax.contact import Capacity, build_pairs
from origami_jax.energy import (
    FoldParams,
    Stiffness,
    needs_barriers,
    rest_lengths,
    stiffness_arrays,
    structure_arrays,
)
from origami_jax.fold import (
    HISTORY_FIELDS,
    FoldResult,
    checked_start,
    contact_capacity,
    contact_reach,
    contact_settings,
    contact_summary,
    default_tol,
    fold,
    measured,
    next_chunk,
    pairs_within,
    signature,
    stop_reason,
)
from origami_jax.metrics import METRIC_NAMES
from origami_jax.padding import (
    Sizes,
    bucket,
    pad_problem,
    problem_sizes,
    round_up,
    unpad_metrics,
)
from origami_jax.pattern import CreasePattern, PatternError
from origami_jax.processes import all_gather
from origami_jax.progress import ProgressBar
from origami_jax.solvers import Solver, Status, get_solver
from origami_jax.solvers.base import (
    Problem,
    default_max_steps,
    rigid_gauges,
)
from origami_jax.solvers.newton import BATCH_DENSE_MAX

__all__ = [
    "fold_batch",
    "BATCH_DENSE_MAX",
    "BatchSizes",
    "bucket",
    "problem_sizes",
    "compile_count",
    "SHARED_TOPOLOGY_MIN",
]

# problems of one topology in a call from which fold_batch vmaps them unpadded, with shared
# index arrays (below it they join the size buckets, whose compiled solves a stream reuses)
SHARED_TOPOLOGY_MIN = 16
# the sizes of a problem (its padding's home: origami_jax.padding)
BatchSizes = Sizes


class _Group(NamedTuple):
    """The per-problem arrays of the members of one mesh topology, stacked (leading axis: the
    group's members), as :func:`_members` computed them."""

    target: np.ndarray
    rest_length: np.ndarray
    start: np.ndarray
    pinned: np.ndarray
    projectors: np.ndarray
    max_step: np.ndarray


class _Member(NamedTuple):
    index: int
    pattern: CreasePattern
    problem: Problem  # unpadded, NumPy leaves
    sizes: BatchSizes
    topology: tuple  # :func:`_topology`, shared by the members of one mesh topology
    group: _Group | None = None  # its problem's arrays are row ``row`` of these
    row: int = 0
    extent: float = 0.0  # :func:`_fold_extents`


def _padded(member: _Member, to: Sizes, solver: Solver) -> Problem:
    """The member's problem padded to the sizes ``to`` (NumPy leaves), prepared."""
    return solver.prepare_batch(pad_problem(member.problem, member.sizes, to), member.pattern.mesh)


def _start(index: int, pattern: CreasePattern, start) -> np.ndarray:
    """The checked (V, 3) start of problem ``index`` (the pattern's own, else flat)."""
    start = checked_start(pattern, start, f"start {index}")
    return np.asarray(pattern.mesh.vertices, np.float64) if start is None else start


def _members(patterns, percents, stiffnesses, starts, tol) -> list[_Member]:
    """The problems (unpadded, NumPy leaves): index arrays, gauges and step limits computed
    once for all the patterns of one mesh topology (on arrays this small Python's per-call
    overhead costs more than the arithmetic: 0.4 ms a problem, one by one)."""
    n = len(patterns)
    default = stiffness_arrays(None)
    checked = [_start(k, cp, starts[k]) for k, cp in enumerate(patterns)]
    groups: dict[tuple, list[int]] = {}
    for k, cp in enumerate(patterns):
        mesh = cp.mesh
        arrays = (mesh.triangles, mesh.edges, mesh.role)
        # the barriers a pattern needs depend on its targets: a key of their own
        key = (mesh.num_vertices, needs_barriers(mesh), *(a.tobytes() for a in arrays))
        groups.setdefault(key, []).append(k)
    members: list = [None] * n
    tol = np.asarray(tol)
    for ks in groups.values():
        mesh = patterns[ks[0]].mesh
        structure = structure_arrays(mesh, free_barriers=False)
        flat = np.stack([patterns[k].mesh.vertices for k in ks])
        start = np.stack([checked[k] for k in ks])
        # variants of one pattern (other fold angles, stiffnesses) share their geometry: its
        # gauges and step limits are computed once (with fold_batch's setup, the devices wait)
        one = bool(np.all(flat == flat[:1])) and bool(np.all(start == start[:1]))
        geometry = slice(0, 1) if one else slice(None)
        pinned, projectors = rigid_gauges(mesh.triangles, flat[geometry], start[geometry], ks)
        steps = default_max_steps(mesh.triangles, flat[geometry])
        # param_arrays of every problem of the group at once
        rest = rest_lengths(flat[geometry], mesh.edges)
        if one:
            pinned, projectors, steps, rest = (
                np.broadcast_to(a, (len(ks), *a.shape[1:]))
                for a in (pinned, projectors, steps, rest)
            )
        driven = mesh.edges_with_role("driven")
        target = np.stack([patterns[k].mesh.target for k in ks])[:, driven].astype(np.float64)
        sizes = BatchSizes(
            mesh.num_vertices,
            len(structure.bars),
            structure.num_creases,
            structure.num_facets,
            len(structure.free),
            pinned.shape[1],
            len(structure.triangles),
            structure.barriers,
        )
        topology = _topology(structure, sizes)
        group = _Group(target, rest, start, pinned, projectors, steps)
        extent = _fold_extents([percents[k] for k in ks], target)
        for j, k in enumerate(ks):
            problem = Problem(
                structure=structure,
                params=FoldParams(
                    target=target[j],
                    percent=np.asarray(percents[k], np.float64),
                    rest_length=rest[j],
                    # the default converted once for all
                    stiffness=default
                    if stiffnesses[k] is None
                    else stiffness_arrays(stiffnesses[k]),
                ),
                start=checked[k],
                pinned=pinned[j],
                projectors=projectors[j],
                tol=tol,
                max_step=np.asarray(steps[j]),
            )
            members[k] = _Member(
                k, patterns[k], problem, sizes, topology, group, j, float(extent[j])
            )
    return members


def _topology(structure, sizes: BatchSizes) -> tuple:
    """What a compiled solve with shared index arrays needs equal: the structure's arrays."""
    st = structure
    arrays = (st.bars, st.hinges, st.hinge_bars, st.free, st.free_bars, st.triangles)
    return (sizes, *(np.asarray(a).tobytes() for a in arrays))


def _problem_axes(shared_aux) -> Problem:
    """vmap axes of slots with shared topology: index arrays (and the solver's ``shared_aux``,
    built from them, where it has one) unbatched, the rest batched."""
    aux = 0 if shared_aux is None else None
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


# default slots per device: on CPUs few, so that one device's slots stay in its caches (with
# continuous batching nothing is gained by more); elsewhere (GPUs) many (32 per CPU device:
# docs/design-notes/measurements.md)
CPU_SLOTS = 32
SLOTS = 256


def _chunk_size(requested: int | None, n: int, solver: Solver, to: BatchSizes, devices) -> int:
    d = len(devices)
    if requested is None:
        requested = d * (CPU_SLOTS if all(x.platform == "cpu" for x in devices) else SLOTS)
        per_member = solver.batch_bytes(to.vertices)
        if per_member > 0:
            # keep the slots' working memory (Newton: dense matrices) near 256 MB in all
            fits = 2 ** int(np.log2(max(2**28 // per_member, 1)))
            requested = max(1, min(requested, fits))
    size = min(int(requested), round_up(n))
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
    processes: bool | None = None,
    contact: bool | float = False,
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
        to each problem from the moment it enters a slot, counted in iterations of the slot
        loop at the time one took in the last call (so are the results' ``wall_time``).
      chunk_size: problems solved at once, the slots of a compiled solve (default
        :data:`CPU_SLOTS` per CPU device, :data:`SLOTS` per other device, fewer for large
        Newton problems); rounded to a multiple of the device count.
      devices: the devices to split the slots across (default all of this process's devices
        of JAX's default backend, ``jax.local_devices()``).
      progress: show problems done / total on stderr (default: once a batch has run 2 s).
      share_topology: vmap problems of one topology unpadded with shared index arrays
        (faster; compiled once per topology): ``None`` (default) for a topology with at
        least :data:`SHARED_TOPOLOGY_MIN` problems or one pattern given for several
        parameter sets, ``True`` for every topology, ``False`` never (size buckets only).
      processes: share the problems among the processes of a run started with
        ``jax.distributed.initialize`` (one per host, say): each folds its share on its own
        devices, and every process returns all the results. ``None`` (default) or ``True``:
        whenever there are several processes (``jax.process_count() > 1``); ``False``: this
        process folds all the problems it was given, alone. Shared, the call is a collective:
        every process calls it with the same problems and options, in the same order of calls
        (a process given other problems raises ``ValueError`` in all of them).
      contact: self-contact, as in :func:`~origami_jax.fold` (``True``: each pattern's default
        reach; a number: that ``dhat``; ``False``, the default: none). Each problem is padded
        to its size bucket with its contact mesh and room for its candidate pairs (the
        padding is inert to contact); a problem whose pairs outgrow that room is folded again
        alone with :func:`~origami_jax.fold`, which grows it. Problems are solved directly
        (``fold``'s ``path="direct"``), never with shared index arrays.

    Returns:
      A list in input order. A problem's result equals folding it alone (to the rounding of a
      different summation order). Above Newton's ``dense_max`` (200) vertices, where a single
      fold solves sparse, its iteration count can be lower than the batch member's: it hands
      an exact-Hessian attempt that does not factor over to the convex part within the
      iteration, where the member spends one (the same steps; so at an iteration or time
      limit the two can stop at different points). When interrupted (KeyboardInterrupt),
      the list holds the results of the problems already done and ``None`` for the rest,
      with a warning; the problems that fold furthest are taken first (:func:`_fold_extents`),
      so those are the ones done. Shared among processes, an interrupted process hands the
      others the results it has and returns at once (``None`` for the others' shares); the
      others return them, ``None`` for the rest of its share, with a warning.

    Raises:
      ValueError: bad arguments; with ``processes``, processes given different problems.
      RuntimeError: with ``processes``, another process failed (its error is named), or JAX's
        distributed runtime cannot be reached (see :mod:`origami_jax.processes`).
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
    devices = list(devices) if devices is not None else jax.local_devices()
    foreign = [d for d in devices if d.process_index != jax.process_index()]
    if foreign:
        raise ValueError(
            f"fold_batch(): devices {foreign} belong to other processes; each process folds on "
            "its own (jax.local_devices())"
        )
    if processes is None:
        processes = jax.process_count() > 1
    processes = bool(processes) and jax.process_count() > 1

    dhat = None if contact is False else contact_reach(contact, solver_obj)
    if contact is not False and share_topology:
        raise ValueError("fold_batch(): contact pads each problem; share_topology=True cannot")
    members = _members(patterns, percents, stiffnesses, start_list, tol)
    if contact is not False:
        members = _with_contact(members, dhat)
        share_topology = False
    count = Counter(m.topology for m in members)
    # key: (sizes compiled for, topology if shared else None)
    groups: dict[tuple[BatchSizes, tuple | None], list[_Member]] = {}
    for m in members:
        topology = m.topology
        shared = share_topology
        if shared is None:
            shared = count[topology] >= (2 if one_pattern else SHARED_TOPOLOGY_MIN)
        key = (m.sizes, topology) if shared else (bucket(m.sizes), None)
        groups.setdefault(key, []).append(m)
    for to, _ in groups:
        solver_obj.check_batch(to.vertices)
    if processes:
        _check_same_problems(
            members, solver_obj, dtype, max_iter, max_time, share_topology, contact
        )
        # each process takes every P-th problem of each group in queue order (those that fold
        # furthest first), so every process gets as many of the long ones as of the short
        me, count_processes = jax.process_index(), jax.process_count()
        groups = {key: _queue_order(group)[me::count_processes] for key, group in groups.items()}
        groups = {key: group for key, group in groups.items() if group}
    plan = []
    for (to, topology), group in groups.items():
        if contact is not False:
            group = _with_capacity(group, to)
        size = _chunk_size(chunk_size, len(group), solver_obj, to, devices)
        plan.append((to, group, size, topology is not None))

    results: list[FoldResult | None] = [None] * n
    bar = None
    if progress is not False:
        mine = sum(len(group) for _, group, _, _ in plan)
        bar = ProgressBar(mine, delay=0.0 if progress else 2.0, unit="problems")
    t_start = time.perf_counter()
    solved, compiling = [0], [0.0]

    def finish(done: list[tuple[int, FoldResult]], compile_time: float = 0.0) -> None:
        """Store results; ``compile_time``: seconds a group spent compiling, which the rate
        shown leaves out."""
        for index, result in done:
            results[index] = result
        solved[0] += len(done)
        compiling[0] += compile_time
        if bar is not None:
            rate = solved[0] / max(time.perf_counter() - t_start - compiling[0], 1e-9)
            bar.update(solved[0], f"{rate:.0f}/s")

    interrupted = False
    try:
        for to, group, size, shared in plan:
            _run_group(
                group, to, size, shared, solver_obj, dtype, devices, max_iter, max_time, finish
            )
    except KeyboardInterrupt:
        interrupted = True
    except BaseException as e:
        if processes:  # the others would wait for this process's share: tell them why not
            all_gather(pickle.dumps(("failed", f"{type(e).__name__}: {e}")), wait=False)
        raise
    finally:
        if bar is not None:
            bar.close()
    if contact is not False and not interrupted:
        _refold_overflowed(results, members, solver_obj, tol, max_iter, dtype, max_time)
    stopped = []  # the other processes that were interrupted
    if processes:
        try:
            stopped = _gather_results(results, patterns, interrupted)
        except KeyboardInterrupt:
            interrupted = True
    if interrupted or stopped:
        done = sum(r is not None for r in results)
        who = "" if interrupted else f" in process{'es' * (len(stopped) > 1)} {stopped}"
        warnings.warn(
            f"fold_batch() interrupted{who}: {done} of {n} problems have results, the rest are "
            "None",
            RuntimeWarning,
            stacklevel=2,
        )
    return results


def _with_contact(members: list[_Member], dhat: float | None) -> list[_Member]:
    """The members with self-contact (:func:`~origami_jax.fold.contact_settings`): the
    contact mesh in their structures (its capacity set per group: :func:`_with_capacity`) and
    the barrier's parameters in theirs; the default reach computed once per sheet."""
    reaches: dict[tuple, float] = {}
    out = []
    for m in members:
        mesh = m.pattern.mesh
        key = (m.topology, np.asarray(mesh.vertices).tobytes())
        reach = dhat if dhat is not None else reaches.get(key)
        cmesh, params = contact_settings(mesh, m.problem.params, reach)
        reaches.setdefault(key, float(params.dhat))
        problem = replace(
            m.problem,
            structure=replace(m.problem.structure, contact=cmesh),
            params=m.problem.params._replace(contact=params),
        )
        sizes = m.sizes._replace(
            contact_triangles=len(cmesh.triangles), contact_edges=len(cmesh.edges)
        )
        out.append(m._replace(problem=problem, sizes=sizes))
    return out


def _with_capacity(group: list[_Member], to: BatchSizes) -> list[_Member]:
    """The members of one bucket, each with the contact pairs' capacity that holds every
    member's at its start (:func:`~origami_jax.fold.contact_capacity` of the padded problems:
    the compiled solve has one)."""
    capacities = []
    for m in group:
        padded = pad_problem(m.problem, m.sizes, to)
        c = padded.params.contact
        radius = float(c.dhat) + float(c.skin)
        capacities.append(contact_capacity(padded.structure.contact, padded.start, radius))
    capacity = Capacity(*np.max(np.array(capacities), axis=0).tolist())
    return [
        m._replace(
            problem=replace(
                m.problem, structure=replace(m.problem.structure, contact_capacity=capacity)
            )
        )
        for m in group
    ]


def _refold_overflowed(results, members, solver, tol, max_iter, dtype, max_time) -> None:
    """Each result that stopped for want of room for its contact pairs replaced by its fold
    alone (:func:`~origami_jax.fold`, which grows the room): the same problem, start and
    reach, solved directly."""
    for k, r in enumerate(results):
        if r is None or r.status != Status.CONTACT_OVERFLOW:
            continue
        problem = members[k].problem
        results[k] = fold(
            members[k].pattern,
            solver=solver,
            tol=tol,
            max_iter=max_iter,
            dtype=dtype,
            max_time=max_time,
            params=problem.params._replace(contact=None),
            start=problem.start,
            path="direct",
            contact=float(problem.params.contact.dhat),
        )


def _queue_order(group: list[_Member]) -> list[_Member]:
    """The order in which :func:`_run_group` queues a group's problems: those that fold
    furthest first (:func:`_fold_extents`), ties in input order."""
    return sorted(group, key=lambda m: m.extent, reverse=True)


def _check_same_problems(
    members, solver: Solver, dtype, max_iter, max_time, share, contact
) -> None:
    """Raise ValueError in every process unless every process was given the same problems
    and options (a digest of each process's, exchanged: each folds a share of the list)."""
    options = (solver.name, dtype.name, max_iter, max_time, share, contact)
    digest = hashlib.sha256(repr(options).encode())
    for m in members:
        p, mesh = m.problem, m.pattern.mesh
        arrays = (mesh.vertices, mesh.edges, mesh.target, p.start, p.params.percent, p.tol)
        for a in (*arrays, *jax.tree.leaves(p.params.stiffness)):
            digest.update(np.ascontiguousarray(a).tobytes())
    digests = all_gather(digest.digest())
    others = [k for k, d in enumerate(digests) if d != digests[0]]
    if others:
        raise ValueError(
            f"fold_batch(): processes {others} were given other problems or options than "
            "process 0; shared among processes, every process calls fold_batch with the same "
            "ones (processes=False: each process folds its own problems, alone)"
        )


def _gather_results(results: list, patterns: list[CreasePattern], interrupted: bool) -> list:
    """Fill ``results`` with the other processes' (each folded a share of them; this one
    ``interrupted``: only hand them its own, without waiting); the other processes that were
    interrupted. Results travel without their pattern, which every process has: each result
    gets its own process's pattern object back, as if folded there."""
    mine = [(k, replace(r, pattern=None)) for k, r in enumerate(results) if r is not None]
    kind = "interrupted" if interrupted else "results"
    parts = all_gather(pickle.dumps((kind, mine), protocol=5), wait=not interrupted)
    stopped = []
    for process, part in enumerate(parts):
        if part is None or process == jax.process_index():
            continue
        kind, payload = pickle.loads(part)  # from a process of this run: trusted
        if kind == "failed":
            raise RuntimeError(f"fold_batch(): process {process} failed: {payload}")
        if kind == "interrupted":
            stopped.append(process)
        for k, r in payload:
            results[k] = replace(r, pattern=patterns[k])
    return stopped


def _stack(*trees):
    return jax.tree.map(lambda *a: np.stack(a), *trees)


def _stacked_shared(members: list[_Member], solver: Solver, shared_aux, dtype) -> Problem:
    """The slots' problems of one topology, unpadded and stacked along the batch axis (NumPy
    leaves, floats in ``dtype``; the leaves that :func:`_problem_axes` shares taken once):
    stiffnesses as per-element arrays (so scalar and per-element ones stack), with the
    solver's static data (``shared_aux``, built once for all slots, else each member's
    ``prepare_batch``). Stacked field by field:
    a problem object per member cost more than the arrays it holds (about 30 us each)."""
    problems = [m.problem for m in members]
    sizes = members[0].sizes
    group = members[0].group
    if group is None or any(m.group is not group for m in members):
        group, rows = None, None
    else:  # rows of the arrays _members stacked (1,024 problems: 2.5 ms, against 8 one by one)
        rows = np.fromiter((m.row for m in members), np.int64, len(members))

    def stack(get, kind=dtype, field=None):
        if rows is not None and field is not None:
            return np.asarray(getattr(group, field)[rows], kind)
        return np.stack([get(p) for p in problems]).astype(kind)

    stiffnesses = [p.params.stiffness for p in problems]
    shared = all(k is stiffnesses[0] for k in stiffnesses)  # the default's one object, say

    def per_element(name: str, n: int) -> np.ndarray:
        if shared and np.ndim(getattr(stiffnesses[0], name)) == 0:
            return np.full((len(problems), n), getattr(stiffnesses[0], name), dtype)
        values = [getattr(k, name) for k in stiffnesses]
        if all(np.ndim(v) == 0 for v in values):  # scalars: one broadcast for all
            return np.repeat(np.asarray(values, dtype)[:, None], n, axis=1)
        return np.stack([np.broadcast_to(v, (n,)) for v in values]).astype(dtype)

    aux = shared_aux
    if aux is None:
        auxes = [solver.prepare_batch(m.problem, m.pattern.mesh).aux for m in members]
        aux = _float_leaves(_stack(*auxes), dtype)
    return replace(
        problems[0],
        params=FoldParams(
            target=stack(lambda p: p.params.target, field="target"),
            percent=stack(lambda p: p.params.percent),
            rest_length=stack(lambda p: p.params.rest_length, field="rest_length"),
            stiffness=Stiffness(
                axial=per_element("axial", sizes.bars),
                facet=per_element("facet", sizes.facets),
                crease=per_element("crease", sizes.creases),
            ),
        ),
        start=stack(lambda p: p.start, field="start"),
        pinned=stack(lambda p: p.pinned, np.int32, "pinned"),
        projectors=stack(lambda p: p.projectors, field="projectors"),
        tol=stack(lambda p: p.tol),
        max_step=stack(lambda p: p.max_step, field="max_step"),
        aux=aux,
    )


def _host_problem(problems: list[Problem], axes, dtype) -> Problem:
    """The slots' problems stacked along the batch axis (leaves of axis None taken once),
    floats in ``dtype`` (NumPy arrays)."""
    stacked = jax.tree.map(
        lambda a, *rest: rest[0] if a is None else _stack(*rest),
        axes,
        *problems,
        is_leaf=lambda a: a is None,
    )
    floats = (stacked.params, stacked.start, stacked.projectors, stacked.tol, stacked.max_step)
    floats = jax.tree.map(lambda a: np.array(a, dtype), floats)
    return replace(
        stacked,
        params=floats[0],
        start=floats[1],
        projectors=floats[2],
        tol=floats[3],
        max_step=floats[4],
        aux=_float_leaves(stacked.aux, dtype),
    )


def _float_leaves(tree, dtype):
    """``tree`` with its floating-point NumPy leaves in ``dtype`` (a solver's ``aux``)."""
    return jax.tree.map(
        lambda a: a.astype(dtype) if isinstance(a, np.ndarray) and a.dtype.kind == "f" else a,
        tree,
    )


def _specs(axes):
    """Partition specs of a prefix tree of batch axes: axis 0 split along the devices, ``None``
    (a shared leaf or subtree) the same on every device."""
    split, copied = jax.sharding.PartitionSpec("batch"), jax.sharding.PartitionSpec()
    return jax.tree.map(lambda a: split if a == 0 else copied, axes, is_leaf=lambda a: a is None)


def _shardings(axes, devices: list):
    """:func:`_specs` as shardings over ``devices``."""
    mesh = jax.sharding.Mesh(np.array(devices), ("batch",))
    return jax.tree.map(lambda s: jax.sharding.NamedSharding(mesh, s), _specs(axes))


def _to_devices(tree, axes, devices):
    """``tree`` on ``devices``: batched leaves (axis 0) split across them, shared ones (axis
    None) copied to each."""
    if len(devices) == 1:
        return jax.device_put(tree, devices[0])
    return jax.device_put(tree, _shardings(axes, devices))


class _Lanes(NamedTuple):
    """The slots of a compiled solve: each one's solver state and problem, the queue row of
    the problem it holds (-1: none), the iterations it has run since it entered and its start
    metrics (``entry``: the first sample of its history)."""

    state: object
    problem: Problem
    row: jax.Array
    age: jax.Array
    entry: dict


class _Out(NamedTuple):
    """The problems that left their slots in one call, in the order they left: queue row, end
    metrics, positions, per-edge fold angles, status, iterations, age (iterations of the loop
    it ran) and start metrics. Its length (a few times the slots) bounds the exits per call;
    it is all the loop carries besides the slots, so an iteration costs the same whatever the
    queue's length."""

    row: jax.Array
    metrics: dict
    x: jax.Array
    angles: jax.Array
    status: jax.Array
    iteration: jax.Array
    age: jax.Array
    entry: dict


_SAMPLED = ("fold_angle_error_max", "strain_max", "energy", "grad_norm_rel")


def _map_batched(fn, axes, *trees):
    """``fn`` over the leaves of problem pytrees ``trees`` that carry the batch axis (``axes``
    0); shared ones (``None``) taken from the first tree."""
    return jax.tree.map(
        lambda a, first, *rest: first if a is None else jax.tree.map(fn, first, *rest),
        axes,
        *trees,
        is_leaf=lambda a: a is None,
    )


def _select(take: jax.Array, new, old):
    """Rows of ``new`` where ``take`` (one flag per row), else of ``old``."""
    return jax.tree.map(
        lambda a, b: jnp.where(take.reshape(-1, *[1] * (a.ndim - 1)), a, b), new, old
    )


def _queue_fn(solver: Solver, num_edges: int, axes, width: int):
    """The compiled loop of one device's slots, pure: ``run(lanes, queue, next, count, out,
    steps, limits)``. Each iteration steps the running slots; once half of ``width`` slots have
    stopped (or none runs), up to ``width`` at a time of the stopped ones write their results
    into the outbox ``out`` and of the free ones take the next rows of ``queue`` (``next``
    (1,) the first not yet taken, ``count`` (1,) how many are real), starting there: gathered
    ``width`` slots wide, so entries and exits cost a fraction of an iteration. Up to
    ``steps`` iterations, until the outbox has no room for ``width`` more, or until every slot
    is free and the queue empty. ``limits``: ``(max_iter, time_steps)``: a problem stops (its
    status still RUNNING) at ``max_iter`` iterations or after ``time_steps`` iterations of
    the loop in its slot (``max_time`` over the measured time of one).

    Returns ``(lanes, next, out, exits (1,), iterations run (1,), end sample of the slots)``.
    """
    init = jax.vmap(solver.init, in_axes=(axes,))
    advance = jax.vmap(solver.run, in_axes=(0, axes, 0))
    measure = jax.vmap(lambda s, p: measured(s, p, num_edges)[1:], in_axes=(0, axes))

    def run(lanes, queue, nxt, count, out, steps, limits):
        max_iter, time_steps = limits
        size, slots, room = queue.start.shape[0], lanes.row.shape[0], out.row.shape[0]

        def running(lanes):
            s = lanes.state
            going = (s.status == Status.RUNNING) & (s.iteration < max_iter)
            return (lanes.row >= 0) & going & (lanes.age < time_steps)

        def stopped(lanes):
            return (lanes.row >= 0) & ~running(lanes)

        def pick(flags):
            """Up to ``width`` slots where ``flags``, first ones first: their indices (past the
            end: none), and the indices clipped."""
            at = jnp.nonzero(flags, size=width, fill_value=slots)[0]
            return at, jnp.minimum(at, slots - 1)

        def put(buffer, at, value):  # rows ``at`` of ``buffer`` (out of range: dropped)
            return buffer.at[at].set(value.astype(buffer.dtype), mode="drop")

        def record(lanes, out, filled, stop):
            at, lane = pick(stop)
            state = jax.tree.map(lambda a: a[lane], lanes.state)
            m, x, angles = measure(state, _map_batched(lambda a: a[lane], axes, lanes.problem))
            leaving = at < slots
            to = jnp.where(leaving, filled[0] + jnp.arange(width), room)
            out = _Out(
                row=put(out.row, to, lanes.row[lane]),
                metrics={k: put(out.metrics[k], to, m[k]) for k in out.metrics},
                x=put(out.x, to, x),
                angles=put(out.angles, to, angles),
                status=put(out.status, to, state.status),
                iteration=put(out.iteration, to, state.iteration),
                age=put(out.age, to, lanes.age[lane]),
                entry={k: put(out.entry[k], to, lanes.entry[k][lane]) for k in out.entry},
            )
            lanes = lanes._replace(row=put(lanes.row, at, jnp.full(width, -1)))
            return lanes, out, filled + jnp.sum(leaving, dtype=jnp.int32)

        def enter(lanes, nxt):
            at, _ = pick(lanes.row < 0)
            take = (at < slots) & (jnp.arange(width) < count[0] - nxt[0])
            at = jnp.where(take, at, slots)
            rows = nxt[0] + jnp.arange(width, dtype=jnp.int32)
            problem = _map_batched(lambda q: q[jnp.minimum(rows, size - 1)], axes, queue)
            fresh = init(problem)
            m, _, _ = measure(fresh, problem)
            lanes = _Lanes(
                state=jax.tree.map(lambda a, b: put(a, at, b), lanes.state, fresh),
                problem=_map_batched(lambda a, b: put(a, at, b), axes, lanes.problem, problem),
                row=put(lanes.row, at, rows),
                age=put(lanes.age, at, jnp.zeros(width)),
                entry={k: put(lanes.entry[k], at, m[k]) for k in lanes.entry},
            )
            return lanes, nxt + jnp.sum(take, dtype=jnp.int32)

        def unsettled(carry):
            lanes, nxt, _, filled = carry
            exits = jnp.any(stopped(lanes)) & (filled[0] + width <= room)
            return exits | (jnp.any(lanes.row < 0) & (nxt[0] < count[0]))

        def settle_once(carry):
            lanes, nxt, out, filled = carry
            stop = stopped(lanes)
            lanes, out, filled = jax.lax.cond(
                jnp.any(stop) & (filled[0] + width <= room),
                record,
                lambda l, o, f, s: (l, o, f),
                lanes,
                out,
                filled,
                stop,
            )
            lanes, nxt = jax.lax.cond(
                jnp.any(lanes.row < 0) & (nxt[0] < count[0]), enter, lambda *c: c, lanes, nxt
            )
            return lanes, nxt, out, filled

        def settle(carry):
            return jax.lax.while_loop(unsettled, settle_once, carry)

        def body(carry):
            k, lanes, nxt, out, filled, first = carry
            # the slots' problems stay fixed until the next settle: as a constant of the inner
            # loop (not carried), what depends on them alone is computed once (carried, an
            # iteration cost about a fifth more)
            problem, row, entry = lanes.problem, lanes.row, lanes.entry

            def due(state, age):
                lanes = _Lanes(state, problem, row, age, entry)
                waiting = jnp.sum(stopped(lanes)) + jnp.minimum(jnp.sum(row < 0), count[0] - nxt[0])
                return (2 * waiting >= width) | ~jnp.any(running(lanes))

            def more_steps(c):
                j, state, age = c
                return ~first & (j < steps) & ~due(state, age)

            def step(c):
                j, state, age = c
                go = running(_Lanes(state, problem, row, age, entry)).astype(jnp.int32)
                return j + 1, advance(state, problem, go), age + go

            k, state, age = jax.lax.while_loop(more_steps, step, (k, lanes.state, lanes.age))
            lanes, nxt, out, filled = settle(
                (lanes._replace(state=state, age=age), nxt, out, filled)
            )
            return k, lanes, nxt, out, filled, jnp.asarray(False)

        def more(carry):
            k, lanes, _, _, filled, first = carry
            # once the outbox is full, the call ends (the next one takes the stopped slots)
            return first | ((k < steps) & jnp.any(lanes.row >= 0) & (filled[0] + width <= room))

        # the first pass of the loop only settles (no steps): one copy of the settling code
        # (starts, measures, the outbox) in the program, where a settle before the loop was a
        # second one to compile
        filled = jnp.zeros(1, jnp.int32)
        carry = (jnp.int32(0), lanes, nxt, out, filled, jnp.asarray(True))
        k, lanes, nxt, out, filled, _ = jax.lax.while_loop(more, body, carry)
        m, _, _ = measure(lanes.state, lanes.problem)
        s = lanes.state
        sample = {**{key: m[key] for key in _SAMPLED}, "iteration": s.iteration}
        sample.update(row=lanes.row, age=lanes.age)
        return lanes, nxt, out, filled, k[None], sample

    return run


# a round of the queue holds up to this many problems per slot, and about this many bytes of
# problems; a larger group runs in several rounds (each ends with its slots draining)
_QUEUE_PER_SLOT = 32
_QUEUE_BYTES = 2**26
# the outbox holds this many exits per slot (a call ends when it is full)
_OUTBOX_PER_SLOT = 4
_INT32_MAX = 2**31 - 1
# compiled slot loops and jitted starts, the most recently used kept (origami_jax.caches)
_QUEUE_FNS = LruCache()
_INITS = LruCache()


def _sharded(fn, devices: list, in_axes: tuple, out_axes: tuple):
    """``fn`` (written over a batch axis) jitted on ``devices``, each taking a slice of the
    batched arguments and results (axes 0; ``None``: the same on every device). The results'
    shardings are given too: XLA would replicate the empty arrays among them (a pattern
    without facets), which the next call, compiled for split ones, would refuse."""
    if len(devices) == 1:
        return jax.jit(fn)
    mesh = jax.sharding.Mesh(np.array(devices), ("batch",))
    fn = jax.shard_map(
        fn, mesh=mesh, in_specs=_specs(in_axes), out_specs=_specs(out_axes), check_vma=False
    )
    return jax.jit(
        fn, in_shardings=_shardings(in_axes, devices), out_shardings=_shardings(out_axes, devices)
    )


def _entry_width(slots: int) -> int:
    """How many of a device's slots enter and exit at once: one per 16 slots. A CPU device's 16
    slots then settle as soon as one has stopped (measured: docs/design-notes/measurements.md)."""
    return max(1, slots // 16)


def _compiled_queue(solver, num_edges, axes, devices, width, args):
    """The compiled slot loop for these shapes (cached) and its compile time (0 when cached)."""
    key = (solver, signature(args[:5]), num_edges, tuple(devices), width)
    hit = _QUEUE_FNS.get(key)
    if hit is not None:
        return hit, 0.0
    lane_axes = _Lanes(state=0, problem=axes, row=0, age=0, entry=0)
    fn = _sharded(
        _queue_fn(solver, num_edges, axes, width),
        devices,
        (lane_axes, axes, 0, 0, 0, None, None),
        (lane_axes, 0, 0, 0, 0, 0),
    )
    t0 = time.perf_counter()
    _QUEUE_FNS[key] = compiled_fn = fn.lower(*args).compile()
    _COMPILES[0] += 1
    return compiled_fn, time.perf_counter() - t0


_SHAPES = LruCache()


def _limits(max_iter: int, max_time: float | None, per_step: float | None) -> tuple:
    """The slot loop's ``(max_iter, time_steps)``: ``max_time`` in iterations of the loop at
    the time one took (unknown before the first call, which runs one)."""
    if max_time is None:
        time_steps = _INT32_MAX
    elif per_step is None:
        time_steps = 0 if max_time <= 0 else _INT32_MAX
    else:
        time_steps = int(min(max_time / max(per_step, 1e-12), _INT32_MAX))
    return np.int32(max_iter), np.int32(time_steps)


def _lane_shapes(solver: Solver, problem: Problem, axes, num_edges: int):
    """Shapes of the slots' solver state, metrics, positions and angles (cached: tracing the
    solver costs a tenth of a second)."""
    key = (solver, signature(problem), num_edges)
    shapes = _SHAPES.get(key)
    if shapes is None:
        shapes = _SHAPES[key] = jax.eval_shape(
            jax.vmap(lambda p: measured(solver.init(p), p, num_edges), in_axes=(axes,)), problem
        )
    return shapes


# the solvers' shared_aux (Newton: a HessianLayout with its block plan) of the last topologies
# folded with shared index arrays
_SHARED_AUX = LruCache(16)


def _fold_extents(percents: list, targets: np.ndarray) -> np.ndarray:
    """(M,) the largest goal angle of each problem's driven creases, ``|percent * target|``
    (radians), of M scalar percents and ``targets`` (M, C): how far it folds from the flat
    sheet (a start is not counted), the order in which a group's problems enter the slots
    (iterations follow it: correlation 0.95 on the benchmark's waterbomb and Miura-ori sets).
    ``|p| max |t|``, which is ``max |p t|`` exactly (rounding is monotone)."""
    if not targets.shape[1]:
        return np.zeros(len(percents))
    return np.abs(np.asarray(percents, np.float64)) * np.max(np.abs(targets), axis=1)


def _run_group(group, to, size, shared, solver, dtype, devices, max_iter, max_time, finish):
    """Solve problems of one compiled shape in ``size`` slots (padded to ``to``, or with
    ``shared`` topology unpadded), handing each finished problem to ``finish([(index,
    result), ...])`` after the call in which it finished.

    The problems wait in a queue on the devices (each device its share); inside the compiled
    loop a slot whose problem has stopped writes its result out and takes the next problem
    (continuous batching: no slot waits for the slowest member of a chunk, nor for the host).
    Each call runs some iterations (about :data:`~origami_jax.fold.CHUNK_SECONDS`), between
    which the host collects results and shows progress. Time is measured per call; a
    problem's wall time and ``max_time`` count the loop iterations it spent in its slot at
    the measured time per iteration.
    """
    first = group[0]
    shared_aux = None
    if shared:
        # one topology: the solver's data shared by all slots (Newton: the plan that factors
        # their systems at once), kept for later calls (a design loop folds the same topology
        # again and again)
        key = (solver, first.topology)
        shared_aux = _SHARED_AUX.pop(key, None)
        if shared_aux is None:
            shared_aux = solver.shared_aux(first.problem, first.pattern.mesh)
        _SHARED_AUX[key] = shared_aux
    axes = _problem_axes(shared_aux) if shared else 0

    padded_first = None if shared else _padded(first, to, solver)

    def stacked(members: list[_Member]) -> Problem:
        """The problems of ``members`` stacked for the slots (free slots hold ``first``'s)."""
        if shared:
            return _stacked_shared(members, solver, shared_aux, dtype)
        problems = [padded_first if m is first else _padded(m, to, solver) for m in members]
        return _host_problem(problems, axes, dtype)

    d = len(devices)
    one = _map_batched(lambda a: a[0], axes, stacked([first]))
    member_bytes = sum(np.asarray(a).nbytes for a in jax.tree.leaves(one))
    rounds = int(np.clip(_QUEUE_BYTES // max(size * member_bytes, 1), 1, _QUEUE_PER_SLOT))
    q = size * (1 << (rounds.bit_length() - 1))  # a power of two times the slots
    qd = q // d
    # the problems that fold furthest enter first: the slots then hold problems of like
    # difficulty side by side (under vmap each iteration runs its slots' longest line search,
    # and the curvature terms for any member's exact attempt), and the last ones to enter,
    # whose slots see no refill, are quick
    remaining = deque(_queue_order(group))
    lanes = None
    init = jax.vmap(solver.init, in_axes=(axes,))
    per_step = None
    while remaining:
        segment = [remaining.popleft() for _ in range(min(q, len(remaining)))]
        # member j of the round goes to device j % d, at row j // d of that device's share
        member_at = np.full(q, -1)
        for j in range(len(segment)):
            member_at[(j % d) * qd + j // d] = j
        counts = np.bincount(np.arange(len(segment)) % d, minlength=d).astype(np.int32)
        host_queue = stacked([first if j < 0 else segment[j] for j in member_at])
        queue = _to_devices(host_queue, axes, devices)
        if solver.checks_start:  # a user's time step, say
            solver.check_start(_INITS.setdefault((solver, shared), jax.jit(init))(queue))
        if lanes is None:  # free slots, holding copies of the first problem
            problem = _map_batched(lambda a: a[np.zeros(size, int)], axes, host_queue)
            state, _, x_like, angles_like = _lane_shapes(solver, problem, axes, to.bars)
            state = jax.tree.map(lambda s: np.zeros(s.shape, s.dtype), state)
            free = np.full(size, -1, np.int32)
            entry = {k: np.zeros(size, dtype) for k in _SAMPLED}
            lanes = _Lanes(state, problem, free, np.zeros(size, np.int32), entry)
            lanes = _to_devices(lanes, _Lanes(0, axes, 0, 0, 0), devices)
            room = _OUTBOX_PER_SLOT * size
            outbox = _Out(
                row=np.zeros(room, np.int32),
                metrics={k: np.zeros(room, dtype) for k in METRIC_NAMES},
                x=np.zeros((room, *x_like.shape[1:]), dtype),
                angles=np.zeros((room, *angles_like.shape[1:]), dtype),
                status=np.zeros(room, np.int32),
                iteration=np.zeros(room, np.int32),
                age=np.zeros(room, np.int32),
                entry={k: np.zeros(room, dtype) for k in _SAMPLED},
            )
            outbox = _to_devices(outbox, 0, devices)
        nxt = _to_devices(np.zeros(d, np.int32), 0, devices)
        count = _to_devices(counts, 0, devices)
        limits = (np.int32(max_iter), np.int32(_INT32_MAX))
        run, compile_time = _compiled_queue(
            solver,
            to.bars,
            axes,
            devices,
            _entry_width(size // d),
            (lanes, queue, nxt, count, outbox, np.int32(1), limits),
        )
        finish([], compile_time)
        wall = np.zeros(q)  # seconds each row has run, up to its age ``aged``
        aged = np.zeros(q, np.int64)
        samples: dict[int, list] = {}
        chunk, left = 1, len(segment)
        limits = _limits(max_iter, max_time, per_step)
        lanes, nxt, out, filled, k, sample = run(
            lanes, queue, nxt, count, outbox, np.int32(chunk), limits
        )
        t_last = time.perf_counter()
        while True:
            out, filled, sample, k = jax.device_get((out, filled, sample, k))
            seconds, t_last = time.perf_counter() - t_last, time.perf_counter()
            iterations = int(np.max(k))
            if iterations:
                per_step = seconds / iterations
            chunk = next_chunk(chunk, seconds, max(iterations, 1))
            left -= int(np.sum(filled))
            if left:  # the next call, before this one's results are read
                limits = _limits(max_iter, max_time, per_step)
                lanes, nxt, next_out, next_filled, next_k, next_sample = run(
                    lanes, queue, nxt, count, outbox, np.int32(chunk), limits
                )
            for lane in np.flatnonzero(sample["row"] >= 0):
                r = lane // (size // d) * qd + int(sample["row"][lane])  # rows are per device
                wall[r] += (int(sample["age"][lane]) - aged[r]) * (per_step or 0.0)
                aged[r] = int(sample["age"][lane])
                samples.setdefault(r, []).append(
                    {key: float(sample[key][lane]) for key in (*_SAMPLED, "iteration")}
                    | {"wall_time": wall[r]}
                )
            done = []
            per_device = room // d  # each device's share of the outbox, filled from its start
            exits = [dev * per_device + i for dev in range(d) for i in range(int(filled[dev]))]
            for j in exits:
                r = j // per_device * qd + int(out.row[j])
                wall[r] += (int(out.age[j]) - aged[r]) * (per_step or 0.0)
                member = segment[member_at[r]]
                history = samples.pop(r, [])
                result = _result(
                    member, to, j, out, history, max_iter, solver, dtype, wall[r], compile_time
                )
                done.append((member.index, result))
            finish(done)
            if not left:
                break
            out, filled, k, sample = next_out, next_filled, next_k, next_sample


def _contact_figures(member: _Member, to: BatchSizes, x: np.ndarray, dtype) -> dict:
    """The result's contact figures (:func:`~origami_jax.fold.contact_summary`) at the padded
    positions ``x`` of a member with contact, over candidate pairs gathered there as its solve
    gathers them (within ``dhat`` and the skin, on its padded contact mesh, at the bucket's
    capacity: one compiled broad phase and report per bucket, not per pattern); where they
    outgrow that capacity, over those of the unpadded sheet."""
    params = jax.tree.map(lambda a: np.asarray(a, dtype), member.problem.params)
    dhat = float(params.contact.dhat)
    structure = pad_problem(member.problem, member.sizes, to).structure
    radius = dhat + float(params.contact.skin)
    pairs = build_pairs(x, structure.contact, radius, structure.contact_capacity)
    if bool(pairs.did_overflow):
        x = np.asarray(x[: member.sizes.vertices])
        pairs = pairs_within(x, member.problem.structure.contact, dhat)
    return contact_summary(x, pairs, params)


def _result(member, to, r, out, samples, max_iter, solver, dtype, wall, compile_time):
    """Queue row ``r``'s result, unpadded; ``samples``: its slot's samples between calls."""
    s = member.sizes
    status = Status(int(out.status[r]))
    iterations = int(out.iteration[r])
    if status == Status.RUNNING:
        status = Status.MAX_ITER if iterations >= max_iter else Status.TIME_LIMIT
    metrics = unpad_metrics({k: float(out.metrics[k][r]) for k in METRIC_NAMES}, s, to)
    entry = {k: float(out.entry[k][r]) for k in _SAMPLED} | {"iteration": 0, "wall_time": 0.0}
    last = {k: metrics[k] for k in _SAMPLED} | {"iteration": iterations, "wall_time": wall}
    rows = [entry] + [x for x in samples if 0 < x["iteration"] < iterations] + [last]
    if iterations == 0:
        rows = [entry]
    table = np.array([[x[k] for k in HISTORY_FIELDS] for x in rows], np.float64)
    history = dict(zip(HISTORY_FIELDS, table.T, strict=True))
    tol = float(member.problem.tol)
    positions = np.asarray(out.x[r, : s.vertices], np.float64)
    touching = {}
    if member.problem.structure.contact is not None:
        touching = _contact_figures(member, to, out.x[r], dtype)
    return FoldResult(
        pattern=member.pattern,
        positions=positions,
        fold_angles=np.asarray(out.angles[r, : s.bars], np.float64),
        converged=status == Status.CONVERGED,
        status=status,
        reason=stop_reason(status, metrics, tol, iterations, positions, member.pattern.mesh),
        iterations=iterations,
        solver=solver.name,
        percent=float(member.problem.params.percent),
        dtype=dtype.name,
        wall_time=wall,
        compile_time=compile_time,
        history=history,
        barriers=s.barriers,
        **touching,
        **metrics,
    )
