"""Waypoint actions (docs/model.md eq. 6.2): device order, commands by hand, bounds."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from semuav_jax.actions import HOME, NUM_WAYPOINT_ACTIONS, SPEEDS, TARGETS, device_order, waypoint_accel
from semuav_jax.control import home_command, speed_command
from semuav_jax.env import reset_state


@pytest.fixture
def state(params):
    s = reset_state(jax.random.key(0), params)
    pos = jnp.array(
        [
            [100.0, 300.0],
            [130.0, 340.0],
            [50.0, 300.0],
            [400.0, 100.0],
            [900.0, 500.0],
            [60.0, 310.0],
            [700.0, 300.0],
            [20.0, 250.0],
            [500.0, 550.0],
            [300.0, 300.0],
        ]
    )
    m = jnp.zeros(10).at[2].set(params.M).at[5].set(10.0)  # device 2 finished, device 5 partly received
    return s.replace(dev_pos=pos, m=m, q=jnp.array([40.0, 300.0]), v=jnp.array([4.0, 0.0]))


def test_device_order_puts_finished_devices_last(state, params):
    # distances from (40, 300): 5: 22.4, 7: 53.9, 0: 60, 1: 100, 9: 260, ...; 2 (10 m) is finished
    order = np.asarray(device_order(state, params))
    assert list(order[:4]) == [5, 7, 0, 1] and order[-1] == 2


def test_waypoint_commands_by_hand(state, params):
    assert NUM_WAYPOINT_ACTIONS == TARGETS * len(SPEEDS) + 1 == HOME + 1
    home = np.asarray(home_command(state.q, state.v, params.v_max, params))
    np.testing.assert_allclose(waypoint_accel(HOME, state, params), home)
    # action 1 * S + 3: the second device in order (7, at (20, 250)) at SPEEDS[3] = 18 m/s
    want = speed_command(state.q, state.v, state.dev_pos[7], SPEEDS[3], params)
    np.testing.assert_allclose(waypoint_accel(len(SPEEDS) + 3, state, params), want)
    # hover over device 5 (22.4 m away): approach speed sqrt(2 * 0.5 * 5 * 22.36) = 10.57 m/s towards it
    a = np.asarray(waypoint_accel(0, state, params))
    u = (np.array([60.0, 310.0]) - np.array([40.0, 300.0])) / np.sqrt(500.0)
    np.testing.assert_allclose(a, np.clip((np.sqrt(5.0 * np.sqrt(500.0)) * u - [4.0, 0.0]) / 0.5, -5, 5), rtol=1e-5)


def test_actions_on_finished_devices_fly_home(state, params):
    done = state.replace(m=jnp.full(10, float(params.M)).at[5].set(0.0))  # one device left
    home = np.asarray(home_command(done.q, done.v, params.v_max, params))
    for a in range(len(SPEEDS), HOME):  # second and third targets do not exist
        np.testing.assert_allclose(waypoint_accel(a, done, params), home)
    assert not np.allclose(waypoint_accel(1, done, params), home)


def test_every_waypoint_command_is_within_a_max(params):
    keys = jax.random.split(jax.random.key(1), 64)
    states = jax.vmap(reset_state, (0, None))(keys, params)
    q = jax.random.uniform(jax.random.key(2), (64, 2), minval=-50.0, maxval=1050.0)
    v = jax.random.uniform(jax.random.key(3), (64, 2), minval=-25.0, maxval=25.0)
    states = states.replace(q=q, v=v)
    a = jax.vmap(lambda s: jax.vmap(lambda i: waypoint_accel(i, s, params))(jnp.arange(NUM_WAYPOINT_ACTIONS)))(states)
    assert np.all(np.isfinite(a)) and np.all(np.abs(np.asarray(a)) <= params.a_max + 1e-6)
