"""The DDQN agent at the BS as an ``engine.Policy`` (docs/ddqn.md): what it sees (its input,
``agents/features.py``), how it chooses (greedy in evaluation, epsilon-greedy in training) and the
BS's shield around the choice (``agents/shield.py``), the same in training and evaluation."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
from flax import struct

from semuav_jax.actions import HOME, HOME_CODE
from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.features import option_features, table_features, waypoint_features
from semuav_jax.agents.options import idle, number_along_path, option_act, option_observe
from semuav_jax.agents.shield import shield, waypoint_shield
from semuav_jax.engine import Policy
from semuav_jax.env import reset_state
from semuav_jax.observation import observation
from semuav_jax.params import EnvParams

if TYPE_CHECKING:
    from semuav_jax.agents.network import QNetwork
    from semuav_jax.env import EnvState


def agent_input(state: EnvState, params: EnvParams, config: DDQNConfig) -> jax.Array:
    """The Q-network's input for one ``EnvState`` (``agents/features.py``)."""
    if config.option_inputs:
        return option_features(state, params, config.option_margin, config.shortest_tour)
    if config.actions != "table":  # waypoint, dwell and option actions (eqs. 6.2-6.4)
        return waypoint_features(state, params)
    obs = observation(state, params)
    return table_features(obs) if config.sorted_devices else obs


def input_size(params: EnvParams, config: DDQNConfig) -> int:
    """Length of :func:`agent_input` for ``params``' N."""
    state = jax.eval_shape(reset_state, jax.random.key(0), params)
    return int(jax.eval_shape(lambda s: agent_input(s, params, config), state).shape[0])


@functools.cache
def agent_shield(config: DDQNConfig) -> Callable:
    """``(action, state, params) -> action sent``: the BS's shield for the agent's action mode
    (no change when ``config.shield_margin`` is None)."""
    if config.actions == "table":
        return lambda action, state, params: shield(action, state, params, config.shield_margin)
    home = HOME_CODE if config.uses_options else HOME
    return lambda action, state, params: waypoint_shield(action, state, params, config.shield_margin, home)


@functools.cache
def _observe(config: DDQNConfig) -> Callable:
    features = lambda state, params: agent_input(state, params, config)
    return option_observe(features, config.option_margin) if config.uses_options else features


def initial_state(inner: Any, config: DDQNConfig) -> Any:
    """The policy state of :func:`greedy_policy` (``inner``: the weights) or :func:`explore_policy`
    (``inner``: an :class:`Explore`) at the start of an episode: ``inner``, and for options
    (eq. 6.4) ``(inner, no option running)``."""
    return (inner, idle()) if config.uses_options else inner


def network_input(obs: Any) -> jax.Array:
    """The network input inside an observation of :func:`greedy_policy` (options: ``obs.x``)."""
    return getattr(obs, "x", obs)


def choice_policy(choose: Callable, config: DDQNConfig) -> Policy:
    """The Policy that chooses ``choose(inner, x, params)`` in every slot, or, for options, at every
    decision (``agents/options.py``), through the shield; with ``config.tour`` 'shortest' the BS
    numbers a new layout's devices along the shortest path."""
    if config.uses_options:
        act = option_act(choose, config.shortest_tour)
    else:
        act = lambda inner, x, params: (choose(inner, x, params), inner)
    number = number_along_path if config.shortest_tour else None
    return Policy(act=act, mode=config.actions, observe=_observe(config), shield=agent_shield(config), number=number)


@functools.cache
def greedy_policy(network: QNetwork, config: DDQNConfig) -> Policy:
    """The trained agent: argmax Q of its input, through the shield. Policy state:
    :func:`initial_state` of the weights."""
    return choice_policy(lambda net, x, params: jnp.argmax(network.apply(net, x)), config)


@struct.dataclass
class Explore:
    """Policy state of one training env in one slot: the weights, epsilon, and the slot's draws
    (uniform u: explore when u < epsilon; the random action)."""

    net: Any
    eps: jax.Array
    u: jax.Array
    random_action: jax.Array


@functools.cache
def explore_policy(network: QNetwork, config: DDQNConfig) -> Policy:
    """Epsilon-greedy :func:`greedy_policy` (training), through the same shield."""

    def choose(ps: Explore, x: jax.Array, params: EnvParams) -> jax.Array:
        return jnp.where(ps.u < ps.eps, ps.random_action, jnp.argmax(network.apply(ps.net, x)))

    return choice_policy(choose, config)
