"""Decisions by simulation at the BS (docs/model.md eq. 7.15): every ``every`` slots, simulate each
of C candidate policy states of one policy from the current state to the end of the mission, with
delays drawn afresh (the BS knows the model, not the future delays), and follow the best until the
next decision. With one candidate that is the base policy itself this is rollout policy
improvement; with several fixed rules it is policy switching (parallel rollout): in expectation
never worse than the best candidate followed throughout.

The candidates are ``candidate(shared, per_episode, c, now, state, params)`` for c = 0 .. C-1:
``shared`` (e.g. network weights) is the same for every episode, ``per_episode`` (e.g. a TSP order)
has an episode axis, ``now`` is the policy state at the decision (None at t = 0; a candidate may go
on from it), ``state`` the env state there (e.g. to plan a tour once per decision, not per slot).
Episodes are those of ``rollout`` for the same keys (layouts and delays), so results pair with
every other policy's. A :class:`Light` simulates the last candidates with a cheaper policy that
flies them alike (same decisions, less work per simulated slot).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from flax import struct
from jax.typing import ArrayLike

from semuav_jax.engine import Policy, as_policy, observe
from semuav_jax.env import EnvState
from semuav_jax.params import EnvParams, validate_params
from semuav_jax.rollout import (
    check_valid,
    delay_draws,
    drawn_numbering,
    episode,
    finish,
    new_episode,
    scan_body,
    start,
)

ARRIVAL_DB = 100.0  # a simulated flight scores this much more for arriving, and again for SLACK_S to spare
SLACK_S = 2.0  # s: the simulated delays are not the flight's, so a plan that arrives just in time is a risk
LOOKAHEAD_STREAM = 0x5E4C  # fold_in tag of the lookahead's own delay draws (never the episode's)


class Light(NamedTuple):
    """The last ``count`` candidates a decision simulates, flown by ``policy`` from
    ``candidate(shared, per_episode, c, now, state, params)``: exactly as the Switching's own
    policy flies them, only cheaper (e.g. a constant option needs no network)."""

    policy: Policy
    candidate: Callable
    count: int


class Switching(NamedTuple):
    """Decisions by simulation over the candidates of ``policy`` (hashable: a static argument of jit)."""

    policy: Policy
    candidate: Callable  # (shared, per_episode, c, now, state, params) -> policy state of candidate c at the decision
    count: int  # C candidates
    every: int  # slots between two decisions
    samples: int = 1  # delay draws each candidate is simulated with (the same for every candidate)
    shortlist: Callable | None = None  # (shared, per_episode, state, now, params) -> candidates to simulate; None: all
    light: Light | None = None  # how the last candidates simulated are simulated cheaper; None: all by ``policy``


def decision_key(key: jax.Array, i: ArrayLike) -> jax.Array:
    """The delay draws of decision i of the episode ``key``: its own stream, never the episode's."""
    return jax.random.fold_in(jax.random.fold_in(key, LOOKAHEAD_STREAM), i)


def check_switching(sw: Switching) -> Switching:
    for name, x in (("count", sw.count), ("every", sw.every), ("samples", sw.samples)):
        if not isinstance(x, int) or isinstance(x, bool) or x < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {x!r}")
    if sw.light is not None:
        if not isinstance(sw.light.count, int) or not 1 <= sw.light.count < sw.count:
            raise ValueError(f"light.count must be an integer in [1, {sw.count}), got {sw.light.count!r}")
        sw = sw._replace(light=sw.light._replace(policy=as_policy(sw.light.policy)))
    return sw._replace(policy=as_policy(sw.policy))


def score(metrics: dict[str, jax.Array], params: EnvParams) -> jax.Array:
    """What a decision maximizes: arrival with ``SLACK_S`` to spare, then arrival, then the mean PSNR."""
    spare = metrics["arrived"] & (metrics["mission_time"] <= params.K * params.tau - SLACK_S)
    return metrics["mean_psnr"] + ARRIVAL_DB * (metrics["arrived"].astype(jnp.float32) + spare)


def choose(
    sw: Switching,
    state: EnvState,
    shared: Any,
    per_episode: Any,
    key: jax.Array,
    params: EnvParams,
    now: Any = None,
    t: ArrayLike | None = None,
) -> tuple[jax.Array, jax.Array]:
    """Eq. 7.15: (index of the best candidate, mean scores of the candidates simulated: all C, or
    those of ``sw.shortlist``) from ``state`` (``now``: the policy state there), each candidate
    simulated to the end with the same ``samples`` delay draws. ``t``: the slot of ``state``, the
    same for a whole batch of decisions (not vmapped), to simulate only the K - t slots left (the
    same scores, less work); None: K slots."""
    keys = jax.random.split(key, sw.samples)
    slots = None if t is None else params.K - t

    def values(policy: Policy, candidate: Callable, ids: jax.Array) -> jax.Array:
        def value(c: jax.Array) -> jax.Array:
            ps = candidate(shared, per_episode, c, now, state, params)
            runs = jax.vmap(lambda k: episode(policy, k, params, ps, init_state=state, slots=slots)[0])(keys)
            return jnp.mean(score(runs, params))

        return jax.vmap(value)(ids)

    ids = jnp.arange(sw.count) if sw.shortlist is None else sw.shortlist(shared, per_episode, state, now, params)
    if sw.light is None:
        v = values(sw.policy, sw.candidate, ids)
    else:
        n = ids.shape[0] - sw.light.count
        v = jnp.concatenate(
            [values(sw.policy, sw.candidate, ids[:n]), values(sw.light.policy, sw.light.candidate, ids[n:])]
        )
    return ids[jnp.argmax(v)], v


def switching_episode(
    sw: Switching, key: jax.Array, params: EnvParams, shared: Any, per_episode: Any, trace: bool = False
) -> tuple[dict[str, jax.Array], jax.Array, dict[str, jax.Array] | None]:
    """One episode (the layout and delays of ``rollout.episode`` for ``key``) with a decision every
    ``sw.every`` slots; returns (metrics, (decisions,) chosen candidate indices, the trace of
    ``rollout.episode`` when asked)."""
    k_reset, k_steps = jax.random.split(key)
    periods = -(-params.K // sw.every)
    u = delay_draws(k_steps, params)
    u = jnp.concatenate([u, jnp.zeros(periods * sw.every - params.K)]).reshape(periods, sw.every)
    state, back = new_episode(sw.policy, k_reset, params)

    def period(c: Any, xs: tuple[jax.Array, jax.Array]) -> tuple[Any, tuple[jax.Array, Any]]:
        draws, i = xs
        best, _ = choose(sw, c.state, shared, per_episode, decision_key(key, i), params, c.policy_state, i * sw.every)
        ps = sw.candidate(shared, per_episode, best, c.policy_state, c.state, params)
        c = c._replace(policy_state=ps, obs=observe(sw.policy, c.state, params))
        c, tr = jax.lax.scan(scan_body(sw.policy, params, trace), c, draws)  # slots after t = K are frozen
        return c, (best, tr)

    c0 = start(
        sw.policy, state, sw.candidate(shared, per_episode, jnp.zeros((), jnp.int32), None, state, params), params
    )
    c, (chosen, tr) = jax.lax.scan(period, c0, (u, jnp.arange(periods)))
    if trace:  # (periods, every, ...) -> the K slots of the episode
        tr = jax.tree.map(lambda x: x.reshape((periods * sw.every,) + x.shape[2:])[: params.K], tr)
    return finish(sw.policy, c, params), chosen, drawn_numbering(tr, back)


@partial(jax.jit, static_argnames=("sw", "trace"))
def _rollout_switching(
    sw: Switching, keys: jax.Array, params: EnvParams, shared: Any, per_episode: Any, trace: bool
) -> tuple[dict[str, jax.Array], jax.Array, dict[str, jax.Array] | None]:
    run = lambda k, pe: switching_episode(sw, k, params, shared, pe, trace)
    return jax.vmap(run, in_axes=(0, 0))(keys, per_episode)


def rollout_switching(
    sw: Switching,
    keys: jax.Array,
    params: EnvParams,
    shared: Any = None,
    per_episode: Any = None,
    trace: bool = False,
) -> tuple[dict[str, jax.Array], jax.Array, dict[str, jax.Array] | None]:
    """``len(keys)`` episodes with decisions by simulation, in one jitted, vmapped program: (metrics
    as ``rollout`` returns them, (E, decisions) chosen candidates, with ``trace`` the (E, K, ...)
    trace of ``rollout``, else None). ``per_episode`` has a leading episode axis (None: nothing per episode)."""
    validate_params(params)
    sw = check_switching(sw)
    keys = jnp.asarray(keys)
    if per_episode is None:
        per_episode = jnp.zeros(len(keys))
    metrics, chosen, tr = _rollout_switching(sw, keys, params, shared, per_episode, trace)
    check_valid(metrics)
    return metrics, chosen, tr


@struct.dataclass
class Forced:
    """Policy state of :func:`forced`: the inner policy's state, the action to send and for how many
    more slots."""

    inner: Any
    action: jax.Array
    left: jax.Array


@functools.cache
def forced(policy: Policy) -> Policy:
    """``policy`` with a forced first action: ``Forced(inner, a, n)`` sends ``a`` for n slots (through
    the policy's shield), then follows ``policy``: the candidates of one-step rollout improvement."""
    policy = as_policy(policy)

    def act(ps: Forced, obs: Any, params: EnvParams) -> tuple[jax.Array, Forced]:
        a, inner = policy.act(ps.inner, obs, params)
        sent = jnp.where(ps.left > 0, jnp.asarray(ps.action, jnp.asarray(a).dtype), a)
        return sent, Forced(inner, ps.action, ps.left - 1)

    return policy._replace(act=act)
