"""MODEL.md section 3-5: one slot by hand, invariants, the NumPy oracle, and the gymnax interface."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from reference_numpy import NumpyEnv, a2g_rate, params_dict, speed_cap

from semuav_jax import channel, env
from semuav_jax.actions import action_table
from semuav_jax.env import SemUAVEnv, bandwidth_shares, initial_state, transition, transition_u
from semuav_jax.observation import obs_size, observation
from semuav_jax.params import make_params

step_u = jax.jit(transition_u)


def test_one_slot_by_hand(curves):
    # UAV above the BS at (500, 300) with v = (10, 0), previous command (2, 0), new command (9, -5).
    # proc = u * proc_max = 0.5 * 0.1 = 0.05 s; L_cmd / R_b: BS 75 m below, P_b = 1 W, B_b = 100 kHz.
    rb = a2g_rate(0.0, 75.0, 1.0, 100e3, params_dict(make_params(curves)))
    assert 4.3e5 < rb < 4.5e5  # ~ 0.15 ms for 64 bits
    delay = 0.05 + 64 / rb
    a_eff = (delay * np.array([2.0, 0.0]) + (0.5 - delay) * np.array([5.0, -5.0])) / 0.5  # clipped to 5
    assert np.allclose(a_eff, [4.7, -4.5], atol=2e-3)  # (0.05*2 + 0.45*5)/0.5, 0.45*(-5)/0.5
    v1 = np.array([10.0, 0.0]) + a_eff * 0.5  # (12.35, -2.25)
    q1 = np.array([500.0, 300.0]) + v1 * 0.5  # (506.175, 298.875)
    p = make_params(curves, device_pos=[q1, [900.0, 100.0]], device_img=[2, 5], layout="fixed")
    s = initial_state(p.device_pos, p.device_img, p).replace(
        q=jnp.array([500.0, 300.0]), v=jnp.array([10.0, 0.0]), a_prev=jnp.array([2.0, 0.0]), t=jnp.int32(7)
    )
    s1, r = step_u(0.5, s, jnp.array([9.0, -5.0]), p)
    assert float(s1.delay) == pytest.approx(delay, rel=1e-5)
    np.testing.assert_allclose(s1.v, v1, rtol=1e-5)
    np.testing.assert_allclose(s1.q, q1, rtol=1e-6)
    np.testing.assert_array_equal(s1.a_prev, [5.0, -5.0])
    # device 0 right below: 324.7 bit/s * 0.5 s / 16 bit = 10.15 symbols; device 1 is out of range
    np.testing.assert_allclose(s1.m, [324.69 * 0.5 / 16, 0.0], rtol=1e-3)
    np.testing.assert_array_equal(s1.x, [True, False])
    np.testing.assert_allclose(s1.phi, [curves[2, 10], curves[5, 0]])
    assert int(s1.t) == 8 and not bool(s1.done)
    # paper reward: r_c = phi_0 (one transmitter), r_d = (D[t-1] - D[t]) / (v_max tau)
    r_d = (math.dist((500, 300), (1000, 300)) - math.dist(q1, (1000, 300))) / 12.5
    assert float(r) == pytest.approx(curves[2, 10] * 1 / (1 + 1e-6) + r_d, rel=1e-5)


def test_ofdma_shares():
    x = jnp.array([True, False, True, True])
    np.testing.assert_allclose(bandwidth_shares(x, 30e3), [10e3, 0, 10e3, 10e3])
    assert float(jnp.sum(bandwidth_shares(jnp.zeros(4, bool), 30e3))) == 0.0


@settings(max_examples=25, deadline=None)
@given(mask=st.lists(st.booleans(), min_size=1, max_size=12), B=st.floats(1e3, 1e6))
def test_ofdma_shares_sum_to_B(mask, B):
    shares = np.asarray(bandwidth_shares(jnp.array(mask), jnp.float32(B)))
    assert shares.sum() == pytest.approx(B if any(mask) else 0.0, rel=1e-5)
    assert np.all(shares[~np.array(mask)] == 0)


def test_two_devices_share_the_band(curves):
    q = np.array([500.0, 300.0])
    p = make_params(curves, device_pos=[q, q], device_img=[0, 1], layout="fixed", proc_max=0.0)
    s = initial_state(p.device_pos, p.device_img, p).replace(q=jnp.asarray(q))
    s1, _ = step_u(0.0, s, jnp.zeros(2), p)
    half = float(channel.rate(0.0, 100.0, 1e-3, 10e3, p)) * 0.5 / 16
    np.testing.assert_allclose(s1.m, [half, half], rtol=1e-5)


def run_episode(p, key, actions_key):
    """A Python loop of jitted single steps with random commands; returns the list of states."""
    s = env.reset_state(key, p)
    states = [s]
    acts = jax.random.uniform(actions_key, (p.K, 2), minval=-8, maxval=8)
    us = jax.random.uniform(jax.random.fold_in(actions_key, 1), (p.K,))
    rewards = []
    for t in range(p.K):
        s, r = step_u(us[t], s, acts[t], p)
        states.append(s)
        rewards.append(float(r))
    return states, np.asarray(acts), np.asarray(us), rewards


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**30), proc_max=st.floats(0.0, 0.6), v_max=st.floats(5, 40))
def test_invariants(curves, seed, proc_max, v_max):
    p = make_params(curves, proc_max=proc_max, v_max=v_max, K=80)
    states, _, _, rewards = run_episode(p, jax.random.key(seed), jax.random.key(seed + 1))
    lo, hi = curves.min(), curves.max()
    for prev, s in zip(states, states[1:]):
        assert np.all(np.abs(np.asarray(s.a_prev)) <= p.a_max + 1e-6)
        assert float(jnp.linalg.norm(s.v)) <= v_max * (1 + 1e-5)
        if not bool(prev.done):  # no wall, no free brake: a velocity component moves by <= a_max tau
            assert np.all(np.abs(np.asarray(s.v) - np.asarray(prev.v)) <= p.a_max * p.tau * (1 + 1e-5) + 1e-5)
        assert 0 <= float(s.delay) <= p.tau
        assert np.all(np.asarray(s.m) >= np.asarray(prev.m)) and np.all(np.asarray(s.m) <= p.M)
        assert np.all((np.asarray(s.phi) >= lo) & (np.asarray(s.phi) <= hi))
        if bool(prev.done):  # no data, no reward, nothing moves after the end
            assert all(np.array_equal(a, b) for a, b in zip(jax.tree.leaves(prev), jax.tree.leaves(s)))
    assert bool(states[-1].done)


def test_arrival_ends_episode(curves):
    p = make_params(curves, K=400, proc_max=0.0)
    s = env.reset_state(jax.random.key(0), p)
    reward_at_arrival = None
    for _ in range(p.K):
        s_new, r = step_u(0.0, s, jnp.array([5.0, 0.0]), p)
        if bool(s_new.arrived) and reward_at_arrival is None:
            reward_at_arrival = float(r)
            assert bool(s_new.done) and float(jnp.linalg.norm(s_new.q - p.q_fin)) <= 15
        s = s_new
    assert bool(s.arrived) and int(s.t) < p.K
    assert reward_at_arrival > 400  # r_g = 500 on arrival


def test_miss_penalty_at_K(curves):
    p = make_params(curves, K=3, proc_max=0.0, reward_mode="gain")
    s = env.reset_state(jax.random.key(0), p)
    for _ in range(3):
        s, r = step_u(0.0, s, jnp.zeros(2), p)
    assert bool(s.done) and not bool(s.arrived)
    assert float(r) == pytest.approx(-500.0)  # no motion, no data: only the miss penalty


def test_no_wall_the_uav_flies_on_beyond_the_area(curves):
    # at (995, 300) with v = (20, 0) and no command: 10 m per slot, straight on past x = 1000
    p = make_params(curves, proc_max=0.0, q_fin=[0.0, 0.0], K=10)
    s = env.reset_state(jax.random.key(0), p).replace(q=jnp.array([995.0, 300.0]), v=jnp.array([20.0, 0.0]))
    for k in range(1, 4):
        s, _ = step_u(0.0, s, jnp.zeros(2), p)
        np.testing.assert_allclose(s.q, [995.0 + 10.0 * k, 300.0], rtol=1e-6)
        np.testing.assert_allclose(s.v, [20.0, 0.0])
        assert not bool(s.done)


def test_leaving_the_airspace_ends_the_episode_as_a_miss(curves):
    # airspace_margin = 12 m: x = 1005 is inside the bound, x = 1015 (> 1012) ends the episode
    p = make_params(curves, proc_max=0.0, q_fin=[0.0, 0.0], K=10, airspace_margin=12.0, reward_mode="gain", kappa_d=0.0)
    s = env.reset_state(jax.random.key(0), p).replace(q=jnp.array([995.0, 300.0]), v=jnp.array([20.0, 0.0]))
    s, r = step_u(0.0, s, jnp.zeros(2), p)
    assert not bool(s.done) and float(r) == 0.0
    s, r = step_u(0.0, s, jnp.zeros(2), p)
    assert bool(s.done) and not bool(s.arrived) and int(s.t) == 2
    assert float(r) == pytest.approx(-500.0)  # -P_miss, as at t = K
    assert float(make_params(curves, airspace_margin=None).airspace_margin) == np.inf


def test_speed_cap_by_hand(curves):
    p = make_params(curves, proc_max=0.0, L_cmd=1e-9)
    s = env.reset_state(jax.random.key(0), p)

    def step(v, a):
        return np.asarray(step_u(0.0, s.replace(v=jnp.array(v), a_prev=jnp.array(a)), jnp.array(a), p)[0].v)

    # under the cap: v + a tau
    np.testing.assert_allclose(step([10.0, 0.0], [5.0, 5.0]), [12.5, 2.5], rtol=1e-6)
    # the radial scaling of MODEL.md when it moves each axis by <= a_max tau = 2.5:
    # (25, 2.5) -> 25 (25, 2.5) / 25.125 = (24.876, 2.4876)
    np.testing.assert_allclose(step([25.0, 0.0], [0.0, 5.0]), np.array([25.0, 2.5]) * 25 / np.hypot(25, 2.5), rtol=1e-5)
    # from (-17.68, 17.68) (|v| = 25) with (5, 5): v + w = (-15.18, 20.18), radially (-15.03, 19.97)
    # would move x by 2.65 > 2.5; the nearest point of the disk on the edge x = -15.18 is
    # (-15.18, sqrt(625 - 15.18^2) = 19.86)
    v0 = 25 / np.sqrt(2)
    np.testing.assert_allclose(step([-v0, v0], [5.0, 5.0]), [-v0 + 2.5, np.sqrt(625 - (v0 - 2.5) ** 2)], rtol=1e-5)
    # the closed form against Dykstra's projections (reference_numpy) on random states at the cap
    rng = np.random.default_rng(0)
    for _ in range(50):
        ang = rng.uniform(0, 2 * np.pi)
        v = 25 * rng.uniform(0.9, 1.0) * np.array([np.cos(ang), np.sin(ang)])
        a = rng.uniform(-5, 5, 2)
        out = step(v, a)
        np.testing.assert_allclose(out, speed_cap(v, a * 0.5, 25.0, 2.5), atol=1e-3)
        assert np.linalg.norm(out) <= 25 * (1 + 1e-6) and np.all(np.abs(out - v) <= 2.5 + 1e-5)


def test_gain_reward_is_psnr_increase(curves):
    q = np.array([500.0, 300.0])
    p = make_params(curves, device_pos=[q], device_img=[3], layout="fixed", reward_mode="gain", kappa_d=0.0)
    s = initial_state(p.device_pos, p.device_img, p).replace(q=jnp.asarray(q))
    s1, r = step_u(0.0, s, jnp.zeros(2), p)
    assert float(r) == pytest.approx(10.0 * float(s1.phi[0] - s.phi[0]), rel=1e-5)  # kappa_c = 10
    assert float(r) > 0


@pytest.mark.parametrize("mode", ["paper", "gain"])
def test_matches_numpy_reference(curves, mode):
    p = make_params(curves, reward_mode=mode, K=200)
    for seed in range(3):
        states, acts, us, rewards = run_episode(p, jax.random.key(seed), jax.random.key(100 + seed))
        ref = NumpyEnv(params_dict(p), curves, np.asarray(states[0].dev_pos), np.asarray(states[0].dev_img))
        for t in range(p.K):
            r_ref = ref.step(acts[t], float(us[t]))
            s = states[t + 1]
            np.testing.assert_allclose(s.q, ref.q, rtol=2e-5, atol=2e-3)  # float32 over K slots
            np.testing.assert_allclose(s.m, ref.m, rtol=1e-3, atol=1e-3)
            assert rewards[t] == pytest.approx(r_ref, rel=1e-3, abs=1e-3)
            assert bool(s.done) == ref.done


def test_layouts(curves):
    p = make_params(curves)
    a, b = env.reset_state(jax.random.key(1), p), env.reset_state(jax.random.key(2), p)
    assert not np.allclose(a.dev_pos, b.dev_pos)
    assert np.all((np.asarray(a.dev_pos) >= 0) & (np.asarray(a.dev_pos) <= [1000, 600]))
    assert np.all((np.asarray(a.dev_img) >= 0) & (np.asarray(a.dev_img) < curves.shape[0]))
    pf = make_params(curves, device_pos=[[10.0, 20.0]], device_img=[4], layout="fixed")
    f = env.reset_state(jax.random.key(1), pf)
    np.testing.assert_array_equal(f.dev_pos, [[10.0, 20.0]])
    assert float(f.phi[0]) == curves[4, 0]  # unvisited: the decoder fed all zeros


def test_transition_key_draws_delay(params):
    s = env.reset_state(jax.random.key(0), params)
    key = jax.random.key(5)
    a, ra = jax.jit(transition)(key, s, jnp.array([1.0, 2.0]), params)
    b, rb = step_u(jax.random.uniform(key), s, jnp.array([1.0, 2.0]), params)
    assert all(np.array_equal(x, y) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))


def test_action_table(params):
    t = np.asarray(action_table(params))
    assert t.shape == (9, 2)
    np.testing.assert_array_equal(t[0], [-5, -5])
    np.testing.assert_array_equal(t[5], [0, 5])
    np.testing.assert_array_equal(t[8], [5, 5])


def test_gymnax_interface(params):
    e = SemUAVEnv(params)
    key = jax.random.key(0)
    obs, state = e.reset(key, params)
    assert obs.shape == (obs_size(params),) == (59,) and obs.dtype == jnp.float32
    assert e.num_actions == 9 and e.action_space(params).n == 9
    assert e.observation_space(params).shape == (59,)
    low, high = e.observation_space(params).low, e.observation_space(params).high
    # v, a, time left, m, x, phi in [-1, 1] / [0, 1]; offsets up to 1 + v_max K tau / min(Lx, Ly) = 1 + 3125 / 600
    np.testing.assert_allclose(high[:9], [1 + 3125 / 600] * 2 + [1] * 5 + [1 + 3125 / 600] * 2, rtol=1e-6)
    np.testing.assert_allclose(low[9:14], [-(1 + 3125 / 600)] * 2 + [0, 0, 0], rtol=1e-6)
    assert bool(e.action_space(params).contains(e.action_space(params).sample(key)))
    step = jax.jit(e.step)
    for _ in range(300):  # longer than K: the auto-reset must kick in
        key, k1, k2 = jax.random.split(key, 3)
        obs, state, r, terminated, truncated, info = step(k1, state, e.action_space(params).sample(k2), params)
        assert bool(e.observation_space(params).contains(obs)) and np.isfinite(float(r))
        assert not bool(truncated)  # t = K is a true terminal (docs/env_api.md)
        if bool(terminated):
            assert int(state.t) == 0 and float(info["discount"]) == 0.0
            break
    else:
        pytest.fail("episode never ended")
    np.testing.assert_allclose(observation(state, params), obs, rtol=1e-5, atol=1e-6)
