"""Batched episodes: one ``lax.scan`` over the K slots of ``engine.slot``, ``vmap`` over episodes,
one compiled program.

A policy is an ``engine.Policy`` or a bare ``fn(policy_state, env_state, params) -> (acceleration,
policy_state)`` (MODEL.md section 7). A policy with a shield reports ``shield_share`` (section 8).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from semuav_jax.engine import Policy, as_policy, numbered, observe, slot
from semuav_jax.env import EnvState, reset_state
from semuav_jax.metrics import episode_metrics
from semuav_jax.params import EnvParams, validate_params
from semuav_jax.state import DEVICE_FIELDS

TRACE_FIELDS = ("q", "v", "a_prev", "delay", "m", "phi", "x", "done")


def random_policy_state(key: jax.Array, params: EnvParams) -> jax.Array:
    """The random policy's state: its K commands, drawn up front, uniform in [-1, 1]^2 (times a_max)."""
    return jax.random.uniform(key, (params.K, 2), minval=-1.0, maxval=1.0)


def random_policy(draws: jax.Array, state: EnvState, params: EnvParams) -> tuple[jax.Array, jax.Array]:
    """Uniform acceleration in [-a_max, a_max]^2, the draw of slot t from ``random_policy_state``."""
    return draws[jnp.minimum(state.t, params.K - 1)] * params.a_max, draws


def delay_draws(key: jax.Array, params: EnvParams) -> jax.Array:
    """The K uniform draws of an episode's processing delays (eq. 3.1), slot t using entry t."""
    return jax.random.uniform(key, (params.K,))


class Carry(NamedTuple):
    """What the slot loop carries: the state, the policy's observation of it, the policy's state and
    the shield's count (slots it replaced the action, slots the episode ran)."""

    state: EnvState
    obs: Any
    policy_state: Any
    shielded: jax.Array
    live: jax.Array


def start(policy: Policy, state: EnvState, policy_state: Any, params: EnvParams) -> Carry:
    zero = jnp.zeros((), jnp.int32)
    return Carry(state, observe(policy, state, params), policy_state, zero, zero)


def scan_body(
    policy: Policy, params: EnvParams, trace: bool
) -> Callable[[Carry, jax.Array], tuple[Carry, dict[str, jax.Array] | None]]:
    """The scan body of one slot: ``engine.slot`` and the slot's trace entry."""

    def body(c: Carry, u: jax.Array) -> tuple[Carry, dict[str, jax.Array] | None]:
        state, obs, ps, out = slot(policy, u, c.state, c.obs, c.policy_state, params)
        c = Carry(state, obs, ps, c.shielded + out.shielded, c.live + ~c.state.done)
        tr = {f: getattr(state, f) for f in TRACE_FIELDS} | {"reward": out.reward} if trace else None
        return c, tr

    return body


def drawn_numbering(tr: dict[str, jax.Array] | None, back: jax.Array | None) -> dict[str, jax.Array] | None:
    """A trace (slots leading) with its device fields back in the layout's drawn numbering."""
    if tr is None or back is None:
        return tr
    return {f: x[:, back] if f in DEVICE_FIELDS else x for f, x in tr.items()}


def new_episode(policy: Policy, key: jax.Array, params: EnvParams) -> tuple[EnvState, jax.Array | None]:
    """A layout reset with ``key``, its devices numbered as ``policy`` numbers them, and the
    order back to the drawn numbering (``engine.numbered``; None when the policy keeps it)."""
    return numbered(policy, reset_state(key, params), params)


def finish(policy: Policy, c: Carry, params: EnvParams) -> dict:
    """The episode's metrics (MODEL.md section 8), with ``shield_share`` for a shielded policy."""
    metrics = episode_metrics(c.state, params)
    if policy.shield is not None:
        metrics["shield_share"] = c.shielded / jnp.maximum(c.live, 1)
    return metrics


def check_valid(metrics: dict[str, jax.Array]) -> None:
    if not isinstance(metrics["valid"], jax.core.Tracer) and not bool(jnp.all(metrics["valid"])):
        raise ValueError(
            "the simulation left float32 (a rate, power or return overflowed): check the parameters' scale"
        )


def episode(
    policy: Policy,
    key: jax.Array,
    params: EnvParams,
    policy_state: Any = None,
    init_state: EnvState | None = None,
    trace: bool = False,
    slots: ArrayLike | None = None,
) -> tuple[dict[str, jax.Array], dict[str, jax.Array] | None]:
    """One episode of K slots from ``init_state`` (or a reset with ``key``, its devices numbered as
    the policy numbers them); returns (metrics, trace).

    The trace (when asked) holds, per slot, the state fields of ``TRACE_FIELDS`` (devices in the
    drawn numbering) and the reward. ``slots`` (an int, traced or not; no trace) runs only the
    first ``slots`` of the K slots, with their delay draws: from a state at slot t, ``K - t`` slots
    give the metrics of all K (the slots after the end are frozen) at the cost of the ones left.
    """
    policy = as_policy(policy)
    k_reset, k_steps = jax.random.split(key)
    state, back = new_episode(policy, k_reset, params) if init_state is None else (init_state, None)
    body, c = scan_body(policy, params, trace), start(policy, state, policy_state, params)
    u = delay_draws(k_steps, params)
    if slots is None:  # unroll=2 lets XLA fuse across two slots: ~15 % faster on CPU (docs/performance.md)
        c, tr = jax.lax.scan(body, c, u, unroll=2)
    elif trace:
        raise ValueError("an episode of fewer slots (slots) has no trace")
    else:  # two slots per iteration, as the scan's unroll=2, then the odd one
        n = jnp.clip(jnp.asarray(slots, jnp.int32), 0, params.K)
        pair = lambda j, c: body(body(c, u[2 * j])[0], u[2 * j + 1])[0]
        c = jax.lax.fori_loop(0, n // 2, pair, c)
        c, tr = jax.lax.cond(n % 2 == 1, lambda c: body(c, u[n - 1])[0], lambda c: c, c), None
    return finish(policy, c, params), drawn_numbering(tr, back)


@partial(jax.jit, static_argnames=("policy", "trace", "state_axes"))
def _rollout(
    policy: Policy,
    keys: jax.Array,
    params: EnvParams,
    policy_state: Any,
    init_state: EnvState | None,
    trace: bool,
    state_axes: int | None,
) -> tuple[dict[str, jax.Array], dict[str, jax.Array] | None]:
    run = partial(episode, policy, params=params, trace=trace)
    return jax.vmap(lambda k, ps, s0: run(k, policy_state=ps, init_state=s0), in_axes=(0, state_axes, 0))(
        keys, policy_state, init_state
    )


def rollout(
    policy: Policy | Callable,
    keys: jax.Array,
    params: EnvParams,
    policy_state: Any = None,
    init_state: EnvState | None = None,
    trace: bool = False,
    state_axes: int | None = 0,
) -> tuple[dict[str, jax.Array], dict[str, jax.Array] | None]:
    """Run ``len(keys)`` episodes in one jitted, vmapped program.

    ``policy_state`` carries a leading episode axis, or is shared by all episodes with
    ``state_axes=None`` (e.g. network weights); ``init_state`` (optional) has an episode axis.
    Returns ``(metrics, trace)``: a dict of (E,) arrays (MODEL.md section 8) and, with
    ``trace=True``, a dict of (E, K, ...) per-slot arrays (else None). Parameters are validated first;
    a state that overflowed float32 is a ValueError (inside an outer ``jit``: ``valid`` is False).
    """
    validate_params(params)
    keys = jnp.asarray(keys)
    if keys.ndim != 2 and not jax.dtypes.issubdtype(keys.dtype, jax.dtypes.prng_key):
        raise ValueError(f"keys must be a batch of PRNG keys (E, 2), got shape {keys.shape}")
    metrics, tr = _rollout(as_policy(policy), keys, params, policy_state, init_state, trace, state_axes)
    check_valid(metrics)
    return metrics, tr


@partial(jax.jit, static_argnames=("policy", "trace"))
def _segment(
    policy: Policy, carry: Carry, draws: jax.Array, params: EnvParams, trace: bool
) -> tuple[Carry, dict[str, jax.Array] | None]:
    """The slots of ``draws`` (E, R) from ``carry``: the body of :func:`episode` over R slots."""
    return jax.vmap(lambda c, u: jax.lax.scan(scan_body(policy, params, trace), c, u))(carry, draws)


def rollout_replanned(
    policy: Policy | Callable, keys: jax.Array, params: EnvParams, replan: Callable, every: int, trace: bool = False
) -> tuple[dict[str, jax.Array], dict[str, jax.Array] | None]:
    """``rollout`` for a policy that a host function re-plans every ``every`` slots (receding horizon).

    ``replan(states, policy_state) -> policy_state`` runs outside ``jit`` on the batch of current
    states (``policy_state`` is None at t = 0); between calls the episodes advance in one jitted,
    vmapped program. Same episodes as :func:`rollout` for the same keys (layouts and delays).
    Returns ``(metrics, trace)`` as :func:`rollout` does.
    """
    validate_params(params)
    if int(every) != every or every < 1:
        raise ValueError(f"every must be an integer number of slots >= 1, got {every!r}")
    policy = as_policy(policy)
    keys = jnp.asarray(keys)
    split = jax.vmap(jax.random.split)(keys)
    states, back = jax.vmap(lambda k: new_episode(policy, k, params))(split[:, 0])
    draws = jax.vmap(delay_draws, (0, None))(split[:, 1], params)
    c, parts = None, []
    for t0 in range(0, params.K, int(every)):
        if c is None:
            c = jax.vmap(lambda s, ps: start(policy, s, ps, params))(states, replan(states, None))
        else:
            c = c._replace(policy_state=replan(c.state, c.policy_state))
        c, tr = _segment(policy, c, draws[:, t0 : t0 + int(every)], params, trace)
        parts.append(tr)
    metrics = jax.vmap(lambda c: finish(policy, c, params))(c)
    check_valid(metrics)
    tr = jax.tree.map(lambda *x: jnp.concatenate(x, axis=1), *parts) if trace else None
    return metrics, (tr if tr is None or back is None else jax.vmap(drawn_numbering)(tr, back))
