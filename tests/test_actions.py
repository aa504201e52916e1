"""Waypoint and dwell actions (docs/model.md eqs. 6.2-6.3): device order, commands by hand, bounds."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from semuav_jax.actions import (
    DWELL_K,
    DWELL_SPEED,
    HOME,
    NUM_DWELL_ACTIONS,
    NUM_WAYPOINT_ACTIONS,
    SPEEDS,
    TARGETS,
    device_order,
    dwell_accel,
    num_actions,
    waypoint_accel,
)
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


def test_dwell_actions_by_hand(state, params):
    """Eq. 6.3: the waypoint actions first; HOME + 1 + i rests over the nearest device short of
    DWELL_K[i] symbols (device 5 holds 10 symbols, device 2 is finished)."""
    for a in (0, 7, HOME):
        np.testing.assert_allclose(dwell_accel(a, state, params), waypoint_accel(a, state, params))
    # k = 16: device 5 (22.4 m, 10 < 16 symbols): approach speed sqrt(2 * 0.6 * 5 * 22.36) = 11.58 m/s
    want = speed_command(state.q, state.v, state.dev_pos[5], np.sqrt(2 * 0.6 * 5.0 * np.sqrt(500.0)), params)
    np.testing.assert_allclose(dwell_accel(HOME + 1, state, params), want, rtol=1e-5)
    # with 16 symbols on device 5 the nearest short of 16 is device 7 (53.9 m): capped at DWELL_SPEED
    got = state.replace(m=state.m.at[5].set(16.0))
    d7 = float(np.linalg.norm(np.array([20.0, 250.0]) - np.array([40.0, 300.0])))
    want = speed_command(got.q, got.v, got.dev_pos[7], min(DWELL_SPEED, np.sqrt(2 * 0.6 * 5.0 * d7)), params)
    np.testing.assert_allclose(dwell_accel(HOME + 1, got, params), want, rtol=1e-5)
    # every device holding DWELL_K[-1]: home at v_max
    full = state.replace(m=jnp.full(10, DWELL_K[-1]))
    home = home_command(full.q, full.v, params.v_max, params)
    np.testing.assert_allclose(dwell_accel(NUM_DWELL_ACTIONS - 1, full, params), home)
    assert num_actions("dwell", params) == NUM_DWELL_ACTIONS == NUM_WAYPOINT_ACTIONS + len(DWELL_K)


def test_a_constant_dwell_action_flies_like_greedy_dwell(params):
    """Sent every slot through the BS's shield, dwell action k visits the devices nearest first
    and stays until k symbols, as greedy-dwell with k* = k does (without its time test)."""
    from baselines.dwell import dwell_metrics, greedy_dwell
    from semuav_jax.agents.shield import waypoint_shield
    from semuav_jax.engine import Policy
    from semuav_jax.rollout import rollout

    keys = jax.random.split(jax.random.key(5), 32)
    act = jnp.int32(NUM_WAYPOINT_ACTIONS + DWELL_K.index(48.0))
    pol = Policy(lambda ps, s, p: (act, ps), "dwell", shield=lambda a, s, p: waypoint_shield(a, s, p, 2.0))
    m = rollout(pol, keys, params, jnp.zeros(32))[0]
    g = dwell_metrics(greedy_dwell, keys, params, DWELL_SPEED, 48.0, -2.0, np.zeros((32, 10), np.int32))
    assert bool(np.all(m["arrived"]))
    assert abs(float(m["mean_psnr"].mean()) - float(g["mean_psnr"].mean())) < 1.0
    assert float(np.mean(m["symbol_fraction"])) > 0.9 * float(np.mean(g["symbol_fraction"]))
