"""The agent with search at the BS (docs/ddqn.md, docs/model.md eq. 7.15): one-step rollout policy
improvement of the greedy agent. Every ``every`` slots the BS simulates, from the current state to
the end of the mission with fresh delay draws, the agent itself and each of its actions sent for
the next ``every`` slots and the agent after it, and sends the best; the Q-network is the base
policy of every simulation (``semuav_jax.lookahead``). An option agent (eq. 6.4) simulates going on
with what runs and starting each of its options now, the agent after each, and may also switch to
a constant option (a dwell rule in option space) kept until a later decision switches again."""

from __future__ import annotations

from functools import cache
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp

from semuav_jax.actions import OPTION_HOME, OPTION_K, OPTION_TARGETS, option_codes
from semuav_jax.agents.demos import SWITCH_OPTIONS
from semuav_jax.agents.features import curve_gains, stay_seconds
from semuav_jax.agents.network import num_actions, q_network
from semuav_jax.agents.options import Option, OptionObs, idle, option_observe, planned_tour, step_option
from semuav_jax.agents.policy import agent_input, agent_shield, greedy_policy
from semuav_jax.engine import Policy
from semuav_jax.lookahead import Forced, Light, Switching, forced, rollout_switching

if TYPE_CHECKING:
    from semuav_jax.agents.config import DDQNConfig
    from semuav_jax.agents.network import QNetwork
    from semuav_jax.env import EnvState
    from semuav_jax.params import EnvParams

SEARCH_EVERY = 10  # slots (5 s) between two decisions
SEARCH_SAMPLES = 1  # delay draws per candidate and decision
SEARCH_TARGETS = OPTION_TARGETS  # option agents: the targets j (eq. 6.4) whose options are simulated
SEARCH_TOP = 4  # option agents: simulate only the agent's TOP best options by Q (None: every one)
SEARCH_RULES = SWITCH_OPTIONS  # option agents: the constant options the search may switch to (eq. 7.15)
SEARCH_CURVES = (0.25, 0.5, 1.0)  # option agents: lambda (dB per second of stay) of the curve rules
SEARCH_BLOCK = 256  # layouts per call when a table maps the search over its layouts (1.4x faster than 64)


@cache
def search_switching(network: QNetwork, config: DDQNConfig, every: int, samples: int, A: int) -> Switching:
    """Candidates: c = 0 the agent; c = 1 .. A its action c - 1 for ``every`` slots, then the agent."""
    policy = forced(greedy_policy(network, config))

    def candidate(net: Any, _: Any, c: jax.Array, now: Any = None, *state_params: Any) -> Forced:
        return Forced(net, jnp.maximum(c - 1, 0).astype(jnp.int32), jnp.where(c > 0, every, 0).astype(jnp.int32))

    return Switching(policy, candidate, A + 1, every, samples)


def rule_choice(
    rule: jax.Array, gains: jax.Array | None, obs: OptionObs, tour: jax.Array, params: EnvParams, curves: tuple
) -> jax.Array:
    """The option rule ``rule`` chooses: a constant option (< OPTION_HOME) itself; curve rule
    OPTION_HOME + 1 + i the first device along ``tour`` with k maximizing gain - curves[i] x stay
    over OPTION_K (gain: ``features.curve_gains``, stay: ``features.stay_seconds``)."""
    if not curves:
        return rule
    L = len(OPTION_K)
    codes, ks = option_codes(L, obs.m, obs.fits, obs.order, tour, params)
    n = jnp.maximum(codes, 0)
    stay = stay_seconds(ks, obs.m[n], params)
    lam = jnp.asarray(curves, jnp.float32)[jnp.clip(rule - OPTION_HOME - 1, 0, len(curves) - 1)]
    score = jnp.where(codes >= 0, gains[n, jnp.arange(L)] - lam * stay, -jnp.inf)
    return jnp.where(rule < OPTION_HOME, rule, jnp.argmax(score)).astype(jnp.int32)


def rule_policy(config: DDQNConfig, curves: tuple[float, ...] = ()) -> Policy:
    """A rule (:func:`rule_choice`) along a tour fixed when it starts: policy state ``((rule id,
    tour), Option)``; the agent's shield and the devices that fit, no network input computed."""

    def act(ps: tuple[tuple[jax.Array, jax.Array], Option], obs: OptionObs, params: EnvParams) -> tuple[jax.Array, Any]:
        (rule, tour), opt = ps
        opt = step_option(opt, rule_choice(rule, obs.x, obs, tour, params, curves), obs, params, tour)
        return opt.code, ((rule, tour), opt)

    features = curve_gains if curves else lambda state, params: jnp.zeros(0)
    observe = option_observe(features, config.option_margin)
    return Policy(act=act, mode=config.actions, observe=observe, shield=agent_shield(config))


def _switch_to(opt: Option, option: jax.Array, switch: jax.Array) -> Option:
    """``opt`` with a decision for ``option`` forced where ``switch`` (a curve rule decides itself)."""
    curve = option > OPTION_HOME
    forced = jnp.where(switch, jnp.where(curve, -1, option), opt.forced).astype(jnp.int32)
    return opt.replace(forced=forced, active=opt.active & ~(switch & curve))


@cache
def option_switching(
    network: QNetwork,
    config: DDQNConfig,
    every: int,
    samples: int,
    targets: int,
    top: int | None = None,
    rules: tuple[int, ...] = (),
    curves: tuple[float, ...] = (),
) -> Switching:
    """Candidates: c = 0 what runs going on (the agent, or the rule it follows); c = 1 .. targets L
    its option c - 1 (targets j < ``targets`` of eq. 6.4, every k) started now, the agent after it;
    c = targets L + 1, home; then, for each option of ``rules``, that option started now and chosen
    again at every option's end (a dwell rule in option space, e.g. TSP-dwell at k), until a decision
    switches (policy switching over those rules and the agent, eq. 7.15; the rules simulated by
    :func:`rule_policy`). Options follow the tour (eq. 6.5) planned at the decision, not every slot:
    the agent's re-planned at each decision, a rule's when it starts. With ``top``, a decision
    simulates c = 0, the ``top`` options (home included) with the highest Q at the decision, and
    every rule. Policy state: ((weights, the rule followed or -1 for the agent, the tour), the
    running option); ``curves``: the lambdas of curve rules (:func:`rule_choice`), candidates after
    the constant ones."""
    last = targets * len(OPTION_K) + 1
    bad = [r for r in rules if not (isinstance(r, int) and 0 <= r < OPTION_HOME)]
    if bad:
        raise ValueError(f"rules must be options in [0, {OPTION_HOME}), got {bad}")
    if not all(isinstance(x, float) and 0.0 <= x < float("inf") for x in curves):
        raise ValueError(f"curves must be lambdas >= 0 (dB per second, floats), got {curves!r}")
    rules = rules + tuple(OPTION_HOME + 1 + i for i in range(len(curves)))
    ids = jnp.asarray(rules + (0,), jnp.int32)
    agent = greedy_policy(network, config)

    def observe(state: EnvState, params: EnvParams) -> tuple[OptionObs, jax.Array]:
        return agent.observe(state, params), curve_gains(state, params)

    def act(ps: tuple[tuple[Any, jax.Array, jax.Array], Option], obs: Any, params: EnvParams) -> tuple:
        (net, rule, tour), opt = ps
        obs, gains = obs if curves else (obs, None)
        agent_choice = jnp.argmax(network.apply(net, obs.x))
        choice = jnp.where(rule >= 0, rule_choice(rule, gains, obs, tour, params, curves), agent_choice)
        opt = step_option(opt, choice, obs, params, tour)
        return opt.code, ((net, rule, tour), opt)

    def shortlist(net: Any, _: Any, state: Any, now: Any, params: EnvParams) -> jax.Array:
        q = network.apply(net, agent_input(state, params, config))
        q = jnp.concatenate([q[: last - 1], q[OPTION_HOME : OPTION_HOME + 1]])  # candidate c = 1 .. last: Q index c - 1
        best = 1 + jax.lax.top_k(q, top)[1].astype(jnp.int32)
        return jnp.concatenate([jnp.zeros(1, jnp.int32), best, last + 1 + jnp.arange(len(rules), dtype=jnp.int32)])

    def option_of(c: jax.Array) -> jax.Array:
        return jnp.where(c > last, ids[jnp.clip(c - last - 1, 0, len(rules))], jnp.where(c == last, OPTION_HOME, c - 1))

    def candidate(net: Any, _: Any, c: jax.Array, now: Any, state: EnvState, params: EnvParams) -> tuple:
        planned = planned_tour(simulated.observe(state, params), params, config.shortest_tour)
        (_, rule, tour), opt = ((None, jnp.int32(-1), planned), idle()) if now is None else now
        option = option_of(c)
        rule = jnp.where(c > last, option, jnp.where(c > 0, -1, rule)).astype(jnp.int32)
        tour = jnp.where((c > 0) | (rule < 0), planned, tour)  # a rule going on keeps the tour it started on
        return (net, rule, tour), _switch_to(opt, option, c > 0)

    def light(net: Any, _: Any, c: jax.Array, now: Any, state: EnvState, params: EnvParams) -> tuple:
        """Candidate c > last as :func:`rule_policy` flies it."""
        (_, option, tour), opt = candidate(net, _, c, now, state, params)
        return (option, tour), opt

    if top is not None and not 1 <= top <= last:
        raise ValueError(f"top must be in [1, {last}] (the options of {targets} targets and home), got {top!r}")
    simulated = rule_policy(config, curves)
    policy = agent._replace(act=act, observe=observe if curves else agent.observe)
    return Switching(
        policy,
        candidate,
        last + 1 + len(rules),
        every,
        samples,
        shortlist if top else None,
        Light(simulated, light, len(rules)) if rules else None,
    )


def agent_switching(
    config: DDQNConfig,
    params: EnvParams,
    every: int = SEARCH_EVERY,
    samples: int = SEARCH_SAMPLES,
    targets: int = SEARCH_TARGETS,
    top: int | None = SEARCH_TOP,
    rules: tuple[int, ...] | None = None,
    curves: tuple[float, ...] | None = None,
) -> Switching:
    """The search of an agent of ``config``: :func:`option_switching` for option agents, else
    :func:`search_switching` over all its actions (``targets``, ``top``, ``rules`` and ``curves`` are
    the options'; None: :data:`SEARCH_RULES`, :data:`SEARCH_CURVES`)."""
    network = q_network(params, config)
    if config.uses_options:
        rules = SEARCH_RULES if rules is None else tuple(rules)
        curves = SEARCH_CURVES if curves is None else tuple(curves)
        return option_switching(network, config, every, samples, targets, top, rules, curves)
    if rules or curves:
        raise ValueError(f"rules are constant options: the agent must choose options, not {config.actions!r} actions")
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
    rules: tuple[int, ...] | None = None,
    curves: tuple[float, ...] | None = None,
) -> tuple[dict[str, jax.Array], jax.Array, None]:
    """Per-episode metrics of the agent with search (weights ``net`` of one seed), the (E,
    decisions) chosen candidates (0: the agent's own action) and None (no trace)."""
    return rollout_switching(
        agent_switching(config, params, every, samples, targets, top, rules, curves), keys, params, net
    )
