"""What the BS can command (MODEL.md section 6, docs/model.md eqs. 6.1-6.2): the paper's table of
accelerations, and waypoint actions that the core controller (``semuav_jax.control``) turns into
accelerations."""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from semuav_jax.control import approach_speed, home_command, rest_command, speed_command, time_via
from semuav_jax.params import EnvParams

if TYPE_CHECKING:
    from semuav_jax.state import EnvState


def axis_levels(params: EnvParams) -> jax.Array:
    """The ``levels`` accelerations per axis, evenly spaced in [-a_max, a_max] (eq. 6.1)."""
    return jnp.linspace(-1.0, 1.0, params.levels) * params.a_max


def action_table(params: EnvParams) -> jax.Array:
    """Eq. 6.1: (levels^2, 2) accelerations, ``levels`` values per axis evenly spaced in [-a_max, a_max].

    Action i commands (a^x, a^y) = (lv[i // levels], lv[i % levels]).
    """
    lv = axis_levels(params)
    ax, ay = jnp.meshgrid(lv, lv, indexing="ij")
    return jnp.stack([ax.reshape(-1), ay.reshape(-1)], axis=-1)


def action_to_accel(action: ArrayLike, params: EnvParams) -> jax.Array:
    """The acceleration of a discrete action index (eq. 6.1)."""
    return action_table(params)[action]


# ---------------------------------------------------------------- waypoint actions (eq. 6.2)

ACTION_MODES = ("table", "waypoint", "dwell", "option", "mixed")  # eqs. 6.1, 6.2, 6.3, 6.4, 6.4 with 6.2
OPTION_MODES = ("option", "mixed")  # the modes whose actions are options (eq. 6.4): one decision per option
ENV_ACTION_MODES = ("table", "waypoint", "dwell")  # what an env step takes: an option needs the BS's policy state

TARGETS = 3  # the nearest unfinished devices a waypoint action can aim at
SPEEDS = (0.0, 6.0, 12.0, 18.0, 25.0)  # m/s; 0 = fly over the device and hover there (eq. 7.3)
HOVER_BRAKE = 0.5  # share of a_max a hover approach brakes with
HOME = TARGETS * len(SPEEDS)  # the last waypoint action: fly home at v_max and brake into the disk
NUM_WAYPOINT_ACTIONS = HOME + 1


def device_order(state: EnvState, params: EnvParams) -> jax.Array:
    """(N,) device indices, unfinished ones (m_n < M) first, each group nearest first: the order in
    which waypoint actions address devices (eq. 6.2)."""
    d2 = jnp.sum((state.dev_pos - state.q) ** 2, axis=-1)
    return jnp.argsort(jnp.where(state.m < params.M, d2, d2 + 1e12))


def waypoint_accel(action: ArrayLike, state: EnvState, params: EnvParams) -> jax.Array:
    """Eq. 6.2: the acceleration of waypoint action ``action`` (0 .. HOME), by the controller of eq. 7.1.

    Action j * len(SPEEDS) + i flies towards the j-th device of :func:`device_order` at SPEEDS[i],
    or, for SPEEDS[i] = 0, at the approach speed of eq. 7.3 (v_max far away, braking with
    HOVER_BRAKE a_max to a stop over the device). HOME, and any action whose device is finished,
    is the home command at v_max.
    """
    order = device_order(state, params)
    slot = jnp.minimum(action // len(SPEEDS), params.N - 1)
    n = order[slot]
    target = state.dev_pos[n]
    dist = jnp.linalg.norm(target - state.q)
    s = jnp.asarray(SPEEDS)[action % len(SPEEDS)]
    speed = jnp.where(s > 0, s, approach_speed(dist, params.v_max, params, brake=HOVER_BRAKE))
    to_device = speed_command(state.q, state.v, target, speed, params)
    home = home_command(state.q, state.v, params.v_max, params)
    go = (action < HOME) & (action // len(SPEEDS) < params.N) & (state.m[n] < params.M)
    return jnp.where(go, to_device, home)


# ---------------------------------------------------------------- dwell actions (eq. 6.3)

DWELL_K = (16.0, 32.0, 48.0, 64.0, 96.0, 128.0)  # symbols: "stay until k" of the dwell actions
DWELL_SPEED = 25.0  # m/s: their cruise speed, that of the tuned dwell rules
NUM_DWELL_ACTIONS = NUM_WAYPOINT_ACTIONS + len(DWELL_K)


def dwell_accel(action: ArrayLike, state: EnvState, params: EnvParams) -> jax.Array:
    """Eq. 6.3: the waypoint actions of eq. 6.2, then for i < len(DWELL_K) the action HOME + 1 + i:
    cruise at DWELL_SPEED to the nearest device with fewer than DWELL_K[i] symbols and come to rest
    over it (eq. 7.3 with STOP_BRAKE); home when every device has that many. Sent slot after slot,
    it is greedy-dwell with k* = DWELL_K[i] (without its time test: the BS's shield sends HOME)."""
    i = jnp.clip(action - NUM_WAYPOINT_ACTIONS, 0, len(DWELL_K) - 1)
    short = state.m < jnp.asarray(DWELL_K)[i] - 1e-3
    d = jnp.linalg.norm(state.dev_pos - state.q, axis=-1)
    stay = rest_command(state.q, state.v, state.dev_pos, d, short, DWELL_SPEED, params.v_max, params)
    return jnp.where(action < NUM_WAYPOINT_ACTIONS, waypoint_accel(action, state, params), stay)


# ---------------------------------------------------------------- options (eq. 6.4)

OPTION_TARGETS = 4  # an option serves the 1st or 2nd candidate of the tour (eq. 6.5), or the nearest or 2nd nearest
TOUR_TARGETS = 2  # targets j < TOUR_TARGETS count along the tour, the others by distance
OPTION_K = (16.0, 24.0, 32.0, 48.0, 64.0, 96.0)  # symbols: "serve until k" of the options
OPTION_HOME = OPTION_TARGETS * len(OPTION_K)  # the last option: fly home
NUM_OPTIONS = OPTION_HOME + 1
NUM_MIXED_ACTIONS = NUM_OPTIONS + NUM_WAYPOINT_ACTIONS  # options, then waypoint actions for one slot each
HOME_CODE = -1  # the command code of the home option; waypoint action w has code HOME_CODE - 1 - w


def option_need(state: EnvState, params: EnvParams) -> jax.Array:
    """(N,) seconds, eqs. 7.4-7.5: flying to each device at DWELL_SPEED, stopping there and flying home."""
    return jax.vmap(lambda p: time_via(state.q, state.v, p, DWELL_SPEED, params, stop=True))(state.dev_pos)


def option_fits(state: EnvState, params: EnvParams, margin: ArrayLike, need: ArrayLike | None = None) -> jax.Array:
    """(N,) bool, eq. 7.9: the devices that an option can still serve, i.e. whose :func:`option_need`
    (or ``need``, when the caller has it) fits in the time left less ``margin`` seconds (negative: a
    flight that eqs. 7.4-7.5 time up to -margin s too long)."""
    need = option_need(state, params) if need is None else need
    return need + margin <= (params.K - state.t) * params.tau


def option_code(
    choice: ArrayLike, m: ArrayLike, fits: ArrayLike, order: ArrayLike, tour: ArrayLike, params: EnvParams
) -> tuple[jax.Array, jax.Array]:
    """Eq. 6.4: the command code and the symbol target k of option ``choice``, given the symbols
    ``m``, :func:`option_fits`, the devices in :func:`device_order` and in the order of the tour
    (``semuav_jax.tour.tour_order``, eq. 6.5). The candidates for k = OPTION_K[i] are the devices short
    of k symbols that fit (eq. 7.9); option j * len(OPTION_K) + i serves, until it holds k, the j-th
    candidate along the tour for j < TOUR_TARGETS, else the (j - TOUR_TARGETS)-th nearest (the last
    candidate when there are fewer): code n, fixed at the decision whatever the orders become.
    Option 0 followed throughout is TSP-dwell with k* = k along ``tour`` (its own order along the
    shortest path, ``semuav_jax.tour.shortest_path``), option
    TOUR_TARGETS * len(OPTION_K) greedy-dwell (eq. 7.10), both with the margin of ``fits``.
    OPTION_HOME, or no candidate, is HOME_CODE (k = inf); a choice NUM_OPTIONS + w (the "mixed"
    actions) is waypoint action w of eq. 6.2 for one slot, code HOME_CODE - 1 - w (k = 0)."""
    L = len(OPTION_K)
    k = jnp.asarray(OPTION_K)[jnp.minimum(choice, OPTION_HOME - 1) % L]
    target = choice // L
    order = jnp.where(target < TOUR_TARGETS, jnp.asarray(tour), jnp.asarray(order))
    short = (jnp.asarray(m)[order] < k - 1e-3) & jnp.asarray(fits)[order]
    rank = jnp.cumsum(short) - 1
    j = jnp.minimum(jnp.where(target < TOUR_TARGETS, target, target - TOUR_TARGETS), jnp.sum(short) - 1)
    n = order[jnp.argmax(short & (rank == j))]
    home = (choice >= OPTION_HOME) | ~jnp.any(short)
    waypoint = choice >= NUM_OPTIONS
    code = jnp.where(waypoint, HOME_CODE - 1 - (choice - NUM_OPTIONS), jnp.where(home, HOME_CODE, n))
    return code.astype(jnp.int32), jnp.where(waypoint, 0.0, jnp.where(home, jnp.inf, k))


def option_codes(
    count: int, m: ArrayLike, fits: ArrayLike, order: ArrayLike, tour: ArrayLike, params: EnvParams
) -> tuple[jax.Array, jax.Array]:
    """:func:`option_code` of the options 0 .. ``count`` - 1: codes (count,) and symbol targets (count,)."""
    return jax.vmap(lambda c: option_code(c, m, fits, order, tour, params))(jnp.arange(count))


def option_accel(code: ArrayLike, state: EnvState, params: EnvParams, waypoints: bool = False) -> jax.Array:
    """The command of an option's code: cruise at DWELL_SPEED to device ``code`` and stay at rest over
    it (eq. 7.3 with STOP_BRAKE), or, for HOME_CODE, fly home at v_max (eq. 7.1); with ``waypoints``
    (static: the "mixed" actions), a code below HOME_CODE is waypoint action HOME_CODE - 1 - code."""
    n = jnp.maximum(code, 0)
    d = jnp.linalg.norm(state.dev_pos - state.q, axis=-1)
    one = jnp.arange(state.dev_pos.shape[0]) == n
    stay = rest_command(state.q, state.v, state.dev_pos, d, one, DWELL_SPEED, params.v_max, params)
    accel = jnp.where(code >= 0, stay, home_command(state.q, state.v, params.v_max, params))
    if not waypoints:
        return accel
    return jnp.where(code < HOME_CODE, waypoint_accel(jnp.maximum(HOME_CODE - 1 - code, 0), state, params), accel)


def num_actions(mode: str, params: EnvParams) -> int:
    """How many discrete actions the action mode ``mode`` has (eq. 6.1: levels^2; eq. 6.2:
    NUM_WAYPOINT_ACTIONS; eq. 6.3: NUM_DWELL_ACTIONS; eq. 6.4: NUM_OPTIONS; mixed: NUM_MIXED_ACTIONS)."""
    sizes = {
        "waypoint": NUM_WAYPOINT_ACTIONS,
        "dwell": NUM_DWELL_ACTIONS,
        "option": NUM_OPTIONS,
        "mixed": NUM_MIXED_ACTIONS,
    }
    return sizes.get(mode, params.levels * params.levels)


def to_accel(mode: str, action: ArrayLike, state: EnvState, params: EnvParams) -> jax.Array:
    """The acceleration of discrete ``action`` in the action mode ``mode`` (static): eq. 6.1, 6.2 or
    6.3, or for options (eq. 6.4, and "mixed") the command code of :func:`option_code`."""
    if mode == "waypoint":
        return waypoint_accel(action, state, params)
    if mode == "dwell":
        return dwell_accel(action, state, params)
    if mode in OPTION_MODES:
        return option_accel(action, state, params, waypoints=mode == "mixed")
    return action_to_accel(action, params)
