"""The "mixed" actions (docs/model.md eq. 6.4 with 6.2): options and waypoint actions that last one
slot, in one network; their codes and commands by hand, a constant waypoint choice flying as the
waypoint agent, one-slot semi-MDP transitions in training, the search over a mixed agent's options,
and demonstrations kept only from the envs at B >= demo_from."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import short_option_training

from semuav_jax.actions import (
    HOME,
    HOME_CODE,
    NUM_MIXED_ACTIONS,
    NUM_OPTIONS,
    NUM_WAYPOINT_ACTIONS,
    OPTION_HOME,
    device_order,
    num_actions,
    option_accel,
    option_code,
    waypoint_accel,
)
from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.features import B_REF
from semuav_jax.agents.options import OptionObs, idle, running, step_option
from semuav_jax.agents.policy import choice_policy, initial_state
from semuav_jax.env import reset_state
from semuav_jax.params import make_params
from semuav_jax.rollout import rollout

MIXED = DDQNConfig(actions="mixed", shield_margin=2.0)


def test_mixed_codes_and_commands_by_hand(params):
    """Choice NUM_OPTIONS + w is waypoint action w: code HOME_CODE - 1 - w, k = 0, the command of
    eq. 6.2 for w; it ends after its slot even over a device short of symbols. Options keep their
    codes and commands."""
    state = reset_state(jax.random.key(0), params)
    assert num_actions("mixed", params) == NUM_MIXED_ACTIONS == NUM_OPTIONS + NUM_WAYPOINT_ACTIONS
    n = jnp.arange(params.N, dtype=jnp.int32)
    fits, m = jnp.ones(params.N, bool), jnp.zeros(params.N)
    for w in (0, 7, HOME):
        code, k = option_code(jnp.int32(NUM_OPTIONS + w), m, fits, n, n, params)
        assert (int(code), float(k)) == (HOME_CODE - 1 - w, 0.0)
        np.testing.assert_array_equal(
            option_accel(code, state, params, waypoints=True), waypoint_accel(jnp.int32(w), state, params)
        )
    for c in (0, 3, OPTION_HOME):  # options: the same code and command with or without waypoints
        code, _ = option_code(jnp.int32(c), m, fits, n, n, params)
        assert int(code) >= HOME_CODE
        with_waypoints = option_accel(code, state, params, waypoints=True)
        np.testing.assert_array_equal(with_waypoints, option_accel(code, state, params))
    obs = OptionObs(jnp.zeros(3), m, fits, device_order(state, params), state.q, state.dev_pos)
    wp = step_option(idle(), jnp.int32(NUM_OPTIONS + 2), obs, params)
    assert bool(wp.decided) and int(wp.code) == HOME_CODE - 3 and not bool(running(wp, obs, params))
    nxt = step_option(wp, jnp.int32(0), obs, params)
    assert bool(nxt.decided) and int(nxt.code) >= 0  # the next slot is a decision: option 0 serves a device


@pytest.mark.parametrize("w", [2, HOME])
def test_a_constant_waypoint_choice_flies_as_the_waypoint_agent(params, w):
    """A mixed policy that chooses waypoint action w at every slot flies the episodes of the waypoint
    policy that sends w every slot (same shield margin: late, both send the home command)."""
    keys = jax.random.split(jax.random.key(3), 6)
    wp_cfg = DDQNConfig(actions="waypoint", shield_margin=2.0)
    mixed = choice_policy(lambda inner, x, p: jnp.int32(NUM_OPTIONS + w), MIXED)
    plain = choice_policy(lambda inner, x, p: jnp.int32(w), wp_cfg)
    a = rollout(mixed, keys, params, initial_state(jnp.zeros(()), MIXED), state_axes=None)[0]
    b = rollout(plain, keys, params, initial_state(jnp.zeros(()), wp_cfg), state_axes=None)[0]
    for k in ("mean_psnr", "arrived", "mission_time", "symbol_fraction"):
        np.testing.assert_allclose(np.asarray(a[k]), np.asarray(b[k]), rtol=1e-6, err_msg=k)


def test_mixed_training_stores_one_slot_waypoint_decisions(curves):
    """A short mixed training: every action in [0, NUM_MIXED_ACTIONS), waypoint choices among them,
    each waypoint decision one slot long (discount gamma exactly), options gamma^tau; reproducible."""
    cfg, ts, ts2, m = short_option_training(curves, "mixed")
    n = int(ts.replay.size)
    action, disc = np.asarray(ts.replay.data.action[:n]), np.asarray(ts.replay.data.discount[:n])
    assert set(np.unique(action)) <= set(range(NUM_MIXED_ACTIONS))
    wp = action >= NUM_OPTIONS
    assert wp.any() and (~wp).any()
    np.testing.assert_allclose(disc[wp], cfg.gamma, rtol=1e-6)
    tau = np.log(disc[~wp]) / np.log(cfg.gamma)
    np.testing.assert_allclose(tau, np.round(tau), atol=1e-3)
    for a, b in zip(jax.tree.leaves(ts.params), jax.tree.leaves(ts2.params)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert np.all(np.isfinite(np.asarray(m["loss"])))


def test_the_search_of_a_mixed_agent_simulates_options_only(curves):
    """The search's candidates are the options (top by Q among options and home), not the waypoint
    actions; the agent between decisions may choose either."""
    from semuav_jax.agents.network import q_network
    from semuav_jax.agents.policy import input_size
    from semuav_jax.agents.search import search_metrics

    cfg = DDQNConfig(hidden=(16,), actions="mixed", shield_margin=2.0)
    params = make_params(curves, B=25e3, K=60)
    network = q_network(params, cfg)
    net = network.init(jax.random.key(1), jnp.zeros((input_size(params, cfg),)))
    keys = jax.random.split(jax.random.PRNGKey(4), 4)
    m, chosen, _ = search_metrics(net, cfg, keys, params, every=8)  # 4 targets x 6 options, home, 12 rules
    assert np.asarray(chosen).shape == (4, 8) and np.asarray(chosen).max() <= 37
    assert np.all(np.isfinite(np.asarray(m["mean_psnr"])))


def test_demonstrations_come_only_from_envs_at_demo_from_and_above(params):
    """With demo_from, every demonstrated state's bandwidth (the input's log2(B / B_REF)) is at least
    demo_from; without it, envs below it demonstrate too."""
    from semuav_jax.agents.trainer import make_train

    base = dict(actions="mixed", demo_steps=60, num_envs=8, steps_per_chunk=5, total_steps=80,
                learning_starts=32, batch_size=8, demo_batch=4, buffer_size=512)  # fmt: skip

    def demo_bandwidths(**kw):
        ts = jax.jit(make_train(DDQNConfig(**base, **kw), params).init)(jax.random.key(0))
        x = np.asarray(ts.demos.data.obs[: int(ts.demos.size)])
        return B_REF * 2.0 ** x[:, 12]  # waypoint_features: q, v, a_prev, left, goal, tanh(goal), slack, log2 B

    every, high = demo_bandwidths(), demo_bandwidths(demo_from=20e3)
    assert every.min() < 10e3 and high.size > 0
    assert high.min() >= 20e3 * (1 - 1e-5)


@pytest.mark.parametrize(
    "bad, match",
    [
        ({"demo_from": -1.0}, "demo_from must be a finite bandwidth"),
        ({"demo_from": float("nan")}, "demo_from must be a finite bandwidth"),
        ({"demo_steps": 10, "demo_from": 50e3}, "above every training bandwidth"),
    ],
)
def test_bad_demo_from_is_a_one_line_error(bad, match):
    with pytest.raises(ValueError, match=match):
        DDQNConfig(actions="mixed", **bad)
