"""Where the Hessian's element blocks go: the layout of the assembled matrix and its
fill-reducing order.

Newton's method (:mod:`origami_jax.solvers.newton`) assembles the Hessian of the energy from
per-element blocks (:mod:`origami_jax.solvers.assembly`), in the order of
:func:`hessian_elements`: bars, then hinges and barrier triangles. A :class:`HessianLayout` says
where each 3 x 3 vertex block of them goes: dense, straight into the flat 3V x 3V matrix (small
patterns, and every ``fold_batch``, whose batch of one topology also carries the
:class:`~origami_jax.solvers.blocksparse.BlockPlan` that factors all its members at once);
sparse, into the upper triangle of a CSR matrix, which the host factors
(:mod:`origami_jax.solvers.hostsparse`), in a fill-reducing nested-dissection order of the flat
pattern (:func:`nested_dissection`). :func:`hessian_layout` builds a mesh's layout once and
caches it (:mod:`origami_jax.caches`).
"""

from __future__ import annotations

import functools
import weakref
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from jax import Array

from origami_jax.caches import LruCache
from origami_jax.energy import Structure
from origami_jax.pattern import Mesh
from origami_jax.solvers.base import piece_labels
from origami_jax.solvers.blocksparse import BlockPlan

__all__ = [
    "HessianLayout",
    "UPPER_PAIRS",
    "hessian_elements",
    "nested_dissection",
    "hessian_layout",
    "layout_arrays",
]


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=[
        "order",
        "diag_blocks",
        "indptr",
        "indices",
        "blocks",
        "block_vertices",
        "block_entries",
        "block_slots",
        "vertex_blocks",
        "piece",
        "plan",
    ],
    meta_fields=[],
)
@dataclass(frozen=True)
class HessianLayout:
    """Where the element Hessians go in the assembled (3V x 3V) matrix.

    ``order`` (3V,) position of each degree of freedom in the solved system (a fill-reducing
    order for the sparse solve); ``diag_blocks`` (V, 3, 3) the storage slots of each vertex's
    diagonal block. Sparse: ``indptr``/``indices`` the CSR pattern of the **upper triangle**
    in that order (the matrix is symmetric: the host factorization reads only that half, which
    halves the assembly) and slots index its data; a diagonal block's entries below the
    diagonal have the slot past the end (dropped). Dense: both empty and slots index the flat
    matrix.

    The solver scatters 3 x 3 vertex blocks, dense straight into the (V, 3, V, 3) matrix;
    sparse into B stored blocks, one per vertex pair ``(i, j)``, ``i`` first in the order,
    twice: ``blocks`` (K,) the stored block of each corner pair ``a <= b`` of the bars (E, 3)
    then hinges (H, 10) (:data:`UPPER_PAIRS`), plus B where the corners come in the other
    order (a second copy that holds transposed blocks: no transpose of the element blocks),
    ``block_vertices`` (B, 2) the row and column vertex of each, ``block_entries`` (N, 2) the
    two entries of the flat (2B, 3, 3) blocks whose sum each CSR value takes, ``block_slots``
    (B, 9) the CSR slot of each block's entries (N below a diagonal block's diagonal),
    ``vertex_blocks`` (V, D) the stored blocks in each vertex's row or column (padded with 2B)
    (all five empty when dense).

    ``piece`` (V,): the connected piece of each vertex, numbered as the gauge numbers its
    pinned triangles (by lowest vertex; -1 for a vertex on no bar).

    ``plan``: for a dense layout shared by a vmapped batch of one topology (``fold_batch``),
    the :class:`~origami_jax.solvers.blocksparse.BlockPlan` that solves all members at once;
    ``None`` otherwise.
    """

    order: Array
    diag_blocks: Array
    indptr: Array
    indices: Array
    blocks: Array
    block_vertices: Array
    block_entries: Array
    block_slots: Array
    vertex_blocks: Array
    piece: Array
    plan: BlockPlan | None = None

    @property
    def sparse(self) -> bool:
        return self.indptr.shape[0] > 0

    @property
    def size(self) -> int:
        return int(self.order.shape[0])

    @property
    def storage(self) -> int:
        return int(self.indices.shape[0]) if self.sparse else self.size**2


# the corner pairs (a, b), a <= b, of an element of 2 (bar), 3 (triangle) or 4 (hinge) corners,
# as the arrays of their a and of their b: the upper triangle of its symmetric Hessian, all that
# the sparse assembly computes
UPPER_PAIRS = {k: np.triu_indices(k) for k in (2, 3, 4)}


def hessian_elements(structure: Structure) -> list:
    """The vertex index arrays of the elements whose Hessians the energy's is assembled from, in
    the order of :func:`element_blocks`: bars, then hinges and barrier triangles where the
    scene has them."""
    return [structure.bars] + [e for e in (structure.hinges, structure.triangles) if e.shape[0]]


def _element_pairs(elements: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of every (a, b) pair of indices within each element, elements of each
    (n_el, k) array in turn (the entries their Hessian blocks touch)."""
    rows = np.concatenate([np.repeat(e, e.shape[1], axis=1).ravel() for e in elements])
    cols = np.concatenate([np.tile(e, (1, e.shape[1])).ravel() for e in elements])
    return rows, cols


def nested_dissection(xy: np.ndarray, adjacency: sp.csr_matrix, leaf: int = 16) -> np.ndarray:
    """A fill-reducing vertex order: split the flat sheet at the median of its longer side, put
    the vertices touching the other half (the separator) last, recurse on both halves (down to
    ``leaf`` vertices: 16 factors a 100 x 100 Miura-ori a quarter faster than 64)."""
    out: list[np.ndarray] = []
    adjacency = sp.csr_matrix(adjacency, copy=True)
    adjacency.eliminate_zeros()  # an entry stored as zero joins nothing
    row_starts, neighbours = adjacency.indptr, adjacency.indices
    in_right = np.zeros(len(xy), bool)  # set during one split

    def touching(left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Which of ``left`` have a neighbour in ``right``, from the CSR rows of ``left``
        (slicing the scipy matrix at each split took most of a 100,000-vertex sheet's set-up)."""
        in_right[right] = True
        counts = row_starts[left + 1] - row_starts[left]
        ends = np.cumsum(counts)
        first = ends - counts  # each row's first place among the gathered neighbours
        rows = np.repeat(np.arange(len(left)), counts)
        places = row_starts[left][rows] + np.arange(len(rows)) - first[rows]
        hits = np.concatenate([[0], np.cumsum(in_right[neighbours[places]])])
        in_right[right] = False
        return hits[ends] - hits[first] > 0

    def visit(idx: np.ndarray) -> None:
        if len(idx) <= leaf:
            out.append(idx)
            return
        p = xy[idx]
        axis = int(np.argmax(p.max(axis=0) - p.min(axis=0)))
        below = p[:, axis] <= np.median(p[:, axis])
        left, right = idx[below], idx[~below]
        if len(left) == 0 or len(right) == 0:
            out.append(idx)
            return
        touches = touching(left, right)
        visit(left[~touches])
        visit(right)
        out.append(left[touches])

    visit(np.arange(len(xy)))
    return np.concatenate(out)


_LAYOUTS = LruCache()  # the most recently used meshes' layouts (origami_jax.caches)


def hessian_layout(mesh: Mesh, structure: Structure, sparse: bool) -> HessianLayout:
    """The assembly layout of a mesh's Hessian (cached per mesh; device arrays)."""
    # the elements depend on the barriers built: a mesh has a layout per set of them
    key = (id(mesh), sparse, structure.barriers, structure.num_free, structure.triangles.shape[0])
    hit = _LAYOUTS.get(key)
    if hit is not None and hit[0]() is mesh:
        return hit[1]
    elements = [np.asarray(e) for e in hessian_elements(structure)]
    vertex_order = None
    if sparse:
        vr, vc = _element_pairs(elements)
        v = mesh.num_vertices
        adjacency = sp.csr_matrix((np.ones(len(vr)), (vr, vc)), shape=(v, v))
        vertex_order = nested_dissection(mesh.vertices[:, :2], adjacency)
    layout = jax.tree.map(jnp.asarray, layout_arrays(elements, mesh.num_vertices, vertex_order))
    _LAYOUTS[key] = (weakref.ref(mesh), layout)
    return layout


def _vertex_pieces(bars: np.ndarray, num_vertices: int) -> np.ndarray:
    """(V,) the connected piece of each vertex over the bars, pieces ranked by their lowest
    vertex (the order of :func:`~origami_jax.solvers.base.rigid_gauges`); -1 off every bar
    (padding vertices of a batch form pieces past the pinned ones, which the gauge ignores)."""
    label = piece_labels(bars, num_vertices)
    on_bar = np.zeros(num_vertices, bool)
    on_bar[bars.ravel()] = True
    _, rank = np.unique(label[on_bar], return_inverse=True)  # sorted: by lowest vertex
    out = np.full(num_vertices, -1, np.int32)
    out[on_bar] = rank
    return out


def layout_arrays(
    elements: list[np.ndarray], num_vertices: int, vertex_order: np.ndarray | None
) -> HessianLayout:
    """A :class:`HessianLayout` of NumPy arrays for :func:`hessian_elements` ``elements`` (bars
    first): sparse in ``vertex_order`` when one is given, else dense (slots index the flat
    3V x 3V matrix)."""
    v = num_vertices
    n = 3 * v
    bars = elements[0]
    parts = [e for e in elements if len(e)]
    diag = np.arange(v)[:, None, None] * 3 + np.arange(3)
    diag_r = np.broadcast_to(diag, (v, 3, 3)).ravel()
    diag_c = np.broadcast_to(diag.transpose(0, 2, 1), (v, 3, 3)).ravel()
    sparse = vertex_order is not None
    if sparse:
        rank = np.empty(v, np.int64)
        rank[vertex_order] = np.arange(v)
        order = (rank[:, None] * 3 + np.arange(3)).ravel()
    else:
        order = np.arange(n)
    none = np.zeros(0, np.int32)
    if sparse:
        # the corner pairs a <= b of every element (in turn), and the stored block (the vertex
        # pair, first in the order first) each goes to, transposed when the order swaps them
        vr, vc = (
            np.concatenate([e[:, UPPER_PAIRS[e.shape[1]][k]].ravel() for e in parts])
            for k in (0, 1)
        )
        lo, hi = np.minimum(rank[vr], rank[vc]), np.maximum(rank[vr], rank[vc])
        diagonal = np.arange(v) * (v + 1)  # every vertex has its diagonal block
        block_keys, blocks = np.unique(np.concatenate([lo * v + hi, diagonal]), return_inverse=True)
        num = len(block_keys)
        blocks = blocks[: len(vr)] + num * (rank[vr] > rank[vc])
        bi, bj = block_keys // v, block_keys % v
        # the upper triangle's entries, block by block: all 9 off the diagonal, 6 on it
        i, j = np.divmod(np.arange(9), 3)
        keep = (bi[:, None] < bj[:, None]) | (i <= j)[None, :]
        block, entry = np.nonzero(keep)
        r, c = 3 * bi[block] + i[entry], 3 * bj[block] + j[entry]
        sort = np.argsort(r * n + c, kind="stable")
        r, c, block, entry = r[sort], c[sort], block[sort], entry[sort]
        indptr = np.searchsorted(r, np.arange(n + 1)).astype(np.int32)
        indices = c.astype(np.int32)
        i, j = np.divmod(entry, 3)
        block_entries = np.stack([block * 9 + entry, (num + block) * 9 + j * 3 + i], axis=1)
        block_slots = np.full((num, 9), len(r))
        block_slots[block, entry] = np.arange(len(r))
        stored, wanted = r * n + c, order[diag_r] * n + order[diag_c]
        at = np.minimum(np.searchsorted(stored, wanted), len(r) - 1)
        diag_blocks = np.where(stored[at] == wanted, at, len(r)).reshape(v, 3, 3)
        block_vertices = vertex_order[np.stack([bi, bj], axis=1)]
        vertex_blocks = _vertex_blocks(block_vertices, v, 2 * num)
    else:
        diag_blocks = (diag_r * n + diag_c).reshape(v, 3, 3)
        indptr, indices, blocks, block_entries = none, none, none, np.zeros((0, 2), np.int32)
        block_slots = np.zeros((0, 9), np.int32)
        block_vertices, vertex_blocks = np.zeros((0, 2), np.int32), np.zeros((0, 0), np.int32)
    return HessianLayout(
        piece=_vertex_pieces(bars, v),
        order=order.astype(np.int32),
        diag_blocks=diag_blocks.astype(np.int32),
        indptr=indptr,
        indices=indices,
        blocks=blocks.astype(np.int32),
        block_vertices=block_vertices.astype(np.int32),
        block_entries=block_entries.astype(np.int32),
        block_slots=block_slots.astype(np.int32),
        vertex_blocks=vertex_blocks.astype(np.int32),
    )


def _vertex_blocks(block_vertices: np.ndarray, v: int, pad: int) -> np.ndarray:
    """(V, D) the blocks whose row or column vertex is each vertex, padded with ``pad``."""
    num = len(block_vertices)
    ids = np.arange(num)
    off = block_vertices[:, 0] != block_vertices[:, 1]
    vertex = np.concatenate([block_vertices[:, 0], block_vertices[off, 1]])
    block = np.concatenate([ids, ids[off]])
    order = np.argsort(vertex, kind="stable")
    vertex, block = vertex[order], block[order]
    counts = np.bincount(vertex, minlength=v)
    out = np.full((v, max(int(counts.max(initial=0)), 1)), pad)
    out[vertex, np.arange(len(vertex)) - np.repeat(np.cumsum(counts) - counts, counts)] = block
    return out
