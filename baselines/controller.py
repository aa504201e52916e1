"""The fixed-speed rules shared by every baseline (MODEL.md section 7).

- speed controller: a = clip((v_b u - v) / tau, -a_max, a_max), u the unit vector to the target;
- feasibility: device n is feasible when (|q - p_n| + |p_n - q_fin|) / v_b <= (K - t) tau;
- passing: the current target device is passed once its horizontal distance is <= v_b tau.
"""

from __future__ import annotations

import jax.numpy as jnp

from semuav_jax.params import EnvParams


def speed_command(q, v, target, v_b, params: EnvParams):
    """Acceleration (2,) steering the velocity to v_b towards ``target`` within +-a_max per axis."""
    d = target - q
    u = d / jnp.maximum(jnp.linalg.norm(d), 1e-6)
    return jnp.clip((v_b * u - v) / params.tau, -params.a_max, params.a_max)


def feasible(q, t, dev_pos, v_b, params: EnvParams):
    """(N,) bool: a detour q -> p_n -> q_fin at speed v_b fits in the time left (K - t) tau."""
    detour = jnp.linalg.norm(dev_pos - q, axis=-1) + jnp.linalg.norm(dev_pos - params.q_fin, axis=-1)
    return detour <= v_b * (params.K - t) * params.tau
