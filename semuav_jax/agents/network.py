"""The Q-network (MODEL.md section 6): an MLP with ReLU and one Q-value per action."""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp

from semuav_jax import actions
from semuav_jax.agents.config import DDQNConfig
from semuav_jax.params import EnvParams


class QNetwork(nn.Module):
    """MLP with ReLU and one linear output per action (the paper's: 128-128-64); with ``dueling``,
    a value and an advantage head, Q = V + A - mean(A)."""

    num_actions: int
    hidden: tuple = (128, 128, 64)
    dueling: bool = False

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        for h in self.hidden:
            x = nn.relu(nn.Dense(h)(x))
        if not self.dueling:
            return nn.Dense(self.num_actions)(x)
        adv = nn.Dense(self.num_actions, name="advantage")(x)
        return nn.Dense(1, name="value")(x) + adv - jnp.mean(adv, axis=-1, keepdims=True)


def num_actions(params: EnvParams, config: DDQNConfig) -> int:
    """Actions of the agent's mode (eq. 6.1 or 6.2)."""
    return actions.num_actions(config.actions, params)


def q_network(params: EnvParams, config: DDQNConfig) -> QNetwork:
    """The Q-network of ``config`` for ``params``' action count."""
    return QNetwork(num_actions(params, config), tuple(config.hidden), config.dueling)
