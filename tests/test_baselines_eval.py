"""Baselines inside the compiled, vmapped env (MODEL.md sections 7-8): arrival, command bound, sweeps."""

from functools import partial

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from baselines.evaluate import evaluate, sweep, tsp_ranks
from baselines.policies import POLICIES, greedy, init_state, straight, tsp
from baselines.tsp import solve_orders
from semuav_jax.env import initial_state, reset_state, transition_u
from semuav_jax.rollout import delay_draws

V_B = 8.9


@partial(jax.jit, static_argnames="policy")
def _flights(policy, keys, params, s0, rank):
    """Episodes as in ``rollout.episode``, also returning the largest raw command of each episode."""

    def one(key, s, r):
        k_steps = jax.random.split(key)[1]

        def body(carry, u):
            s, ps, amax = carry
            a, ps = policy(ps, s, params)
            s, _ = transition_u(u, s, a, params)
            return (s, ps, jnp.maximum(amax, jnp.max(jnp.abs(a)))), None

        carry = (s, init_state(V_B, r), 0.0)
        (s, _, amax), _ = jax.lax.scan(body, carry, delay_draws(k_steps, params))
        return s.arrived, jnp.sum(s.m > 0), amax

    return jax.vmap(one)(keys, s0, rank)


def _hand_layouts():
    on_line = np.stack([np.linspace(90.0, 910.0, 10), np.full(10, 300.0)], -1)
    # (500, 0) needs a 1166 m detour = 131 s > 125 s at 8.9 m/s: never feasible, 300 m off the route
    one_off = on_line.copy()
    one_off[4] = [500.0, 0.0]
    return np.stack([on_line, one_off])


@pytest.fixture(scope="module")
def flights(params):
    keys = jax.random.split(jax.random.PRNGKey(2024), 1002)
    s0 = jax.vmap(lambda k: reset_state(jax.random.split(k)[0], params))(keys[:1000])
    hand = jnp.asarray(_hand_layouts(), jnp.float32)
    s_hand = jax.vmap(lambda p: initial_state(p, jnp.zeros(10, jnp.int32), params))(hand)
    s0 = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), s0, s_hand)
    rank = np.concatenate(
        [
            tsp_ranks(keys[:1000], params),
            np.argsort(solve_orders(_hand_layouts(), params.q0, params.q_fin), axis=1),
        ]
    )
    out = {}
    for name, policy in POLICIES.items():
        out[name] = jax.tree.map(np.asarray, _flights(policy, keys, params, s0, jnp.asarray(rank, jnp.int32)))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(POLICIES))
def test_every_baseline_arrives_on_99_5_percent_of_1000_layouts(flights, name):
    arrived, _, _ = flights[name]
    assert arrived[:1000].mean() >= 0.995, arrived[:1000].mean()


@pytest.mark.slow
@pytest.mark.parametrize("margin", [None, 0.0])
def test_baselines_arrive_at_every_speed_and_stay_in_the_airspace(params, margin):
    """MODEL.md section 7: the feasibility test counts turning, braking and delays, so every baseline
    arrives at every v_b from 8.9 to 25 m/s; with an airspace margin of 0 none leaves the area."""
    p = params.replace(airspace_margin=np.inf if margin is None else margin)
    keys = jax.random.split(jax.random.PRNGKey(99), 300)
    rank = tsp_ranks(keys, p)
    for name in sorted(POLICIES):
        m = sweep(name, keys, p, v_b=[8.9, 11.0, 14.0, 17.0, 20.0, 22.5, 25.0], rank=rank)
        assert m["arrived"].mean(-1).min() >= 0.995, (name, m["arrived"].mean(-1))
        left = ~m["arrived"] & (m["mission_time"] < p.K * p.tau)  # ended early without arriving
        assert not left.any(), name


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(POLICIES))
def test_no_command_exceeds_a_max(flights, name, params):
    _, _, amax = flights[name]
    assert np.all(amax <= params.a_max)
    assert np.all(amax == params.a_max)  # every flight starts from rest with a saturated command


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(POLICIES))
def test_hand_layouts_coverage(flights, name):
    arrived, coverage, _ = flights[name]
    # ten devices on the route: all covered; the infeasible device 300 m off the route: never
    np.testing.assert_array_equal(coverage[1000:], [10, 9])
    assert np.all(arrived[1000:])


@pytest.mark.slow
def test_greedy_and_tsp_cover_more_than_straight(flights):
    cov = {k: v[1][:1000].mean() for k, v in flights.items()}
    assert cov["greedy"] > cov["straight"] + 1 and cov["tsp"] > cov["straight"] + 1, cov


def counted(policy):
    """The policy wrapped so that chex fails on a second trace."""
    return chex.assert_max_traces(lambda ps, s, p: policy(ps, s, p), n=1)


@pytest.mark.parametrize("policy", [greedy, tsp, straight], ids=["greedy", "tsp", "straight"])
def test_bandwidth_x_velocity_sweep_is_one_program(policy, params):
    keys = jax.random.split(jax.random.PRNGKey(7), 24)
    rank = tsp_ranks(keys, params)
    chex.clear_trace_counter()
    fn = counted(policy)
    B = [5e3, 10e3, 20e3, 40e3]
    m = sweep(fn, keys, params, v_b=[4.0, 8.9, 16.0, 24.0], B=B, rank=rank)
    m2 = sweep(fn, keys, params, v_b=[6.0, 8.9, 12.0, 20.0], B=B, rank=rank)  # new values, no retrace
    assert m["mean_psnr"].shape == (4, 4, 24)
    np.testing.assert_array_equal(m["mean_psnr"][:, 1], m2["mean_psnr"][:, 1])
    psnr = m["mean_psnr"].mean(-1)
    assert np.all(np.diff(psnr[:, 1]) > 0), psnr[:, 1]  # rises with bandwidth at 8.9 m/s
    assert np.all(np.diff(psnr, axis=0) >= 0)  # never falls, at any speed
    # 1000 m at 4 m/s takes 250 s > T = 125 s: no arrival, the mission lasts all K slots
    assert not m["arrived"][:, 0].any() and np.all(m["mission_time"][:, 0] == 125.0)
    # the same flights at every bandwidth (B does not change the trajectory)
    np.testing.assert_array_equal(m["mission_time"][0], m["mission_time"][-1])
    if policy is straight:
        # v_b / (2 a_max) lost accelerating from rest, cruise to d0 = v_b^2 / 2.5 m before q_fin, then
        # brake along sqrt(2.5 d) (eq. 7.3) down to the 15 m circle: 2 (sqrt(d0) - sqrt(15)) / sqrt(2.5) s
        for j, v_b in ((1, 8.9), (3, 24.0)):
            d0 = v_b**2 / 2.5
            expected = (1000.0 - d0) / v_b + v_b / (2 * params.a_max) + 2 * (np.sqrt(d0) - np.sqrt(15.0)) / np.sqrt(2.5)
            np.testing.assert_allclose(m["mission_time"][0, j], expected, atol=params.tau)


@pytest.mark.slow
def test_evaluate_runs_the_same_episodes(flights, params):
    """``evaluate`` (the library path) reproduces the flights above: same layouts, delays and seeds."""
    keys = jax.random.split(jax.random.PRNGKey(2024), 1002)[:1000]
    m = evaluate("straight", keys, params, v_b=V_B)
    arrived, coverage, _ = flights["straight"]
    np.testing.assert_array_equal(m["arrived"], arrived[:1000])
    # two differently fused programs may round a device at the very edge of range differently
    assert np.sum(m["coverage"] != coverage[:1000]) <= 2
    assert np.max(np.abs(m["coverage"] - coverage[:1000])) <= 1
    assert m["mean_psnr"].shape == (1000,) and np.all(m["mean_psnr"] >= params.C[:, 0].min())


def test_sweep_grids_are_checked_on_the_host(params, monkeypatch):
    """A bad bandwidth or speed anywhere in a sweep grid, or bad params, is a one-line ValueError
    before anything is traced (a value inside the traced grid could not raise)."""
    import importlib

    be = importlib.import_module("baselines.evaluate")

    def traced(*a, **k):
        raise AssertionError("reached the traced sweep")

    monkeypatch.setattr(be, "_sweep", traced)
    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    for B in ([5e3, -1.0], [5e3, 0.0], [np.nan], [20e3, np.inf]):
        with pytest.raises(ValueError, match="B must be finite and > 0 Hz"):
            sweep("greedy", keys, params, v_b=[8.9], B=B)
    for v in ([8.9, 0.0], [np.nan], [8.9, -np.inf]):
        with pytest.raises(ValueError, match="v_b must be finite and > 0 m/s"):
            sweep("greedy", keys, params, v_b=v, B=[5e3])
    with pytest.raises(ValueError, match="tau must be > 0"):
        sweep("greedy", keys, params.replace(tau=0.0), v_b=[8.9])
    with pytest.raises(ValueError, match="v_b must be finite and > 0 m/s"):
        evaluate("straight", keys, params, v_b=float("nan"))
    with pytest.raises(AssertionError, match="traced sweep"):  # good grids reach it
        sweep("greedy", keys, params, v_b=[8.9], B=[5e3])
