"""The BS's return-home shield around the DDQN's action choice (docs/ddqn.md, "Shield").

An agent that hovers too long misses the destination (MODEL.md section 3, step 6; r_miss of
section 4). The BS knows the UAV's state, so before sending the agent's command it checks
whether the time left still covers a conservative flight home; when it no longer does, it sends
instead the table action (eq. 6.1) nearest to the section-7 speed controller aimed at q_fin (at
v_max, slowing down near q_fin). The same shield acts in training (the replay memory stores the
action that was sent) and in evaluation, so it is part of the policy, not a change of the
environment.
"""

from __future__ import annotations

import jax.numpy as jnp

from baselines.controller import speed_command
from semuav_jax.actions import action_table
from semuav_jax.params import EnvParams


def home_speed(params: EnvParams):
    """The cruise speed assumed on the way home: the command aims at v_max, but the nearest table action
    leaves a velocity error of up to half a level step (a_max tau / (levels - 1)) on each axis."""
    dead = jnp.sqrt(2.0) * params.a_max * params.tau / max(params.levels - 1, 1)
    return jnp.maximum(params.v_max - dead, 0.5 * params.v_max)


BRAKE = 0.25  # share of a_max the approach brakes with; the rest steers onto q_fin


def approach_speed(dist, params: EnvParams):
    """Speed the home command aims at, ``dist`` metres from q_fin: v_max, capped near q_fin at
    sqrt(2 BRAKE a_max dist), the speed from which braking at BRAKE a_max stops at q_fin. At full
    speed the turn radius v_max^2 / a_max = 125 m would make the UAV circle the 15 m disk."""
    return jnp.minimum(params.v_max, jnp.sqrt(2.0 * BRAKE * params.a_max * dist))


def time_home(q, v, params: EnvParams):
    """Conservative seconds to reach the arrival disk from (q, v) under :func:`home_action`.

    Turn the velocity onto the home course at a_max per axis (max_i |v_home u_i - v_i| / a_max,
    counted without progress), while drifting up to w^2 / (2 a_max) further for every velocity
    component w that does not point home (sideways, or away), and overshooting q_fin and coming
    back by twice (w^2 - s^2) / (2 a_max) when the speed w towards home exceeds
    s = approach_speed; then cruise at the home speed and brake along :func:`approach_speed`
    over the last v_home^2 / (2 BRAKE a_max) metres down to r_arr.
    """
    a, r = params.a_max, params.r_arr
    v_home = home_speed(params)
    diff = params.q_fin - q
    dist = jnp.linalg.norm(diff)
    u = diff / jnp.maximum(dist, 1e-6)
    along = jnp.dot(v, u)
    side = v - along * u
    over = jnp.maximum(along * along - approach_speed(dist, params) ** 2, 0.0)  # too fast to brake in time
    drift = (jnp.sum(side * side) + jnp.minimum(along, 0.0) ** 2 + 2.0 * over) / (2.0 * a)
    d = dist + drift
    c = 2.0 * BRAKE * a
    d0 = v_home * v_home / c
    brake = 2.0 * (jnp.sqrt(jnp.clip(d, r, d0)) - jnp.sqrt(r)) / jnp.sqrt(c)
    cruise = jnp.maximum(d - d0, 0.0) / v_home
    return jnp.max(jnp.abs(v_home * u - v)) / a + cruise + brake


def home_action(q, v, params: EnvParams):
    """Index of the table action nearest to the speed controller's command towards q_fin at
    :func:`approach_speed`."""
    dist = jnp.linalg.norm(params.q_fin - q)
    a = speed_command(q, v, params.q_fin, approach_speed(dist, params), params)
    return jnp.argmin(jnp.sum((action_table(params) - a) ** 2, axis=-1))


def shield(action, state, params: EnvParams, margin: float | None):
    """The action the BS sends: ``action``, or :func:`home_action` once the time left after this
    slot, (K - t - 1) tau, is at most :func:`time_home` + ``margin`` seconds (never when
    ``margin`` is None: no shield)."""
    if margin is None:
        return action
    left = (params.K - state.t - 1) * params.tau
    late = left <= time_home(state.q, state.v, params) + margin
    return jnp.where(late, home_action(state.q, state.v, params), action)
