"""The DDQN pieces: double-Q target, replay ring buffer, target schedule, learning, seeding."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from semuav_jax.agents.config import DDQNConfig
from semuav_jax.agents.evaluate import evaluate_agent
from semuav_jax.agents.replay import Transition, n_step_transition, replay_add, replay_init, replay_sample
from semuav_jax.agents.scenarios import scenario_params
from semuav_jax.agents.trainer import double_q_target, epsilon, make_train, train_bandwidths

SMALL = dict(num_envs=8, steps_per_chunk=10, batch_size=16, buffer_size=400, learning_starts=64, total_steps=8 * 10 * 6)


def test_double_q_target_by_hand():
    q_online = jnp.array([[1.0, 3.0, 2.0], [5.0, 0.0, 4.0], [0.0, 0.0, 9.0]])
    q_target = jnp.array([[10.0, 20.0, 30.0], [-1.0, -2.0, -3.0], [7.0, 8.0, 6.0]])
    reward = jnp.array([1.0, 0.5, 2.0])
    done = jnp.array([0.0, 0.0, 1.0])
    y = double_q_target(q_online, q_target, reward, done, 0.9)
    # online argmax = 1, 0, 2; the target net evaluates it: 20, -1, (terminal)
    np.testing.assert_allclose(y, [1.0 + 0.9 * 20.0, 0.5 + 0.9 * -1.0, 2.0], rtol=1e-6)
    # not the max of the target net (that would be plain DQN: 1 + 0.9 * 30)
    assert float(y[0]) != pytest.approx(1.0 + 0.9 * 30.0)


def _batch(start, n, obs_dim=3):
    v = jnp.arange(start, start + n, dtype=jnp.float32)
    return Transition(
        jnp.repeat(v[:, None], obs_dim, 1), v.astype(jnp.int32), v, v[:, None] + jnp.zeros(obs_dim), v * 0, v * 0 + 0.9
    )


def test_replay_wraps_around():
    buf = replay_init(5, 3)
    buf = replay_add(buf, _batch(0, 3))
    assert int(buf.pos) == 3 and int(buf.size) == 3
    buf = replay_add(buf, _batch(3, 4))  # 3, 4 fill slots 3, 4; 5, 6 overwrite slots 0, 1
    assert int(buf.pos) == 2 and int(buf.size) == 5
    np.testing.assert_array_equal(buf.data.reward, [5, 6, 2, 3, 4])
    np.testing.assert_array_equal(buf.data.obs[:, 0], [5, 6, 2, 3, 4])
    sample = replay_sample(buf, jax.random.PRNGKey(0), 200)
    assert set(np.asarray(sample.reward).tolist()) == {2.0, 3.0, 4.0, 5.0, 6.0}


def test_replay_samples_only_filled_slots():
    buf = replay_add(replay_init(100, 3), _batch(1, 4))
    sample = replay_sample(buf, jax.random.PRNGKey(1), 500)
    assert set(np.asarray(sample.reward).tolist()) == {1.0, 2.0, 3.0, 4.0}


def test_epsilon_schedule():
    cfg = DDQNConfig(**SMALL, eps_decay_frac=0.5)
    n = int(0.5 * cfg.num_chunks * cfg.steps_per_chunk)
    assert float(epsilon(0, cfg)) == pytest.approx(cfg.eps_start)
    assert float(epsilon(n // 2, cfg)) == pytest.approx((cfg.eps_start + cfg.eps_end) / 2, abs=0.05)
    assert float(epsilon(n, cfg)) == pytest.approx(cfg.eps_end)
    assert float(epsilon(10 * n, cfg)) == pytest.approx(cfg.eps_end)


def test_train_bandwidths_linear_and_log(params):
    """Four envs over 4-32 kHz: evenly 4, 13.33, 22.67, 32 kHz; geometrically 4, 8, 16, 32 kHz
    (ratio (32/4)^(1/3) = 2); no range: the scenario's B for every env."""
    cfg = lambda **kw: DDQNConfig(num_envs=4, learning_starts=8, batch_size=8, bandwidth_range=(4e3, 32e3), **kw)
    np.testing.assert_allclose(train_bandwidths(cfg(), params), [4e3, 40e3 / 3, 68e3 / 3, 32e3], rtol=1e-6)
    log = train_bandwidths(cfg(bandwidth_spacing="log"), params)
    np.testing.assert_allclose(log, [4e3, 8e3, 16e3, 32e3], rtol=1e-5)
    one = DDQNConfig(num_envs=4, learning_starts=8, batch_size=8, bandwidth_range=None)
    np.testing.assert_array_equal(train_bandwidths(one, params), np.full(4, params.B, np.float32))
    with pytest.raises(ValueError, match="bandwidth_spacing must be one of .*got 'cubic'"):
        cfg(bandwidth_spacing="cubic")


@pytest.fixture(scope="module")
def small(curves):
    params = scenario_params("fixed", curves)
    return params, make_train(DDQNConfig(**SMALL, target_period=3), params)


def _same(a, b):
    return all(jax.tree.leaves(jax.tree.map(lambda x, y: bool(jnp.array_equal(x, y)), a, b)))


def test_target_network_updates_only_on_schedule(small):
    _, tr = small
    run1 = jax.jit(lambda s: tr.run(s, 1))
    state = jax.jit(tr.init)(jax.random.PRNGKey(0))
    initial_target = state.target_params
    for chunk in range(1, 7):
        state, _ = run1(state)
        assert not _same(state.params, initial_target)  # the online net learns every step
        if chunk % 3 == 0:
            assert _same(state.target_params, state.params)
            initial_target = state.target_params
        else:
            assert _same(state.target_params, initial_target)


@pytest.mark.slow
def test_seeds_differ_and_reproduce(small):
    _, tr = small
    init = jax.jit(jax.vmap(tr.init))
    keys = jax.random.split(jax.random.PRNGKey(7), 2)
    s = init(keys)
    w = s.params["params"]["Dense_0"]["kernel"]
    assert not jnp.array_equal(w[0], w[1])
    run = jax.jit(jax.vmap(lambda st: tr.run(st, 2)))
    a, ma = run(s)
    b, mb = run(init(keys))
    assert _same(a.params, b.params)
    np.testing.assert_array_equal(ma["loss"], mb["loss"])


def test_config_validation():
    with pytest.raises(ValueError, match="learning_starts"):
        DDQNConfig(learning_starts=10, batch_size=64)
    with pytest.raises(ValueError, match="less than one chunk"):
        DDQNConfig(total_steps=10)


@pytest.mark.slow
def test_short_training_improves_return(curves):
    """Fixed layout, paper reward: ~100 k env steps lift the greedy return far above the untrained net's."""
    params = scenario_params("fixed", curves, reward_mode="paper")
    cfg = DDQNConfig(
        num_envs=32,
        steps_per_chunk=50,
        total_steps=96_000,
        learning_starts=4096,
        lr=1e-3,
        eps_decay_frac=0.6,
        target_period=2,
        gamma=0.98,
    )
    tr = make_train(cfg, params)
    state, _ = jax.jit(tr.train)(jax.random.PRNGKey(0))
    untrained = jax.jit(tr.init)(jax.random.PRNGKey(0)).params
    keys = jax.random.split(jax.random.PRNGKey(1), 16)
    before = evaluate_agent(tr.network, untrained, cfg, keys, params)["return"].mean()
    after = evaluate_agent(tr.network, state.params, cfg, keys, params)["return"].mean()
    assert after > before + 300.0, (before, after)


def _permuted(s):
    perm = jnp.array([3, 1, 4, 0, 9, 2, 8, 5, 7, 6])
    return s.replace(dev_pos=s.dev_pos[perm], dev_img=s.dev_img[perm], m=s.m[perm], phi=s.phi[perm], x=s.x[perm])


def test_agent_inputs_ignore_device_order(curves):
    """Permuting the devices of a state leaves the Q-network's input unchanged (random layouts), for
    both action modes, mid-episode (some devices partly or fully received)."""
    from semuav_jax.agents.policy import agent_input
    from semuav_jax.env import reset_state

    params = scenario_params("random", curves)
    s = reset_state(jax.random.PRNGKey(3), params)
    m = jnp.array([0.0, 40.0, params.M, 0.0, 3.0, 0.0, params.M, 0.0, 0.0, 100.0])
    s = s.replace(
        m=m,
        phi=params.C[s.dev_img, jnp.floor(m).astype(jnp.int32)],
        q=jnp.array([420.0, 310.0]),
        v=jnp.array([6.0, -3.0]),
        t=jnp.int32(80),
    )
    for actions, size in (("table", 9 + 2 + 10 * 7), ("waypoint", 14 + 10 * 9)):
        cfg = DDQNConfig(**SMALL, actions=actions)
        f1, f2 = agent_input(s, params, cfg), agent_input(_permuted(s), params, cfg)
        np.testing.assert_allclose(f1, f2)
        assert f1.shape == (size,) and np.all(np.isfinite(f1))


def test_n_step_transition_by_hand():
    """Window of 3 steps for two envs; env 1 ends its episode at the second step."""
    g = 0.9
    obs = jnp.arange(3 * 2, dtype=jnp.float32).reshape(3, 2, 1)
    w = Transition(
        obs=obs,
        action=jnp.array([[1, 2], [3, 4], [5, 6]]),
        reward=jnp.array([[1.0, 10.0], [2.0, 20.0], [4.0, 40.0]]),
        next_obs=obs + 100.0,
        done=jnp.array([[0.0, 0.0], [0.0, 1.0], [0.0, 0.0]]),
        discount=jnp.full((3, 2), g),
    )
    t = n_step_transition(w, g)
    # env 0: 1 + 0.9 * 2 + 0.81 * 4, bootstrap from the third next_obs with 0.9^3
    np.testing.assert_allclose(t.reward, [1 + g * 2 + g * g * 4, 10 + g * 20], rtol=1e-6)
    np.testing.assert_allclose(t.discount, [g**3, g**2], rtol=1e-6)
    np.testing.assert_array_equal(t.done, [0.0, 1.0])
    np.testing.assert_array_equal(t.next_obs[:, 0], [104.0, 103.0])  # env 1 stops at its terminal step
    np.testing.assert_array_equal(t.action, [1, 2])


def _close(a, b):
    if np.issubdtype(np.asarray(a).dtype, np.floating):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-6)
    else:
        np.testing.assert_array_equal(a, b)


def test_training_steps_the_gymnax_step_through_the_agent(curves):
    """Training steps ``engine.slot`` with gymnax's auto-reset (``trainer.env_slot``): for the same
    key its state, reward, end and reset equal ``SemUAVEnv.step`` of the shielded action; its
    observation is the agent's input, and at an episode's end it reports the input and metrics of
    the state before the reset."""
    from semuav_jax.agents.policy import Explore, agent_input, agent_shield, input_size
    from semuav_jax.agents.trainer import env_slot
    from semuav_jax.env import SemUAVEnv
    from semuav_jax.metrics import episode_metrics

    params = scenario_params("random", curves, K=6)
    cfg = DDQNConfig(**SMALL)
    tr = make_train(cfg, params)
    env = SemUAVEnv(params, "waypoint")
    net = tr.network.init(jax.random.key(1), jnp.zeros((input_size(params, cfg),)))
    _, s = env.reset(jax.random.key(0), params)
    step = jax.jit(lambda k, s, o, ps: env_slot(tr, k, s, o, ps, params))
    for t in range(6):
        k = jax.random.key(10 + t)
        explore = Explore(net, jnp.float32(1.0), jnp.float32(0.0), jnp.int32(4 - t % 2))  # explore: device 0
        s_next, obs, out, final_obs, done, met, _ = step(k, s, agent_input(s, params, cfg), explore)
        sent = agent_shield(cfg)(4 - t % 2, s, params)
        _, g_next, g_rew, g_term, _, info = env.step(k, s, sent, params)
        jax.tree.map(_close, s_next, g_next)  # jitted vs eager float32: equal up to rounding
        np.testing.assert_array_equal([done, out.action], [g_term, sent])
        np.testing.assert_allclose(out.reward, g_rew, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(obs, agent_input(s_next, params, cfg), rtol=1e-6, atol=1e-6)
        _, s_st, _, _, _ = env.step_env(jax.random.split(k)[0], s, sent, params)
        np.testing.assert_allclose(final_obs, agent_input(s_st, params, cfg), rtol=1e-6, atol=1e-6)
        for name, v in episode_metrics(s_st, params).items():
            _close(met[name], v)
        if bool(done):
            assert int(s_next.t) == 0 and int(s_st.t) == t + 1
            break
        s = s_next
    else:
        pytest.fail("no episode end within K steps")


def test_dueling_head_by_hand():
    """Dueling head: Q(s, a) = V(s) + A(s, a) - mean_a A(s, a), computed here from its own layers."""
    from semuav_jax.agents.network import QNetwork

    net = QNetwork(5, (8,), dueling=True)
    x = jax.random.normal(jax.random.key(0), (4, 3))
    w = net.init(jax.random.key(1), x)["params"]
    h = jax.nn.relu(x @ w["Dense_0"]["kernel"] + w["Dense_0"]["bias"])
    v = h @ w["value"]["kernel"] + w["value"]["bias"]
    a = h @ w["advantage"]["kernel"] + w["advantage"]["bias"]
    q = net.apply({"params": w}, x)
    np.testing.assert_allclose(q, v + a - a.mean(-1, keepdims=True), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(q.mean(-1), v[:, 0], rtol=1e-5, atol=1e-6)
    assert set(QNetwork(5, (8,)).init(jax.random.key(1), x)["params"]) == {"Dense_0", "Dense_1"}


@pytest.mark.slow
def test_lr_end_decays_the_learning_rate(curves):
    """lr_end < 1: cosine decay from lr (the first update equals the constant-lr one) to
    lr_end * lr; out-of-range shares are refused."""
    import dataclasses

    for bad in (0.0, 1.5, float("nan")):
        with pytest.raises(ValueError, match="lr_end"):
            DDQNConfig(**SMALL, lr_end=bad)
    params = scenario_params("fixed", curves)
    cfg = DDQNConfig(**{**SMALL, "steps_per_chunk": 1, "total_steps": 8 * 40})
    const, decay = (make_train(dataclasses.replace(cfg, lr_end=e), params) for e in (1.0, 0.01))
    s_c, s_d = (jax.jit(t.init)(jax.random.PRNGKey(0)) for t in (const, decay))
    assert _same(s_c.params, s_d.params)
    run_c, run_d = (jax.jit(lambda s, t=t: t.run(s, 1)) for t in (const, decay))
    s_c, s_d = run_c(s_c)[0], run_d(s_d)[0]
    assert _same(s_c.params, s_d.params)  # update 1: the schedule's value at count 0 is lr
    for _ in range(3):
        s_c, s_d = run_c(s_c)[0], run_d(s_d)[0]
    assert not _same(s_c.params, s_d.params)
