"""Spread a batch of episodes over every device of every process (CPU cores, GPUs, hosts).

jit propagates the input sharding, so a rollout or sweep whose per-episode inputs (keys, policy
states) are sharded runs its episode axis in parallel, with no change to the code. On one device
this is a no-op. Force several host CPU devices with
``XLA_FLAGS=--xla_force_host_platform_device_count=2`` (set before importing jax); several
processes come from ``semuav_jax.distributed`` (docs/scaling.md). Every process builds the same
whole batch (the same keys), so no key depends on how the episodes are split; each feeds its own
rows, and :func:`gather` brings the results back to every process as NumPy arrays.

XLA compiles a program for the shape each device holds, and on CPU the float rounding of an
episode may change with that shape (another tiling of a product or a reduction).
:func:`map_episodes` therefore runs every episode in a block of :func:`block_size` episodes, a
size that depends on the batch only, never on the devices: the numbers are the same bits on any
number of devices and processes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import multihost_utils
from jax.sharding import Mesh, NamedSharding, PartitionSpec

AXIS = "episodes"
BLOCK = 64  # episodes per device in one call of map_episodes' program


def episode_mesh() -> Mesh:
    """A 1-D mesh over the devices of every process."""
    return Mesh(np.array(jax.devices()), (AXIS,))


def padded_size(n: int) -> int:
    """The smallest multiple of the (global) device count that holds n episodes."""
    d = jax.device_count()
    return -(-n // d) * d


def _pad(x: jax.Array, size: int):
    n = x.shape[0]
    return x if size == n else jnp.concatenate([x, jnp.repeat(x[-1:], size - n, axis=0)])


def _put(x: jax.Array, sharding: NamedSharding):
    """The whole array x on ``sharding``: device_put in one process, else this process's rows."""
    if jax.process_count() == 1:
        return jax.device_put(x, sharding)
    if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key):
        return jax.random.wrap_key_data(_put(jax.random.key_data(x), sharding), impl=jax.random.key_impl(x))
    x = np.asarray(x)
    rows = [i[0] for i in sharding.addressable_devices_indices_map(x.shape).values()]
    lo, hi = min(r.start or 0 for r in rows), max(x.shape[0] if r.stop is None else r.stop for r in rows)
    return jax.make_array_from_process_local_data(sharding, x[lo:hi], x.shape)


def shard_episodes(tree: Any) -> Any:
    """Pad the leading (episode) axis of every leaf to a multiple of the device count, repeating
    the last entry, and shard it over all devices. Slice results back with ``[:n]`` after
    :func:`gather`."""
    n = jax.tree.leaves(tree)[0].shape[0]
    size = padded_size(n)
    if jax.device_count() == 1:
        return jax.tree.map(lambda x: _pad(jnp.asarray(x), size), tree)
    sharding = NamedSharding(episode_mesh(), PartitionSpec(AXIS))
    return jax.tree.map(lambda x: _put(_pad(jnp.asarray(x), size), sharding), tree)


def block_size(n: int, block: int = BLOCK) -> int:
    """Episodes per device and call in :func:`map_episodes` for a batch of n: ``min(block, n)``."""
    return min(block, n)


def map_episodes(fn: Callable, tree: Any, axis: int = -1, block: int = BLOCK) -> Any:
    """``fn`` (a jitted function of a pytree of per-episode inputs, leading axis n) over blocks of
    :func:`block_size` (n, ``block``) episodes, the batch padded by repeating its last entry; returns
    fn's leaves (episode axis ``axis``) for the n episodes, whole NumPy arrays in every process. A
    larger ``block`` runs faster where one step of ``fn`` is many small operations (the search).

    Each process takes an equal share of the blocks and runs each block on one of its devices as a
    single-device program (not one program partitioned over the devices, whose float results
    differ in the last bits), so episode i is row i mod block of a block computed by the same
    program whatever the devices and processes."""
    n = jax.tree.leaves(tree)[0].shape[0]
    block, devices = block_size(n, block), jax.local_devices()
    size = -(-n // (block * jax.device_count())) * block * jax.device_count()
    padded = jax.tree.map(lambda x: np.asarray(_pad(jnp.asarray(x), size)), tree)
    share = size // jax.process_count()
    lo = jax.process_index() * share
    outs = []
    for j, start in enumerate(range(lo, lo + share, block)):  # dispatched asynchronously, one block per device
        part = jax.tree.map(lambda x, start=start: x[start : start + block], padded)
        outs.append(fn(jax.device_put(part, devices[j % len(devices)])))
    mine = jax.tree.map(lambda *xs: np.concatenate([np.asarray(x) for x in xs], axis=axis), *outs)
    if jax.process_count() > 1:  # (processes, ...) in process order, joined along the episode axis
        everyone = multihost_utils.process_allgather(mine)
        mine = jax.tree.map(lambda x: np.concatenate(list(x), axis=axis), everyone)
    return jax.tree.map(lambda x: np.take(x, np.arange(n), axis=axis), mine)


def gather(tree: Any) -> Any:
    """Every leaf as a whole NumPy array in every process (an all-gather across processes)."""
    if jax.process_count() == 1:
        return jax.tree.map(np.asarray, tree)
    return multihost_utils.process_allgather(tree, tiled=True)


def split_hosts(fn: Callable[[int, int], Any], n: int) -> Any:
    """``fn(lo, hi)`` (host-side work on episodes lo..hi-1: a pytree of arrays with that leading axis)
    in each process on its share of the n episodes, gathered in episode order in every process."""
    p, i = jax.process_count(), jax.process_index()
    if p == 1:
        return fn(0, n)
    if n < p:
        raise ValueError(f"{n} episodes cannot be split over {p} processes")
    bounds = [(int(a[0]), int(a[-1]) + 1) if len(a) else (n, n) for a in np.array_split(np.arange(n), p)]
    lo, hi = bounds[i]
    width = max(b - a for a, b in bounds)
    part = jax.tree.map(np.asarray, fn(lo, hi))
    padded = jax.tree.map(lambda x: np.concatenate([x, np.zeros((width - len(x), *x.shape[1:]), x.dtype)]), part)
    stacked = multihost_utils.process_allgather(padded)  # (processes, width, ...)
    return jax.tree.map(lambda s: np.concatenate([s[j, : b - a] for j, (a, b) in enumerate(bounds)]), stacked)


def agree(flag: bool) -> bool:
    """True only if ``flag`` is True in every process (e.g. a saved step every process can read)."""
    if jax.process_count() == 1:
        return bool(flag)
    return bool(np.all(multihost_utils.process_allgather(np.asarray(flag))))
