"""The one stepping function: a policy's command and the transition of one slot (MODEL.md section 3).

Evaluation (``semuav_jax.rollout``: ``lax.scan`` over K slots, ``vmap`` over episodes) and DDQN
training (``semuav_jax.agents.trainer``: ``vmap`` over envs, auto-reset) both step :func:`slot`,
so an action mode, a shield or a per-slot metric is written once, here.

A :class:`Policy` is ``act(policy_state, obs, params) -> (action, policy_state)``, where ``obs`` is
``observe(state, params)`` (the ``EnvState`` itself unless the policy says otherwise) and ``mode``
says what the action is: an acceleration (2,) (``"accel"``, the baselines of section 7) or a
discrete action of eq. 6.1 (``"table"``) or eq. 6.2 (``"waypoint"``). An optional ``shield``
(``action, state, params) -> action`` replaces the chosen action before it is sent (the BS's
return-home shield, ``agents/shield.py``). An optional ``number`` says how the BS numbers the
devices of a layout when an episode starts (``EnvState.renumbered``; e.g. along the shortest path).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from semuav_jax.actions import to_accel
from semuav_jax.env import EnvState, transition_u
from semuav_jax.params import EnvParams

POLICY_MODES = ("accel", "table", "waypoint", "dwell", "option", "mixed")


def full_state(state: EnvState, params: EnvParams) -> EnvState:
    """The default observation: the whole ``EnvState`` (a policy at the BS knows the model)."""
    return state


class Policy(NamedTuple):
    """A controller at the BS: pure functions, hashable (a static argument of ``jit``)."""

    act: Callable  # (policy_state, obs, params) -> (action, policy_state)
    mode: str = "accel"  # what ``act`` returns (POLICY_MODES)
    observe: Callable = full_state  # (state, params) -> the ``obs`` that ``act`` sees
    shield: Callable | None = None  # (action, state, params) -> the action sent
    number: Callable | None = None  # (state, params) -> (N,): how the BS numbers a new layout's devices


def as_policy(policy: Policy | Callable) -> Policy:
    """``policy`` itself, or a bare ``fn(policy_state, state, params) -> (acceleration, policy_state)``
    as an acceleration :class:`Policy` on the full state."""
    if isinstance(policy, Policy):
        if policy.mode not in POLICY_MODES:
            raise ValueError(f"policy mode must be one of {POLICY_MODES}, got {policy.mode!r}")
        return policy
    if not callable(policy):
        raise ValueError(f"a policy is a Policy or a function (policy_state, state, params), got {policy!r}")
    return Policy(act=policy)


class SlotOut(NamedTuple):
    """What one slot reports besides the new state: the action sent, whether the shield replaced
    the chosen one (only counted while the episode runs) and the reward (MODEL.md section 4)."""

    action: Any
    shielded: jax.Array
    reward: jax.Array


def numbered(policy: Policy, state: EnvState, params: EnvParams) -> tuple[EnvState, jax.Array | None]:
    """A new episode's state as ``policy`` numbers its devices, and the order back to the drawn
    numbering (None when the policy keeps it)."""
    if policy.number is None:
        return state, None
    order = policy.number(state, params)
    return state.renumbered(order), jnp.argsort(order)


def observe(policy: Policy, state: EnvState, params: EnvParams) -> jax.Array | None:
    """What ``policy`` sees of ``state``; None for a full-state policy (the state is not carried twice)."""
    return None if policy.observe is full_state else policy.observe(state, params)


def command(
    policy: Policy, policy_state: Any, obs: jax.Array | None, state: EnvState, params: EnvParams
) -> tuple[jax.Array, jax.Array, jax.Array, Any]:
    """The BS's command in ``state`` (``obs``: :func:`observe` of it): (action sent, shielded?,
    acceleration (2,), policy_state)."""
    chosen, policy_state = policy.act(policy_state, state if obs is None else obs, params)
    if policy.shield is None:
        sent, shielded = chosen, jnp.zeros((), bool)
    else:
        sent = policy.shield(chosen, state, params)
        shielded = jnp.any(sent != chosen)
    accel = sent if policy.mode == "accel" else to_accel(policy.mode, sent, state, params)
    return sent, shielded, accel, policy_state


def slot(
    policy: Policy, u: ArrayLike, state: EnvState, obs: jax.Array | None, policy_state: Any, params: EnvParams
) -> tuple[EnvState, jax.Array | None, Any, SlotOut]:
    """One slot: the command, the transition (``env.transition_u`` with the delay draw ``u``) and the
    policy's observation of the new state. Returns ``(state', obs', policy_state', SlotOut)``."""
    sent, shielded, accel, policy_state = command(policy, policy_state, obs, state, params)
    new, rew = transition_u(u, state, accel, params)
    return new, observe(policy, new, params), policy_state, SlotOut(sent, shielded & ~state.done, rew)
