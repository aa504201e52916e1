"""The vmapped rollout: equal to a Python loop, deterministic, one program for a bandwidth sweep."""

import functools

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from semuav_jax import env
from semuav_jax.control import rest_command
from semuav_jax.engine import Policy
from semuav_jax.metrics import episode_metrics
from semuav_jax.params import _NON_NEGATIVE, _POSITIVE, make_params
from semuav_jax.rollout import delay_draws, episode, random_policy, random_policy_state, rollout


def toward_goal(ps, state, params):
    """A state-dependent policy: head for q_fin, with a y wobble from the policy state."""
    d = params.q_fin - state.q
    return d / (jnp.linalg.norm(d) + 1e-6) * params.a_max + ps, ps


def test_rollout_equals_python_loop(params):
    E = 4
    keys = jax.random.split(jax.random.key(3), E)
    wobble = jnp.stack([jnp.zeros(E), jnp.linspace(-3, 3, E)], -1)
    metrics, trace = rollout(toward_goal, keys, params, policy_state=wobble, trace=True)
    step = jax.jit(env.transition_u)
    for e in range(E):
        k_reset, k_steps = jax.random.split(keys[e])
        s = env.reset_state(k_reset, params)
        us = delay_draws(k_steps, params)
        ret = 0.0
        for t in range(params.K):
            a, _ = toward_goal(wobble[e], s, params)
            s, r = step(us[t], s, a, params)
            ret += float(r)
            np.testing.assert_allclose(trace["q"][e, t], s.q, rtol=1e-5, atol=1e-3)
            np.testing.assert_allclose(trace["m"][e, t], s.m, rtol=1e-5, atol=1e-4)
            assert float(trace["reward"][e, t]) == pytest.approx(float(r), rel=1e-4, abs=1e-4)
        final = episode_metrics(s, params)
        for name, value in final.items():
            assert float(metrics[name][e]) == pytest.approx(float(value), rel=1e-4, abs=1e-4), name
        assert float(metrics["return"][e]) == pytest.approx(ret, rel=1e-4, abs=1e-3)


@pytest.mark.parametrize("t", [37, 60])  # K - t odd (213 slots left) and even (190)
def test_the_slots_left_are_the_whole_episode_and_fewer_slots_stop_early(params, t):
    """From the state at slot t, ``episode(slots=K - t)`` gives the K-slot episode's metrics bit for
    bit (the slots after the end are frozen); ``slots=n`` is the first n slots (a Python loop)."""
    k_reset, k_run = jax.random.split(jax.random.key(5))
    wobble = jnp.array([0.0, 1.5])
    step = jax.jit(env.transition_u)
    s, us = env.reset_state(k_reset, params), delay_draws(k_reset, params)
    for i in range(t):
        s, _ = step(us[i], s, toward_goal(wobble, s, params)[0], params)
    assert int(s.t) == t and not bool(s.done)
    run = jax.jit(lambda n: episode(toward_goal, k_run, params, wobble, init_state=s, slots=n)[0])
    whole = episode(toward_goal, k_run, params, wobble, init_state=s)[0]
    left = run(params.K - t)
    for name in whole:
        np.testing.assert_array_equal(left[name], whole[name], err_msg=name)
    few = run(5)
    u = delay_draws(jax.random.split(k_run)[1], params)
    for i in range(5):
        s, _ = step(u[i], s, toward_goal(wobble, s, params)[0], params)
    assert int(s.t) == t + 5
    for name, value in episode_metrics(s, params).items():
        assert float(few[name]) == pytest.approx(float(value), rel=1e-5, abs=1e-5), name
    assert float(few["mission_time"]) < float(whole["mission_time"])
    with pytest.raises(ValueError, match="no trace"):
        episode(toward_goal, k_run, params, wobble, init_state=s, slots=3, trace=True)


def toward_device(i):
    """Come to rest over device ``i`` (by its number), whatever it holds."""

    def act(ps, state, params):
        n = state.m.shape[0]
        return rest_command(state.q, state.v, state.dev_pos, jnp.zeros(n), jnp.arange(n) == i, 20.0, 25.0, params), ps

    return act


def test_a_policy_that_numbers_the_devices_sees_them_numbered_and_traces_the_drawn_numbers(params):
    """Numbered in reverse, device 0 is the drawn device N - 1: flying to it is flying to N - 1 in the
    drawn numbering, slot for slot, and the trace's device fields come back in the drawn numbering."""
    keys = jax.random.split(jax.random.key(4), 6)
    reverse = lambda state, params: jnp.arange(state.m.shape[0])[::-1]
    m1, t1 = rollout(Policy(act=toward_device(0), number=reverse), keys, params, trace=True)
    m2, t2 = rollout(Policy(act=toward_device(params.N - 1)), keys, params, trace=True)
    for f in ("q", "m", "phi", "x"):
        np.testing.assert_allclose(t1[f], t2[f], rtol=1e-6, atol=1e-5, err_msg=f)
    assert float(np.max(t1["m"][:, -1, -1])) > 0.0  # the drawn last device was served
    np.testing.assert_allclose(m1["mean_psnr"], m2["mean_psnr"], rtol=1e-6)


def test_fixed_key_reproduces_bit_for_bit(params):
    keys = jax.random.split(jax.random.key(11), 64)
    draws = jax.vmap(random_policy_state, (0, None))(jax.random.split(jax.random.key(12), 64), params)
    m1, t1 = rollout(random_policy, keys, params, policy_state=draws, trace=True)
    m2, t2 = rollout(random_policy, keys, params, policy_state=draws, trace=True)
    for a, b in zip(jax.tree.leaves((m1, t1)), jax.tree.leaves((m2, t2))):
        np.testing.assert_array_equal(a, b)
    m3, _ = rollout(random_policy, jax.random.split(jax.random.key(13), 64), params, policy_state=draws)
    assert not np.array_equal(m1["return"], m3["return"])


def test_bandwidth_sweep_is_one_program(params):
    keys = jax.random.split(jax.random.key(0), 32)

    @jax.jit
    @chex.assert_max_traces(n=1)
    def mean_psnr_at(B):
        run = lambda k: episode(toward_goal, k, params.replace(B=B), policy_state=jnp.zeros(2))[0]
        return jnp.mean(jax.vmap(run)(keys)["symbol_fraction"])

    fractions = [float(mean_psnr_at(jnp.float32(b))) for b in (5e3, 20e3, 40e3)]
    assert fractions[0] < fractions[1] < fractions[2]  # more band, more symbols on the same path
    swept = jax.jit(jax.vmap(mean_psnr_at))(jnp.array([5e3, 20e3, 40e3], jnp.float32))
    np.testing.assert_allclose(swept, fractions, rtol=1e-5)


def test_metrics_by_hand(curves):
    p = make_params(curves, N=3)
    s = env.initial_state(jnp.zeros((3, 2)), jnp.array([0, 1, 2]), p).replace(
        m=jnp.array([0.0, 128.0, 256.0]),
        phi=jnp.array([curves[0, 0], curves[1, 128], curves[2, 256]]),
        t=jnp.int32(180),
        arrived=jnp.bool_(True),
        ret=jnp.float32(42.0),
    )
    m = episode_metrics(s, p)
    assert float(m["mean_psnr"]) == pytest.approx((curves[0, 0] + curves[1, 128] + curves[2, 256]) / 3, rel=1e-6)
    assert int(m["coverage"]) == 2
    assert float(m["psnr_visited"]) == pytest.approx((curves[1, 128] + curves[2, 256]) / 2, rel=1e-6)
    assert float(m["symbol_fraction"]) == pytest.approx(384 / 768)
    assert float(m["mission_time"]) == 90.0 and bool(m["arrived"]) and float(m["return"]) == 42.0


def test_rollout_validates_params(params):
    keys = jax.random.split(jax.random.key(0), 2)
    with pytest.raises(ValueError, match="overflowed"):  # P_n is finite in float32, the rate of eq. 2.6 is not
        rollout(toward_goal, keys, params.replace(P_n=1e38), policy_state=jnp.zeros((2, 2)))
    with pytest.raises(ValueError, match="B must be > 0"):
        rollout(toward_goal, keys, params.replace(B=-1.0), policy_state=jnp.zeros((2, 2)))
    with pytest.raises(ValueError, match="keys"):
        rollout(toward_goal, jnp.zeros(3), params, policy_state=jnp.zeros((3, 2)))


@pytest.mark.parametrize("bad", [{"B": -1.0}, {"device_img": jnp.full(10, 99, jnp.int32)}])
def test_traced_bad_value_is_flagged_never_a_number(curves, bad):
    """Inside jit a bad value cannot raise: the metrics say valid = False and carry NaN, not a believable number
    (every scalar: the hypothesis test below)."""
    params = make_params(curves, K=20)
    keys = jax.random.split(jax.random.key(0), 3)
    name, value = next(iter(bad.items()))

    @jax.jit
    def run(x):
        return jax.vmap(lambda k: episode(toward_goal, k, params.replace(**{name: x}), policy_state=jnp.zeros(2))[0])(
            keys
        )

    good = run(getattr(params, name))
    assert bool(np.all(good["valid"])) and np.all(np.isfinite(good["mean_psnr"]))
    m = run(jnp.asarray(value, getattr(params, name).dtype if hasattr(getattr(params, name), "dtype") else jnp.float32))
    assert not np.any(m["valid"]) and not np.any(m["arrived"])
    for k in ("mean_psnr", "coverage", "return", "mission_time"):
        assert np.all(np.isnan(m[k])), k


_SCALARS = sorted(set(_POSITIVE) | set(_NON_NEGATIVE))


@settings(max_examples=20, deadline=None)
@given(name=st.sampled_from(_SCALARS), kind=st.sampled_from(["zero", "negative", "nan", "inf", "-inf"]))
def test_invalid_values_never_give_a_believable_number(curves, name, kind):
    """Any out-of-range scalar is a one-line ValueError on the host and, traced inside jit, a
    metrics dict with valid = False and NaN PSNR: never a finite-looking result."""
    value = {"zero": 0.0, "negative": -1.0, "nan": float("nan"), "inf": float("inf"), "-inf": float("-inf")}[kind]
    allowed = (kind == "zero" and name in _NON_NEGATIVE) or (kind == "inf" and name == "airspace_margin")
    if allowed:
        return
    with pytest.raises(ValueError, match=name):
        make_params(curves, K=20, **{name: value})
    params = make_params(curves, K=20)
    m = _short_episode(params, name, value)
    assert not bool(m["valid"]) and np.isnan(float(m["mean_psnr"])) and not bool(m["arrived"])


@functools.cache
def _short_episode_fn(name):
    return jax.jit(
        lambda params, x: episode(
            toward_goal, jax.random.key(0), params.replace(**{name: x}), policy_state=jnp.zeros(2)
        )[0]
    )


def _short_episode(params, name, value):
    return _short_episode_fn(name)(params, jnp.float32(value))
