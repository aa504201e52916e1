"""The BS's observation of MODEL.md section 5 (eq. 5.1 in docs/model.md)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from semuav_jax.params import EnvParams

if TYPE_CHECKING:
    from semuav_jax.state import EnvState

GLOBAL_FEATURES = 9  # q (2), v (2), a (2), time left (1), q_fin - q (2)
DEVICE_FEATURES = 5  # p_n - q (2), m_n / M, x_n, phi_n normalized


def obs_size(params: EnvParams) -> int:
    return GLOBAL_FEATURES + DEVICE_FEATURES * params.N


def obs_bounds(params: EnvParams) -> tuple[jax.Array, jax.Array]:
    """(low, high) of every entry of eq. 5.1. Offsets scale with the farthest the UAV can fly from
    q0 in T (no wall: it may leave the area); in ordinary flight they stay in about [-1, 1]."""
    reach = 1.0 + params.v_max * params.K * params.tau / jnp.minimum(params.Lx, params.Ly)
    one = jnp.ones(())
    glob = jnp.stack([reach, reach, one, one, one, one, one, reach, reach])
    dev = jnp.stack([reach, reach, one, one, one])
    high = jnp.concatenate([glob, jnp.tile(dev, params.N)])
    low = high * jnp.concatenate(
        [-jnp.ones(6), jnp.zeros(1), -jnp.ones(2), jnp.tile(jnp.array([-1.0, -1, 0, 0, 0]), params.N)]
    )
    return low, high


def observation(state: EnvState, params: EnvParams) -> jax.Array:
    """Eq. 5.1: a flat float32 vector, each entry in about [-1, 1].

    phi_n is normalized to [0, 1] by the range of the curves C.
    """
    area = jnp.stack([params.Lx, params.Ly])
    lo, hi = jnp.min(params.C), jnp.max(params.C)
    time_left = (params.K - state.t) / params.K
    glob = jnp.concatenate(
        [
            state.q / area,
            state.v / params.v_max,
            state.a_prev / params.a_max,
            jnp.reshape(time_left, (1,)),
            (params.q_fin - state.q) / area,
        ]
    )
    dev = jnp.concatenate(
        [
            (state.dev_pos - state.q) / area,
            (state.m / params.M)[:, None],
            state.x[:, None].astype(jnp.float32),
            ((state.phi - lo) / jnp.maximum(hi - lo, 1e-6))[:, None],
        ],
        axis=-1,
    )
    return jnp.concatenate([glob, dev.reshape(-1)]).astype(jnp.float32)
