"""Held-Karp over device subsets (docs/baselines.md, "Planner"): for every subset S of the devices,
the shortest time q0 -> all of S -> q_fin in any travel matrix, and the path that achieves it.

NumPy only: the orienteering worker processes (``baselines/workers.py``) load it without JAX.
"""

from __future__ import annotations

import functools

import numpy as np


@functools.cache
def _layers(n: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
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


def held_karp(travel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """T (2^N,): shortest time q0 -> all of S -> q_fin for travel (N+2, N+2) over [q0, devices,
    q_fin]; dp, parent (2^N, N) for the path through S ending at device j."""
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


def path(travel: np.ndarray, dp: np.ndarray, parent: np.ndarray, S: int) -> list[int]:
    """The devices of subset ``S`` in the order of its shortest path (from :func:`held_karp`)."""
    order, s = [], S
    if s:
        j = int(np.argmin(dp[s] + travel[1:-1, -1]))
        while s:
            order.append(j)
            s, j = s ^ (1 << j), int(parent[s, j])
    return order[::-1]
