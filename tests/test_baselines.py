"""Rules of the fixed-speed baselines (MODEL.md section 7) on hand-built states, values by hand."""

import jax.numpy as jnp
import numpy as np
import pytest
from test_control import time_home_by_hand

from baselines.evaluate import resolve, tsp_ranks
from baselines.policies import MARGIN_S, feasible, greedy, init_state, straight, tsp
from baselines.tsp import solve_order
from semuav_jax.control import home_command, speed_command
from semuav_jax.env import initial_state
from semuav_jax.params import make_params

V_B = 8.9


def state_at(params, dev_pos, q=(0.0, 300.0), v=(0.0, 0.0), t=0):
    dev_pos = jnp.asarray(dev_pos, jnp.float32)
    s = initial_state(dev_pos, jnp.zeros(len(dev_pos), jnp.int32), params)
    return s.replace(q=jnp.asarray(q, jnp.float32), v=jnp.asarray(v, jnp.float32), t=jnp.int32(t))


def need_by_hand(q, v, p, v_b):
    """Eq. 7.6's left side, from docs/model.md: eq. 7.4 to p_n, eq. 7.5 from p_n, plus MARGIN_S."""
    d = np.subtract(p, q)
    u = d / np.linalg.norm(d)
    along = np.dot(v, u)
    side = np.subtract(v, along * u)
    drift = (side @ side + min(along, 0.0) ** 2) / 10.0
    to_p = np.max(np.abs(v_b * u - np.asarray(v))) / 5.0 + (np.linalg.norm(d) + drift) / v_b
    return to_p + time_home_by_hand(p, v_b * u, v_b, v_b) + MARGIN_S


def test_feasibility_by_hand(params):
    dev = [[500.0, 300.0], [500.0, 600.0], [900.0, 300.0]]
    q, v = [0.0, 300.0], [0.0, 0.0]
    # from rest at q0 through (500, 300) at 8.9 m/s: 1.78 + 56.18 s, then 52.62 s cruise + 2.22 s brake, + 1 s
    assert need_by_hand(q, v, dev[0], V_B) == pytest.approx(1.78 + 500 / 8.9 + 52.620 + 2.221 + 1.0, abs=1e-3)
    need = [need_by_hand(q, v, p, V_B) for p in dev]
    feas = lambda t, v_b=V_B: np.asarray(feasible(jnp.array(q), jnp.array(v), t, jnp.array(dev), v_b, params))
    np.testing.assert_array_equal(feas(0), [n <= 125.0 for n in need])
    np.testing.assert_array_equal(feas(0), [True, False, True])
    # the boundary slot of each feasible device: (K - t) tau >= need
    for n in (0, 2):
        t_last = int(np.floor(250 - 2 * need[n]))
        assert feas(t_last)[n] and not feas(t_last + 1)[n]
    # a faster UAV makes the far device feasible: 583.1 m each way at 10 m/s
    assert need_by_hand(q, v, dev[1], 10.0) < 125.0 and feas(0, 10.0)[1]


# A: nearest (250 m) but infeasible (250 + 1030.8 m > 125 s at 8.9 m/s); B: 291.5 m, feasible; C: far, feasible.
A, B, C = [0.0, 50.0], [250.0, 450.0], [700.0, 300.0]


def test_greedy_first_target_is_nearest_feasible_device(params):
    u_b = np.array([250.0, 150.0]) / np.hypot(250.0, 150.0)
    s = state_at(params, [A, B, C], v=V_B * u_b)  # cruising exactly towards B
    a, ps = greedy(init_state(V_B, jnp.arange(3)), s, params)
    np.testing.assert_allclose(a, [0.0, 0.0], atol=1e-5)
    np.testing.assert_allclose(a, speed_command(s.q, s.v, jnp.array(B), V_B, params))
    assert not np.any(ps.passed)
    # at 12 m/s A's detour fits (1280.8 m / 12 = 106.7 s plus turns), so A (the nearest) is the target
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
    np.testing.assert_allclose(a, home_command(s.q, s.v, V_B, params))
    np.testing.assert_allclose(a, [5.0, -5.0])  # 400 m out the approach speed is v_b: (17.8, -8) clipped
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
