"""Batched Newton systems of one topology: a block-sparse Cholesky with the batch innermost.

``fold_batch`` solves many problems of one pattern topology with ``jax.vmap``. Vmapped, the
dense path of :mod:`origami_jax.solvers.newton` (a scatter of element Hessians into a
(3V x 3V) matrix, then LAPACK's Cholesky) costs each member more than a single solve does: XLA's
CPU scatter moves every 3 x 3 block of every member on its own, and the batched Cholesky calls
LAPACK once per member. Here the Hessian of all members is kept as 3 x 3 vertex blocks with the
batch as the last (contiguous) axis, only the blocks of the factor's sparsity pattern (a
minimum-degree order of the vertex graph, with its fill), and the factorization runs one vertex
at a time over all members at once (``lax.scan`` over vertices, so compile time does not grow
with the pattern).

The plan (:class:`BlockPlan`) depends only on the topology and is shared by the batch: it is
built once on the host (:func:`block_plan`) and carried in the Hessian layout. Unbatched (a
single solve), :func:`solve` runs the same kernel with a batch of one.

Shapes: V vertices, B batch members, N blocks stored (lower triangle of the filled pattern),
n the most blocks below the diagonal in one column, p = n (n + 1) / 2.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from origami_jax.solvers.innermost import batch_innermost

__all__ = [
    "BlockPlan",
    "Factor",
    "block_plan",
    "factor",
    "solve",
    "solve_factored",
]


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=[
        "order",
        "rank",
        "source",
        "target",
        "block_vertices",
        "diag",
        "column",
        "below",
        "pair_a",
        "pair_b",
        "pair_target",
    ],
    meta_fields=[],
)
@dataclass(frozen=True)
class BlockPlan:
    """Where each block goes in a block-sparse Cholesky factorization of fixed pattern.

    ``order`` (V,) the vertex eliminated at each step, ``rank`` (V,) its inverse; ``source``
    (K,) and ``target`` (K,): element Hessian block ``source`` (in the flattened (a, b) vertex
    blocks of the bars, then the hinges) adds into stored block ``target`` (only blocks on or
    below the diagonal in elimination order); ``block_vertices`` (N, 2) the (row, column)
    step of each stored block; per step k: ``diag`` (V,) its diagonal block. The steps run in
    a few consecutive **segments** (one ``lax.scan`` each), each padded to its own widest step
    (a minimum-degree order eliminates few-neighbour vertices first and the last separator
    last: one width for all padded a Miura-ori 4 x 4's 444 block products to 1,125). Per
    segment, a tuple entry of: ``column`` (steps, n) each step's blocks below the diagonal
    (padded with block N, kept zero), ``below`` (steps, n) their rows (padded with V, a spare
    row), ``pair_a``, ``pair_b`` (steps, p) the pairs of those blocks whose product updates
    block ``pair_target`` (steps, p) (padded with block N + 1, never read).
    """

    order: Array
    rank: Array
    source: Array
    target: Array
    block_vertices: Array
    diag: Array
    column: tuple[Array, ...]
    below: tuple[Array, ...]
    pair_a: tuple[Array, ...]
    pair_b: tuple[Array, ...]
    pair_target: tuple[Array, ...]

    @property
    def segments(self) -> list[tuple[int, int]]:
        """(first, end) step of each segment."""
        ends = np.cumsum([c.shape[0] for c in self.column])
        return [(int(e - c.shape[0]), int(e)) for e, c in zip(ends, self.column, strict=True)]


def _minimum_degree(neighbours: list[set[int]]) -> list[int]:
    """Greedy minimum-degree elimination order of a small graph (ties: lowest index)."""
    adj = [set(n) for n in neighbours]
    alive = set(range(len(adj)))
    order = []
    while alive:
        k = min(alive, key=lambda v: (len(adj[v]), v))
        order.append(k)
        alive.remove(k)
        for a in adj[k]:
            adj[a] |= adj[k]
            adj[a] -= {a, k}
        adj[k] = set()
    return order


def block_plan(elements: list[np.ndarray], num_vertices: int) -> BlockPlan:
    """The plan (NumPy arrays) for Hessians assembled from ``elements`` (each (n_el, k) vertex
    indices: the bars, then the hinges) on ``num_vertices`` vertices."""
    v = num_vertices
    neighbours: list[set[int]] = [set() for _ in range(v)]
    for e in elements:
        for row in np.asarray(e):
            for a in row:
                neighbours[a].update(int(b) for b in row if b != a)
    order = np.array(_minimum_degree(neighbours), np.int64)
    rank = np.empty(v, np.int64)
    rank[order] = np.arange(v)
    # the filled pattern: eliminating step k joins all its later neighbours
    later: list[set[int]] = [set() for _ in range(v)]
    for a in range(v):
        later[rank[a]].update(int(rank[b]) for b in neighbours[a] if rank[b] > rank[a])
    for k in range(v):
        below = sorted(later[k])
        for x, i in enumerate(below):
            later[i].update(below[x + 1 :])
    index: dict[tuple[int, int], int] = {}
    for k in range(v):
        index[(k, k)] = len(index)
        for i in sorted(later[k]):
            index[(i, k)] = len(index)
    zero, spare = len(index), len(index) + 1
    source, target, offset = [], [], 0
    for e in elements:
        e = np.asarray(e)
        k_ = e.shape[1]
        r = rank[e]
        a, b = np.meshgrid(np.arange(k_), np.arange(k_), indexing="ij")
        for el in range(e.shape[0]):
            keep = r[el][a] >= r[el][b]
            source += list(offset + (el * k_ + a[keep]) * k_ + b[keep])
            target += [
                index[(int(r[el][i]), int(r[el][j]))] for i, j in zip(a[keep], b[keep], strict=True)
            ]
        offset += e.shape[0] * k_ * k_
    as32 = functools.partial(np.asarray, dtype=np.int32)
    segments = {name: [] for name in ("column", "below", "pair_a", "pair_b", "pair_target")}
    for first, end in _segments([len(s) for s in later]):
        steps = range(first, end)
        n = max([1] + [len(later[k]) for k in steps])
        p = n * (n + 1) // 2
        column = np.full((len(steps), n), zero)
        below = np.full((len(steps), n), v)
        pair_a, pair_b = np.zeros((len(steps), p), np.int64), np.zeros((len(steps), p), np.int64)
        pair_target = np.full((len(steps), p), spare)
        for row, k in enumerate(steps):
            rows = sorted(later[k])
            column[row, : len(rows)] = [index[(i, k)] for i in rows]
            below[row, : len(rows)] = rows
            pairs = [(x, y) for x in range(len(rows)) for y in range(x + 1)]
            for j, (x, y) in enumerate(pairs):
                pair_a[row, j], pair_b[row, j] = x, y
                pair_target[row, j] = index[(rows[x], rows[y])]
        for name, a in zip(segments, (column, below, pair_a, pair_b, pair_target), strict=True):
            segments[name].append(as32(a))
    blocks = sorted(index, key=index.get)
    return BlockPlan(
        order=as32(order),
        rank=as32(rank),
        source=as32(source),
        target=as32(target),
        block_vertices=as32(blocks),
        diag=as32([index[(k, k)] for k in range(v)]),
        **{name: tuple(a) for name, a in segments.items()},
    )


def _segments(widths: list[int]) -> list[tuple[int, int]]:
    """Split the steps (``widths``: blocks below the diagonal at each) into at most three
    consecutive segments (first, end) that minimize the padded work, a step costing its
    segment's widest ``n (n + 1) / 2`` block products, ``n`` column blocks and a few more."""
    v = len(widths)
    w = np.asarray(widths, np.int64)
    # widest[i, j]: the widest step in [i, j] (j >= i)
    widest = np.maximum.accumulate(np.triu(np.broadcast_to(w, (v, v))), axis=1)

    def cost(steps, n):
        return steps * (n * (n + 1) // 2 + n + 4)

    best, cuts = None, []
    for i in range(v):  # [0, i), [i, j), [j, v) for every j in (i, v]; empty ones dropped
        j = np.arange(i + 1, v + 1)
        total = cost(j - i, widest[i, j - 1])
        total[:-1] += cost(v - j[:-1], widest[j[:-1], v - 1])
        if i > 0:
            total += cost(i, widest[0, i - 1])
        k = int(np.argmin(total))
        if best is None or total[k] < best:
            best = total[k]
            cuts = [(a, b) for a, b in ((0, i), (i, int(j[k])), (int(j[k]), v)) if b > a]
    return cuts


# -- 3 x 3 kernels on (3, 3, ...) blocks, elementwise over the trailing (batch) axes -----------


def _chol3(d: Array) -> tuple[Array, ...]:
    """Cholesky factor of a 3 x 3 block: (l00, l10, l11, l20, l21, l22); NaN if not positive
    definite."""
    l00 = jnp.sqrt(d[0, 0])
    l10 = d[1, 0] / l00
    l20 = d[2, 0] / l00
    l11 = jnp.sqrt(d[1, 1] - l10 * l10)
    l21 = (d[2, 1] - l20 * l10) / l11
    l22 = jnp.sqrt(d[2, 2] - l20 * l20 - l21 * l21)
    return l00, l10, l11, l20, l21, l22


def _lower_solve(f: tuple[Array, ...], b: Array) -> Array:
    """``L^-1 b`` for ``b`` (3, ...)."""
    l00, l10, l11, l20, l21, l22 = f
    y0 = b[0] / l00
    y1 = (b[1] - l10 * y0) / l11
    y2 = (b[2] - l20 * y0 - l21 * y1) / l22
    return jnp.stack([y0, y1, y2])


def _upper_solve(f: tuple[Array, ...], y: Array) -> Array:
    """``L^-T y`` for ``y`` (3, ...)."""
    l00, l10, l11, l20, l21, l22 = f
    x2 = y[2] / l22
    x1 = (y[1] - l21 * x2) / l11
    x0 = (y[0] - l10 * x1 - l20 * x2) / l00
    return jnp.stack([x0, x1, x2])


class Factor(NamedTuple):
    """A batch's block Cholesky factor, batch innermost: per segment, ``columns`` (steps, n, 3,
    3, B) each step's blocks of L below the diagonal (in the order of the plan's ``column``,
    padding zero), so that a solve's scan reads them as its own slices instead of gathering
    them; ``diag`` (V, 6, B) each step's 3 x 3 diagonal factor (:func:`_chol3`)."""

    columns: tuple[Array, ...]
    diag: Array


def _factor_batched(
    plan: BlockPlan, blocks: list[Array], proj: Array, scale: Array, mu: Array
) -> Factor:
    """Factor ``H + mu |diag H| + floor`` over a trailing batch axis of every argument but
    ``plan``: ``blocks`` (el, k, k, 3, 3, b), ``proj`` (V, 3, 3, b), ``scale`` and ``mu``
    (b,)."""
    # the element Hessians are computed once, not fused into (and recomputed by) the gathers
    blocks = jax.lax.optimization_barrier(blocks)
    b, dtype = proj.shape[-1], proj.dtype
    num = plan.block_vertices.shape[0]
    eye = jnp.eye(3, dtype=dtype)[None, :, :, None]
    # (el, k, k, 3, 3, b) -> vertex blocks (el * k * k, 3, 3, b) -> stored blocks (N, 3, 3, b)
    flat = jnp.concatenate([e.reshape(-1, 3, 3, b) for e in blocks])
    matrix = jnp.zeros((num, 3, 3, b), dtype).at[plan.target].add(flat[plan.source])
    # gauge: P_i H_ik P_k for every block (P the identity but at pinned vertices), and a
    # stiffness-sized identity on the pinned-out directions
    p = proj[plan.order]  # (V, 3, 3, b) in elimination order
    rows, cols = p[plan.block_vertices[:, 0]], p[plan.block_vertices[:, 1]]
    matrix = jnp.sum(rows[:, :, :, None] * matrix[:, None], axis=2)
    matrix = jnp.sum(matrix[:, :, :, None] * cols[:, None], axis=2)  # P symmetric
    diag = matrix[plan.diag] + scale * (eye - p)
    # the Levenberg-Marquardt shift and a rounding-sized floor, as the dense solve (the exact
    # Hessian's diagonal can be negative: the shift scales with its magnitude)
    d = jnp.abs(jnp.stack([diag[:, a, a] for a in range(3)], axis=1))  # (V, 3, b)
    floor = jnp.finfo(dtype).eps * jnp.max(d, axis=(0, 1))
    diag = diag + (mu * d + floor)[:, :, None, :] * eye
    spare = jnp.zeros((2, 3, 3, b), dtype)  # the padding blocks: zero, then written only
    matrix = jnp.concatenate([matrix.at[plan.diag].set(diag), spare])

    def eliminate(m, step):
        k, column, a, c, target = step
        f = _chol3(m[k])
        x = jnp.moveaxis(_lower_solve(f, jnp.moveaxis(m[column], 2, 0)), 0, 2)  # L_ik
        update = jnp.sum(x[a][:, :, None] * x[c][:, None], axis=3)  # L_ik L_jk^T
        # column k is final: kept as the scan's output, not written back (only later columns
        # are read from here on)
        return m.at[target].add(-update), (jnp.stack(f), x)

    factors, columns = [], []
    for (first, end), *segment in zip(
        plan.segments, plan.column, plan.pair_a, plan.pair_b, plan.pair_target, strict=True
    ):
        matrix, (f, x) = jax.lax.scan(eliminate, matrix, (plan.diag[first:end], *segment))
        factors.append(f)
        columns.append(x)
    return Factor(tuple(columns), jnp.concatenate(factors))


def _solve_batched(plan: BlockPlan, factor: Factor, rhs: Array) -> tuple[Array, Array]:
    """``L^-T L^-1 rhs`` for ``rhs`` (B, V, 3); the solution and whether each member's is finite."""
    b, dtype = rhs.shape[0], rhs.dtype
    y = jnp.moveaxis(rhs[:, plan.order], 0, -1)
    y = jnp.concatenate([y, jnp.zeros((1, 3, b), dtype)])  # spare row for the padding
    ks = jnp.arange(plan.order.shape[0])

    def forward(y, step):
        k, f, column, below = step
        yk = _lower_solve(tuple(f), y[k])
        y = y.at[k].set(yk)
        return y.at[below].add(-jnp.sum(column * yk[None, None], axis=2)), None

    def backward(x, step):
        k, f, column, below = step
        rest = jnp.sum(column * x[below][:, :, None], axis=(0, 1))
        return x.at[k].set(_upper_solve(tuple(f), x[k] - rest)), None

    segments = [
        (ks[first:end], factor.diag[first:end], column, below)
        for (first, end), column, below in zip(
            plan.segments, factor.columns, plan.below, strict=True
        )
    ]
    for steps in segments:
        y, _ = jax.lax.scan(forward, y, steps)
    x = y
    for steps in reversed(segments):
        x, _ = jax.lax.scan(backward, x, steps, reverse=True)
    out = jnp.moveaxis(x[plan.rank], -1, 0)
    return out, jnp.all(jnp.isfinite(out), axis=(1, 2))


def _batch_last(a: Array) -> Array:
    return jnp.moveaxis(a, 0, -1)


def _factor(plan: BlockPlan, blocks: list[Array], proj: Array, scale: Array, mu: Array) -> Factor:
    """Factor ``H + mu |diag H| + floor`` for the gauged Hessian ``H`` of one problem.

    ``blocks`` the element Hessians (bars (E, 2, 2, 3, 3), then hinges (H, 4, 4, 3, 3), as
    :func:`origami_jax.solvers.assembly.element_blocks` gives them); ``proj`` (V, 3, 3) each
    vertex's gauge projector (identity but at pinned vertices); ``scale`` the stiffness put on
    the pinned-out directions; ``mu`` the Levenberg-Marquardt shift relative to the diagonal.
    With a trailing batch axis on every argument but ``plan`` (``proj`` (V, 3, 3, B)), the
    factor's arrays have it last too. Under ``vmap`` (with ``plan`` shared) all members factor
    at once, the batch innermost. A matrix that is not positive definite gives NaN in the
    factor, and so in every :func:`solve_factored`.
    """
    if proj.ndim == 4:
        return _factor_batched(plan, blocks, proj, scale, mu)
    args = jax.tree.map(lambda a: jnp.asarray(a)[..., None], (blocks, proj, scale, mu))
    return jax.tree.map(lambda a: a[..., 0], _factor_batched(plan, *args))


# vmapped, batch-first at the boundary: solve_factored moves it back (XLA cancels the transposes)
factor = batch_innermost(_factor, index_args=(0,))


@jax.custom_batching.custom_vmap
def solve_factored(plan: BlockPlan, factor: Factor, rhs: Array) -> tuple[Array, Array]:
    """``(V, 3)`` solution of the factored system for ``rhs`` (V, 3), and whether it is finite."""
    out, ok = _solve_batched(plan, jax.tree.map(lambda a: a[..., None], factor), rhs[None])
    return out[0], ok[0]


@solve_factored.def_vmap
def _solve_factored_vmap(axis_size, in_batched, plan, factor, rhs):
    if any(jax.tree.leaves(in_batched[0])):
        axes = jax.tree.map(lambda batched: 0 if batched else None, in_batched)
        return jax.vmap(solve_factored.fun, in_axes=tuple(axes))(plan, factor, rhs), (True, True)
    factor = jax.tree.map(
        lambda a, batched: (
            _batch_last(a) if batched else jnp.broadcast_to(a[..., None], (*a.shape, axis_size))
        ),
        factor,
        in_batched[1],
    )
    rhs = rhs if in_batched[2] else jnp.broadcast_to(rhs, (axis_size, *rhs.shape))
    return _solve_batched(plan, factor, rhs), (True, True)


def solve(
    plan: BlockPlan, blocks: list[Array], proj: Array, scale: Array, mu: Array, rhs: Array
) -> tuple[Array, Array]:
    """:func:`factor` then :func:`solve_factored`: the solution (V, 3) of ``(H + mu |diag H| +
    floor) d = rhs`` and whether it is finite (the matrix was positive definite)."""
    return solve_factored(plan, factor(plan, blocks, proj, scale, mu), rhs)
