"""Demonstrations (agents/demos.py, DQfD): the expert's choice by bandwidth, the large-margin loss
by hand, the demonstration memory holding the expert's decisions, the switch expert against a plain
loop over its candidates, and bad settings refused."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from semuav_jax.actions import OPTION_K
from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.demos import (
    SWITCH_OPTIONS,
    expert_choice,
    expert_k,
    expert_policy,
    margin_loss,
    switch_choices,
    weighted_margin_loss,
)
from semuav_jax.agents.evaluate import expert_metrics
from semuav_jax.agents.features import bandwidth, option_features, waypoint_features
from semuav_jax.agents.options import idle, idle_batch
from semuav_jax.agents.policy import choice_policy
from semuav_jax.agents.trainer import make_train, update
from semuav_jax.env import reset_state
from semuav_jax.keys import episode_keys
from semuav_jax.lookahead import score
from semuav_jax.rollout import episode

CFG = DDQNConfig(actions="option", demo_steps=40, num_envs=4, steps_per_chunk=5, total_steps=80,
                 learning_starts=32, batch_size=8, demo_batch=4, buffer_size=256)  # fmt: skip


def test_the_expert_takes_the_k_of_its_bandwidth():
    """k = 16 below 7.5 kHz, 48 up to 35 kHz, 32 above (an edge belongs to the band above it)."""
    got = [int(expert_choice(jnp.float32(b), CFG)) for b in (4e3, 7.5e3, 20e3, 35e3, 45e3)]
    assert got == [OPTION_K.index(k) for k in (16.0, 48.0, 48.0, 32.0, 32.0)]


def test_the_experts_metrics_are_its_episodes_one_by_one(params):
    """``evaluate.expert_metrics`` (vmapped over B and layouts) equals a plain loop of episodes of the
    expert option policy, and its k is that of its band (``expert_k``)."""
    keys = episode_keys(3, 3)
    got = expert_metrics(CFG, keys, params, (5e3, 40e3))
    for j, b in enumerate((5e3, 40e3)):
        at = params.replace(B=b)
        assert float(expert_k(jnp.float32(b), CFG)) == (16.0 if b < 7.5e3 else 32.0)
        for i, k in enumerate(keys):
            m, _ = episode(expert_policy(CFG), k, at, (jnp.zeros(()), idle()))
            np.testing.assert_allclose(got["mean_psnr"][j, i], m["mean_psnr"], rtol=1e-5)
            assert bool(got["arrived"][j, i]) == bool(m["arrived"])


def test_margin_loss_by_hand():
    """J_E = max_a [Q(s, a) + l(a_E, a)] - Q(s, a_E): 0 when the expert's Q leads by the margin."""
    q = jnp.array([[1.0, 0.5, 0.9], [0.0, 2.0, 1.0]])
    # row 0, expert 0: max(1, 0.5 + 0.2, 0.9 + 0.2) - 1 = 0.1; row 1, expert 1: max(0.2, 2, 1.2) - 2 = 0
    np.testing.assert_allclose(margin_loss(q, jnp.array([0, 1]), 0.2), [0.1, 0.0], rtol=1e-6)
    np.testing.assert_allclose(margin_loss(q, jnp.array([2, 1]), 0.0), [1.0 - 0.9, 0.0], rtol=1e-6)


@pytest.fixture
def state(params):
    return reset_state(jax.random.key(0), params)


def test_the_inputs_tell_their_bandwidth(state, params):
    """``features.bandwidth`` reads B back from a waypoint or option input, one or a batch."""
    bs = (4e3, 7.5e3, 23.3e3, 45e3)
    for b in bs:
        at = params.replace(B=b)
        np.testing.assert_allclose(bandwidth(waypoint_features(state, at)), b, rtol=1e-5)
        np.testing.assert_allclose(bandwidth(option_features(state, at, -4.0, True)), b, rtol=1e-5)
    x = jnp.stack([waypoint_features(state, params.replace(B=b)) for b in bs])
    np.testing.assert_allclose(bandwidth(x), bs, rtol=1e-5)


def test_the_large_margin_loss_weighted_by_band_by_hand(state, params):
    """One weight multiplies the mean J_E; one per band weighs each row by its input's bandwidth
    (5 kHz below the 7.5 kHz edge, 20 kHz between, 40 kHz above 35 kHz)."""
    q = jnp.array([[1.0, 0.5, 0.9], [0.0, 2.0, 1.0], [0.0, 0.5, 0.1]])
    a = jnp.array([0, 1, 0])  # J_E: 0.1, 0, 0.7
    x = jnp.stack([waypoint_features(state, params.replace(B=b)) for b in (5e3, 20e3, 40e3)])
    one = DDQNConfig(**{**CFG.to_dict(), "demo_weight": 4.0})
    np.testing.assert_allclose(weighted_margin_loss(one, x, q, a), 4.0 * 0.8 / 3, rtol=1e-6)
    bands = DDQNConfig(**{**CFG.to_dict(), "demo_weight": (2.0, 4.0, 16.0)})
    np.testing.assert_allclose(weighted_margin_loss(bands, x, q, a), (2.0 * 0.1 + 16.0 * 0.7) / 3, rtol=1e-6)
    none_low = DDQNConfig(**{**CFG.to_dict(), "demo_weight": (0.0, 4.0, 16.0)})  # no margin loss below 7.5 kHz
    np.testing.assert_allclose(weighted_margin_loss(none_low, x, q, a), 16.0 * 0.7 / 3, rtol=1e-6)


def test_the_demonstration_memory_holds_the_experts_decisions(params):
    """After init, the memory holds the expert's decisions (its choice at each env's bandwidth),
    with finite rewards and discounts gamma^tau in (0, 1]; without demo_steps there is none."""
    tr = make_train(CFG, params)
    ts = jax.jit(tr.init)(jax.random.key(0))
    size = int(ts.demos.size)
    assert size > 0
    data = jax.tree.map(lambda x: np.asarray(x[:size]), ts.demos.data)
    allowed = {OPTION_K.index(k) for k in CFG.demo_k}
    assert set(data.action.tolist()) <= allowed
    assert np.all(np.isfinite(data.reward)) and np.all((data.discount > 0) & (data.discount <= 1))
    plain = jax.jit(make_train(DDQNConfig(**{**CFG.to_dict(), "demo_steps": 0}), params).init)(jax.random.key(0))
    assert plain.demos is None


def test_training_with_demonstrations_runs_and_is_deterministic(params):
    """Two chunks of training with the demonstration losses: finite, the same under the same key,
    and not the weights of the same run without demonstrations."""
    tr = make_train(CFG, params)
    run = jax.jit(lambda k: tr.run(tr.init(k), 2))
    (a, ma), (b, _) = run(jax.random.key(1)), run(jax.random.key(1))
    assert np.all(np.isfinite(np.asarray(ma["loss"])))
    for x, y in zip(jax.tree.leaves(a.params), jax.tree.leaves(b.params)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    bare = make_train(DDQNConfig(**{**CFG.to_dict(), "demo_steps": 0}), params)
    c, _ = jax.jit(lambda k: bare.run(bare.init(k), 2))(jax.random.key(1))
    assert any(not np.array_equal(x, y) for x, y in zip(jax.tree.leaves(a.params), jax.tree.leaves(c.params)))


def test_updates_on_mixed_minibatches_learn_the_experts_choices(params):
    """Updates alone (no env steps), the last demo_batch rows of each minibatch demonstrations with
    a heavy large-margin loss: the greedy choice on the demonstrated states becomes the expert's."""
    cfg = DDQNConfig(**{**CFG.to_dict(), "lr": 3e-3, "demo_weight": 20.0, "lr_end": 1.0})
    tr = make_train(cfg, params)
    ts = jax.jit(tr.init)(jax.random.key(2))
    size = int(ts.demos.size)
    obs, action = ts.demos.data.obs[:size], np.asarray(ts.demos.data.action[:size])
    agree = lambda ts: np.mean(np.asarray(jnp.argmax(tr.network.apply(ts.params, obs), -1)) == action)
    steps = jax.jit(lambda ts, k: jax.lax.scan(lambda t, k: update(tr, t, k), ts, jax.random.split(k, 400))[0])
    before, ts = agree(ts), steps(ts, jax.random.key(3))
    assert agree(ts) >= 0.95 > before


def test_the_switch_expert_takes_the_best_constant_option_of_a_plain_loop(params):
    """From a fresh state at 5 and 40 kHz, the switch expert's option is the constant option of
    SWITCH_OPTIONS that scores best (eq. 7.15) flown to the end with the env's delay draws, found by
    a plain loop over the candidates, one episode each."""
    cfg = DDQNConfig(**{**CFG.to_dict(), "demo_expert": "switch"})
    B = jnp.array([5e3, 40e3], jnp.float32)
    env = params.replace(B=B)
    axes = jax.tree.map(lambda _: None, params).replace(B=0)
    states = jax.vmap(reset_state, (0, axes))(jax.random.split(jax.random.key(4), 2), env)
    key = jax.random.key(5)
    got = np.asarray(switch_choices(cfg, states, idle_batch((2,)), key, env, axes))
    constant = choice_policy(lambda option, x, params: option, cfg)
    fly = jax.jit(lambda o, state, p, draws: score(episode(constant, draws, p, (o, idle()), state)[0], p))
    for e, k in enumerate(jax.random.split(key, 2)):
        state, p = jax.tree.map(lambda x, e=e: x[e], states), params.replace(B=B[e])
        draws = jax.random.split(k, 1)[0]  # the one delay draw of each candidate (lookahead.choose)
        scores = [float(fly(jnp.int32(o), state, p, draws)) for o in SWITCH_OPTIONS]
        assert got[e] == SWITCH_OPTIONS[int(np.argmax(scores))]
        assert len(set(np.round(scores, 3))) > 1  # the candidates differ, so the choice is not a tie-break


def test_switch_demonstrations_hold_the_simulated_options(params):
    """The switch expert's memory holds its decisions: options of SWITCH_OPTIONS (the constant
    expert's after a restart), finite rewards, discounts gamma^tau in (0, 1]."""
    cfg = DDQNConfig(**{**CFG.to_dict(), "demo_expert": "switch", "demo_every": 8})
    ts = jax.jit(make_train(cfg, params).init)(jax.random.key(0))
    size = int(ts.demos.size)
    assert size > 0
    data = jax.tree.map(lambda x: np.asarray(x[:size]), ts.demos.data)
    assert set(data.action.tolist()) <= set(SWITCH_OPTIONS)
    assert np.all(np.isfinite(data.reward)) and np.all((data.discount > 0) & (data.discount <= 1))


@pytest.mark.parametrize(
    "bad, match",
    [
        ({"actions": "waypoint", "demo_steps": 10}, "need actions='option'"),
        ({"demo_steps": -1}, "demo_steps must be >= 0"),
        ({"demo_k": (16.0, 40.0, 32.0)}, "demo_k must hold"),
        ({"demo_k": (16.0, 48.0)}, "demo_k must hold"),
        ({"demo_edges": (35e3, 7.5e3)}, "demo_edges must be increasing"),
        ({"demo_margin": float("nan")}, "demo_margin must be finite"),
        ({"demo_weight": 0.0}, "demo_weight must be one finite weight > 0"),
        ({"demo_weight": (4.0, 8.0)}, "one finite weight >= 0 per band"),
        ({"demo_weight": (4.0, float("nan"), 8.0)}, "demo_weight must be one finite weight > 0"),
        ({"demo_weight": (0.0, 0.0, 0.0)}, "not all 0"),
        ({"demo_weight": (-1.0, 4.0, 16.0)}, "one finite weight >= 0 per band"),
        ({"demo_steps": 10, "demo_batch": 0}, "demo_batch must be in"),
        ({"demo_steps": 10, "demo_batch": 256}, "demo_batch must be in"),
        ({"demo_expert": "planner"}, "demo_expert must be one of"),
        ({"demo_every": 0}, "demo_every must be an integer >= 1"),
        ({"demo_every": 2.5}, "demo_every must be an integer >= 1"),
        ({"option_margin": float("nan")}, "option_margin must be a finite number"),
        ({"option_margin": float("-inf")}, "option_margin must be a finite number"),
    ],
)
def test_bad_demonstration_settings_are_one_line_errors(bad, match):
    with pytest.raises(ValueError, match=match):
        DDQNConfig(**{"actions": "option", **bad})
