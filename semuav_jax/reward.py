"""The two reward modes of MODEL.md section 4 (eqs. 4.1-4.5 in docs/model.md)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from semuav_jax.params import EnvParams

if TYPE_CHECKING:
    from semuav_jax.state import EnvState


def distance_to_goal(q: ArrayLike, params: EnvParams) -> jax.Array:
    d = q - params.q_fin
    return jnp.sqrt(jnp.sum(d * d))


def reward(prev: EnvState, new: EnvState, params: EnvParams) -> jax.Array:
    """r[t] for the transition prev -> new (two ``EnvState``s).

    paper (eq. 4.1): r_c = sum x phi / (sum x + eps); gain (eq. 4.2): r_c = kappa_c sum (phi - phi_prev);
    plus progress r_d (eq. 4.3), arrival r_g (eq. 4.4) and the miss penalty (eq. 4.5).
    """
    if params.reward_mode == "paper":
        x = new.x.astype(jnp.float32)
        r_c = jnp.sum(x * new.phi) / (jnp.sum(x) + params.eps)
    else:
        r_c = params.kappa_c * jnp.sum(new.phi - prev.phi)
    r_d = (
        params.kappa_d
        * (distance_to_goal(prev.q, params) - distance_to_goal(new.q, params))
        / (params.v_max * params.tau)
    )
    r_g = jnp.where(new.arrived, params.r_g, 0.0)
    r_miss = jnp.where(new.done & ~new.arrived, -params.P_miss, 0.0)
    return r_c + r_d + r_g + r_miss
