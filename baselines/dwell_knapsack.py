"""The multiple-choice knapsack of the orienteering planner (docs/baselines.md, "Planner"): which
dwell option each visited device gets in the slack a route leaves, on a time grid.

Service times are counted in steps of the coarsest of 1, 0.5, ..., 0.05 s that divides every one
of them (then exact), else of ``TIME_STEP_S`` with every service time rounded up. NumPy only: the
orienteering worker processes (``baselines/workers.py``) load it without JAX.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

TIME_STEP_S = 0.05  # knapsack grid when no coarser one of _STEPS divides all service times
_STEPS = (1.0, 0.5, 0.25, 0.2, 0.1, 0.05)
ROUND_TOL = 1e-9  # in grid units / centiseconds: keeps e.g. 2.0 / 0.05 from rounding up to 41


def grid_step(service: np.ndarray) -> float:
    """Largest of ``_STEPS`` dividing every service time (then the DP is exact), else ``TIME_STEP_S``."""
    for step in _STEPS:
        q = service / step
        if np.all(np.abs(q - np.rint(q)) <= ROUND_TOL):
            return step
    return TIME_STEP_S


def capacity(slack: npt.ArrayLike, step: float) -> np.ndarray:
    """Whole grid steps within ``slack`` seconds (int64 of its shape)."""
    return np.floor(np.asarray(slack) / step + ROUND_TOL).astype(np.int64)


def weights(service: np.ndarray, step: float) -> np.ndarray:
    """Service times in grid steps, rounded up (int64 of their shape)."""
    return np.ceil(service / step - ROUND_TOL).astype(np.int64)


def subset_table(w: np.ndarray, prize: np.ndarray, cap: np.ndarray) -> tuple[np.ndarray, int]:
    """K (2^N, C + 1): K[S, c] the best prize of one option per device of subset S whose services
    take <= c steps (-inf: none fits), for every c <= the capacity any feasible superset of S reads,
    with ``cap`` (2^N,) the capacity of each subset (-1: infeasible) and C its useful maximum."""
    n, n_opt = w.shape
    C = int(min(cap.max(), w.max(axis=1).sum()))
    # need[S]: the largest capacity any superset of S that could be feasible reads from K[S]; -1: none
    subsets = np.arange(1 << n)
    min_service = (((subsets[:, None] >> np.arange(n)) & 1) * w.min(axis=1)).sum(axis=1)
    need = np.where(cap >= min_service, np.minimum(cap, C), -1)
    for k in range(n):
        with_k = subsets[subsets & (1 << k) > 0]
        need[with_k ^ (1 << k)] = np.maximum(need[with_k ^ (1 << k)], need[with_k])
    K = np.full((1 << n, C + 1), -np.inf)
    K[0] = 0.0
    for k in range(n):  # subsets with highest device k from those without it (K[S, c] valid for c <= need[S])
        rows = (1 << k) + np.nonzero(need[1 << k : 2 << k] >= 0)[0]
        if not len(rows):
            continue
        top = int(need[rows].max()) + 1
        src, dst = K[rows - (1 << k), :top], np.full((len(rows), top), -np.inf)
        for o in range(n_opt):
            if w[k, o] < top:
                np.maximum(dst[:, w[k, o] :], src[:, : top - w[k, o]] + prize[k, o], out=dst[:, w[k, o] :])
        K[rows, :top] = dst
    return K, C


def subset_options(K: np.ndarray, w: np.ndarray, prize: np.ndarray, S: int, c: int) -> dict[int, int]:
    """{device: option} of subset ``S`` that reaches K[S, c] (undone from the highest device down)."""
    options, s = {}, S
    while s:
        k = s.bit_length() - 1
        prev = s ^ (1 << k)
        for o in range(w.shape[1]):
            if w[k, o] <= c and K[prev, c - w[k, o]] + prize[k, o] == K[s, c]:
                options[k], c, s = o, c - w[k, o], prev
                break
        else:
            raise RuntimeError("knapsack backtrack failed")
    return options


def route_options(
    travel: np.ndarray, service: np.ndarray, prize: np.ndarray, budget: float, visits: list[tuple[int, int]]
) -> list[tuple[int, int]]:
    """The route of ``visits`` [(device, option), ...] with the best options for its slack (the
    knapsack over its devices in order); ``visits`` unchanged when they are already as good."""
    if not visits:
        return visits
    devs = [d for d, _ in visits]
    nodes = [0] + [d + 1 for d in devs] + [len(travel) - 1]
    step = grid_step(service)
    w = weights(service[devs], step)
    cap = int(capacity(budget - travel[nodes[:-1], nodes[1:]].sum(), step))
    if cap < w.min(axis=1).sum() or cap > 1 << 20:
        return visits
    K = np.full((len(devs) + 1, cap + 1), -np.inf)  # K[i, c]: best prize of the first i devices within c steps
    K[0] = 0.0
    for i, d in enumerate(devs):
        for o in range(w.shape[1]):
            if w[i, o] <= cap:
                np.maximum(K[i + 1, w[i, o] :], K[i, : cap + 1 - w[i, o]] + prize[d, o], out=K[i + 1, w[i, o] :])
    if K[-1, cap] <= sum(prize[d, o] for d, o in visits):
        return visits
    c, options = int(np.argmax(K[-1] >= K[-1, cap])), []
    for i in range(len(devs), 0, -1):
        d = devs[i - 1]
        fits = (o for o in range(w.shape[1]) if w[i - 1, o] <= c)
        o = next(o for o in fits if K[i - 1, c - w[i - 1, o]] + prize[d, o] == K[i, c])
        options.append(o)
        c -= w[i - 1, o]
    return list(zip(devs, reversed(options)))
