"""TSP visiting order of MODEL.md section 7: the shortest open path q0 -> all devices -> q_fin.

Deterministic whatever the machine's load or the split of a batch (docs/scaling.md): up to
``EXACT_MAX_DEVICES`` devices the exact optimum by Held-Karp dynamic programming over device
subsets (float64 metres, ties to the lowest device index), batched over layouts in NumPy; above
that OR-Tools routing (one vehicle, fixed start and end node, integer distances in centimetres,
cheapest-arc start, guided local search stopped after ``SOLUTION_LIMIT`` solutions, never by a
clock), one layout at a time, large batches split over worker processes (``baselines/workers.py``)
that load this file, which therefore imports no JAX and nothing from ``baselines`` at top level.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt
from ortools.constraint_solver import pywrapcp, routing_enums_pb2

EXACT_MAX_DEVICES = 12  # Held-Karp: 2^N x N states per layout
SCALE = 100.0  # integer arc costs in centimetres (OR-Tools)
SOLUTION_LIMIT = 200  # OR-Tools: solutions the guided local search visits (optimal on 10 layouts of 13 devices)
PARALLEL_MIN_LAYOUTS = 64
_EXACT_CELLS = 1 << 22  # layouts x subsets x devices x devices in one step of the exact solver


def distance_matrix(dev_pos: npt.ArrayLike, q0: npt.ArrayLike, q_fin: npt.ArrayLike) -> np.ndarray:
    """Euclidean distances between the nodes [q0, p_1..p_N, q_fin] (metres); batched over leading axes."""
    dev_pos = np.asarray(dev_pos, float)
    ends = lambda q: np.broadcast_to(np.asarray(q, float), (*dev_pos.shape[:-2], 1, 2))
    nodes = np.concatenate([ends(q0), dev_pos, ends(q_fin)], axis=-2)
    return np.linalg.norm(nodes[..., :, None, :] - nodes[..., None, :, :], axis=-1)


def exact_orders(dist: npt.ArrayLike) -> np.ndarray:
    """Shortest open paths (E, N) for distance matrices ``dist`` (E, N + 2, N + 2) over [q0, devices, q_fin].

    Held-Karp: best[S, j], the shortest path from q0 through the device set S ending at j, is the
    min over i in S \\ {j} of best[S \\ {j}, i] + d(i, j), for the sets S by size. Each entry is one
    float64 sum and a min, so the order of a layout does not depend on the batch it is solved in."""
    dist = np.asarray(dist, np.float64)
    e, n = dist.shape[0], dist.shape[1] - 2
    if n <= 1:
        return np.zeros((e, n), np.int32)
    sets = np.arange(1 << n)
    size = np.bitwise_count(sets)
    chunk = max(1, _EXACT_CELLS // (int(np.bincount(size).max()) * n * n))
    if e > chunk:
        return np.concatenate([exact_orders(dist[lo : lo + chunk]) for lo in range(0, e, chunk)])
    member = (sets[:, None] >> np.arange(n)) & 1 == 1  # (2^N, N)
    to_j = dist[:, 1:-1, 1:-1].transpose(0, 2, 1)[:, None]  # (E, 1, j, i): d(i, j)
    best = np.full((e, 1 << n, n), np.inf)
    parent = np.zeros((e, 1 << n, n), np.int8)
    best[:, 1 << np.arange(n), np.arange(n)] = dist[:, 0, 1:-1]
    for k in range(2, n + 1):
        S = sets[size == k]
        prev = S[:, None] ^ (1 << np.arange(n))  # (sets, j): S without j (used where j is in S)
        cand = np.where(member[prev], best[:, prev, :] + to_j, np.inf)  # (E, sets, j, i): i in S \ {j}
        i = np.argmin(cand, axis=-1)
        best[:, S] = np.where(member[S], np.take_along_axis(cand, i[..., None], -1)[..., 0], np.inf)
        parent[:, S] = i
    full = (1 << n) - 1
    j = np.argmin(best[:, full] + dist[:, 1:-1, -1], axis=-1)
    orders = np.zeros((e, n), np.int32)
    S = np.full(e, full)
    for pos in range(n - 1, -1, -1):  # undo the recursion from the last device back
        orders[:, pos] = j
        S, j = S ^ (1 << j), parent[np.arange(e), S, j].astype(np.int64)
    return orders


def _search():
    """Cheapest-arc start, then guided local search for ``SOLUTION_LIMIT`` solutions."""
    search = pywrapcp.DefaultRoutingSearchParameters()
    search.first_solution_strategy = routing_enums_pb2.FirstSolutionStrategy.PATH_CHEAPEST_ARC
    search.local_search_metaheuristic = routing_enums_pb2.LocalSearchMetaheuristic.GUIDED_LOCAL_SEARCH
    search.solution_limit = SOLUTION_LIMIT
    return search


def routing_order(dev_pos: npt.ArrayLike, q0: npt.ArrayLike, q_fin: npt.ArrayLike) -> np.ndarray:
    """OR-Tools' open path (device indices (N,)) for one layout; deterministic (no time limit)."""
    n = len(dev_pos)
    cost = np.rint(distance_matrix(dev_pos, q0, q_fin) * SCALE).astype(np.int64)
    manager = pywrapcp.RoutingIndexManager(n + 2, 1, [0], [n + 1])
    model = pywrapcp.RoutingModel(manager)
    arc = model.RegisterTransitMatrix(cost.tolist())
    model.SetArcCostEvaluatorOfAllVehicles(arc)
    solution = model.SolveWithParameters(_search())
    if solution is None:
        raise RuntimeError(f"OR-Tools found no route (status {model.status()})")
    order, index = [], solution.Value(model.NextVar(model.Start(0)))
    while not model.IsEnd(index):
        order.append(manager.IndexToNode(index) - 1)
        index = solution.Value(model.NextVar(index))
    return np.asarray(order, np.int32)


def solve_order(dev_pos: npt.ArrayLike, q0: npt.ArrayLike, q_fin: npt.ArrayLike) -> np.ndarray:
    """Device indices (N,) in visiting order of the shortest open path from q0 to q_fin."""
    return solve_orders(np.asarray(dev_pos, float)[None], q0, q_fin, workers=1)[0]


def _solve_batch(dev_pos: np.ndarray, q0: np.ndarray, q_fin: np.ndarray) -> np.ndarray:
    return np.stack([routing_order(p, q0, q_fin) for p in dev_pos]).reshape(len(dev_pos), -1)


def solve_orders(dev_pos: npt.ArrayLike, q0: npt.ArrayLike, q_fin: npt.ArrayLike, workers: int = 2) -> np.ndarray:
    """Visiting orders (E, N) for a batch of layouts ``dev_pos`` (E, N, 2).

    Exact in this process up to ``EXACT_MAX_DEVICES`` devices; above, batches of at least
    ``PARALLEL_MIN_LAYOUTS`` layouts are split over ``workers`` processes (``baselines/workers.py``,
    arrays through stdin/stdout). Nothing is cached.
    """
    dev_pos = np.asarray(dev_pos, float)
    q0, q_fin = np.asarray(q0, float), np.asarray(q_fin, float)
    if dev_pos.shape[1] <= EXACT_MAX_DEVICES:
        return exact_orders(distance_matrix(dev_pos, q0, q_fin))
    if workers <= 1 or len(dev_pos) < PARALLEL_MIN_LAYOUTS:
        return _solve_batch(dev_pos, q0, q_fin)
    from baselines.workers import map_chunks  # not at top level: the workers load this file without the package

    shared = {"q0": q0, "q_fin": q_fin}
    return map_chunks(Path(__file__), "_worker_batch", {"dev_pos": dev_pos}, shared, workers, desc="TSP tours")[
        "orders"
    ]


def _worker_batch(dev_pos: np.ndarray, q0: np.ndarray, q_fin: np.ndarray) -> dict[str, np.ndarray]:
    """Entry point of a worker process (``baselines/workers.py``)."""
    return {"orders": _solve_batch(dev_pos, q0, q_fin)}
