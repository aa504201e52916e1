"""Greedy (epsilon = 0) evaluation of a trained DDQN through ``semuav_jax.rollout``: one jitted,
vmapped program over episodes, the metrics of MODEL.md section 8 plus ``shield_share``."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.demos import expert_policy
from semuav_jax.agents.policy import greedy_policy, initial_state
from semuav_jax.params import EnvParams, validate_params
from semuav_jax.rollout import rollout
from semuav_jax.sharding import map_episodes

if TYPE_CHECKING:
    from semuav_jax.agents.network import QNetwork
    from semuav_jax.engine import Policy


def evaluate_agent(
    network: QNetwork, net_params: Any, config: DDQNConfig, keys: jax.Array, params: EnvParams, trace: bool = False
) -> dict[str, np.ndarray] | tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Metrics (dict of (E,) NumPy arrays, with ``shield_share``) of the greedy policy of ``net_params``
    on the episodes ``keys``; with ``trace``, also the per-slot trace of ``rollout``."""
    validate_params(params)
    ps = initial_state(net_params, config)
    metrics, tr = rollout(greedy_policy(network, config), keys, params, ps, trace=trace, state_axes=None)
    metrics = jax.tree.map(np.asarray, metrics)
    return (metrics, jax.tree.map(np.asarray, tr)) if trace else metrics


def seed_metrics(
    network: QNetwork, nets: Any, config: DDQNConfig, keys: jax.Array, params: EnvParams, bandwidths: ArrayLike
) -> dict[str, np.ndarray]:
    """Per-episode metrics (seeds, len(bandwidths), E) of the greedy policy of every seed of ``nets``
    (weights with a leading seed axis) at every B, in one jitted program vmapped over seeds and B,
    run in fixed-size blocks of episodes over every device of every process
    (``sharding.map_episodes``): the bits do not depend on the devices and processes, and one
    program holds at most a block's episodes for every seed and B."""
    return _metrics(greedy_policy(network, config), nets, 0, config, keys, params, bandwidths)


def expert_metrics(config: DDQNConfig, keys: jax.Array, params: EnvParams, bandwidths: ArrayLike) -> dict:
    """Per-episode metrics (len(bandwidths), E) of the agent's constant expert, the fixed rule its
    demonstrations come from (``agents/demos.py``), as :func:`seed_metrics` runs them."""
    return _metrics(expert_policy(config), jnp.zeros(()), None, config, keys, params, bandwidths)


def _metrics(
    policy: Policy,
    inner: Any,
    seed_axis: int | None,
    config: DDQNConfig,
    keys: jax.Array,
    params: EnvParams,
    bandwidths: ArrayLike,
) -> dict[str, np.ndarray]:
    validate_params(params)
    if not all(0 < b < float("inf") for b in np.asarray(bandwidths, np.float64).ravel()):
        raise ValueError(f"bandwidths must be finite and > 0 Hz, got {bandwidths}")

    def at(inner: Any, b: jax.Array, k: jax.Array) -> dict[str, jax.Array]:
        return rollout(policy, k, params.replace(B=b), initial_state(inner, config), state_axes=None)[0]

    over_b = jax.vmap(at, (None, 0, None))
    run = jax.jit(over_b if seed_axis is None else jax.vmap(over_b, (seed_axis, None, None)))
    B = jnp.asarray(bandwidths, jnp.float32)
    return map_episodes(lambda k: run(inner, B, k), keys)
