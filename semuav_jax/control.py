"""The BS's speed and tracking controller (docs/model.md, section 7): one owner for the baselines,
the planner and the DDQN's return-home shield.

- :func:`speed_command` steers the velocity to a speed along the unit vector to a target (eq. 7.1),
  never faster towards an airspace limit than the UAV can still brake (eq. 7.2);
- :func:`approach_speed` is the speed from which braking with ``BRAKE`` a_max stops at a point (eq. 7.3);
- :func:`time_to_pass` and :func:`time_home` are conservative flight times (eqs. 7.4-7.5) used by
  the feasibility tests: turning the velocity, drifting while turning, cruising and braking;
- :func:`rest_command` brings the UAV to rest over a chosen device (eqs. 6.3, 7.10).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from semuav_jax.params import EnvParams

BRAKE = 0.25  # share of a_max an approach brakes with; the rest steers onto the target
STOP_BRAKE = 0.6  # share of a_max used to come to rest over a device (eq. 7.3)


def range_radius(params: EnvParams) -> jax.Array:
    """r_c: the ground radius of the communication range, sqrt(D_com^2 - H^2) (eq. 3.5)."""
    return jnp.sqrt(jnp.maximum(params.D_com**2 - params.H**2, 0.0))


def airspace_cap(q: ArrayLike, v_des: ArrayLike, params: EnvParams) -> jax.Array:
    """Eq. 7.2: ``v_des`` with each axis component towards an airspace limit (area + margin) capped
    to the speed w that still stops in the gap g: w^2 / (2 a_max) + 1.5 w tau <= g (one slot of
    command delay, one of Euler integration). A no-op without a margin (``airspace_margin`` = inf)."""
    lo = -params.airspace_margin
    hi = jnp.stack([params.Lx, params.Ly]) + params.airspace_margin
    a, k = params.a_max, 1.5 * params.tau

    def cap(gap: ArrayLike) -> jax.Array:
        gap = jnp.maximum(gap, 0.0)
        return jnp.sqrt((k * a) ** 2 + 2.0 * a * gap) - k * a

    return jnp.clip(v_des, -cap(q - lo), cap(hi - q))


def speed_command(q: ArrayLike, v: ArrayLike, target: ArrayLike, speed: ArrayLike, params: EnvParams) -> jax.Array:
    """Eq. 7.1: a = clip((s u - v) / tau, +-a_max), u the unit vector to ``target``, s = ``speed``."""
    d = target - q
    u = d / jnp.maximum(jnp.linalg.norm(d), 1e-6)
    v_des = airspace_cap(q, speed * u, params)
    return jnp.clip((v_des - v) / params.tau, -params.a_max, params.a_max)


def approach_speed(dist: ArrayLike, speed: ArrayLike, params: EnvParams, brake: float = BRAKE) -> jax.Array:
    """Eq. 7.3: ``speed``, capped ``dist`` metres from the target at sqrt(2 b a_max dist), the
    speed from which braking with b a_max (b = ``brake``) stops there. Braking with only part of
    a_max leaves the rest for steering: at 25 m/s the turn radius v^2 / a_max = 125 m would circle
    the 15 m arrival disk."""
    return jnp.minimum(speed, jnp.sqrt(2.0 * brake * params.a_max * jnp.maximum(dist, 0.0)))


def _turn(v: ArrayLike, u: ArrayLike, speed: ArrayLike, params: EnvParams) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Seconds to turn v onto ``speed`` u at a_max per axis, and the metres drifted meanwhile by the
    sideways and backwards components of v (w^2 / (2 a_max) each), both counted without progress."""
    along = jnp.dot(v, u)
    side = v - along * u
    turn = jnp.max(jnp.abs(speed * u - v)) / params.a_max
    drift = (jnp.sum(side * side) + jnp.minimum(along, 0.0) ** 2) / (2.0 * params.a_max)
    return turn, drift, along


def _unit(d: ArrayLike) -> tuple[jax.Array, jax.Array]:
    dist = jnp.linalg.norm(d)
    return d / jnp.maximum(dist, 1e-6), dist


def time_to_pass(q: ArrayLike, v: ArrayLike, target: ArrayLike, speed: ArrayLike, params: EnvParams) -> jax.Array:
    """Eq. 7.4: conservative seconds to fly from (q, v) through ``target`` at ``speed`` without
    stopping: turn (without progress), then ``dist + drift`` metres at ``speed``."""
    u, dist = _unit(target - q)
    turn, drift, _ = _turn(v, u, speed, params)
    return turn + (dist + drift) / speed


def time_home(
    q: ArrayLike, v: ArrayLike, speed: ArrayLike, params: EnvParams, cruise: ArrayLike | None = None
) -> jax.Array:
    """Eq. 7.5: conservative seconds to reach the arrival disk from (q, v) under :func:`home_command`
    at ``speed``: turn and drift as in eq. 7.4, plus twice (w^2 - s^2) / (2 a_max) of overshoot when
    the speed w towards q_fin exceeds s = :func:`approach_speed`; then cruise at ``cruise`` (default
    ``speed``; lower when a discrete action table cannot hold ``speed`` exactly) and brake along
    :func:`approach_speed` over the last cruise^2 / (2 BRAKE a_max) metres down to r_arr."""
    cruise = speed if cruise is None else cruise
    a, r = params.a_max, params.r_arr
    u, dist = _unit(params.q_fin - q)
    turn, drift, along = _turn(v, u, cruise, params)
    over = jnp.maximum(along * along - approach_speed(dist, speed, params) ** 2, 0.0)
    d = dist + drift + over / a
    c = 2.0 * BRAKE * a
    d0 = cruise * cruise / c
    brake = 2.0 * (jnp.sqrt(jnp.clip(d, r, d0)) - jnp.sqrt(r)) / jnp.sqrt(c)
    return turn + jnp.maximum(d - d0, 0.0) / cruise + brake


def time_via(
    q: ArrayLike, v: ArrayLike, p: ArrayLike, speed: ArrayLike, params: EnvParams, stop: bool = False
) -> jax.Array:
    """Eqs. 7.4-7.5: conservative seconds to fly from (q, v) through ``p`` at ``speed``
    (:func:`time_to_pass`) and from there home (:func:`time_home` at ``speed``), leaving ``p`` at
    ``speed`` along the approach course, or at rest with ``stop``. A device's time slack is the
    time left minus this (the feasibility test of eq. 7.6, the candidates of eq. 7.9)."""
    if stop:
        v_p = jnp.zeros(2)
    else:
        v_p = speed * _unit(p - q)[0]
    return time_to_pass(q, v, p, speed, params) + time_home(p, v_p, speed, params)


def home_command(q: ArrayLike, v: ArrayLike, speed: ArrayLike, params: EnvParams) -> jax.Array:
    """Eq. 7.1 aimed at q_fin with :func:`approach_speed` (``speed`` far away, braking near q_fin)."""
    dist = jnp.linalg.norm(params.q_fin - q)
    return speed_command(q, v, params.q_fin, approach_speed(dist, speed, params), params)


def rest_command(
    q: ArrayLike,
    v: ArrayLike,
    dev_pos: ArrayLike,
    score: ArrayLike,
    mask: ArrayLike,
    cruise: ArrayLike,
    home_speed: ArrayLike,
    params: EnvParams,
) -> jax.Array:
    """Come to rest over the device of lowest ``score`` among ``mask`` (eq. 7.1 at ``cruise``,
    braking by eq. 7.3 with ``STOP_BRAKE``), or fly home at ``home_speed`` when ``mask`` is empty:
    the dwell rules (eq. 7.10) and the dwell actions (eq. 6.3)."""
    i = jnp.argmin(jnp.where(mask, score, jnp.inf))
    dist = jnp.linalg.norm(dev_pos[i] - q)
    to_dev = speed_command(q, v, dev_pos[i], approach_speed(dist, cruise, params, STOP_BRAKE), params)
    return jnp.where(jnp.any(mask), to_dev, home_command(q, v, home_speed, params))
