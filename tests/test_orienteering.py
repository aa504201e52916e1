"""Prize-collecting orienteering with dwell options against brute force over subsets, orders and options."""

import itertools

import numpy as np
import pytest

from baselines import orienteering
from baselines.dwell_knapsack import TIME_STEP_S
from baselines.orienteering import PARALLEL_MIN_PROBLEMS, solve, solve_batch


def random_instance(rng, n=4, n_opt=3, grid=0.25):
    """Asymmetric travel (roughly metric), services on ``grid`` (None: arbitrary floats), concave prizes."""
    nodes = np.concatenate([[[0.0, 300.0]], rng.uniform(size=(n, 2)) * [1000.0, 600.0], [[1000.0, 300.0]]])
    travel = np.linalg.norm(nodes[:, None] - nodes[None], axis=-1) / 15.0 + 2.0 + rng.uniform(0, 3, (n + 2, n + 2))
    np.fill_diagonal(travel, 0.0)
    service = np.cumsum(rng.uniform(1, 8, (n, n_opt)), axis=1)
    if grid is not None:
        service = np.ceil(service / grid) * grid
    prize = np.cumsum(rng.uniform(0, 6, (n, n_opt)) * 0.6 ** np.arange(n_opt), axis=1)
    budget = travel[0, -1] + rng.uniform(5, 60)
    return travel, service, prize, budget


def plan_seconds(travel, service, order, option):
    """Total time of a plan, summed leg by leg."""
    visited = [int(d) for d in order if d >= 0]
    nodes = [0] + [d + 1 for d in visited] + [len(travel) - 1]
    return sum(travel[a, b] for a, b in zip(nodes[:-1], nodes[1:])) + sum(service[d, option[d]] for d in visited)


def brute_force(travel, service, prize, budget):
    """Best total prize over every ordered subset of devices and every option per visited device."""
    n, n_opt = service.shape
    best = 0.0
    for r in range(1, n + 1):
        for seq in itertools.permutations(range(n), r):
            nodes = [0] + [d + 1 for d in seq] + [n + 1]
            slack = budget - sum(travel[a, b] for a, b in zip(nodes[:-1], nodes[1:]))
            for opts in itertools.product(range(n_opt), repeat=r):
                if service[list(seq), list(opts)].sum() <= slack:
                    best = max(best, prize[list(seq), list(opts)].sum())
    return best


def check_plan(plan, travel, service, prize, budget):
    """The plan is well formed, within budget in float seconds, and its value is its prize."""
    order, option, value = plan
    n = len(service)
    assert order.dtype == option.dtype == np.int32 and order.shape == option.shape == (n,)
    visited = order[order >= 0]
    k = len(visited)
    assert np.all(order[k:] == -1) and len(set(visited.tolist())) == k
    assert sorted(np.nonzero(option >= 0)[0].tolist()) == sorted(visited.tolist())
    assert plan_seconds(travel, service, order, option) <= budget + 1e-9
    assert value == pytest.approx(sum(prize[d, option[d]] for d in visited), abs=1e-12)


@pytest.mark.parametrize(
    "seed, n, n_opt, grid", [(s, 4, 3, 0.25) for s in range(8)] + [(100 + s, 6, 2, 1.0) for s in range(2)]
)
def test_matches_brute_force_optimum(seed, n, n_opt, grid):
    instance = random_instance(np.random.default_rng(seed), n=n, n_opt=n_opt, grid=grid)
    plan = solve(*instance)
    check_plan(plan, *instance)
    assert plan[2] == pytest.approx(brute_force(*instance), abs=1e-9)


def test_off_grid_service_times_stay_within_budget_and_near_optimal():
    """Services off every grid: rounded up to TIME_STEP_S, so between the optima with and without rounding."""
    rng = np.random.default_rng(7)
    for _ in range(4):
        travel, service, prize, budget = random_instance(rng, n=4, n_opt=3, grid=None)
        plan = solve(travel, service, prize, budget)
        check_plan(plan, travel, service, prize, budget)
        rounded = np.ceil(service / TIME_STEP_S) * TIME_STEP_S
        assert (
            brute_force(travel, rounded, prize, budget) - 1e-9
            <= plan[2]
            <= brute_force(travel, service, prize, budget) + 1e-9
        )


def test_generous_budget_visits_everything_at_the_top_option_and_tight_budget_nothing():
    rng = np.random.default_rng(3)
    travel, service, prize, _ = random_instance(rng, n=5, n_opt=4)
    order, option, value = solve(travel, service, prize, 1e4)
    assert sorted(order.tolist()) == list(range(5)) and np.all(option == 3)
    assert value == pytest.approx(prize[:, -1].sum())
    direct = travel[0, -1]
    assert solve(travel, service, prize, direct)[2] == 0.0  # the direct flight fits, no device does
    for budget in (direct - 1e-6, 0.0):
        order, option, value = solve(travel, service, prize, budget)
        assert np.all(order == -1) and np.all(option == -1) and value == 0.0


def test_worthless_devices_are_skipped():
    rng = np.random.default_rng(4)
    travel, service, prize, _ = random_instance(rng, n=4, n_opt=3)
    prize[[1, 3]] = 0.0
    order, option, value = solve(travel, service, prize, 1e4)
    assert sorted(order[order >= 0].tolist()) == [0, 2] and option[1] == option[3] == -1


def test_batch_in_two_workers_equals_one_by_one():
    """The DP is deterministic, so the worker processes reproduce the serial plans exactly."""
    rng = np.random.default_rng(5)
    instances = [random_instance(rng, n=6, n_opt=3) for _ in range(PARALLEL_MIN_PROBLEMS)]
    travel, service, prize, budget = (np.stack(a) for a in zip(*instances))
    order, option, value = solve_batch(travel, service, prize, budget, workers=2)
    assert order.shape == option.shape == (PARALLEL_MIN_PROBLEMS, 6) and value.shape == (PARALLEL_MIN_PROBLEMS,)
    for e, instance in enumerate(instances):
        o, p, v = solve(*instance)
        np.testing.assert_array_equal(order[e], o)
        np.testing.assert_array_equal(option[e], p)
        assert value[e] == v
    serial = solve_batch(travel[:3], service[:3], prize[:3], 60.0, workers=2)  # scalar budget, in process
    assert serial[2][0] == solve(travel[0], service[0], prize[0], 60.0)[2]


def test_routing_fallback_is_feasible_and_never_beats_the_optimum(monkeypatch):
    monkeypatch.setattr(orienteering, "DP_MAX_DEVICES", 0)
    rng = np.random.default_rng(6)
    values, optima = [], []
    for _ in range(4):
        instance = random_instance(rng, n=4, n_opt=3)
        plan = solve(*instance, time_limit_ms=20)
        check_plan(plan, *instance)
        values.append(plan[2])
        optima.append(brute_force(*instance))
    assert np.all(np.array(values) <= np.array(optima) + 1e-9)
    assert sum(values) >= 0.8 * sum(optima)


def test_no_devices():
    travel = np.array([[0.0, 10.0], [10.0, 0.0]])
    order, option, value = solve(travel, np.zeros((0, 2)), np.zeros((0, 2)), 20.0)
    assert order.shape == option.shape == (0,) and value == 0.0


@pytest.mark.parametrize(
    "change, message",
    [
        ({"time_limit_ms": 0}, "time_limit_ms must be a positive integer, got 0"),
        ({"time_limit_ms": -5}, "time_limit_ms must be a positive integer, got -5"),
        ({"prize": -np.ones((4, 3))}, "prize must be >= 0, got -1.0"),
        ({"prize": np.ones((4, 2))}, "prize must have the shape of service_s (4, 3), got (4, 2)"),
        ({"travel_s": np.ones((5, 5))}, "travel_s must have shape (6, 6) for service_s (4, 3), got (5, 5)"),
        ({"service_s": np.ones(4)}, "service_s must be (N, L) with L >= 1, got shape (4,)"),
        ({"budget_s": np.nan}, "budget_s must be finite, got nan"),
    ],
)
def test_bad_input(change, message):
    travel, service, prize, budget = random_instance(np.random.default_rng(0))
    kwargs = {"travel_s": travel, "service_s": service, "prize": prize, "budget_s": budget, **change}
    with pytest.raises(ValueError) as err:
        solve(**kwargs)
    assert str(err.value) == message and "\n" not in message


def test_bad_batch_budget_shape():
    travel, service, prize, _ = random_instance(np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"budget_s must be a scalar or of shape \(2,\), got \(3,\)"):
        solve_batch(np.stack([travel] * 2), np.stack([service] * 2), np.stack([prize] * 2), np.ones(3))
