"""Prize-collecting orienteering with dwell options: the offline UAV plan q0 -> chosen devices -> q_fin.

Each chosen device n gets one dwell option o (service time ``service_s[n, o]``, prize ``prize[n, o]``);
travel plus services must fit the time budget; the plan maximises the total prize.

Small instances (the default up to ~12 devices) are solved exactly by dynamic programming:
Held-Karp (``baselines/held_karp.py``) gives the shortest path T(S) through every device subset S
(float seconds, any travel matrix), and a multiple-choice knapsack over subsets
(``baselines/dwell_knapsack.py``) gives the best options for the slack budget - T(S) on a time grid.
Larger ones use OR-Tools routing (one node per (device, option), one disjunction per device, a time
dimension in centiseconds rounded up, local cheapest insertion + tabu search under
``time_limit_ms``), then the best options for that route. Either way the returned plan is re-checked
in float seconds.

Large batches are split over worker processes (``baselines/workers.py``) that load this file and its
two NumPy-only siblings without the package, so none of them imports JAX.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt
from ortools.constraint_solver import pywrapcp, routing_enums_pb2

from baselines.dwell_knapsack import (
    ROUND_TOL,
    capacity,
    grid_step,
    route_options,
    subset_options,
    subset_table,
    weights,
)
from baselines.held_karp import held_karp, path

DEFAULT_TIME_LIMIT_MS = 100  # OR-Tools path only (large instances); the exact DP ignores it
PARALLEL_MIN_PROBLEMS = 64
DP_MAX_DEVICES = 14
DP_MAX_CELLS = 1 << 23  # subsets x time bins of the DP table (64 MiB); beyond it OR-Tools
BUDGET_TOL_S = 1e-9  # float rounding allowed in the final budget check


# ----------------------------------------------------------------------------- input checks


def _check(
    travel_s: npt.ArrayLike,
    service_s: npt.ArrayLike,
    prize: npt.ArrayLike,
    budget_s: npt.ArrayLike,
    time_limit_ms: int,
    batched: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    travel_s, service_s, prize = (np.asarray(a, np.float64) for a in (travel_s, service_s, prize))
    lead = travel_s.shape[:1] if batched else ()
    if batched and travel_s.ndim != 3:
        raise ValueError(f"travel_s must be (E, N+2, N+2), got shape {travel_s.shape}")
    if service_s.ndim != len(lead) + 2 or service_s.shape[-1] < 1:
        raise ValueError(
            f"service_s must be {'(E, N, L)' if batched else '(N, L)'} with L >= 1, got shape {service_s.shape}"
        )
    n, n_opt = service_s.shape[-2:]
    if travel_s.shape != lead + (n + 2, n + 2):
        raise ValueError(
            f"travel_s must have shape {lead + (n + 2, n + 2)} for service_s {service_s.shape}, got {travel_s.shape}"
        )
    if prize.shape != service_s.shape:
        raise ValueError(f"prize must have the shape of service_s {service_s.shape}, got {prize.shape}")
    budget = np.asarray(budget_s, np.float64)
    if batched:
        if budget.ndim == 0:
            budget = np.full(lead, float(budget))
        if budget.shape != lead:
            raise ValueError(f"budget_s must be a scalar or of shape {lead}, got {budget.shape}")
    elif budget.ndim != 0:
        raise ValueError(f"budget_s must be a scalar, got shape {budget.shape}")
    for name, a in (("travel_s", travel_s), ("service_s", service_s), ("prize", prize), ("budget_s", budget)):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite, got {a[~np.isfinite(a)].ravel()[0]}")
        if np.any(a < 0):
            raise ValueError(f"{name} must be >= 0, got {a.min()}")
    if not isinstance(time_limit_ms, (int, np.integer)) or time_limit_ms <= 0:
        raise ValueError(f"time_limit_ms must be a positive integer, got {time_limit_ms!r}")
    return travel_s, service_s, prize, budget, int(time_limit_ms)


def _empty(n: int) -> tuple[np.ndarray, np.ndarray, float]:
    return np.full(n, -1, np.int32), np.full(n, -1, np.int32), 0.0


def plan_time(travel_s: np.ndarray, service_s: np.ndarray, order: np.ndarray, option: np.ndarray) -> float:
    """Total time (s) of a plan: travel q0 -> visited devices -> q_fin plus their services."""
    travel_s, service_s = np.asarray(travel_s, float), np.asarray(service_s, float)
    order, option = np.asarray(order), np.asarray(option)
    visited = order[order >= 0]
    nodes = np.concatenate([[0], visited + 1, [len(travel_s) - 1]])
    return float(travel_s[nodes[:-1], nodes[1:]].sum() + service_s[visited, option[visited]].sum())


def _finish(
    travel_s: np.ndarray, service_s: np.ndarray, prize: np.ndarray, budget: float, visits: list[tuple[int, int]]
) -> tuple[np.ndarray, np.ndarray, float]:
    """(order, option, value) of visits [(device, option), ...] in order, re-checked against the budget."""
    n = len(service_s)
    order, option = _empty(n)[:2]
    for i, (dev, opt) in enumerate(visits):
        order[i], option[dev] = dev, opt
    total = plan_time(travel_s, service_s, order, option)
    if total > budget + BUDGET_TOL_S:  # unreachable: travel and services are rounded conservatively
        raise RuntimeError(f"plan takes {total} s > budget {budget} s")
    value = float(sum(prize[dev, opt] for dev, opt in visits))
    return order, option, value


# ----------------------------------------------------------------------------- exact DP


def _solve_dp(travel: np.ndarray, service: np.ndarray, prize: np.ndarray, budget: float) -> list[tuple[int, int]]:
    """Visits [(device, option), ...] of the best plan: the subset whose shortest path leaves the
    slack with the best options (ties: the least time, then the lowest subset)."""
    n = len(service)
    T, dp, parent = held_karp(travel)
    step = grid_step(service)
    slack = budget - T
    cap = np.full(1 << n, -1, np.int64)
    ok = slack >= 0
    cap[ok] = capacity(slack[ok], step)
    w = weights(service, step)
    K, C = subset_table(w, prize, cap)
    value = np.full(1 << n, -np.inf)
    value[ok] = K[ok, np.minimum(cap[ok], C)]
    best = value.max()
    if not np.isfinite(best):
        return []
    ties = np.nonzero(value >= best - 1e-9)[0]
    c_min = {int(S): int(np.argmax(K[S] >= value[S])) for S in ties}  # least service with that prize
    S = int(min(ties, key=lambda s: (T[s] + c_min[int(s)] * step, s)))
    options = subset_options(K, w, prize, S, c_min[S])
    return [(dev, options[dev]) for dev in path(travel, dp, parent, S)]


# ----------------------------------------------------------------------------- OR-Tools


def _solve_routing(
    travel: np.ndarray, service: np.ndarray, prize: np.ndarray, budget: float, time_limit_ms: int
) -> list[tuple[int, int]]:
    n, n_opt = service.shape
    dev = np.concatenate([[-1], np.repeat(np.arange(n), n_opt), [n]])  # device of each routing node
    opt = np.concatenate([[0], np.tile(np.arange(n_opt), n), [0]])
    node = dev + 1  # row of travel_s
    serv = np.concatenate([[0.0], service.ravel(), [0.0]])
    transit = np.ceil((serv[:, None] + travel[node[:, None], node[None]]) * 100.0 - ROUND_TOL).astype(np.int64)
    tie = np.ceil(travel[node[:, None], node[None]] * 10.0).astype(np.int64)  # deciseconds
    scale = 100 * (int(np.ceil(budget * 10.0)) + 1)  # per dB: 0.01 dB outweighs any total travel
    max_prize = prize.max(axis=1)
    regret = np.concatenate([[0], np.rint((max_prize[:, None] - prize) * scale).ravel(), [0]]).astype(np.int64)
    cost = regret[None, :] + tie
    cost[:, 0] = 0
    manager = pywrapcp.RoutingIndexManager(len(dev), 1, [0], [len(dev) - 1])
    model = pywrapcp.RoutingModel(manager)
    model.SetArcCostEvaluatorOfAllVehicles(model.RegisterTransitMatrix(cost.tolist()))
    model.AddDimension(
        model.RegisterTransitMatrix(transit.tolist()), 0, int(np.floor(budget * 100.0 + ROUND_TOL)), True, "time"
    )
    for d in range(n):
        nodes = [manager.NodeToIndex(1 + d * n_opt + o) for o in range(n_opt)]
        model.AddDisjunction(nodes, int(np.rint(max_prize[d] * scale)), 1)
    search = pywrapcp.DefaultRoutingSearchParameters()
    search.first_solution_strategy = routing_enums_pb2.FirstSolutionStrategy.LOCAL_CHEAPEST_INSERTION
    search.local_search_metaheuristic = routing_enums_pb2.LocalSearchMetaheuristic.TABU_SEARCH
    search.time_limit.FromMilliseconds(time_limit_ms)
    solution = model.SolveWithParameters(search)
    if solution is None:
        return []
    visits, index = [], solution.Value(model.NextVar(model.Start(0)))
    while not model.IsEnd(index):
        i = manager.IndexToNode(index)
        visits.append((int(dev[i]), int(opt[i])))
        index = solution.Value(model.NextVar(index))
    return route_options(travel, service, prize, budget, visits)


# ----------------------------------------------------------------------------- API


def _use_dp(n: int, travel: np.ndarray, service: np.ndarray, budget: float) -> bool:
    if n > DP_MAX_DEVICES:
        return False
    step = grid_step(service)
    bins = min(budget / step, np.ceil(service / step).max(axis=1).sum()) + 1
    return (1 << n) * bins <= DP_MAX_CELLS


def _solve_one(
    travel: np.ndarray, service: np.ndarray, prize: np.ndarray, budget: float, time_limit_ms: int
) -> tuple[np.ndarray, np.ndarray, float]:
    n = len(service)
    if travel[0, -1] > budget or n == 0:
        return _empty(n)
    if _use_dp(n, travel, service, budget):
        visits = _solve_dp(travel, service, prize, budget)
    else:
        visits = _solve_routing(travel, service, prize, budget, time_limit_ms)
    return _finish(travel, service, prize, budget, visits)


def solve(
    travel_s: npt.ArrayLike,
    service_s: npt.ArrayLike,
    prize: npt.ArrayLike,
    budget_s: npt.ArrayLike,
    time_limit_ms: int = DEFAULT_TIME_LIMIT_MS,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Best plan (order, option, value) for nodes [q0, dev_1..dev_N, q_fin].

    travel_s (N+2, N+2) s; service_s, prize (N, L); budget_s: travel plus services must fit.
    order (N,) int32: visited devices in order, then -1; option (N,) int32: option per device
    (-1: not visited); value: total prize. All -1 and 0 if q0 -> q_fin alone exceeds the budget.
    ``time_limit_ms`` bounds the OR-Tools search (used above ``DP_MAX_DEVICES`` devices).
    """
    args = _check(travel_s, service_s, prize, budget_s, time_limit_ms, batched=False)
    return _solve_one(*args[:3], float(args[3]), args[4])


def _solve_many(
    travel_s: np.ndarray, service_s: np.ndarray, prize: np.ndarray, budget_s: np.ndarray, time_limit_ms: int
) -> dict:
    plans = [
        _solve_one(t, s, p, float(b), int(time_limit_ms)) for t, s, p, b in zip(travel_s, service_s, prize, budget_s)
    ]
    n = service_s.shape[1]
    return {
        "order": np.array([p[0] for p in plans], np.int32).reshape(-1, n),
        "option": np.array([p[1] for p in plans], np.int32).reshape(-1, n),
        "value": np.array([p[2] for p in plans], np.float64),
    }


def solve_batch(
    travel_s: npt.ArrayLike,
    service_s: npt.ArrayLike,
    prize: npt.ArrayLike,
    budget_s: npt.ArrayLike,
    time_limit_ms: int = DEFAULT_TIME_LIMIT_MS,
    workers: int = 2,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``solve`` over a leading axis E (budget_s (E,) or scalar): order, option (E, N), value (E,).

    Batches of at least ``PARALLEL_MIN_PROBLEMS`` are split over ``workers`` processes.
    """
    travel_s, service_s, prize, budget_s, time_limit_ms = _check(
        travel_s, service_s, prize, budget_s, time_limit_ms, batched=True
    )
    if workers <= 1 or len(travel_s) < PARALLEL_MIN_PROBLEMS:
        out = _solve_many(travel_s, service_s, prize, budget_s, time_limit_ms)
    else:
        from baselines.workers import map_chunks  # not at top level: workers.py loads this file

        batched = {"travel_s": travel_s, "service_s": service_s, "prize": prize, "budget_s": budget_s}
        out = map_chunks(
            Path(__file__), "_solve_many", batched, {"time_limit_ms": time_limit_ms}, workers, desc="orienteering"
        )
    return out["order"], out["option"], out["value"]
