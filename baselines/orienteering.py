"""Prize-collecting orienteering with dwell options: the offline UAV plan q0 -> chosen devices -> q_fin.

Each chosen device n gets one dwell option l (service time ``service_s[n, l]``, prize ``prize[n, l]``);
travel plus services must fit the time budget; the plan maximises the total prize.

Small instances (the default up to ~12 devices) are solved exactly by dynamic programming:
Held-Karp gives the shortest path T(S) through every device subset S (float seconds, any travel
matrix), and a multiple-choice knapsack over subsets gives the best options for the slack
budget - T(S), on a time grid: the coarsest of 1, 0.5, ..., 0.05 s dividing every service time
(then exact), else ``TIME_STEP_S`` with every service time rounded up. Larger ones use OR-Tools routing (one node per
(device, option), one disjunction per device, a time dimension in centiseconds rounded up, local
cheapest insertion + tabu search under ``time_limit_ms``), then the best options for that route. Either way the returned plan is re-checked in float seconds.

Large batches are split over worker processes (``baselines/workers.py``) that load this file,
which therefore imports no JAX and nothing from ``baselines`` at top level.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
from ortools.constraint_solver import pywrapcp, routing_enums_pb2

DEFAULT_TIME_LIMIT_MS = 100  # OR-Tools path only (large instances); the exact DP ignores it
PARALLEL_MIN_PROBLEMS = 64
TIME_STEP_S = 0.05  # knapsack grid of the exact DP when no coarser one of _STEPS divides all service times
_STEPS = (1.0, 0.5, 0.25, 0.2, 0.1, 0.05)
DP_MAX_DEVICES = 14
DP_MAX_CELLS = 1 << 23  # subsets x time bins of the DP table (64 MiB); beyond it OR-Tools
BUDGET_TOL_S = 1e-9  # float rounding allowed in the final budget check
_ROUND_TOL = 1e-9  # in grid units / centiseconds: keeps e.g. 2.0 / 0.05 from rounding up to 41


# ----------------------------------------------------------------------------- input checks


def _check(travel_s, service_s, prize, budget_s, time_limit_ms, batched: bool):
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


def _empty(n):
    return np.full(n, -1, np.int32), np.full(n, -1, np.int32), 0.0


def plan_time(travel_s, service_s, order, option) -> float:
    """Total time (s) of a plan: travel q0 -> visited devices -> q_fin plus their services."""
    travel_s, service_s = np.asarray(travel_s, float), np.asarray(service_s, float)
    order, option = np.asarray(order), np.asarray(option)
    visited = order[order >= 0]
    nodes = np.concatenate([[0], visited + 1, [len(travel_s) - 1]])
    return float(travel_s[nodes[:-1], nodes[1:]].sum() + service_s[visited, option[visited]].sum())


def _finish(travel_s, service_s, prize, budget, visits):
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


@functools.cache
def _layers(n: int):
    """Per subset size r >= 2: arrays (S, j, S without j) of all subsets S of size r and j in S."""
    subsets = np.arange(1 << n)
    size = np.array([bin(s).count("1") for s in subsets])
    out = []
    for r in range(2, n + 1):
        s_r = subsets[size == r]
        s_idx, j_idx = np.nonzero((s_r[:, None] >> np.arange(n)) & 1)
        S = s_r[s_idx]
        out.append((S, j_idx, S ^ (1 << j_idx)))
    return out


def _held_karp(travel):
    """T (2^N,): shortest time q0 -> all of S -> q_fin; dp, parent (2^N, N) for the path ending at j."""
    n = len(travel) - 2
    dev = travel[1:-1, 1:-1]
    dp = np.full((1 << n, n), np.inf)
    parent = np.full((1 << n, n), -1, np.int16)
    dp[1 << np.arange(n), np.arange(n)] = travel[0, 1:-1]
    for S, j, prev in _layers(n):
        cand = dp[prev] + dev[:, j].T  # cand[p, i] = dp[S \ j, i] + travel(i -> j)
        best = np.argmin(cand, axis=1)
        dp[S, j] = cand[np.arange(len(S)), best]
        parent[S, j] = best
    T = np.min(dp + travel[1:-1, -1], axis=1)
    T[0] = travel[0, -1]
    return T, dp, parent


def _grid_step(service) -> float:
    """Largest of ``_STEPS`` dividing every service time (then the DP is exact), else ``TIME_STEP_S``."""
    for step in _STEPS:
        q = service / step
        if np.all(np.abs(q - np.rint(q)) <= _ROUND_TOL):
            return step
    return TIME_STEP_S


def _solve_dp(travel, service, prize, budget):
    n, n_opt = service.shape
    T, dp, parent = _held_karp(travel)
    step = _grid_step(service)
    slack = budget - T
    cap = np.full(1 << n, -1, np.int64)
    ok = slack >= 0
    cap[ok] = np.floor(slack[ok] / step + _ROUND_TOL).astype(np.int64)
    w = np.ceil(service / step - _ROUND_TOL).astype(np.int64)
    C = int(min(cap.max(), w.max(axis=1).sum()))
    # need[S]: the largest capacity any superset of S that could be feasible reads from K[S]; -1: none
    subsets = np.arange(1 << n)
    min_service = (((subsets[:, None] >> np.arange(n)) & 1) * w.min(axis=1)).sum(axis=1)
    need = np.where(cap >= min_service, np.minimum(cap, C), -1)
    for k in range(n):
        with_k = subsets[subsets & (1 << k) > 0]
        need[with_k ^ (1 << k)] = np.maximum(need[with_k ^ (1 << k)], need[with_k])
    K = np.full((1 << n, C + 1), -np.inf)  # K[S, c]: best prize of options for S with services <= c steps
    K[0] = 0.0
    for k in range(n):  # subsets with highest device k from those without it (K[S, c] valid for c <= need[S])
        rows = (1 << k) + np.nonzero(need[1 << k : 2 << k] >= 0)[0]
        if not len(rows):
            continue
        top = int(need[rows].max()) + 1
        src, dst = K[rows - (1 << k), :top], np.full((len(rows), top), -np.inf)
        for l in range(n_opt):
            if w[k, l] < top:
                np.maximum(dst[:, w[k, l] :], src[:, : top - w[k, l]] + prize[k, l], out=dst[:, w[k, l] :])
        K[rows, :top] = dst
    value = np.full(1 << n, -np.inf)
    value[ok] = K[ok, np.minimum(cap[ok], C)]
    best = value.max()
    if not np.isfinite(best):
        return []
    ties = np.nonzero(value >= best - 1e-9)[0]
    c_min = {int(S): int(np.argmax(K[S] >= value[S])) for S in ties}  # least service with that prize
    S = min(ties, key=lambda s: (T[s] + c_min[int(s)] * step, s))
    S, c = int(S), c_min[int(S)]
    # options: undo the knapsack from the highest device down
    options, s = {}, S
    while s:
        k = s.bit_length() - 1
        prev = s ^ (1 << k)
        for l in range(n_opt):
            if w[k, l] <= c and K[prev, c - w[k, l]] + prize[k, l] == K[s, c]:
                options[k], c, s = l, c - w[k, l], prev
                break
        else:
            raise RuntimeError("knapsack backtrack failed")
    # order: undo Held-Karp from the last device back
    order, s = [], S
    if s:
        j = int(np.argmin(dp[s] + travel[1:-1, -1]))
        while s:
            order.append(j)
            s, j = s ^ (1 << j), int(parent[s, j])
    return [(dev, options[dev]) for dev in reversed(order)]


# ----------------------------------------------------------------------------- OR-Tools


def _solve_routing(travel, service, prize, budget, time_limit_ms):
    n, n_opt = service.shape
    dev = np.concatenate([[-1], np.repeat(np.arange(n), n_opt), [n]])  # device of each routing node
    opt = np.concatenate([[0], np.tile(np.arange(n_opt), n), [0]])
    node = dev + 1  # row of travel_s
    serv = np.concatenate([[0.0], service.ravel(), [0.0]])
    transit = np.ceil((serv[:, None] + travel[node[:, None], node[None]]) * 100.0 - _ROUND_TOL).astype(np.int64)
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
        model.RegisterTransitMatrix(transit.tolist()), 0, int(np.floor(budget * 100.0 + _ROUND_TOL)), True, "time"
    )
    for d in range(n):
        nodes = [manager.NodeToIndex(1 + d * n_opt + l) for l in range(n_opt)]
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
    return _best_options(travel, service, prize, budget, visits)


def _best_options(travel, service, prize, budget, visits):
    """The same route with the best options for its slack (multiple-choice knapsack on the DP grid)."""
    if not visits:
        return visits
    devs = [d for d, _ in visits]
    nodes = [0] + [d + 1 for d in devs] + [len(travel) - 1]
    slack = budget - travel[nodes[:-1], nodes[1:]].sum()
    step = _grid_step(service)
    w = np.ceil(service[devs] / step - _ROUND_TOL).astype(np.int64)
    cap = int(np.floor(slack / step + _ROUND_TOL))
    if cap < w.min(axis=1).sum() or cap > 1 << 20:
        return visits
    K = np.full((len(devs) + 1, cap + 1), -np.inf)  # K[i, c]: best prize of the first i devices within c steps
    K[0] = 0.0
    for i, d in enumerate(devs):
        for l in range(w.shape[1]):
            if w[i, l] <= cap:
                np.maximum(K[i + 1, w[i, l] :], K[i, : cap + 1 - w[i, l]] + prize[d, l], out=K[i + 1, w[i, l] :])
    if K[-1, cap] <= sum(prize[d, o] for d, o in visits):
        return visits
    c, options = int(np.argmax(K[-1] >= K[-1, cap])), []
    for i in range(len(devs), 0, -1):
        d = devs[i - 1]
        l = next(
            l for l in range(w.shape[1]) if w[i - 1, l] <= c and K[i - 1, c - w[i - 1, l]] + prize[d, l] == K[i, c]
        )
        options.append(l)
        c -= w[i - 1, l]
    return list(zip(devs, reversed(options)))


# ----------------------------------------------------------------------------- API


def _use_dp(n: int, travel, service, budget) -> bool:
    if n > DP_MAX_DEVICES:
        return False
    step = _grid_step(service)
    bins = min(budget / step, np.ceil(service / step).max(axis=1).sum()) + 1
    return (1 << n) * bins <= DP_MAX_CELLS


def _solve_one(travel, service, prize, budget, time_limit_ms):
    n = len(service)
    if travel[0, -1] > budget or n == 0:
        return _empty(n)
    if _use_dp(n, travel, service, budget):
        visits = _solve_dp(travel, service, prize, budget)
    else:
        visits = _solve_routing(travel, service, prize, budget, time_limit_ms)
    return _finish(travel, service, prize, budget, visits)


def solve(
    travel_s, service_s, prize, budget_s, time_limit_ms=DEFAULT_TIME_LIMIT_MS
) -> tuple[np.ndarray, np.ndarray, float]:
    """Best plan (order, option, value) for nodes [q0, dev_1..dev_N, q_fin].

    travel_s (N+2, N+2) s; service_s, prize (N, L); budget_s: travel plus services must fit.
    order (N,) int32: visited devices in order, then -1; option (N,) int32: option per device
    (-1: not visited); value: total prize. All -1 and 0 if q0 -> q_fin alone exceeds the budget.
    ``time_limit_ms`` bounds the OR-Tools search (used above ``DP_MAX_DEVICES`` devices).
    """
    args = _check(travel_s, service_s, prize, budget_s, time_limit_ms, batched=False)
    return _solve_one(*args[:3], float(args[3]), args[4])


def _solve_many(travel_s, service_s, prize, budget_s, time_limit_ms) -> dict:
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
    travel_s, service_s, prize, budget_s, time_limit_ms=DEFAULT_TIME_LIMIT_MS, workers: int = 2
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
        from baselines.workers import map_chunks  # not at top level: the workers load this file without the package

        batched = {"travel_s": travel_s, "service_s": service_s, "prize": prize, "budget_s": budget_s}
        out = map_chunks(
            Path(__file__), "_solve_many", batched, {"time_limit_ms": time_limit_ms}, workers, desc="orienteering"
        )
    return out["order"], out["option"], out["value"]
