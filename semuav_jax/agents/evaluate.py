"""Greedy (epsilon = 0) evaluation of a trained DDQN through ``semuav_jax.rollout``: one jitted,
vmapped program over episodes, the metrics of MODEL.md section 8 plus ``shield_share``."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.policy import greedy_policy
from semuav_jax.params import EnvParams, validate_params
from semuav_jax.rollout import rollout
from semuav_jax.sharding import gather, shard_episodes

if TYPE_CHECKING:
    from semuav_jax.agents.network import QNetwork


def evaluate_agent(
    network: QNetwork, net_params: Any, config: DDQNConfig, keys: jax.Array, params: EnvParams, trace: bool = False
) -> dict[str, np.ndarray] | tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Metrics (dict of (E,) NumPy arrays, with ``shield_share``) of the greedy policy of ``net_params``
    on the episodes ``keys``; with ``trace``, also the per-slot trace of ``rollout``."""
    validate_params(params)
    metrics, tr = rollout(greedy_policy(network, config), keys, params, net_params, trace=trace, state_axes=None)
    metrics = jax.tree.map(np.asarray, metrics)
    return (metrics, jax.tree.map(np.asarray, tr)) if trace else metrics


MAX_RUNS = 2**16  # episodes (seeds x bandwidths x layouts) in one compiled evaluation


def seed_metrics(
    network: QNetwork, nets: Any, config: DDQNConfig, keys: jax.Array, params: EnvParams, bandwidths: ArrayLike
) -> dict:
    """Per-episode metrics (seeds, len(bandwidths), E) of the greedy policy of every seed of ``nets``
    (weights with a leading seed axis) at every B, in one jitted program vmapped over seeds and B
    and sharded over every device of every process; run in chunks of episodes so that one program
    holds at most ``MAX_RUNS`` episodes (about 4 kB of device memory each)."""
    validate_params(params)
    if not all(0 < b < float("inf") for b in np.asarray(bandwidths, np.float64).ravel()):
        raise ValueError(f"bandwidths must be finite and > 0 Hz, got {bandwidths}")
    policy = greedy_policy(network, config)

    # the keys are an argument: a jit may not close over another process's shards
    def at(net: Any, b: jax.Array, k: jax.Array) -> dict[str, jax.Array]:
        return rollout(policy, k, params.replace(B=b), net, state_axes=None)[0]

    run = jax.jit(jax.vmap(jax.vmap(at, (None, 0, None)), (0, None, None)))
    B = jnp.asarray(bandwidths, jnp.float32)
    chunk = max(1, MAX_RUNS // (jax.tree.leaves(nets)[0].shape[0] * max(B.size, 1)))
    parts = []
    for i in range(0, len(keys), chunk):
        part = keys[i : i + chunk]
        parts.append({k: v[..., : len(part)] for k, v in gather(run(nets, B, shard_episodes(part))).items()})
    return {k: np.concatenate([p[k] for p in parts], axis=-1) for k in parts[0]}
