"""Options at the BS (docs/model.md eq. 6.4, docs/ddqn.md "Options"): the agent decides which device
to serve next and until how many symbols, and the BS flies that decision until it is done, so an
episode is ~10 decisions instead of K slot decisions (a semi-MDP: ``agents/smdp.py`` makes its
transitions).

A running :class:`Option` is part of the policy state: ``(inner, option)``, where ``inner`` is
what the choice needs (the weights, or the exploration draws). At every slot the option either
goes on (its device still short of k symbols; the home option until the end) or ends, and then the
agent chooses the next one from its input.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple

import jax
import jax.numpy as jnp
from flax import struct

from semuav_jax.actions import HOME_CODE, OPTION_K, device_order, option_code, option_fits
from semuav_jax.tour import numbered_order, shortest_path, tour_order

if TYPE_CHECKING:
    from semuav_jax.env import EnvState
    from semuav_jax.params import EnvParams


class OptionObs(NamedTuple):
    """What an option agent sees: its network input, the symbols of every device, which devices
    still fit (``actions.option_fits``), the devices nearest first (``actions.device_order``), and
    the UAV's and the devices' positions, which the tour its options follow is planned from
    (``semuav_jax.tour``; planned when acting, not here, as training observes each state twice)."""

    x: jax.Array
    m: jax.Array
    fits: jax.Array
    order: jax.Array
    q: jax.Array
    dev_pos: jax.Array


@struct.dataclass
class Option:
    """The option running in one episode (command code, symbol target k, running?, how many devices
    were :func:`live` at its decision) and, of the last slot, whether it was a decision and the agent's
    choice there; ``forced`` >= 0 makes the next slot a decision for that choice (the agent with
    search, ``agents/search.py``)."""

    code: jax.Array
    k: jax.Array
    active: jax.Array
    decided: jax.Array
    choice: jax.Array
    forced: jax.Array
    live_at_decision: jax.Array


def idle() -> Option:
    """No option running: the next slot is a decision."""
    i = jnp.zeros((), jnp.int32)
    return Option(i + HOME_CODE, jnp.zeros((), jnp.float32), jnp.zeros((), bool), jnp.zeros((), bool), i, i - 1, i)


def idle_batch(shape: tuple[int, ...]) -> Option:
    """:func:`idle` for every entry of a batch of ``shape``."""
    return jax.tree.map(lambda x: jnp.broadcast_to(x, shape + x.shape), idle())


def option_observe(features: Callable, margin: float) -> Callable:
    """``(state, params) -> OptionObs`` around the input ``features(state, params)``, the devices that
    fit with the time margin ``margin`` s (eq. 7.9)."""

    def observe(state: EnvState, params: EnvParams) -> OptionObs:
        fits, order = option_fits(state, params, margin), device_order(state, params)
        return OptionObs(features(state, params), state.m, fits, order, state.q, state.dev_pos)

    return observe


def live(obs: OptionObs) -> jax.Array:
    """(N,) bool: the devices an option of the smallest k could serve, short of OPTION_K[0] symbols
    and fitting (eq. 7.9); the tour runs through them."""
    return obs.fits & (obs.m < OPTION_K[0] - 1e-3)


def running(opt: Option, obs: OptionObs, params: EnvParams) -> jax.Array:
    """Whether ``opt`` goes on: it runs, and its device holds fewer than min(k, M) symbols and still
    fits (eq. 7.9: a dwell rule leaves a device there too), or it is the home option and no more
    devices are :func:`live` than at its decision (flying off a device at speed, eqs. 7.4-7.5 can fit
    one again, and a dwell rule turns to it). A waypoint action (a code below HOME_CODE) ends after its slot."""
    n = jnp.maximum(opt.code, 0)
    m = obs.m[n]
    serving = (m < opt.k - 1e-3) & (m < params.M - 1e-3) & obs.fits[n]
    home = (opt.code == HOME_CODE) & (jnp.sum(live(obs)) <= opt.live_at_decision)
    return opt.active & (opt.code >= HOME_CODE) & (home | serving)


def planned_tour(obs: OptionObs, params: EnvParams, shortest: bool = False) -> jax.Array:
    """(N,) the tour the options follow (eq. 6.5) through the devices that fit and hold fewer than
    OPTION_K[0] symbols: planned from ``obs``, or (``shortest``) in the order of the devices'
    numbers, which :func:`number_along_path` gave them along the shortest path."""
    return numbered_order(live(obs)) if shortest else tour_order(obs.q, obs.dev_pos, live(obs), params.q_fin)


def number_along_path(state: EnvState, params: EnvParams) -> jax.Array:
    """The ``engine.Policy.number`` of a BS whose options follow the shortest path: a new layout's
    devices in the order of the shortest path q0 -> devices -> q_fin (``tour.shortest_path``)."""
    return shortest_path(state.q, state.dev_pos, params.q_fin)


def step_option(
    opt: Option, choice: jax.Array, obs: OptionObs, params: EnvParams, tour: jax.Array | None = None
) -> Option:
    """The option of this slot: ``opt`` while it runs (and nothing is forced), else a decision for
    ``choice`` (or the forced choice) along ``tour`` (None: :func:`planned_tour` re-planned now)."""
    decide = ~running(opt, obs, params) | (opt.forced >= 0)
    choice = jnp.where(opt.forced >= 0, opt.forced, choice).astype(jnp.int32)
    tour = planned_tour(obs, params) if tour is None else tour
    code, k = option_code(choice, obs.m, obs.fits, obs.order, tour, params)
    return Option(
        code=jnp.where(decide, code, opt.code),
        k=jnp.where(decide, k, opt.k),
        active=jnp.ones((), bool),
        decided=decide,
        choice=jnp.where(decide, choice, opt.choice),
        forced=jnp.full((), -1, jnp.int32),
        live_at_decision=jnp.where(decide, jnp.sum(live(obs)), opt.live_at_decision).astype(jnp.int32),
    )


def option_act(choose: Callable, shortest: bool = False) -> Callable:
    """The ``act`` of an option policy whose choice is ``choose(inner, x, params)`` (x: the network
    input), along :func:`planned_tour` (``shortest``: the devices' numbers): policy state
    ``(inner, Option)``, action the option's command code."""

    def act(ps: tuple[Any, Option], obs: OptionObs, params: EnvParams) -> tuple[jax.Array, tuple[Any, Option]]:
        inner, opt = ps
        opt = step_option(opt, choose(inner, obs.x, params), obs, params, planned_tour(obs, params, shortest))
        return opt.code, (inner, opt)

    return act
