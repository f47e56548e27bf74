"""Bytes across the processes of a multi-process JAX run: :func:`all_gather`.

A run of several processes (one per host, say) starts each with
``jax.distributed.initialize(coordinator_address, num_processes, process_id)``; JAX then keeps
a key-value store on the coordinator (process 0) for its own bookkeeping. :func:`all_gather`
passes each process's bytes to every other through that store: it needs no cross-process
collectives of any backend (no device memory, no compilation, no equal device counts), only
what ``jax.distributed.initialize`` set up. :func:`~origami_jax.batch.fold_batch` uses it to
hand every process the results of the others' shares.

The store is JAX's private API (``jax._src.distributed.global_state.client``, which JAX's own
compile-cache sharing uses): one small function of this module reaches it, and raises a clear
error where a JAX version lacks it.

Example (in each of the run's processes, after ``jax.distributed.initialize``):
  >>> from origami_jax.processes import all_gather
  >>> parts = all_gather(f"hello from {jax.process_index()}".encode())  # doctest: +SKIP
  >>> [p.decode() for p in parts]  # doctest: +SKIP
  ['hello from 0', 'hello from 1']
"""

from __future__ import annotations

import jax

__all__ = ["all_gather", "CHUNK_BYTES", "POLL_SECONDS"]

# a value of the store is a gRPC message: a large one is stored in pieces of this many bytes
# (protobuf refuses messages of 2 GiB)
CHUNK_BYTES = 2**26
# a wait for another process's bytes is a series of waits this long, so that Ctrl-C (handled
# between two calls into the store) stops it within a second
POLL_SECONDS = 1.0
_PREFIX = "origami_jax/all_gather"
# exchanges so far in this process: every process numbers them alike (they are collectives)
_EXCHANGES = [0]
# this process's keys of earlier exchanges, deleted once no process can still read them
_OLD_KEYS: list[str] = []


def _client():
    """The distributed runtime's client of this process (its key-value store).

    Raises:
      RuntimeError: JAX's distributed runtime is not initialized, or this JAX keeps its client
        elsewhere (a private API: origami_jax knows JAX 0.10's).
    """
    try:
        from jax._src import distributed

        client = distributed.global_state.client
    except (ImportError, AttributeError) as e:
        raise RuntimeError(
            f"origami_jax cannot reach the key-value store of JAX {jax.__version__}'s "
            "distributed runtime (jax._src.distributed.global_state.client, a private API it "
            "uses to gather results across processes); fold each process's problems with "
            "fold_batch(..., processes=False) and gather them yourself"
        ) from e
    if client is None:
        raise RuntimeError(
            "several processes need jax.distributed.initialize(coordinator_address, "
            "num_processes, process_id) in every process first"
        )
    missing = [
        name
        for name in ("key_value_set_bytes", "blocking_key_value_get_bytes", "key_value_delete")
        if not hasattr(client, name)
    ]
    if missing:
        raise RuntimeError(
            f"the distributed runtime client of JAX {jax.__version__} lacks {missing} (a "
            "private API origami_jax uses to gather results across processes); fold each "
            "process's problems with fold_batch(..., processes=False) and gather them yourself"
        )
    return client


def _get(client, key: str) -> bytes:
    """The value of ``key``, waiting for it in steps of :data:`POLL_SECONDS`."""
    timeout_ms = int(POLL_SECONDS * 1000)
    while True:
        try:
            return client.blocking_key_value_get_bytes(key, timeout_ms)
        except jax.errors.JaxRuntimeError as e:
            if "DEADLINE_EXCEEDED" not in str(e):
                raise
            # not there yet: wait again (a process that died stops the run: JAX's heartbeats)


def all_gather(data: bytes, wait: bool = True) -> list[bytes | None]:
    """Every process's ``data``, in process order, in every process.

    A collective: every process of the run calls it, as many times and in the same order
    (the calls are numbered in each process). With one process (no ``jax.distributed``), it
    returns ``[data]``. A process that stopped (died) stops the run: JAX's heartbeats end every
    process within ``heartbeat_timeout_seconds`` (100 by default).

    Args:
      data: this process's bytes, any length (stored in pieces of :data:`CHUNK_BYTES`).
      wait: ``False`` to publish ``data`` for the others and return at once, without theirs
        (an interrupted process: the others still get its part).

    Returns:
      One entry per process, by process index: its bytes (``None`` for the others' when
      ``wait`` is ``False``).

    Raises:
      RuntimeError: several processes, but ``jax.distributed.initialize`` was not called or
        this JAX keeps its key-value store elsewhere.
      KeyboardInterrupt: Ctrl-C while waiting (this process's part was published).
    """
    count, me = jax.process_count(), jax.process_index()
    if count == 1:
        return [data]
    client = _client()
    number = _EXCHANGES[0]
    _EXCHANGES[0] += 1
    view = memoryview(data)
    pieces = max(1, -(-len(view) // CHUNK_BYTES))
    mine = f"{_PREFIX}/{number}/{me}"
    for i in range(pieces):
        piece = bytes(view[i * CHUNK_BYTES : (i + 1) * CHUNK_BYTES])
        client.key_value_set_bytes(f"{mine}/{i}", piece)
    # the count last: a process that reads it finds every piece stored
    client.key_value_set_bytes(f"{mine}/pieces", str(pieces).encode())
    parts: list[bytes | None] = [None] * count
    parts[me] = data
    if not wait:
        _OLD_KEYS.append(mine)
        return parts
    for p in range(count):
        if p == me:
            continue
        theirs = f"{_PREFIX}/{number}/{p}"
        n = int(_get(client, f"{theirs}/pieces"))
        parts[p] = b"".join(_get(client, f"{theirs}/{i}") for i in range(n))
    # every process has published this exchange, so it is done reading the earlier ones:
    # their keys can go (the store lives in process 0's memory)
    for key in _OLD_KEYS:
        client.key_value_delete(key)
    _OLD_KEYS[:] = [mine]
    return parts
