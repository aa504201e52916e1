"""The agent with search at the BS (docs/ddqn.md, docs/model.md eq. 7.15): one-step rollout policy
improvement of the greedy agent. Every ``every`` slots the BS simulates, from the current state to
the end of the mission with fresh delay draws, the agent itself and each of its actions sent for
the next ``every`` slots and the agent after it, and sends the best; the Q-network is the base
policy of every simulation (``semuav_jax.lookahead``). An option agent (eq. 6.4) simulates going on
with the option it runs and starting each of its options now, the agent after each."""

from __future__ import annotations

from functools import cache
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp

from semuav_jax.actions import OPTION_HOME, OPTION_K, OPTION_TARGETS
from semuav_jax.agents.network import num_actions, q_network
from semuav_jax.agents.options import idle
from semuav_jax.agents.policy import agent_input, greedy_policy
from semuav_jax.lookahead import Forced, Switching, forced, rollout_switching

if TYPE_CHECKING:
    from semuav_jax.agents.config import DDQNConfig
    from semuav_jax.agents.network import QNetwork
    from semuav_jax.params import EnvParams

SEARCH_EVERY = 8  # slots (4 s) between two decisions
SEARCH_SAMPLES = 1  # delay draws per candidate and decision
SEARCH_TARGETS = OPTION_TARGETS  # option agents: the targets j (eq. 6.4) whose options are simulated
SEARCH_TOP = None  # option agents: simulate only the agent's TOP best options by Q (None: every one)


@cache
def search_switching(network: QNetwork, config: DDQNConfig, every: int, samples: int, A: int) -> Switching:
    """Candidates: c = 0 the agent; c = 1 .. A its action c - 1 for ``every`` slots, then the agent."""
    policy = forced(greedy_policy(network, config))

    def candidate(net: Any, _: Any, c: jax.Array, now: Any = None) -> Forced:
        return Forced(net, jnp.maximum(c - 1, 0).astype(jnp.int32), jnp.where(c > 0, every, 0).astype(jnp.int32))

    return Switching(policy, candidate, A + 1, every, samples)


@cache
def option_switching(
    network: QNetwork, config: DDQNConfig, every: int, samples: int, targets: int, top: int | None = None
) -> Switching:
    """Candidates: c = 0 the agent going on with its option (or choosing one); c = 1 .. targets L its
    option c - 1 (targets j < ``targets`` of eq. 6.4, every k) started now; the last, home; the
    agent after each. With ``top``, a decision simulates c = 0 and the ``top`` options of those
    (home included) with the highest Q at the decision."""
    last = targets * len(OPTION_K) + 1

    def shortlist(net: Any, _: Any, state: Any, now: Any, params: EnvParams) -> jax.Array:
        q = network.apply(net, agent_input(state, params, config))
        q = jnp.concatenate([q[: last - 1], q[OPTION_HOME:]])  # candidate c = 1 .. last: Q index c - 1
        return jnp.concatenate([jnp.zeros(1, jnp.int32), 1 + jax.lax.top_k(q, top)[1].astype(jnp.int32)])

    def candidate(net: Any, _: Any, c: jax.Array, now: Any) -> tuple[Any, Any]:
        opt = idle() if now is None else now[1]
        option = jnp.where(c == last, OPTION_HOME, c - 1)
        return net, opt.replace(forced=jnp.where(c > 0, option, opt.forced).astype(jnp.int32))

    if top is not None and not 1 <= top <= last:
        raise ValueError(f"top must be in [1, {last}] (the options of {targets} targets and home), got {top!r}")
    return Switching(greedy_policy(network, config), candidate, last + 1, every, samples, shortlist if top else None)


def agent_switching(
    config: DDQNConfig,
    params: EnvParams,
    every: int = SEARCH_EVERY,
    samples: int = SEARCH_SAMPLES,
    targets: int = SEARCH_TARGETS,
    top: int | None = SEARCH_TOP,
) -> Switching:
    """The search of an agent of ``config``: :func:`option_switching` for option agents, else
    :func:`search_switching` over all its actions (``targets`` and ``top`` are the options')."""
    network = q_network(params, config)
    if config.uses_options:
        return option_switching(network, config, every, samples, targets, top)
    return search_switching(network, config, every, samples, num_actions(params, config))


def search_metrics(
    net: Any,
    config: DDQNConfig,
    keys: jax.Array,
    params: EnvParams,
    every: int = SEARCH_EVERY,
    samples: int = SEARCH_SAMPLES,
    targets: int = SEARCH_TARGETS,
    top: int | None = SEARCH_TOP,
) -> tuple[dict[str, jax.Array], jax.Array, None]:
    """Per-episode metrics of the agent with search (weights ``net`` of one seed), the (E,
    decisions) chosen candidates (0: the agent's own action) and None (no trace)."""
    return rollout_switching(agent_switching(config, params, every, samples, targets, top), keys, params, net)
