"""Command delay and UAV motion of MODEL.md section 3, steps 1-2 (eqs. 3.1-3.4 in docs/model.md)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from semuav_jax import channel
from semuav_jax.params import EnvParams


def command_delay(u, q_prev, params: EnvParams):
    """Eq. 3.1: delay = min(tau, proc + L_cmd / R_b(q[t-1])), proc = u proc_max with u ~ U(0, 1)."""
    d = q_prev - params.bs_pos
    r_b = channel.rate(d[0] * d[0] + d[1] * d[1], params.H - params.bs_h, params.P_b, params.B_b, params)
    return jnp.minimum(params.tau, u * params.proc_max + params.L_cmd / r_b)

def move(q, v, a_prev, a_new, delay, params: EnvParams):
    """Eqs. 3.2-3.4: delayed acceleration, speed cap, integration and geofence.

    ``a_new`` must already be clipped to the per-axis bound. Returns (q', v').
    """
    a_eff = (delay * a_prev + (params.tau - delay) * a_new) / params.tau
    v = v + a_eff * params.tau
    speed2 = jnp.sum(v * v)
    v = v * jnp.where(speed2 > params.v_max**2, params.v_max * jax.lax.rsqrt(speed2), 1.0)
    q_raw = q + v * params.tau
    hi = jnp.stack([params.Lx, params.Ly])
    q_new = jnp.clip(q_raw, 0.0, hi)
    v = jnp.where(q_new == q_raw, v, 0.0)
    return q_new, v
