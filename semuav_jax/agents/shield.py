"""The BS's shield around the DDQN's action choice (docs/ddqn.md, "Shield").

An agent that hovers too long misses the destination (MODEL.md section 3, step 6; r_miss of
section 4), and with an ``airspace_margin`` one that flies too far out fails. The BS knows the
UAV's state, so before sending the agent's command it checks (1) whether the time left still
covers a conservative flight home (docs/model.md eq. 7.5); when it no longer does, it sends the
table action (eq. 6.1) nearest to the controller's home command (eq. 7.1 at v_max, braking near
q_fin); (2) otherwise, on each axis where the command would leave the velocity above the
airspace braking cap (eq. 7.2), it sends the strongest table level that keeps it below. The same
shield acts in training (the replay memory stores the action that was sent) and in evaluation,
so it is part of the policy, not a change of the environment.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from semuav_jax.actions import HOME, action_table, axis_levels
from semuav_jax.control import airspace_cap, home_command, time_home
from semuav_jax.params import EnvParams

if TYPE_CHECKING:
    from semuav_jax.env import EnvState


def home_speed(params: EnvParams) -> jax.Array:
    """The cruise speed assumed on the way home: the command aims at v_max, but the nearest table action
    leaves a velocity error of up to half a level step (a_max tau / (levels - 1)) on each axis."""
    dead = jnp.sqrt(2.0) * params.a_max * params.tau / max(params.levels - 1, 1)
    return jnp.maximum(params.v_max - dead, 0.5 * params.v_max)


def home_action(q: jax.Array, v: jax.Array, params: EnvParams) -> jax.Array:
    """Index of the table action nearest to the controller's home command (eq. 7.1 towards q_fin)."""
    a = home_command(q, v, params.v_max, params)
    return jnp.argmin(jnp.sum((action_table(params) - a) ** 2, axis=-1))


def airspace_action(action: ArrayLike, q: jax.Array, v: jax.Array, params: EnvParams) -> jax.Array:
    """``action`` with each axis level lowered (towards braking) just enough that v + a tau stays
    within the airspace cap of eq. 7.2; unchanged without an ``airspace_margin``."""
    lv = axis_levels(params)
    i = jnp.stack([action // params.levels, action % params.levels])
    a = lv[i]
    v_next = v + a * params.tau
    capped = airspace_cap(q, v_next, params)
    need = (capped - v) / params.tau  # the acceleration that respects the cap
    # the strongest level <= need where the cap binds above, >= need where it binds below
    up = jnp.clip(jnp.searchsorted(lv, need, side="right") - 1, 0, params.levels - 1)
    down = jnp.clip(jnp.searchsorted(lv, need, side="left"), 0, params.levels - 1)
    i = jnp.where(v_next > capped, jnp.minimum(i, up), jnp.where(v_next < capped, jnp.maximum(i, down), i))
    return i[0] * params.levels + i[1]


def late(state: EnvState, params: EnvParams, margin: float, cruise: ArrayLike | None = None) -> jax.Array:
    """True once the time left after this slot, (K - t - 1) tau, is at most the flight home of
    eq. 7.5 at v_max (cruising at ``cruise``) + ``margin`` seconds."""
    left = (params.K - state.t - 1) * params.tau
    return left <= time_home(state.q, state.v, params.v_max, params, cruise=cruise) + margin


def shield(action: ArrayLike, state: EnvState, params: EnvParams, margin: float | None) -> jax.Array:
    """The table action the BS sends: :func:`home_action` when :func:`late` (cruising at
    :func:`home_speed`), else ``action`` kept inside the airspace (:func:`airspace_action`).
    ``margin`` None: no shield at all."""
    if margin is None:
        return action
    return jnp.where(
        late(state, params, margin, home_speed(params)),
        home_action(state.q, state.v, params),
        airspace_action(action, state.q, state.v, params),
    )


def waypoint_shield(
    action: ArrayLike, state: EnvState, params: EnvParams, margin: float | None, home: int = HOME
) -> jax.Array:
    """The waypoint action (eq. 6.2) the BS sends: ``home`` (HOME; HOME_CODE for an option's command
    code, eq. 6.4) when :func:`late`, else ``action`` (the controller of eq. 7.1 already keeps every
    waypoint and option command inside the airspace)."""
    if margin is None:
        return action
    return jnp.where(late(state, params, margin), home, action)
