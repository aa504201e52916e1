"""The BS's return-home shield (semuav_jax/agents/shield.py, docs/ddqn.md "Shield")."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_control import time_home_by_hand

from semuav_jax.actions import action_to_accel, num_actions
from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.shield import home_action, home_speed, shield
from semuav_jax.agents.trainer import make_train
from semuav_jax.control import time_home
from semuav_jax.env import reset_state
from semuav_jax.rollout import episode


def test_time_home_by_hand(params):
    # home speed 25 - sqrt(2) * 5 * 0.5 / 2 = 23.232 m/s (half a level step of error per axis)
    v_home = 25.0 - np.sqrt(2.0) * 1.25
    assert float(home_speed(params)) == pytest.approx(v_home, rel=1e-6)
    th = lambda q, v: float(time_home(jnp.array(q), jnp.array(v), params.v_max, params, cruise=home_speed(params)))
    # at rest at the BS (500, 300), 500 m from q_fin = (1000, 300): turn 4.646 s, cruise
    # (500 - 215.89) / 23.232 = 12.229 s, brake 2 (sqrt(215.89) - sqrt(15)) / sqrt(2.5) = 13.687 s
    assert th([500.0, 300.0], [0.0, 0.0]) == pytest.approx(30.562, abs=1e-3)
    # already flying home at the home speed: no turn, no drift
    assert th([500.0, 300.0], [v_home, 0.0]) == pytest.approx(25.916, abs=1e-3)
    # flying sideways and away: turn 4 s while drifting 20^2 / 10 = 40 m further
    assert th([500.0, 300.0], [10.0, -20.0]) == pytest.approx(4.0 + (540.0 - 215.89) / v_home + 13.687, abs=1e-3)
    # 50 m out at 25 m/s: faster than the approach speed sqrt(2.5 * 50) = 11.2 m/s, overshoot and back
    assert th([950.0, 300.0], [25.0, 0.0]) > th([950.0, 300.0], [11.0, 0.0]) + 4.0  # 10.95 s vs 6.50 s
    for q, v in (
        ([120.0, 40.0], [-20.0, 7.0]),
        ([980.0, 330.0], [15.0, 20.0]),
        ([700.0, 590.0], [3.0, 1.0]),
        ([950.0, 300.0], [25.0, 0.0]),
    ):
        assert th(q, v) == pytest.approx(time_home_by_hand(q, v, 25.0, v_home), rel=1e-5)
    # inside the arrival disk at rest: only the turn (acceleration) term is left
    assert th([990.0, 300.0], [0.0, 0.0]) == pytest.approx(v_home / 5.0)


def test_home_action_points_home(params):
    # levels = 3: action i = (lv[i // 3], lv[i % 3]), lv = (-5, 0, 5); at rest at q0 the controller wants +x
    assert int(home_action(jnp.array([0.0, 300.0]), jnp.zeros(2), params)) == 7
    # above q_fin's line, flying +x at 22 m/s: the x error rounds to 0, steer down in y
    assert int(home_action(jnp.array([500.0, 560.0]), jnp.array([22.0, 0.0]), params)) == 3
    # 10 m before q_fin at 20 m/s: the approach speed is sqrt(2.5 * 10) = 5 m/s, so brake in x
    assert int(home_action(jnp.array([990.0, 300.0]), jnp.array([20.0, 0.0]), params)) == 1


def test_shield_overrides_only_when_late(params):
    s = reset_state(jax.random.key(0), params)  # t = 0 at q0: 125 s left, 52 s needed
    for a in range(num_actions("table", params)):
        assert int(shield(jnp.int32(a), s, params, 2.0)) == a
    late = s.replace(t=jnp.int32(params.K - 60))  # 29.5 s left after this slot
    for a in range(num_actions("table", params)):
        assert int(shield(jnp.int32(a), late, params, 2.0)) == 7
    # the boundary: time left after the slot equals time_home + margin
    need = float(time_home(s.q, s.v, params.v_max, params, cruise=home_speed(params))) + 2.0
    t_edge = int(np.ceil(params.K - 1 - need / params.tau))
    assert int(shield(jnp.int32(0), s.replace(t=jnp.int32(t_edge)), params, 2.0)) == 7
    assert int(shield(jnp.int32(0), s.replace(t=jnp.int32(t_edge - 1)), params, 2.0)) == 0


def _shielded_random_policy(margin):
    def policy(draws, state, params):
        a = shield(draws[jnp.minimum(state.t, params.K - 1)], state, params, margin)
        return action_to_accel(a, params), draws

    return policy


def test_any_policy_arrives_with_the_shield(params):
    """Random action sequences (and every constant action) arrive in every episode, over random
    bandwidths, speed caps and acceleration bounds; without the shield most do not."""
    E = 256
    ks = jax.random.split(jax.random.key(3), 6)
    draws = jax.random.randint(ks[0], (E, params.K), 0, num_actions("table", params))
    const = jnp.repeat(jnp.arange(E) % num_actions("table", params), params.K).reshape(E, params.K)
    draws = jnp.where((jnp.arange(E) < E // 2)[:, None], draws, const)
    B = jax.random.uniform(ks[1], (E,), minval=2e3, maxval=50e3)
    v_max = jax.random.uniform(ks[2], (E,), minval=12.0, maxval=30.0)
    a_max = jax.random.uniform(ks[3], (E,), minval=2.0, maxval=8.0)
    keys = jax.random.split(ks[4], E)

    def one(margin):
        def ep(k, d, b, v, a):
            p = params.replace(B=b, v_max=v, a_max=a)
            return episode(_shielded_random_policy(margin), k, p, policy_state=d)[0]["arrived"]

        return np.asarray(jax.jit(jax.vmap(ep))(keys, draws, B, v_max, a_max))

    assert one(2.0).all()
    assert one(-1e9).mean() < 0.5  # a margin of -inf never overrides: the same policies mostly miss


@pytest.mark.slow
def test_training_stores_shielded_actions(params):
    """With epsilon = 1 throughout, every training episode still arrives when the shield is on."""
    base = DDQNConfig(
        num_envs=16,
        total_steps=16 * 250 * 2,
        steps_per_chunk=250,
        learning_starts=128,
        batch_size=32,
        buffer_size=8_000,
        eps_start=1.0,
        eps_end=1.0,
    )
    out = {}
    for margin in (2.0, None):
        tr = make_train(dataclasses.replace(base, shield_margin=margin), params)
        _, metrics = jax.jit(tr.train)(jax.random.key(0))
        assert float(metrics["episodes"].sum()) > 0
        out[margin] = float((metrics["arrived"] * metrics["episodes"]).sum() / metrics["episodes"].sum())
    assert out[2.0] == 1.0
    assert out[None] < 0.5


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), float("-inf")])
def test_config_rejects_a_margin_that_is_not_finite(bad):
    with pytest.raises(ValueError, match="shield_margin must be finite"):
        DDQNConfig(shield_margin=bad)


@pytest.mark.parametrize("margin", [2.0, -2.0])
def test_waypoint_shield_sends_home_exactly_when_late(params, margin):
    """Waypoint actions: HOME from the slot where the time left falls to eq. 7.5 at v_max + margin
    (a negative margin: that many seconds later)."""
    from semuav_jax.actions import HOME, NUM_WAYPOINT_ACTIONS
    from semuav_jax.agents.shield import late, waypoint_shield

    s = reset_state(jax.random.key(0), params).replace(q=jnp.array([600.0, 200.0]), v=jnp.array([3.0, -4.0]))
    need = float(time_home(s.q, s.v, params.v_max, params)) + margin
    t_edge = int(np.ceil(params.K - 1 - need / float(params.tau)))  # first slot with (K - t - 1) tau <= need
    for t, want_home in ((t_edge - 1, False), (t_edge, True)):
        st = s.replace(t=jnp.int32(t))
        assert bool(late(st, params, margin)) == want_home
        for a in range(NUM_WAYPOINT_ACTIONS):
            assert int(waypoint_shield(jnp.int32(a), st, params, margin)) == (HOME if want_home else a)
    assert int(waypoint_shield(jnp.int32(0), s.replace(t=jnp.int32(params.K - 1)), params, None)) == 0
