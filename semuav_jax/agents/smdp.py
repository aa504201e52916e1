"""Semi-MDP transitions of an option agent (docs/ddqn.md "Options", docs/model.md eq. 6.4): one
transition per decision, y = R + gamma^tau (1 - done) max-Q(s'), where R sums the per-slot rewards
discounted by the slots elapsed since the decision and tau counts them (Sutton, Precup & Singh
1999). The replay memory's ``discount`` field carries gamma^tau, so the double-Q loss is the one
of every other agent.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from semuav_jax.agents.options import Option, idle_batch
from semuav_jax.agents.replay import Transition


@struct.dataclass
class Pending:
    """Per env (leading axis): the option transition under way (obs and action of its decision, the
    discounted reward and gamma^slots so far), whether the episode has had a decision, and the
    running option."""

    tr: Transition
    started: jax.Array
    option: Option


def pending_init(empty: Transition) -> Pending:
    """Nothing under way in any env (``empty``: zero transitions with a leading env axis)."""
    E = empty.done.shape[0]
    return Pending(empty, jnp.zeros((E,), bool), idle_batch((E,)))


def option_transitions(
    pend: Pending, x: jax.Array, opt: Option, reward: jax.Array, x_next: jax.Array, done: jax.Array, gamma: float
) -> tuple[Transition, jax.Array, Pending]:
    """One slot of every env: ``x`` the input before it, ``opt`` the option after its decision,
    ``reward`` its (scaled) reward, ``x_next`` the input after it (before any reset), ``done``.
    Returns the (2 E) transitions that completed (a decision ends the one under way; the end of an
    episode ends the new one), which of them are real, and the pending transitions after the slot."""
    f32 = jnp.float32
    zero = jnp.zeros_like(reward)
    ended = pend.tr._replace(next_obs=x, done=zero)
    fresh = Transition(x, opt.choice, zero, x, zero, jnp.ones_like(reward))
    cur = jax.tree.map(lambda a, b: jnp.where(opt.decided.reshape((-1,) + (1,) * (a.ndim - 1)), a, b), fresh, pend.tr)
    cur = cur._replace(reward=cur.reward + cur.discount * reward, discount=cur.discount * gamma)
    last = cur._replace(next_obs=x_next, done=done.astype(f32))
    batch = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), ended, last)
    valid = jnp.concatenate([opt.decided & pend.started, done])
    reset = lambda a, b: jnp.where(done.reshape((-1,) + (1,) * (a.ndim - 1)), a, b)
    option = jax.tree.map(reset, idle_batch(done.shape), opt)
    return batch, valid, Pending(cur, ~done, option)
