"""Rules of the fixed-speed baselines (MODEL.md section 7) on hand-built states, values by hand."""

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from baselines.controller import feasible, speed_command
from baselines.evaluate import resolve, tsp_ranks
from baselines.policies import greedy, init_state, straight, tsp
from baselines.tsp import solve_order
from semuav_jax.env import initial_state
from semuav_jax.params import make_params

V_B = 8.9


def state_at(params, dev_pos, q=(0.0, 300.0), v=(0.0, 0.0), t=0):
    dev_pos = jnp.asarray(dev_pos, jnp.float32)
    s = initial_state(dev_pos, jnp.zeros(len(dev_pos), jnp.int32), params)
    return s.replace(q=jnp.asarray(q, jnp.float32), v=jnp.asarray(v, jnp.float32), t=jnp.int32(t))


def test_speed_command_by_hand(params):
    q = jnp.array([0.0, 0.0])
    # from rest towards +x: (8.9 - 0) / 0.5 = 17.8 -> clipped to a_max = 5
    np.testing.assert_allclose(speed_command(q, jnp.zeros(2), jnp.array([100.0, 0.0]), V_B, params), [5.0, 0.0])
    # cruising at v_b towards the target: no command
    np.testing.assert_allclose(speed_command(q, jnp.array([V_B, 0.0]), jnp.array([100.0, 0.0]), V_B, params), [0.0, 0.0])
    # 0.5 m/s short: (8.9 - 8.4) / 0.5 = 1.0
    np.testing.assert_allclose(speed_command(q, jnp.array([8.4, 0.0]), jnp.array([100.0, 0.0]), V_B, params), [1.0, 0.0], rtol=1e-5)
    # a right-angle turn: (-17.8, 17.8) -> (-5, 5)
    np.testing.assert_allclose(speed_command(q, jnp.array([V_B, 0.0]), jnp.array([0.0, 100.0]), V_B, params), [-5.0, 5.0])
    # at the target itself: brake, no NaN
    np.testing.assert_allclose(speed_command(q, jnp.array([1.0, -2.0]), q, V_B, params), [-2.0, 4.0])


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.floats(-2000, 2000), min_size=6, max_size=6),
    st.floats(0.1, 40.0),
)
def test_speed_command_never_exceeds_a_max(params, xs, v_b):
    a = speed_command(jnp.array(xs[:2]), jnp.array(xs[2:4]) / 50.0, jnp.array(xs[4:]), v_b, params)
    assert np.all(np.abs(np.asarray(a)) <= params.a_max)


def test_feasibility_by_hand(params):
    dev = jnp.array([[500.0, 300.0], [500.0, 600.0], [1000.0, 300.0]])
    q = jnp.array([0.0, 300.0])
    # detours: 1000 m -> 112.4 s <= 125 s; 2 * 583.1 m -> 131.0 s > 125 s; 1000 m -> feasible
    np.testing.assert_array_equal(feasible(q, 0, dev, V_B, params), [True, False, True])
    # at t = 25 only 112.5 s are left: 1000 m still fits (112.36 s); at t = 26 (112.0 s) it does not
    np.testing.assert_array_equal(feasible(q, 25, dev, V_B, params), [True, False, True])
    np.testing.assert_array_equal(feasible(q, 26, dev, V_B, params), [False, False, False])
    # a faster UAV makes the far device feasible: 1166.2 m / 10 m/s = 116.6 s
    np.testing.assert_array_equal(feasible(q, 0, dev, 10.0, params), [True, True, True])


# A: nearest (250 m) but infeasible (250 + 1030.8 m = 143.9 s); B: 291.5 m, feasible (118.7 s); C: far, feasible.
A, B, C = [0.0, 50.0], [250.0, 450.0], [700.0, 300.0]


def test_greedy_first_target_is_nearest_feasible_device(params):
    u_b = np.array([250.0, 150.0]) / np.hypot(250.0, 150.0)
    s = state_at(params, [A, B, C], v=V_B * u_b)  # cruising exactly towards B
    a, ps = greedy(init_state(V_B, jnp.arange(3)), s, params)
    np.testing.assert_allclose(a, [0.0, 0.0], atol=1e-5)
    np.testing.assert_allclose(a, speed_command(s.q, s.v, jnp.array(B), V_B, params))
    assert not np.any(ps.passed)
    # at 12 m/s A's detour takes 106.7 s, so A (the nearest) becomes feasible and the target
    a_fast, _ = greedy(init_state(12.0, jnp.arange(3)), s, params)
    np.testing.assert_allclose(a_fast, speed_command(s.q, s.v, jnp.array(A), 12.0, params))


def test_tsp_follows_rank_and_skips_infeasible(params):
    s = state_at(params, [A, B, C], v=(3.0, 1.0))
    # order A, C, B: A is infeasible and skipped, so the target is C (not the nearer B)
    a, _ = tsp(init_state(V_B, jnp.array([0, 2, 1])), s, params)
    np.testing.assert_allclose(a, speed_command(s.q, s.v, jnp.array(C), V_B, params))
    # order B, C, A: B first
    a, _ = tsp(init_state(V_B, jnp.array([2, 0, 1])), s, params)
    np.testing.assert_allclose(a, speed_command(s.q, s.v, jnp.array(B), V_B, params))


@pytest.mark.parametrize("policy", [greedy, tsp])
def test_reached_target_is_passed_and_the_next_one_taken(policy, params):
    # the UAV is 4 m (<= v_b tau = 4.45 m) from device 0 and 4.4 m from device 1: both pass in one slot
    dev = [[300.0, 304.0], [304.4, 300.0], [600.0, 300.0]]
    s = state_at(params, dev, q=(300.0, 300.0), v=(V_B, 0.0), t=10)
    a, ps = policy(init_state(V_B, jnp.array([0, 1, 2])), s, params)
    np.testing.assert_array_equal(ps.passed, [True, True, False])
    np.testing.assert_allclose(a, [0.0, 0.0], atol=1e-5)  # cruising towards device 2 along +x
    # a passed device is never targeted again, even when it is the nearest
    s2 = s.replace(q=jnp.array([310.0, 300.0]))
    a2, ps2 = policy(ps, s2, params)
    np.testing.assert_array_equal(ps2.passed, [True, True, False])
    np.testing.assert_allclose(a2, speed_command(s2.q, s2.v, jnp.array(dev[2]), V_B, params))


@pytest.mark.parametrize("policy", [greedy, tsp, straight])
def test_no_feasible_device_means_fly_to_destination(policy, params):
    s = state_at(params, [[500.0, 500.0], [200.0, 100.0]], q=(600.0, 300.0), v=(0.0, 4.0), t=200)
    a, ps = policy(init_state(V_B, jnp.array([0, 1])), s, params)
    np.testing.assert_allclose(a, speed_command(s.q, s.v, params.q_fin, V_B, params))
    np.testing.assert_allclose(a, [5.0, -5.0])  # (17.8, -8) clipped
    assert not np.any(ps.passed)


def test_tsp_ranks_invert_the_solver_order(curves):
    dev = np.array([[700.0, 300.0], [200.0, 320.0], [450.0, 280.0], [900.0, 310.0]])
    params = make_params(curves, device_pos=dev, layout="fixed")
    keys = jnp.stack([jnp.array([0, i], jnp.uint32) for i in range(3)])
    rank = tsp_ranks(keys, params)
    np.testing.assert_array_equal(solve_order(dev, params.q0, params.q_fin), [1, 2, 0, 3])
    np.testing.assert_array_equal(rank, np.broadcast_to([2, 0, 1, 3], (3, 4)))


def test_resolve_names_and_functions():
    assert resolve("greedy") is greedy and resolve(tsp) is tsp
    with pytest.raises(ValueError, match="unknown baseline 'ddqn'"):
        resolve("ddqn")
