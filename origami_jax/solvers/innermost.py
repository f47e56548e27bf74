"""Element kernels evaluated with the batch innermost under ``jax.vmap``.

``fold_batch`` vmaps a solver over problems of one topology that share their index arrays.
Vmapped as written, a kernel keeps the batch as the leading axis, and XLA's CPU code then works
on (B, H, 4, 3) arrays whose innermost axis (3 coordinates) is too short to vectorize, and
gathers each member's corners on their own. The geometry and energy kernels also take trailing
batch axes (see :mod:`origami_jax.geometry`); :func:`batch_innermost` makes vmap call them once
with the batch as the last axis instead: corners are gathered as whole rows of the batch, and
every elementwise operation runs along it (measured: docs/design-notes/measurements.md).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp

__all__ = ["batch_innermost"]


def _innermost(a, batched: bool, size: int):
    a = jnp.asarray(a)
    if batched:
        return jnp.moveaxis(a, 0, -1)
    return jnp.broadcast_to(a[..., None], (*a.shape, size))


def batch_innermost(fn: Callable, index_args: Sequence[int]) -> Callable:
    """``fn`` as a ``custom_vmap``: called directly unbatched; under ``vmap``, with its
    ``index_args`` (index arrays: a structure, a block plan) unbatched, called once with every
    other array argument's batch axis moved last (unbatched ones broadcast to the batch), its
    outputs' last axis then moved back to the front. With an index argument batched (members of
    different topologies), plainly vmapped.

    ``fn`` must accept one trailing batch axis on all its array arguments but the index ones
    (arrays (n, ...) become (n, ..., B), scalars (B,)) and return arrays with it last.
    Differentiated forward, it is ``fn`` itself (a ``custom_jvp`` around the ``custom_vmap``,
    which has no reverse mode).
    """
    index_args = tuple(index_args)
    wrapped = jax.custom_batching.custom_vmap(fn)

    @wrapped.def_vmap
    def _rule(axis_size, in_batched, *args):
        if any(any(jax.tree.leaves(in_batched[i])) for i in index_args):
            axes = tuple(jax.tree.map(lambda b: 0 if b else None, flags) for flags in in_batched)
            out = jax.vmap(fn, in_axes=axes)(*args)
        else:
            moved = [
                a
                if i in index_args
                else jax.tree.map(functools.partial(_innermost, size=axis_size), a, flags)
                for i, (a, flags) in enumerate(zip(args, in_batched, strict=True))
            ]
            out = jax.tree.map(lambda a: jnp.moveaxis(a, -1, 0), fn(*moved))
        return out, jax.tree.map(lambda _: True, out)

    @jax.custom_jvp
    def innermost(*args):
        return wrapped(*args)

    @innermost.defjvp
    def _jvp(primals, tangents):
        return jax.jvp(fn, primals, tangents)

    return functools.wraps(fn)(innermost)
