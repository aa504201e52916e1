"""The layouts a training env restarts on (gymnax's auto-reset): a new one per episode, or, for a
policy that numbers a new layout's devices (``engine.Policy.number``: the shortest path, ~0.55 ms a
layout, too slow for every slot of every env), one of LAYOUT_POOL layouts numbered once when
training starts.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp

from semuav_jax.env import reset_state

if TYPE_CHECKING:
    from semuav_jax.engine import Policy
    from semuav_jax.env import EnvState
    from semuav_jax.params import EnvParams

LAYOUT_POOL = 32768  # numbered training layouts (about half the episodes of a default run)


def layout_pool(policy: Policy, params: EnvParams, key: jax.Array) -> tuple[jax.Array, jax.Array] | None:
    """(key, (LAYOUT_POOL, N) numbering): layout i is ``reset_state(fold_in(key, i), params)``, its
    numbering by ``policy`` row i. None for a policy that keeps the drawn numbering."""
    if policy.number is None:
        return None
    number = lambda i: policy.number(reset_state(jax.random.fold_in(key, i), params), params)
    return key, jax.lax.map(number, jnp.arange(LAYOUT_POOL), batch_size=1024)


def restart_state(key: jax.Array, params: EnvParams, layouts: Any) -> EnvState:
    """The state an env restarts from: a new layout (``layouts`` None), or one drawn with ``key``
    from the pool of :func:`layout_pool`, numbered."""
    if layouts is None:
        return reset_state(key, params)
    pool_key, numbering = layouts
    i = jax.random.randint(key, (), 0, LAYOUT_POOL)
    return reset_state(jax.random.fold_in(pool_key, i), params).renumbered(numbering[i])
