"""TSP visiting order of MODEL.md section 7: the shortest open path q0 -> all devices -> q_fin.

Solved with OR-Tools routing (one vehicle, fixed start and end node, integer distances in
centimetres, guided local search under a time limit) outside jit, one layout at a time. Large
batches are split over worker processes (``baselines/workers.py``) that load this file, which
therefore imports no JAX and nothing from ``baselines`` at top level.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from ortools.constraint_solver import pywrapcp, routing_enums_pb2

SCALE = 100.0  # integer arc costs in centimetres
DEFAULT_TIME_LIMIT_MS = 50
PARALLEL_MIN_LAYOUTS = 64


def distance_matrix(dev_pos, q0, q_fin) -> np.ndarray:
    """Euclidean distances between the nodes [q0, p_1..p_N, q_fin] (metres)."""
    nodes = np.concatenate([np.asarray(q0, float)[None], np.asarray(dev_pos, float), np.asarray(q_fin, float)[None]])
    return np.linalg.norm(nodes[:, None] - nodes[None], axis=-1)


def _search(time_limit_ms):
    """Cheapest-arc start, then guided local search for ``time_limit_ms`` (None: default local search, no limit)."""
    search = pywrapcp.DefaultRoutingSearchParameters()
    search.first_solution_strategy = routing_enums_pb2.FirstSolutionStrategy.PATH_CHEAPEST_ARC
    if time_limit_ms is not None:
        search.local_search_metaheuristic = routing_enums_pb2.LocalSearchMetaheuristic.GUIDED_LOCAL_SEARCH
        search.time_limit.FromMilliseconds(int(time_limit_ms))
    return search


def solve_order(dev_pos, q0, q_fin, time_limit_ms: int = DEFAULT_TIME_LIMIT_MS) -> np.ndarray:
    """Device indices (N,) in visiting order of the shortest open path from q0 to q_fin."""
    n = len(dev_pos)
    if n <= 1:
        return np.arange(n, dtype=np.int32)
    cost = np.rint(distance_matrix(dev_pos, q0, q_fin) * SCALE).astype(np.int64)
    manager = pywrapcp.RoutingIndexManager(n + 2, 1, [0], [n + 1])
    model = pywrapcp.RoutingModel(manager)
    arc = model.RegisterTransitMatrix(cost.tolist())
    model.SetArcCostEvaluatorOfAllVehicles(arc)
    solution = model.SolveWithParameters(_search(time_limit_ms))
    if solution is None:  # no first solution within the limit (a loaded machine): plain local search
        solution = model.SolveWithParameters(_search(None))
    if solution is None:
        raise RuntimeError(f"OR-Tools found no route (status {model.status()})")
    order, index = [], solution.Value(model.NextVar(model.Start(0)))
    while not model.IsEnd(index):
        order.append(manager.IndexToNode(index) - 1)
        index = solution.Value(model.NextVar(index))
    return np.asarray(order, np.int32)


def _solve_batch(dev_pos, q0, q_fin, time_limit_ms) -> np.ndarray:
    return np.stack([solve_order(p, q0, q_fin, time_limit_ms) for p in dev_pos]).reshape(len(dev_pos), -1)


def solve_orders(dev_pos, q0, q_fin, time_limit_ms: int = DEFAULT_TIME_LIMIT_MS, workers: int = 2) -> np.ndarray:
    """Visiting orders (E, N) for a batch of layouts ``dev_pos`` (E, N, 2).

    Batches of at least ``PARALLEL_MIN_LAYOUTS`` layouts are split over ``workers`` processes
    (``baselines/workers.py``, arrays through stdin/stdout); nothing is cached.
    """
    dev_pos = np.asarray(dev_pos, float)
    q0, q_fin = np.asarray(q0, float), np.asarray(q_fin, float)
    if workers <= 1 or len(dev_pos) < PARALLEL_MIN_LAYOUTS:
        return _solve_batch(dev_pos, q0, q_fin, time_limit_ms)
    from baselines.workers import map_chunks  # not at top level: the workers load this file without the package

    shared = {"q0": q0, "q_fin": q_fin, "time_limit_ms": time_limit_ms}
    return map_chunks(Path(__file__), "_worker_batch", {"dev_pos": dev_pos}, shared, workers, desc="TSP tours")[
        "orders"
    ]


def _worker_batch(dev_pos, q0, q_fin, time_limit_ms) -> dict:
    """Entry point of a worker process (``baselines/workers.py``)."""
    return {"orders": _solve_batch(dev_pos, q0, q_fin, int(time_limit_ms))}
