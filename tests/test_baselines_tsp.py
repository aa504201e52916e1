"""TSP order of MODEL.md section 7 against exact open-path optima (brute force, Held-Karp): exact up to
EXACT_MAX_DEVICES devices, OR-Tools above; deterministic and independent of the batch."""

import itertools

import numpy as np
import pytest

from baselines.tsp import EXACT_MAX_DEVICES, PARALLEL_MIN_LAYOUTS, solve_order, solve_orders

Q0, Q_FIN = np.array([0.0, 300.0]), np.array([1000.0, 300.0])


def random_layout(rng, n):
    return rng.uniform(size=(n, 2)) * [1000.0, 600.0]


def path_length(order, pos):
    """Length (metres) of the open path q0 -> devices in ``order`` -> q_fin."""
    pts = np.concatenate([Q0[None], pos[list(order)], Q_FIN[None]])
    return float(np.linalg.norm(np.diff(pts, axis=0), axis=-1).sum())


def brute_force(pos):
    """Shortest open path q0 -> all devices -> q_fin by enumerating every permutation."""
    perms = np.array(list(itertools.permutations(range(len(pos)))))
    pts = np.concatenate(
        [np.broadcast_to(Q0, (len(perms), 1, 2)), pos[perms], np.broadcast_to(Q_FIN, (len(perms), 1, 2))], 1
    )
    lengths = np.linalg.norm(np.diff(pts, axis=1), axis=-1).sum(1)
    return perms[np.argmin(lengths)], lengths.min()


def held_karp(pos):
    """Exact shortest open path length q0 -> all devices -> q_fin (dynamic programming over subsets)."""
    n = len(pos)
    start = np.linalg.norm(pos - Q0, axis=-1)
    end = np.linalg.norm(pos - Q_FIN, axis=-1)
    D = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
    dp = np.full((1 << n, n), np.inf)  # dp[S, j]: shortest path from q0 through set S ending at j
    dp[1 << np.arange(n), np.arange(n)] = start
    for S in range(1, 1 << n):
        ext = np.min(dp[S][:, None] + D, axis=0)  # best extension to each k
        for k in range(n):
            if not S >> k & 1:
                dp[S | 1 << k, k] = min(dp[S | 1 << k, k], ext[k])
    return float(np.min(dp[-1] + end))


def test_held_karp_matches_brute_force():
    rng = np.random.default_rng(1)
    for _ in range(5):
        pos = random_layout(rng, 6)
        assert held_karp(pos) == pytest.approx(brute_force(pos)[1], rel=1e-12)


@pytest.mark.parametrize("n", range(1, 8))
def test_order_is_brute_force_optimum_up_to_7_devices(n):
    rng = np.random.default_rng(n)
    for _ in range(4):
        pos = random_layout(rng, n)
        order = solve_order(pos, Q0, Q_FIN)
        best, _ = brute_force(pos)
        np.testing.assert_array_equal(order, best)


def test_ten_devices_are_the_held_karp_optimum_whatever_the_batch():
    rng = np.random.default_rng(10)
    pos = np.stack([random_layout(rng, 10) for _ in range(20)])
    orders = solve_orders(pos, Q0, Q_FIN)
    for p, order in zip(pos, orders):
        assert sorted(order) == list(range(10))
        assert path_length(order, p) == pytest.approx(held_karp(p), rel=1e-12)
    # the split of a batch (over processes, docs/scaling.md) does not change any order
    parts = [solve_orders(pos[i : i + 3], Q0, Q_FIN) for i in range(0, 20, 3)]
    np.testing.assert_array_equal(np.concatenate(parts), orders)
    np.testing.assert_array_equal(solve_order(pos[7], Q0, Q_FIN), orders[7])


def test_above_the_exact_size_or_tools_is_deterministic_and_within_one_percent():
    n = EXACT_MAX_DEVICES + 1
    rng = np.random.default_rng(13)
    pos = np.stack([random_layout(rng, n) for _ in range(2)])
    orders = solve_orders(pos, Q0, Q_FIN)  # OR-Tools, stopped by a count of solutions, not by a clock
    np.testing.assert_array_equal(solve_orders(pos, Q0, Q_FIN), orders)
    for p, order in zip(pos, orders):
        assert sorted(order) == list(range(n))
        assert path_length(order, p) <= 1.01 * held_karp(p)


def test_collinear_devices_are_visited_left_to_right_also_in_parallel():
    """Devices on the segment q0 -> q_fin: the optimum visits them by increasing x (length 1000 m)."""
    rng = np.random.default_rng(3)
    x = rng.uniform(10, 990, size=(PARALLEL_MIN_LAYOUTS, 6))
    pos = np.stack([x, np.full_like(x, 300.0)], -1)
    orders = solve_orders(pos, Q0, Q_FIN, workers=2)
    np.testing.assert_array_equal(orders, np.argsort(x, axis=1))
    assert path_length(orders[0], pos[0]) == pytest.approx(1000.0)


def test_degenerate_sizes():
    assert solve_order(np.zeros((0, 2)), Q0, Q_FIN).shape == (0,)
    np.testing.assert_array_equal(solve_order(np.array([[5.0, 5.0]]), Q0, Q_FIN), [0])
