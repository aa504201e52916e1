"""docs/env_api.md: the gymnax 1.0 interface, ``make``, and the Gymnasium adapter."""

import warnings

import gymnasium
import jax
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnax.environments.environment import Environment

import semuav_jax
from semuav_jax.env import SemUAVEnv, reset_state
from semuav_jax.gym_adapter import SemUAVGymEnv
from semuav_jax.metrics import episode_metrics
from semuav_jax.observation import observation

K = 12  # short episodes: the auto-reset comes within a few steps


def assert_same_state(a, b, rtol=0.0):
    """Integer and boolean fields equal; float fields within ``rtol`` (0: bit-identical)."""
    assert jax.tree.structure(a) == jax.tree.structure(b)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        if np.issubdtype(x.dtype, np.floating):
            np.testing.assert_allclose(x, y, rtol=rtol, atol=rtol)
        else:
            np.testing.assert_array_equal(x, y)


@pytest.fixture(scope="module")
def short(curves):
    return semuav_jax.make("SemUAV-v0", curves=curves, K=K)


def test_gymnax_step_six_tuple_and_auto_reset(short):
    env, p = short
    assert isinstance(env, Environment) and env.name == "SemUAV-v0"
    key = jax.random.key(0)
    obs, s = env.reset(key, p)
    step_env = jax.jit(env.step_env)
    for t in range(K):
        key, k = jax.random.split(key)
        obs, s_next, r, terminated, truncated, info = env.step(k, s, t % 9, p)
        assert not bool(truncated) and bool(info["terminated"]) == bool(terminated)
        # the step half of gymnax's step is step_env on the first half of the key
        k_step, k_reset = jax.random.split(k)
        obs_st, s_st, r_st, term_st, _ = step_env(k_step, s, t % 9, p)
        assert float(r) == float(r_st) and bool(terminated) == bool(term_st) == bool(s_st.done)
        np.testing.assert_array_equal(info["final_observation"], obs_st)
        if bool(terminated):
            break
        assert_same_state(s_next, s_st)
        s = s_next
    else:
        pytest.fail("no episode end within K steps")
    assert int(s_st.t) == K and not bool(s_st.arrived)  # t = K: terminated, not truncated
    fresh = jax.jit(reset_state)(k_reset, p)
    assert_same_state(s_next, fresh)
    assert int(s_next.t) == 0
    # same state; its observation computed inside another program: equal up to float32 rounding
    np.testing.assert_allclose(obs, jax.jit(observation)(fresh, p), rtol=1e-6, atol=1e-7)


def test_jit_vmap_step_matches_python_loop(short):
    env, p = short
    E = 4
    keys = jax.random.split(jax.random.key(1), E)
    obs, states = jax.vmap(env.reset, (0, None))(keys, p)
    actions = jax.random.randint(jax.random.key(2), (K + 2, E), 0, env.num_actions)
    step_keys = jax.random.split(jax.random.key(3), (K + 2, E))
    batch_step = jax.jit(jax.vmap(env.step, (0, 0, 0, None)))
    singles = [env.reset(keys[i], p)[1] for i in range(E)]
    for i in range(E):
        assert_same_state(jax.tree.map(lambda x, i=i: x[i], jax.device_get(states)), jax.device_get(singles[i]))
    # vmap vectorizes the float32 arithmetic differently: equal up to rounding (1e-6), the discrete
    # outcomes (t, x, done, arrived, layouts) exactly
    for t in range(K + 2):  # through every episode's end and auto-reset
        obs, states, rew, term, trunc, _ = batch_step(step_keys[t], states, actions[t], p)
        batch = jax.device_get((obs, states, rew, term, trunc))
        for i in range(E):
            o, singles[i], r, d, tr, _ = env.step(step_keys[t, i], singles[i], actions[t, i], p)
            np.testing.assert_allclose(batch[0][i], o, rtol=1e-6, atol=1e-6)
            assert float(batch[2][i]) == pytest.approx(float(r), rel=1e-6, abs=1e-6)
            assert batch[3][i] == bool(d) and not batch[4][i] and not bool(tr)
            assert_same_state(jax.tree.map(lambda x, i=i: x[i], batch[1]), jax.device_get(singles[i]), rtol=1e-6)


def test_make(curves):
    env, p = semuav_jax.make("SemUAV-v0", curves=curves, B=5e3)
    assert isinstance(env, SemUAVEnv) and float(p.B) == 5e3 and env.default_params is p
    with pytest.raises(ValueError, match="known ids: SemUAV-v0") as err:
        semuav_jax.make("CartPole-v1")
    assert "\n" not in str(err.value)
    assert isinstance(semuav_jax.__version__, str) and semuav_jax.__version__


def test_gymnasium_check_env(curves):
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # gymnasium's checker warns on API deviations
        check_env(SemUAVGymEnv(curves=curves, K=K), skip_render_check=True)
    with pytest.raises(ValueError, match="render_mode"):
        SemUAVGymEnv(render_mode="human")
    e = SemUAVGymEnv(curves=curves, K=K)
    e.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        e.step(9)


def test_gymnasium_episode_matches_functional_env(curves, short):
    env, p = short
    seed = 5
    actions = [int(a) for a in np.random.default_rng(0).integers(0, 9, K)]
    g = SemUAVGymEnv(curves=curves, K=K)
    obs_g, _ = g.reset(seed=seed)
    assert obs_g.dtype == np.float32 and isinstance(obs_g, np.ndarray)
    key = jax.random.key(seed)
    key, k = jax.random.split(key)
    obs_f, s = env.reset(k, p)
    np.testing.assert_array_equal(obs_g, obs_f)
    total_g = total_f = 0.0
    for a in actions:
        obs_g, r_g, term_g, trunc_g, info_g = g.step(a)
        key, k = jax.random.split(key)
        obs_f, s, r_f, term_f, _, info_f = env.step(k, s, a, p)
        assert r_g == float(r_f) and term_g == bool(term_f) and trunc_g is False
        total_g, total_f = total_g + r_g, total_f + float(r_f)
        if term_g:
            break
        np.testing.assert_array_equal(obs_g, obs_f)
    assert term_g and total_g == total_f  # no auto-reset: obs_g is the final observation
    np.testing.assert_array_equal(obs_g, info_f["final_observation"])
    final = episode_metrics(g.env_state, g.env_params)
    assert info_g["mean_psnr"] == float(final["mean_psnr"]) and info_g["arrived"] == bool(final["arrived"])
    assert info_g["return"] == pytest.approx(total_g, rel=1e-5)


def test_gymnasium_make(curves):
    e = gymnasium.make("SemUAV-v0", curves=curves, K=K, B=5e3)
    assert float(e.unwrapped.env_params.B) == 5e3 and e.spec.max_episode_steps is None
    obs, _ = e.reset(seed=0)
    assert e.observation_space.contains(obs) and e.action_space.n == 9
    obs, r, terminated, truncated, info = e.step(e.action_space.sample())
    assert e.observation_space.contains(obs) and not truncated and set(info) >= {"arrived", "delay", "discount"}
    e.close()


def test_step_validates_replaced_params_and_flags_traced_ones(short):
    """``params.replace(...)`` into ``step``: a concrete bad value is a one-line ValueError naming it;
    traced inside the caller's jit it cannot raise, and ``info["valid"]`` is False."""
    env, p = short
    _, s = env.reset(jax.random.key(0), p)
    for name, bad in (("B", -1.0), ("B", 0.0), ("tau", 0.0), ("v_max", float("nan")), ("P_n", 1e300)):
        with pytest.raises(ValueError, match=name):
            env.step(jax.random.key(1), s, 0, p.replace(**{name: bad}))
        with pytest.raises(ValueError, match=name):
            env.reset(jax.random.key(1), p.replace(**{name: bad}))
    valid = jax.jit(lambda B: env.step(jax.random.key(1), s, 0, p.replace(B=B))[-1]["valid"])
    assert bool(valid(p.B)) and not bool(valid(jax.numpy.float32(-1.0))) and not bool(valid(jax.numpy.float32("nan")))


def test_waypoint_action_mode(curves):
    """actions="waypoint": eq. 6.2 through the same gymnax step; the slot is transition() under waypoint_accel."""
    from semuav_jax.actions import HOME, NUM_WAYPOINT_ACTIONS, waypoint_accel
    from semuav_jax.env import transition

    env, p = semuav_jax.make("SemUAV-v0", actions="waypoint", curves=curves, K=K)
    assert env.num_actions == NUM_WAYPOINT_ACTIONS == env.action_space(p).n
    with pytest.raises(ValueError, match="actions must be one of"):
        SemUAVEnv(p, actions="speed")
    _, s = env.reset(jax.random.key(3), p)
    for a in (0, 4, HOME):  # nearest device at 0 (hover approach) and 25 m/s, and home
        obs, s_env, r, *_ = env.step_env(jax.random.key(a), s, a, p)
        s_ref, r_ref = transition(jax.random.key(a), s, waypoint_accel(a, s, p), p)
        assert_same_state(s_env, s_ref)
        assert float(r) == float(r_ref)
        np.testing.assert_array_equal(obs, observation(s_ref, p))
    # a waypoint command differs from table action 0 (full braking on both axes)
    table, _ = semuav_jax.make("SemUAV-v0", curves=curves, K=K)
    s_table = table.step_env(jax.random.key(0), s, 0, p)[1]
    assert not np.array_equal(
        np.asarray(s_table.a_prev), np.asarray(env.step_env(jax.random.key(0), s, 0, p)[1].a_prev)
    )
