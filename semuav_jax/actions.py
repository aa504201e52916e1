"""The DDQN's discrete action table of MODEL.md section 6 (eq. 6.1 in docs/model.md)."""

from __future__ import annotations

import jax.numpy as jnp

from semuav_jax.params import EnvParams


def axis_levels(params: EnvParams):
    """The ``levels`` accelerations per axis, evenly spaced in [-a_max, a_max] (eq. 6.1)."""
    return jnp.linspace(-1.0, 1.0, params.levels) * params.a_max


def action_table(params: EnvParams):
    """Eq. 6.1: (levels^2, 2) accelerations, ``levels`` values per axis evenly spaced in [-a_max, a_max].

    Action i commands (a^x, a^y) = (lv[i // levels], lv[i % levels]).
    """
    lv = axis_levels(params)
    ax, ay = jnp.meshgrid(lv, lv, indexing="ij")
    return jnp.stack([ax.reshape(-1), ay.reshape(-1)], axis=-1)


def action_to_accel(action, params: EnvParams):
    """The acceleration of a discrete action index (eq. 6.1)."""
    return action_table(params)[action]
