"""The replay memory of the DDQN (MODEL.md section 6: 50 000 transitions) and its n-step returns.

A ring buffer of device arrays inside the compiled training program, as pure functions with
flashbax's signatures (``init``/``add``/``sample``), so ``flashbax.make_item_buffer(...,
add_batches=True)`` can replace it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
from flax import struct


class Transition(NamedTuple):
    """One stored (n-step) transition: y = reward + discount (1 - done) max-Q(next_obs)."""

    obs: jax.Array
    action: jax.Array
    reward: jax.Array
    next_obs: jax.Array
    done: jax.Array
    discount: jax.Array


@struct.dataclass
class Replay:
    """Ring buffer of ``capacity`` transitions; ``pos`` is the next write slot, ``size`` the fill."""

    data: Transition
    pos: jax.Array
    size: jax.Array

    @property
    def capacity(self) -> int:
        return self.data.done.shape[0]


def replay_init(capacity: int, obs_dim: int) -> Replay:
    data = Transition(
        obs=jnp.zeros((capacity, obs_dim), jnp.float32),
        action=jnp.zeros((capacity,), jnp.int32),
        reward=jnp.zeros((capacity,), jnp.float32),
        next_obs=jnp.zeros((capacity, obs_dim), jnp.float32),
        done=jnp.zeros((capacity,), jnp.float32),
        discount=jnp.zeros((capacity,), jnp.float32),
    )
    return Replay(data=data, pos=jnp.zeros((), jnp.int32), size=jnp.zeros((), jnp.int32))


def replay_add(buf: Replay, batch: Transition) -> Replay:
    """Write a batch of B transitions at pos, pos+1, ... (mod capacity), overwriting the oldest."""
    return replay_add_where(buf, batch, jnp.ones(batch.done.shape[:1], bool))


def replay_add_where(buf: Replay, batch: Transition, valid: jax.Array) -> Replay:
    """:func:`replay_add` of the transitions of ``batch`` where ``valid``, in order, at pos, pos+1, ...
    (mod capacity); the others are dropped."""
    slot = jnp.cumsum(valid.astype(jnp.int32)) - 1
    idx = jnp.where(valid, (buf.pos + slot) % buf.capacity, buf.capacity)  # out of range: dropped
    data = jax.tree.map(lambda d, b: d.at[idx].set(b.astype(d.dtype), mode="drop"), buf.data, batch)
    n = jnp.sum(valid.astype(jnp.int32))
    return Replay(data=data, pos=(buf.pos + n) % buf.capacity, size=jnp.minimum(buf.size + n, buf.capacity))


def replay_sample(buf: Replay, key: jax.Array, batch_size: int) -> Transition:
    """Uniform sample (with replacement) among the ``size`` stored transitions."""
    idx = jax.random.randint(key, (batch_size,), 0, jnp.maximum(buf.size, 1))
    return jax.tree.map(lambda d: d[idx], buf.data)


class ReplayBuffer(NamedTuple):
    """A replay memory as pure functions, with flashbax's signatures: ``init(example Transition)``,
    ``add(state, batch of Transitions)``, ``sample(state, key)`` -> an object whose ``experience``
    is a batch of Transitions (``flashbax.make_item_buffer(..., add_batches=True)`` fits)."""

    init: Callable
    add: Callable
    sample: Callable
    add_where: Callable | None = None  # (state, batch, valid) -> state: the option agents' memory needs it


class Sample(NamedTuple):
    experience: Transition


def ring_buffer(capacity: int, batch_size: int) -> ReplayBuffer:
    """The default memory: :class:`Replay`, uniform sampling with replacement."""
    return ReplayBuffer(
        init=lambda example: replay_init(capacity, example.obs.shape[-1]),
        add=replay_add,
        sample=lambda buf, key: Sample(replay_sample(buf, key, batch_size)),
        add_where=replay_add_where,
    )


def n_step_transition(window: Transition, gamma: float) -> Transition:
    """The n-step transition of the oldest entry of ``window`` (n one-step transitions, oldest first,
    leading axis n): rewards summed with gamma^k up to and including the first ``done``, bootstrapped
    from the next observation there with discount gamma^m, m the number of steps summed."""
    n = window.done.shape[0]
    alive = jnp.cumprod(jnp.concatenate([jnp.ones_like(window.done[:1]), 1.0 - window.done[:-1]]), axis=0)
    powers = gamma ** jnp.arange(n, dtype=jnp.float32).reshape((n,) + (1,) * (window.done.ndim - 1))
    steps = jnp.sum(alive, axis=0).astype(jnp.int32)
    last = jnp.take_along_axis(window.next_obs, (steps - 1)[None, ..., None], axis=0)[0]
    return Transition(
        obs=window.obs[0],
        action=window.action[0],
        reward=jnp.sum(powers * alive * window.reward, axis=0),
        next_obs=last,
        done=1.0 - jnp.prod(1.0 - window.done, axis=0),
        discount=gamma ** steps.astype(jnp.float32),
    )
