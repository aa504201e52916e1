"""Command delay and UAV motion of MODEL.md section 3, steps 1-2 (eqs. 3.1-3.4 in docs/model.md)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from semuav_jax import channel
from semuav_jax.params import EnvParams


def command_delay(u: ArrayLike, q_prev: ArrayLike, params: EnvParams) -> jax.Array:
    """Eq. 3.1: delay = min(tau, proc + L_cmd / R_b(q[t-1])), proc = u proc_max with u ~ U(0, 1)."""
    d = q_prev - params.bs_pos
    r_b = channel.rate(d[0] * d[0] + d[1] * d[1], params.H - params.bs_h, params.P_b, params.B_b, params)
    return jnp.minimum(params.tau, u * params.proc_max + params.L_cmd / r_b)


def speed_cap(v: ArrayLike, w: ArrayLike, params: EnvParams) -> jax.Array:
    """Eq. 3.3: the velocity after the step w = a_eff tau under the speed cap v_max.

    v + w when ``|v + w| <= v_max``; else its radial scaling to v_max (MODEL.md) when that stays
    within a_max tau per axis of v; else the point of the disk |v'| <= v_max nearest to v + w
    among those reachable with |v'_i - v_i| <= a_max tau (on an edge of that box). So the speed
    never exceeds v_max and no velocity component ever changes by more than a_max tau in a slot
    (``|v| <= v_max`` on entry; w within the box, as a_eff is).
    """
    R, h = params.v_max, params.a_max * params.tau
    c = v + w
    radial = c * (R / jnp.maximum(jnp.linalg.norm(c), 1e-12))
    in_box = jnp.all(jnp.abs(radial - v) <= h)
    # nearest feasible point on each of the four box edges: x = v_x +- h, then y = v_y +- h
    X = v[0] + jnp.array([-h, h])
    Y = v[1] + jnp.array([-h, h])

    def edge(fixed: ArrayLike, free_v: ArrayLike, free_c: ArrayLike) -> tuple[jax.Array, jax.Array]:
        s = jnp.sqrt(jnp.maximum(R * R - fixed * fixed, 0.0))
        lo, hi = jnp.maximum(free_v - h, -s), jnp.minimum(free_v + h, s)
        ok = (fixed * fixed <= R * R) & (lo <= hi)
        return jnp.clip(free_c, lo, hi), ok

    yx, okx = edge(X, v[1], c[1])
    xy, oky = edge(Y, v[0], c[0])
    cand = jnp.concatenate([jnp.stack([X, yx], -1), jnp.stack([xy, Y], -1)])
    ok = jnp.concatenate([okx, oky])
    d2 = jnp.where(ok, jnp.sum((cand - c) ** 2, -1), jnp.inf)
    best = jnp.where(jnp.any(ok), cand[jnp.argmin(d2)], v)
    return jnp.where(jnp.sum(c * c) <= R * R, c, jnp.where(in_box, radial, best))


def move(
    q: ArrayLike, v: ArrayLike, a_prev: ArrayLike, a_new: ArrayLike, delay: ArrayLike, params: EnvParams
) -> tuple[jax.Array, jax.Array]:
    """Eqs. 3.2-3.4: delayed acceleration, speed cap (:func:`speed_cap`) and integration.

    No wall: only the bounded acceleration changes the velocity, and the UAV may leave the area.
    ``a_new`` must already be clipped to the per-axis bound. Returns (q', v').
    """
    a_eff = (delay * a_prev + (params.tau - delay) * a_new) / params.tau
    v = speed_cap(v, a_eff * params.tau, params)
    return q + v * params.tau, v


def outside_airspace(q: ArrayLike, params: EnvParams) -> jax.Array:
    """Eq. 3.10: q lies more than ``airspace_margin`` outside the area (never with the default inf)."""
    m = params.airspace_margin
    hi = jnp.stack([params.Lx, params.Ly])
    return jnp.any((q < -m) | (q > hi + m))
