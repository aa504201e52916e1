"""Demonstrations for an option agent (docs/ddqn.md "Demonstrations"; DQfD, Hester et al. 2018):
an expert option policy flies ``demo_steps`` vmapped env steps before training, its decisions fill a
demonstration memory kept for the whole run, and every update adds, on a minibatch of it, the TD
loss and the large-margin loss

    J_E = max_a [Q(s, a) + l(a_E, a)] - Q(s, a_E),   l(a_E, a) = demo_margin for a != a_E, else 0,

weighted by ``demo_weight`` (one weight, or one per band of ``demo_edges`` by each row's
bandwidth, ``features.bandwidth``). Two experts (``demo_expert``):

- ``constant``: the constant option of docs/model.md eq. 6.4, the first device along the tour
  (eq. 6.5) until k symbols, k = ``demo_k`` by bandwidth (``demo_edges``), which is TSP-dwell along
  the agent's tour (its own order with ``tour="shortest"``; ``actions.option_code``);
- ``switch``: every ``demo_every`` slots the BS simulates each constant option of
  :data:`SWITCH_OPTIONS` (first along the tour or nearest, every k) from each env's state to the
  end of the mission, the running option going on first, and follows the best (eq. 7.15,
  ``semuav_jax.lookahead``): dwell-switch in option space. An env whose episode restarts within
  a period follows the constant expert until the next switch.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp

from semuav_jax.actions import OPTION_K, TOUR_TARGETS
from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.features import bandwidth
from semuav_jax.agents.options import Option, idle
from semuav_jax.agents.policy import choice_policy
from semuav_jax.agents.replay import replay_init
from semuav_jax.agents.smdp import pending_init
from semuav_jax.engine import Policy
from semuav_jax.lookahead import Switching, choose

if TYPE_CHECKING:
    from semuav_jax.env import EnvState
    from semuav_jax.params import EnvParams

L = len(OPTION_K)
EXPERT = "its expert"  # the constant expert's name in the tables: the fixed rule an agent with demonstrations must beat
SWITCH_OPTIONS = tuple(range(L)) + tuple(TOUR_TARGETS * L + i for i in range(L))  # TSP-dwell's, then greedy-dwell's


def expert_k(B: jax.Array, config: DDQNConfig) -> jax.Array:
    """The expert option's k at bandwidth ``B``: that of ``config.demo_k`` between the ``demo_edges`` around B."""
    return jnp.asarray(OPTION_K)[expert_choice(B, config)]


def band(B: jax.Array, config: DDQNConfig) -> jax.Array:
    """The band of ``config.demo_edges`` bandwidth ``B`` lies in: 0 below the first edge, ... ."""
    return jnp.searchsorted(jnp.asarray(config.demo_edges, jnp.float32), B, side="right")


def expert_choice(B: jax.Array, config: DDQNConfig) -> jax.Array:
    """The expert's option at bandwidth ``B``: option i (the first along the tour, k = OPTION_K[i])
    for the k of ``config.demo_k`` between the ``demo_edges`` around B."""
    return jnp.asarray([OPTION_K.index(k) for k in config.demo_k], jnp.int32)[band(B, config)]


@functools.cache
def expert_policy(config: DDQNConfig) -> Policy:
    """The constant expert as an option policy (``policy.choice_policy``), through the agent's shield."""
    return choice_policy(lambda inner, x, params: expert_choice(params.B, config), config)


@functools.cache
def switch_expert(config: DDQNConfig) -> Switching:
    """Eq. 7.15 over the constant options of :data:`SWITCH_OPTIONS`: candidate c is option
    SWITCH_OPTIONS[c] at every decision (policy state ``(option id, Option)``), the option running
    at the switch (``now[1]``) going on first. ``lookahead.rollout_switching`` flies it."""
    constant = choice_policy(lambda option, x, params: option, config)
    ids = jnp.asarray(SWITCH_OPTIONS, jnp.int32)

    def candidate(_: Any, __: Any, c: jax.Array, now: Any, *state_params: Any) -> tuple[jax.Array, Option]:
        return ids[c], idle() if now is None else now[1]

    return Switching(constant, candidate, len(SWITCH_OPTIONS), config.demo_every)


def switch_choices(
    config: DDQNConfig, states: EnvState, options: Option, key: jax.Array, params: EnvParams, axes: Any
) -> jax.Array:
    """(E,) the switch expert's option for every env from its state and running option (``params``
    vmapped over ``axes``), each candidate simulated with the env's own delay draws of ``key``."""
    sw, ids = switch_expert(config), jnp.asarray(SWITCH_OPTIONS, jnp.int32)
    best = lambda s, k, p, o: choose(sw, s, None, None, k, p, (None, o))[0]
    keys = jax.random.split(key, options.code.shape[0])
    return ids[jax.vmap(best, (0, 0, axes, 0))(states, keys, params, options)]


def demonstrate(tr: Any, ts: Any, key: jax.Array, step: Callable) -> Any:
    """``ts`` with the demonstration memory: the expert's decisions over ``demo_steps`` vmapped env
    steps (``switch``: rounded up to whole periods of ``demo_every``) from ``ts``'s envs (their
    first decisions end nothing), which then go on as they were; only the decisions of envs at
    B >= ``demo_from`` are kept. ``step(tr, ts, key, eps, action)``
    is the trainer's env step; ``tr`` its Trainer."""
    c = tr.config
    n_in = ts.obs.x.shape[-1]
    empty = ts.replace(replay=replay_init(c.buffer_size, n_in), window=pending_init(replay_init(c.num_envs, n_in).data))
    keep = jnp.tile(tr.env_params.B >= c.demo_from, 2)  # a step's decisions that ended, then episodes that ended
    add = tr.demo_buffer.add_where
    tr = tr._replace(buffer=tr.demo_buffer._replace(add_where=lambda s, batch, valid: add(s, batch, valid & keep)))
    if c.demo_expert == "constant":
        fly = lambda ts, k: (step(tr._replace(policy=expert_policy(c)), ts, k, 0.0, None)[0], None)
        return ts.replace(demos=jax.lax.scan(fly, empty, jax.random.split(key, c.demo_steps))[0].replay)
    fallback = expert_choice(tr.env_params.B, c)

    def period(carry: Any, k: jax.Array) -> tuple[Any, None]:
        k_switch, k_fly = jax.random.split(k)
        choice = switch_choices(c, carry.env_state, carry.window.option, k_switch, tr.env_params, tr.env_axes)

        def fly(x: tuple[Any, jax.Array], k: jax.Array) -> tuple[tuple[Any, jax.Array], None]:
            ts, restarted = x  # eps = 1 sends the given choice at every decision
            ts, (done, _, _) = step(tr, ts, k, 1.0, jnp.where(restarted, fallback, choice))
            return (ts, restarted | done), None

        restarted = jnp.zeros(c.num_envs, bool)
        return jax.lax.scan(fly, (carry, restarted), jax.random.split(k_fly, c.demo_every))[0][0], None

    periods = -(-c.demo_steps // c.demo_every)
    return ts.replace(demos=jax.lax.scan(period, empty, jax.random.split(key, periods))[0].replay)


def margin_loss(q: jax.Array, action: jax.Array, margin: float) -> jax.Array:
    """(batch,) J_E of each row: ``q`` (batch, actions), ``action`` the expert's (batch,)."""
    other = margin * (1.0 - jax.nn.one_hot(action, q.shape[-1], dtype=q.dtype))
    q_e = jnp.take_along_axis(q, action[:, None], axis=-1)[:, 0]
    return jnp.max(q + other, axis=-1) - q_e


def weighted_margin_loss(config: DDQNConfig, x: jax.Array, q: jax.Array, action: jax.Array) -> jax.Array:
    """``demo_weight`` times the mean J_E of demonstration rows with inputs ``x`` (batch, n): one
    weight times the mean, or the mean of each row's J_E times the weight of its bandwidth's band."""
    j, w = margin_loss(q, action, config.demo_margin), config.demo_weight
    if len(w) == 1:  # weight times mean, not mean of weighted rows: trains bit-identically to the shipped weights
        return w[0] * jnp.mean(j)
    return jnp.mean(jnp.asarray(w, jnp.float32)[band(bandwidth(x), config)] * j)
