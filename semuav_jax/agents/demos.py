"""Demonstrations for an option agent (docs/ddqn.md "Demonstrations"; DQfD, Hester et al. 2018):
an expert option policy flies ``demo_steps`` vmapped env steps before training, its decisions fill a
demonstration memory kept for the whole run, and every update adds, on a minibatch of it, the TD
loss and the large-margin loss

    J_E = max_a [Q(s, a) + l(a_E, a)] - Q(s, a_E),   l(a_E, a) = demo_margin for a != a_E, else 0,

weighted by ``demo_weight``. The expert is the constant option of docs/model.md eq. 6.4: the first
device along the tour (eq. 6.5) until k symbols, k = ``demo_k`` by bandwidth (``demo_edges``),
which is TSP-dwell on the re-planned tour (``actions.option_code``).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from semuav_jax.actions import OPTION_K
from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.policy import choice_policy
from semuav_jax.engine import Policy


def expert_choice(B: jax.Array, config: DDQNConfig) -> jax.Array:
    """The expert's option at bandwidth ``B``: option i (the first along the tour, k = OPTION_K[i])
    for the k of ``config.demo_k`` between the ``demo_edges`` around B."""
    ks = jnp.asarray([OPTION_K.index(k) for k in config.demo_k], jnp.int32)
    return ks[jnp.searchsorted(jnp.asarray(config.demo_edges, jnp.float32), B, side="right")]


@functools.cache
def expert_policy(config: DDQNConfig) -> Policy:
    """The expert as an option policy (``policy.choice_policy``), through the agent's shield."""
    return choice_policy(lambda inner, x, params: expert_choice(params.B, config), config)


def margin_loss(q: jax.Array, action: jax.Array, margin: float) -> jax.Array:
    """Mean over the batch of J_E: ``q`` (batch, actions), ``action`` the expert's (batch,)."""
    other = margin * (1.0 - jax.nn.one_hot(action, q.shape[-1], dtype=q.dtype))
    q_e = jnp.take_along_axis(q, action[:, None], axis=-1)[:, 0]
    return jnp.mean(jnp.max(q + other, axis=-1) - q_e)
