"""Episode metrics of MODEL.md section 8 (eq. 8.1 in docs/model.md)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from semuav_jax.params import EnvParams, params_valid

if TYPE_CHECKING:
    from semuav_jax.env import EnvState


def episode_metrics(state: EnvState, params: EnvParams) -> dict[str, jax.Array]:
    """Metrics of one finished episode from its final ``EnvState``.

    psnr_visited is the mean PSNR over covered devices (m_n > 0); 0 when none is covered, so it
    is never NaN (average it only over episodes with coverage > 0). ``valid`` is False when a
    parameter traced inside ``jit``/``vmap`` is out of range (``params.params_valid``) or the
    state overflowed float32: the other metrics are then NaN, never a believable number.
    """
    covered = state.m > 0
    n_cov = jnp.sum(covered)
    m = {
        "mean_psnr": jnp.mean(state.phi),
        "coverage": n_cov,
        "psnr_visited": jnp.sum(jnp.where(covered, state.phi, 0.0)) / jnp.maximum(n_cov, 1),
        "symbol_fraction": jnp.mean(state.m) / params.M,
        "arrived": state.arrived,
        "mission_time": state.t * params.tau,
        "return": state.ret,
    }
    finite = [jnp.all(jnp.isfinite(x)) for x in (state.q, state.v, state.m, state.phi, state.ret)]
    valid = params_valid(params) & jnp.all(jnp.stack(finite))
    return {k: v & valid if k == "arrived" else jnp.where(valid, v, jnp.nan) for k, v in m.items()} | {"valid": valid}
