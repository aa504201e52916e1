"""Spread a batch of episodes over every device JAX sees (CPU cores, GPUs, hosts).

jit propagates the input sharding, so a rollout or sweep whose per-episode inputs (keys, policy
states) are sharded runs its episode axis in parallel, with no change to the code. On one device
this is a no-op. Force several host CPU devices with
``XLA_FLAGS=--xla_force_host_platform_device_count=2`` (set before importing jax).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

AXIS = "episodes"


def episode_mesh() -> Mesh:
    return Mesh(np.array(jax.devices()), (AXIS,))


def padded_size(n: int) -> int:
    """The smallest multiple of the device count that holds n episodes."""
    d = jax.device_count()
    return -(-n // d) * d


def shard_episodes(tree):
    """Pad the leading (episode) axis of every leaf to a multiple of the device count, repeating
    the last entry, and shard it over all devices. Slice results back with ``[:n]``."""
    n = jax.tree.leaves(tree)[0].shape[0]
    size = padded_size(n)

    def put(x):
        x = jnp.asarray(x)
        if size > n:
            x = jnp.concatenate([x, jnp.repeat(x[-1:], size - n, axis=0)])
        if jax.device_count() == 1:
            return x
        return jax.device_put(x, NamedSharding(episode_mesh(), PartitionSpec(AXIS)))

    return jax.tree.map(put, tree)
