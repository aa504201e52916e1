"""Air-to-ground channel of MODEL.md section 2 (eqs. 2.1-2.6 in docs/model.md).

Functions take the squared horizontal distance ``r2`` and the height difference ``dh`` so the
hot path needs no square root for the range test and the free-space term.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from semuav_jax.params import EnvParams

_LN10_OVER_10 = float(jnp.log(10.0)) / 10.0
_TAN_PI_8 = 0.41421356237


def _atan_unit(z: ArrayLike) -> jax.Array:
    """atan(z) for z in [0, 1], float32-accurate (Cephes atanf polynomial).

    XLA:CPU lowers ``arctan2`` to a scalar libm call (about 30 ns an element here, 20x an exp),
    which dominated the env step; this form vectorizes.
    """
    big = z > _TAN_PI_8
    w = jnp.where(big, (z - 1.0) / (z + 1.0), z)
    w2 = w * w
    p = (((8.05374449538e-2 * w2 - 1.38776856032e-1) * w2 + 1.99777106478e-1) * w2 - 3.33329491539e-1) * w2
    return jnp.where(big, jnp.pi / 4, 0.0) + w + w * p


def elevation_deg(r2: ArrayLike, dh: ArrayLike) -> jax.Array:
    """Eq. 2.2: elevation angle in degrees, theta = (180/pi) atan2(dh, r), for r = sqrt(r2) >= 0."""
    r, h = jnp.sqrt(r2), jnp.abs(dh)
    steep = h > r
    z = jnp.where(steep, r, h) / jnp.maximum(jnp.where(steep, h, r), 1e-30)
    a = _atan_unit(z)
    return jnp.sign(dh) * jnp.degrees(jnp.where(steep, jnp.pi / 2 - a, a))


def los_probability(r2: ArrayLike, dh: ArrayLike, params: EnvParams) -> jax.Array:
    """Eq. 2.3: P_LoS = 1 / (1 + a exp(-b (theta - a)))."""
    theta = elevation_deg(r2, dh)
    return 1.0 / (1.0 + params.los_a * jnp.exp(-params.los_b * (theta - params.los_a)))


def excess_loss_db(r2: ArrayLike, dh: ArrayLike, params: EnvParams) -> jax.Array:
    """The LoS/NLoS term of eq. 2.4: P_LoS eta_LoS + (1 - P_LoS) eta_NLoS, in dB."""
    p = los_probability(r2, dh, params)
    return params.eta_nlos + p * (params.eta_los - params.eta_nlos)


def free_space_gain(r2: ArrayLike, dh: ArrayLike, params: EnvParams) -> jax.Array:
    """(4 pi f_c d / c)^2, the linear free-space loss of eq. 2.4."""
    k = 4.0 * jnp.pi * params.f_c / params.c
    return k * k * (r2 + dh * dh)


def path_loss_db(r2: ArrayLike, dh: ArrayLike, params: EnvParams) -> jax.Array:
    """Eq. 2.4: PL = 20 log10(4 pi f_c d / c) + P_LoS eta_LoS + (1 - P_LoS) eta_NLoS, in dB."""
    return 10.0 * jnp.log10(free_space_gain(r2, dh, params)) + excess_loss_db(r2, dh, params)


def snr(r2: ArrayLike, dh: ArrayLike, power: ArrayLike, params: EnvParams) -> jax.Array:
    """Eq. 2.5: SNR = P / (sigma^2 10^(PL/10)), computed in linear form (no log10, no pow)."""
    loss = free_space_gain(r2, dh, params) * jnp.exp(_LN10_OVER_10 * excess_loss_db(r2, dh, params))
    return power / (params.noise * loss)


def _log1p(x: ArrayLike) -> jax.Array:
    """log(1 + x) for x >= 0, accurate for tiny x (Goldberg's trick).

    XLA:CPU's own ``log1p`` takes a slow path (about 25x) on the tiny SNRs of far devices.
    """
    u = 1.0 + x
    return jnp.where(u == 1.0, x, jnp.log(u) * (x / (u - 1.0)))


def rate(r2: ArrayLike, dh: ArrayLike, power: ArrayLike, bandwidth: ArrayLike, params: EnvParams) -> jax.Array:
    """Eq. 2.6: R = B log2(1 + SNR), bit/s."""
    return bandwidth * _log1p(snr(r2, dh, power, params)) * (1.0 / jnp.log(2.0))


def rest_rate(params: EnvParams) -> jax.Array:
    """R(0): the rate (bit/s) of a lone device right below the UAV (eq. 2.6 at r = 0, dh = H), the
    rate a hover over it receives at."""
    return rate(0.0, params.H, params.P_n, params.B, params)
