"""The BS's tours (docs/model.md eq. 6.5): the re-planned one a permutation with the live devices
first, exact on a line, never longer than its nearest-neighbour start, and within a few per cent of
Held-Karp; the shortest path Held-Karp's."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from baselines.tsp import distance_matrix, exact_orders
from semuav_jax.tour import numbered_order, shortest_path, tour_order

Q0, QF = np.array([0.0, 300.0]), np.array([1000.0, 300.0])


def length(order, pos, q, qf):
    pts = np.concatenate([[q], pos[np.asarray(order)], [qf]])
    return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(0, 2**10 - 1))
def test_a_permutation_with_the_live_devices_first_and_no_longer_than_nearest_neighbour(seed, mask):
    rng = np.random.default_rng(seed)
    pos = rng.uniform([0, 0], [1000, 600], (10, 2))
    live = (mask >> np.arange(10)) & 1 == 1
    order = np.asarray(tour_order(Q0, pos, live, QF))
    assert sorted(order) == list(range(10))
    n = int(live.sum())
    assert live[order[:n]].all() and not live[order[n:]].any()
    nn = np.asarray(tour_order(Q0, pos, live, QF, moves=0))
    assert length(order[:n], pos, Q0, QF) <= length(nn[:n], pos, Q0, QF) + 1e-3


def test_devices_on_the_line_are_visited_by_x():
    """On the segment q0 -> q_fin the shortest path takes the devices by x, from any start order."""
    x = np.array([850.0, 120.0, 400.0, 640.0, 60.0, 990.0, 300.0, 720.0, 510.0, 200.0])
    pos = np.stack([x, np.full(10, 300.0)], axis=1)
    order = np.asarray(tour_order(Q0, pos, np.ones(10, bool), QF))
    assert list(order) == list(np.argsort(x))


def test_within_a_few_per_cent_of_held_karp():
    """200 uniform layouts from q0: the paths are at most 2 % longer than Held-Karp's on average
    and the shortest on at least half of them; jit(vmap) gives the plain loop's orders."""
    rng = np.random.default_rng(7)
    pos = rng.uniform([0, 0], [1000, 600], (200, 10, 2))
    live = np.ones((200, 10), bool)
    batch = np.asarray(jax.jit(jax.vmap(tour_order, (None, 0, 0, None)))(jnp.asarray(Q0), pos, live, jnp.asarray(QF)))
    for e in range(0, 200, 40):
        np.testing.assert_array_equal(batch[e], np.asarray(tour_order(Q0, pos[e], live[e], QF)))
    exact = exact_orders(distance_matrix(pos, Q0, QF))
    ratio = np.array([length(batch[e], pos[e], Q0, QF) / length(exact[e], pos[e], Q0, QF) for e in range(200)])
    assert ratio.min() > 1 - 1e-5
    assert ratio.mean() < 1.02 and np.mean(ratio < 1 + 1e-5) > 0.7


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 9))
def test_the_shortest_path_is_held_karps(seed, n):
    """``shortest_path`` (JAX, float32) gives the order of the NumPy Held-Karp of the TSP baseline."""
    pos = np.random.default_rng(seed).uniform([0, 0], [1000, 600], (n, 2))
    order = np.asarray(shortest_path(Q0, pos, QF))
    ref = exact_orders(distance_matrix(pos[None], Q0, QF))[0]
    assert sorted(order) == list(range(n))
    assert length(order, pos, Q0, QF) == pytest.approx(length(ref, pos, Q0, QF), rel=1e-6)


def test_the_shortest_path_on_the_line_and_its_limit():
    x = np.array([850.0, 120.0, 400.0, 640.0, 60.0])
    pos = np.stack([x, np.full(5, 300.0)], axis=1)
    assert list(np.asarray(shortest_path(Q0, pos, QF))) == list(np.argsort(x))
    with pytest.raises(ValueError, match="exact up to 12 devices, got N = 13"):
        shortest_path(Q0, np.zeros((13, 2)), QF)


def test_numbered_order_keeps_the_numbers_of_the_live_devices():
    live = np.array([False, True, True, False, True])
    assert list(np.asarray(numbered_order(live))) == [1, 2, 4, 0, 3]
